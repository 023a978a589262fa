//! Scenario files: which buses exist, at which bit rates, and which devices sit on them with
//! which settings.
//!
//! A scenario is TOML. Errors name the file, the line and the key, because the person reading
//! them is editing that file:
//!
//! ```toml
//! name = "two generators"
//! seed = 7
//!
//! [[bus]]
//! name = "can0"
//! bit_rate = "500k"
//!
//! [[device]]
//! name = "gen1"
//! kind = "generator"
//! bus = "can0"
//! id = 0x123
//! period_ms = 10
//! ```
//!
//! Device kinds are plug-ins ([`DeviceKind`]) looked up in a [`Registry`]; each kind reads its
//! own keys from the device's table and reports unknown or bad keys with their line, and
//! builds the device. What a device is afterwards (its dictionary, signals, live values,
//! internal faults) it tells as a [`cantwin_twin::Twin`], reached through the simulation.
//!
//! ```
//! use cantwin_scenario::{Registry, Scenario};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let device = |name: &str, id: u32| {
//!     format!("[[device]]\nname = \"{name}\"\nkind = \"generator\"\nbus = \"can0\"\nid = {id}\nperiod_ms = 1\n")
//! };
//! // Two devices: a frame is acknowledged only when another node is on the bus.
//! let text = format!("[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n{}{}", device("a", 0x100), device("b", 0x101));
//! let scenario = Scenario::parse(&text, "inline.toml")?;
//! let mut built = scenario.build(&Registry::builtin(), &Default::default())?;
//! built.sim.run_for(cantwin_can::Duration::from_millis(10));
//! let can0 = built.bus("can0").ok_or("no bus")?;
//! assert_eq!(built.sim.bus(can0).map(|b| b.stats().frames()), Some(20));
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

mod build;
mod error;
#[doc(hidden)]
pub mod fuzz;
pub mod kinds;
mod model;
mod registry;
pub mod script;
mod spec;

pub use build::{Built, BuiltDevice};
pub use cantwin_twin::{LiveValue, Role};
pub use error::{Located, ScenarioError};
pub use model::Scenario;
pub use registry::{BuildEnv, DeviceKind, Registry, Settings};
pub use script::{CheckReport, Script, check, check_with_progress, validate};
pub use spec::{BusSpec, DeviceSpec};
