//! Vector SIL Kit for cantwin: twins join a SIL Kit co-simulation as participants, and
//! cantwin's bus model serves as SIL Kit's CAN network simulator.
//!
//! `libSilKit.so` is loaded at run time ([`SilKit::load`]), so cantwin builds, runs and
//! tests where SIL Kit is not installed; asking for SIL Kit where it is absent gives an
//! [`Error::NotFound`] that says what was tried and how to get it. The C API is reached only
//! through the `ffi` module, the one place with `unsafe` code; everything else here is safe:
//! [`Participant`], [`Lifecycle`], [`TimeSync`] and [`CanController`] wrap SIL Kit's handles,
//! and their callbacks are plain Rust closures.
//!
//! ```no_run
//! use cantwin_silkit::{CanFrame, DirectionMask, OperationMode, Participant, SilKit};
//!
//! # fn main() -> Result<(), cantwin_silkit::Error> {
//! let kit = SilKit::load()?;
//! let p = Participant::create(&kit, "Tester", "silkit://127.0.0.1:8500", "")?;
//! let can = p.can_controller("CAN1", "can0")?;
//! can.on_frame(DirectionMask::Receive, |ev| println!("{:#x} at {} ns", ev.frame.id, ev.timestamp))?;
//! let lifecycle = p.lifecycle(OperationMode::Autonomous)?;
//! let c = can.clone();
//! lifecycle.on_communication_ready(move || {
//!     let _ = c.start();
//! })?;
//! lifecycle.start()?;
//! can.send(&CanFrame { id: 0x000, flags: 0, dlc: 2, data: vec![0x01, 0x00] }, 0)?;
//! lifecycle.stop("done")?;
//! p.wait_for_lifecycle(&lifecycle)?;
//! # Ok(())
//! # }
//! ```
#![deny(unsafe_code)]

pub mod bench;
pub mod bridge;
mod error;
#[allow(unsafe_code)]
mod ffi;
pub mod netsim;
pub mod netsim_faults;
mod types;

pub use bridge::{
    BridgeConfig, BridgeError, Deadlines, PacedBridge, run_synchronized, run_synchronized_within,
};
pub use error::Error;
pub use ffi::{
    CanController, CanEventProducer, LIBRARY_NAME, Lifecycle, Participant, SilKit,
    SimulatedCanNetwork, SystemMonitor, TimeSync,
};
pub use netsim::{
    CanNetworkModel, NetsimConfig, NetsimFaults, NetsimOutcome, run_network_simulator,
    run_network_simulator_with_faults, run_network_simulator_within,
};
pub use netsim_faults::{BusFault, NetsimFault, faults_from_scenario};
pub use types::{
    CanFrame, ControllerState, Direction, DirectionMask, ErrorState, ErrorStateChangeEvent,
    FLAG_BRS, FLAG_ESI, FLAG_FDF, FLAG_IDE, FLAG_RTR, FLAG_SEC, FLAG_XLF, FrameConversionError,
    FrameEvent, OperationMode, ParticipantState, StateChangeEvent, TransmitEvent, TransmitStatus,
};
