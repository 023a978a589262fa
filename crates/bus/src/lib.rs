//! A virtual CAN bus that behaves like the wire.
//!
//! * Frames occupy the bus for their exact bit length ([`cantwin_can::Frame::bit_length`]);
//!   pending frames arbitrate as ISO 11898-1 does (lowest arbitration key wins); each port has
//!   a transmit queue ([`PortConfig`], [`TxOrder`]) and optional self-reception.
//! * Acknowledgement, error frames and fault confinement (TEC/REC, error-passive, bus-off
//!   and recovery) as on the wire, reported to nodes as [`cantwin_can::ControllerEvent`]s.
//! * Seeded, replayable fault injection ([`FaultRule`]), forced bus-off, disconnection,
//!   power cycles, babbling and bit-rate-mismatched nodes.
//! * Statistics ([`BusStats`]) and observers ([`Tap`]) for captures and traces.
//! * A [`Simulation`] of one or more buses in virtual time, or a [`PacedSimulation`] paced to
//!   the wall clock with [`ExternalPort`]s for other threads, which receive through an
//!   [`RxQueue`].
//!
//! The exact timing model is described in the [`bus`] module.
//!
//! ```
//! use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
//! use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
//!
//! /// Sends one frame when powered.
//! struct Once(Frame);
//! impl Node for Once {
//!     fn on_power_up(&mut self, _now: Instant, out: &mut Outbox) {
//!         out.push(self.0);
//!     }
//!     fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
//!     fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
//!     fn next_deadline(&self) -> Option<Instant> {
//!         None
//!     }
//! }
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut sim = Simulation::new();
//! let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
//! let a = Frame::std(0x200, &[1])?;
//! let b = Frame::std(0x100, &[2])?;
//! sim.attach(bus, Once(a), PortConfig::default())?;
//! sim.attach(bus, Once(b), PortConfig::default())?;
//! let tap = sim.bus_mut(bus).ok_or("bus")?.add_tap(Recorder::new());
//! sim.run_until(Instant::from_nanos(1_000_000));
//!
//! let rec = sim.bus(bus).and_then(|b| b.tap::<Recorder>(tap)).ok_or("tap")?;
//! let ends: Vec<(u32, u64)> =
//!     rec.frames().map(|f| (f.frame.id().as_raw(), f.end.as_nanos())).collect();
//! // 0x100 wins arbitration; at 1 Mbit/s a bit is 1 µs; delivery at the end of EOF.
//! let (nb, na) = (u64::from(b.bit_length()), u64::from(a.bit_length()));
//! assert_eq!(ends, [(0x100, (nb - 3) * 1000), (0x200, (nb + na - 3) * 1000)]);
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

mod arbiter;
pub mod bench;
pub mod bus;
mod error;
mod fault;
mod ids;
pub mod paced;
mod port;
mod queue;
mod rng;
mod rx_queue;
mod sim;
mod stats;
mod tap;
mod time_map;
mod timers;

pub use bus::{Bus, BusConfig, TapId};
pub use error::BusError;
pub use fault::{FaultAction, FaultRule, FrameSelector};
pub use ids::{BusId, PortId};
pub use paced::{ExternalConfig, ExternalPort, PacedConfig, PacedSimulation, SimHandle, Sink};
pub use port::{AnyNode, BoxedNode, PortConfig, PortStatus};
pub use queue::TxOrder;
pub use rng::SplitMix64;
pub use rx_queue::{Received, RxClosed, RxQueue};
pub use sim::Simulation;
pub use stats::{BusStats, IdStats, PortStats};
pub use tap::{
    AnyTap, BusEvent, BusInfo, ErrorKind, ErrorRecord, FnTap, FrameRecord, Recorder, Tap,
};
pub use time_map::TimeMap;
