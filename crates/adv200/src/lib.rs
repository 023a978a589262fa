//! Digital twin of the Gefran ADV200 drive with the EXP-CAN/DN-ADV fieldbus card.
//!
//! * [`params`]: the parameter database (types, units, defaults, limits, read-only flags);
//! * [`drive`]: command sources, speed ramp, current, thermal model, I/O, alarms;
//! * [`alarms`]: the alarm list and its EMCY codes (§1.5);
//! * [`pdc`]: the Process Data Channel mapping rules (§1.3) and their Opt Bus Fault codes;
//! * [`ds402`]: the CiA 402 power state machine (chapter 2);
//! * [`devicenet`]: the DeviceNet personality (chapter 3);
//! * [`od`]: the card's object dictionary for the CANopen and DS402 personalities;
//! * [`eds`]: their EDS files, generated from the dictionary;
//! * [`card`]: the drive and its card as one sans-IO [`cantwin_can::Node`];
//! * [`example`]: the worked example of §1.6 as a ready network.
//!
//! ```
//! use cantwin_adv200::{Adv200, Adv200Config, params::par};
//! use cantwin_can::{Frame, Instant, Node, Outbox};
//!
//! let mut drive = Adv200::new(Adv200Config::default());
//! // §1.6.2.1: CANopen, 500 kbit/s, node 12 — effective after the next drive reset.
//! drive.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
//! drive.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
//! drive.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
//! let mut out = Outbox::new();
//! drive.on_power_up(Instant::ZERO, &mut out);
//! assert_eq!(out.frames()[0], Frame::std(0x70C, &[0x00]).unwrap()); // boot-up
//! // §1.4: write 1000 to PAR 600 (index 0x2258 sub 1) with four data bytes.
//! out.clear();
//! let req = Frame::std(0x60C, &[0x23, 0x58, 0x22, 0x01, 0xE8, 0x03, 0x00, 0x00]).unwrap();
//! drive.on_frame(&req, Instant::from_nanos(1_000_000), &mut out);
//! assert_eq!(out.frames()[0], Frame::std(0x58C, &[0x60, 0x58, 0x22, 0x01, 0, 0, 0, 0]).unwrap());
//! assert_eq!(drive.param(par::DIG_RAMP_REF_1), Ok(1000));
//! ```
#![forbid(unsafe_code)]

pub mod alarms;
pub mod card;
pub mod devicenet;
pub mod drive;
pub mod ds402;
pub mod eds;
pub mod example;
pub mod od;
pub mod params;
pub mod pdc;

pub use card::{Adv200, Adv200Config, Leds};
