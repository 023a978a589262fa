//! The CiA 402 drive profile, reusable by any drive: the objects ([`objects`]), the power
//! drive state machine ([`state`]), the controlword and statusword ([`controlword`],
//! [`statusword`]), the option codes that say how the drive stops ([`options`]), the modes
//! of operation ([`modes`]) and velocity mode with its limits and ramps ([`vl`]).
//!
//! Like the other profiles it is sans-IO and pure: a drive model feeds the controlword
//! and its own facts (a fault present, the motor stopped) to a [`PowerStateMachine`],
//! drives its power stage from the [`PowerStage`] it gets back, steps the vl ramp with
//! the time that passed and writes the [`Statusword`] and the velocity demand back.
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_can::Duration;
//! use cantwin_canopen::od::{ObjectDictionary, OdBuilder, Value};
//! use cantwin_cia402::objects::{self, Objects};
//! use cantwin_cia402::vl::{VelocityMode, VlParams};
//! use cantwin_cia402::{Facts, OptionCodes, PowerStateMachine, State, StatusFlags};
//!
//! let desc = objects::add_objects(OdBuilder::new(), &Objects::velocity_drive())
//!     .build()
//!     .expect("valid");
//! let mut od = ObjectDictionary::new(Arc::new(desc), 1);
//! let mut drive = PowerStateMachine::new().with_options(OptionCodes::from_od(&od, OptionCodes::STANDARD));
//! let mut vl = VelocityMode::new();
//!
//! // Transition 1 (initialised), then shutdown (2) and switch on + enable operation (3 + 4),
//! // with the vl ramp function generator bits 4–6 set.
//! drive.update(0x0000, Facts::default());
//! drive.update(0x0006, Facts::default());
//! let step = drive.update(0x007F, Facts::default());
//! assert_eq!(step.transitions, [3, 4]);
//! assert_eq!(drive.state(), State::OperationEnabled);
//!
//! // 1500 rpm at the default 1000 rpm per second: 500 rpm after half a second.
//! od.set(objects::VL_TARGET_VELOCITY, 0, &Value::Integer16(1500)).expect("exists");
//! let params = VlParams::from_od(&od, VlParams::default());
//! let stage = drive.power_stage();
//! for _ in 0..500 {
//!     vl.step(1500, drive.controlword(), &stage, &params, Duration::from_millis(1));
//! }
//! assert_eq!(vl.demand(), 500);
//!
//! let flags = StatusFlags { voltage_enabled: stage.voltage, remote: true, ..StatusFlags::default() };
//! assert_eq!(drive.statusword(flags).0, 0x0237);
//! assert_eq!(drive.statusword(flags).state_name(), "operation enabled");
//! ```
#![forbid(unsafe_code)]

pub mod controlword;
pub mod index;
pub mod modes;
pub mod objects;
pub mod options;
pub mod state;
pub mod statusword;
pub mod vl;

pub use controlword::{Command, Controlword};
pub use modes::{Mode, SupportedModes};
pub use options::{OptionCodes, StopRamp};
pub use state::{Facts, Motion, PowerStage, PowerStateMachine, State, Step, StopReason};
pub use statusword::{StatusFlags, Statusword};
