//! One way in from above: front ends (the CLI, the monitor, the web dashboard, Python) see a
//! simulated device as a [`Twin`]: its object dictionary where it has one, its signals as
//! typed ids and values ([`SignalId`], [`SignalValue`], [`SignalError`]), its live values,
//! injectable internal faults ([`Fault`]), its parameters, a summary of its model and, for a
//! personality without a dictionary, its own data sheet. No
//! front end downcasts to a concrete twin type: the bus hands out `&dyn Twin` for the
//! ports whose node is one.
//!
//! The generic CiA 301 [`Device`](cantwin_canopen::device::Device) is a twin here; each
//! device crate implements the trait for its own twin.
//!
//! ```
//! use cantwin_can::{Instant, Outbox};
//! use cantwin_twin::{
//!     Context, Direction, LiveValue, Role, SignalError, SignalId, SignalValue, Twin,
//! };
//!
//! /// A lamp with one switch input.
//! #[derive(Default)]
//! struct Lamp {
//!     on: bool,
//! }
//!
//! impl Twin for Lamp {
//!     fn set_signal(
//!         &mut self,
//!         id: &SignalId,
//!         value: &SignalValue,
//!         _cx: &mut Context<'_>,
//!     ) -> Result<(), SignalError> {
//!         match id.as_str() {
//!             "switch" => self.on = value.to_bool(id)?,
//!             _ => return Err(SignalError::unknown(id, Direction::Set, "switch")),
//!         }
//!         Ok(())
//!     }
//!
//!     fn live_values(&self) -> Vec<LiveValue> {
//!         vec![LiveValue::digital("switch", self.on, Role::DigitalInput)]
//!     }
//! }
//!
//! let mut lamp = Lamp::default();
//! let twin: &mut dyn Twin = &mut lamp;
//! let mut out = Outbox::new();
//! let mut cx = Context::new(Instant::ZERO, &mut out);
//! twin.set_signal(&"switch".into(), &SignalValue::Bool(true), &mut cx)?;
//! assert_eq!(twin.live_values()[0].value, 1.0);
//! let e = twin.set_signal(&"switch".into(), &SignalValue::Integer(3), &mut cx).unwrap_err();
//! assert_eq!(e.to_string(), "signal \"switch\" takes true or false, not 3");
//! let e = twin.read_signal(&"switch".into()).unwrap_err();
//! assert_eq!(e.to_string(), "no signal \"switch\" to read");
//! # Ok::<(), SignalError>(())
//! ```
#![forbid(unsafe_code)]

mod device;
mod fault;
mod live;
mod object;
mod param;
mod sheet;
mod signal;
mod twin;

pub use device::write_through;
pub use fault::{Fault, FaultError, FaultKind};
pub use live::{LiveValue, Role};
pub use object::{Context, ObjectError};
pub use param::{ParameterError, ParameterKey};
pub use sheet::{DataSheetError, FileDate};
pub use signal::{
    Direction, SignalDescription, SignalError, SignalId, SignalValue, Terminal, ValueKind,
};
pub use twin::{SummaryEntry, Twin};
