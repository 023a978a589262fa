//! Replay a capture on a scenario's twins: put the capture's master frames back on freshly
//! built twins in virtual time and compare what the twins answer with what the capture
//! holds, frame by frame. A front model: no files, no printing.
//!
//! Which frames are the master's: those whose identifier no twin transmits. The twins'
//! identifiers are learnt from the replay itself, to a fixed point: a first run injects
//! nothing and records what the twins send on their own (boot-up, heartbeats, DeviceNet
//! duplicate MAC ID checks); every further run injects the capture's frames on the
//! identifiers no twin has sent yet and adds what the twins then answer, until the set of
//! injected identifiers stops changing. The identifiers a CANopen twin with node-ID n owns in
//! the predefined connection set (CiA 301 §7.3.5: EMCY 0x80+n, TPDO1–4 0x180+n … 0x480+n,
//! SDO response 0x580+n, NMT error control 0x700+n) always count as the twin's, so that a
//! twin that stopped answering shows as missing frames instead of being replaced by the
//! capture's. NMT (0x000), SDO requests (0x600+n), RPDOs, SYNC and TIME when no twin
//! produces them, and DeviceNet group-2 master messages thus come out as the master's.
//! A fixed list of master identifiers replaces the rule.
//!
//! A replay's cost follows its input, never a timestamp in it: [`CapturedFrames::read`] keeps
//! only the frames of the records it reads and refuses (or shortens) gaps beyond a
//! [`GapBound`], naming the records around them; a run jumps over idle virtual time without
//! work, and keeps at most a hundred twin frames per captured frame (and 100,000 more), so
//! a capture whose span is out of proportion to its size ends in
//! [`ReplayError::TooManyFrames`] instead of growing without bound.
//!
//! ```
//! use cantwin_can::Frame;
//! use cantwin_replay::{Captured, Kind, replay};
//! use cantwin_scenario::{Registry, Scenario};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let scenario = Scenario::parse(
//!     r#"
//!     name = "one device"
//!     [[bus]]
//!     name = "can0"
//!     bit_rate = "500k"
//!     [[device]]
//!     name = "node5"
//!     kind = "cia301"
//!     bus = "can0"
//!     node_id = 5
//!     "#,
//!     "example.toml",
//! )?;
//! // The capture: node 5's boot-up message, the first frame.
//! let captured = [Captured { bus: 0, t: 0, frame: Frame::std(0x705, &[0x00])? }];
//! let report = replay(&scenario, &Registry::builtin(), &captured, 1_000_000, None)?;
//! assert_eq!(report.count(Kind::Matching), 1);
//! assert_eq!(report.count(Kind::Missing) + report.count(Kind::Unexpected), 0);
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

mod diff;
mod error;
mod frames;
mod run;

pub use diff::{Entry, Kind, diff};
pub use error::ReplayError;
pub use frames::{Captured, CapturedFrames, ClampedGap, GapBound, id_key, key_text, seconds};
pub use run::{Progress, Report, replay, replay_with_progress};
