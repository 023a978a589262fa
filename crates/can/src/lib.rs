//! The physical CAN layer as data.
//!
//! Everything above the wire in cantwin is built on the types of this crate:
//!
//! * [`Id`], [`StandardId`], [`ExtendedId`] and [`Frame`]: classic CAN (ISO 11898-1) data and
//!   remote frames with validated constructors;
//! * [`Frame::bit_length`]: the exact number of bits a frame occupies on the bus, from its real
//!   bit stream with the CRC-15 computed and stuff bits counted ([`bits`]);
//! * [`Instant`] and [`Duration`]: bus time in nanoseconds, and [`BitRate`];
//! * [`ErrorCounters`]: fault confinement (TEC/REC, error-active/passive, bus-off);
//! * the sans-IO [`Node`] contract, its [`Outbox`], [`ControllerEvent`]s and [`Filter`]s.
//!
//! ```
//! use cantwin_can::{BitRate, Frame, Id};
//!
//! # fn main() -> Result<(), cantwin_can::FrameError> {
//! let frame = Frame::data(Id::standard(0x123)?, &[0xDE, 0xAD, 0xBE, 0xEF])?;
//! assert_eq!(frame.len(), 4);
//! // The frame's real length on the wire, stuff bits and 3 bits of intermission included.
//! let bits = frame.bit_length();
//! assert!((79..=95).contains(&bits));
//! let on_the_wire = BitRate::R500K.duration_of(bits);
//! assert_eq!(on_the_wire.as_nanos(), u64::from(bits) * 2_000);
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

mod bitrate;
pub mod bits;
mod fault;
mod filter;
mod frame;
#[doc(hidden)]
pub mod fuzz;
mod id;
mod node;
pub mod rng;
mod time;

pub use bitrate::{BitRate, BitRateError};
pub use fault::{ErrorCounters, ErrorState};
pub use filter::{Filter, FilterSet};
pub use frame::{Frame, FrameError};
pub use id::{ExtendedId, Id, IdError, StandardId};
pub use node::{AfterCall, ControllerEvent, ListenOnly, Node, Outbox};
pub use rng::SplitMix64;
pub use time::{Duration, Instant};
