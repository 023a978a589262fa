//! A generic CiA 402 servo drive twin: a CiA 301 device ([`cantwin_canopen::device`]) whose
//! dictionary holds the CiA 402 objects, with the profile's behaviour from
//! [`cantwin_cia402::drive`] running every operating mode on a motor and load model in
//! virtual time. The dictionary is built in ([`od::description`], with the pre-defined
//! PDO mappings of CiA 402-3) or a vendor's ([`od::hooked`] over a description read from
//! its EDS); [`Servo`] is the node and [`cantwin_twin::Twin`] its face to front ends.
//!
//! ```
//! use cantwin_can::{Frame, Instant, Node, Outbox};
//! use cantwin_servo::{Servo, ServoConfig};
//! use cantwin_cia402::State;
//!
//! let mut servo = Servo::new(ServoConfig::new(5)).expect("valid");
//! let mut out = Outbox::new();
//! servo.on_power_up(Instant::ZERO, &mut out);
//! // The boot-up message, then the master starts the node and enables the drive by SDO:
//! // shutdown, then switch on + enable operation, written to 0x6040.
//! assert_eq!(out.frames()[0].id().as_raw(), 0x705);
//! let t = Instant::from_nanos(1_000_000);
//! servo.on_frame(&Frame::std(0x000, &[0x01, 5]).expect("frame"), t, &mut out);
//! for cw in [0x06u8, 0x0F] {
//!     let sdo = [0x2B, 0x40, 0x60, 0x00, cw, 0x00, 0, 0];
//!     servo.on_frame(&Frame::std(0x605, &sdo).expect("frame"), t, &mut out);
//! }
//! assert_eq!(servo.drive().state(), State::OperationEnabled);
//! ```
#![forbid(unsafe_code)]

pub mod od;
pub mod servo;
mod twin;

pub use servo::{Servo, ServoConfig, ServoError, ServoHooks};
