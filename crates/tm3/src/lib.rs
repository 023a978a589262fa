//! Twin of the Schneider TM3 CANopen bus coupler (TM3BCCO) with its TM3 and TM2
//! expansion modules.
//!
//! * [`catalogue`]: the modules and their channels;
//! * [`island`]: the configured modules (up to 14) and where their channels sit;
//! * [`od`]: the object dictionary built from the island — the manual's communication
//!   objects and the CiA 401 objects of `cantwin-cia401`;
//! * [`coupler`]: the coupler as a [`cantwin_can::Node`], with inputs settable and outputs
//!   observable, module faults, failure state and the manual's EMCY codes;
//! * [`diag`]: the EMCY codes, 0x1002/0x1003 formats and the life time factor advice;
//! * [`eds`]: the island's EDS.
//!
//! ```
//! use cantwin_can::{Frame, Instant, Node, Outbox};
//! use cantwin_tm3::coupler::{CouplerConfig, Tm3Coupler};
//! use cantwin_tm3::island::Island;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let island = Island::from_references(&["TM3DI16", "TM3DQ16T", "TM3AI4"])?;
//! let mut coupler = Tm3Coupler::new(CouplerConfig::new(3, island))?;
//! let mut out = Outbox::new();
//! coupler.on_power_up(Instant::ZERO, &mut out);
//! assert_eq!(out.frames(), [Frame::std(0x703, &[0x00])?]); // boot-up
//! out.clear();
//! // NMT start: the event-driven TPDOs are sent once on entering OPERATIONAL.
//! let t = Instant::from_nanos(1_000_000);
//! coupler.on_frame(&Frame::std(0x000, &[0x01, 0x03])?, t, &mut out);
//! assert_eq!(out.frames()[0], Frame::std(0x183, &[0x00])?);
//! out.clear();
//! // Input 0 of module 1 goes high: TPDO1 carries 0x6000 sub 1.
//! let t = Instant::from_nanos(2_000_000);
//! coupler.set_digital_input(1, 0, true)?;
//! coupler.on_tick(t, &mut out);
//! assert_eq!(out.frames(), [Frame::std(0x183, &[0x01])?]);
//! // RPDO1 sets output byte 1: outputs 0 and 2 of module 2 switch on.
//! coupler.on_frame(&Frame::std(0x203, &[0x05])?, t, &mut out);
//! assert!(coupler.digital_output(2, 2)?);
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod catalogue;
pub mod coupler;
pub mod diag;
pub mod eds;
pub mod full_island;

/// A ready-made island for demonstrations: the modules of `scenarios/tm3-island.toml`
/// (digital inputs and outputs, relays, analog inputs and outputs, temperature inputs, a
/// TM2 module).
pub mod demo {
    use crate::coupler::{CouplerConfig, CouplerError, Tm3Coupler};
    use crate::island::Island;

    /// The demo island's modules, in bus order.
    pub const MODULES: [&str; 7] = [
        "TM3DI16",
        "TM3DQ16T",
        "TM3DM24R",
        "TM3AI4",
        "TM3AQ2",
        "TM3TI4",
        "TM2DDI8DT",
    ];

    /// The demo island.
    pub fn island() -> Island {
        // The references are in the catalogue and fewer than 14.
        Island::from_references(&MODULES).unwrap_or_else(|_| unreachable!())
    }

    /// An unpowered coupler at `node_id` carrying the demo island.
    pub fn coupler(node_id: u8) -> Result<Tm3Coupler, CouplerError> {
        Tm3Coupler::new(CouplerConfig::new(node_id, island()))
    }

    #[cfg(test)]
    mod tests {
        #[test]
        fn demo_island_matches_the_scenario() {
            let text = include_str!("../../../scenarios/tm3-island.toml");
            let line = text.lines().find(|l| l.starts_with("modules")).unwrap();
            for m in super::MODULES {
                assert!(line.contains(&format!("\"{m}\"")), "{m}");
            }
            assert_eq!(super::island().modules().len(), 7);
            assert!(super::coupler(3).is_ok());
            assert!(super::coupler(0).is_err());
        }
    }
}
pub mod island;
pub mod od;
mod twin;

pub use coupler::{CouplerConfig, Tm3Coupler};
pub use island::Island;
