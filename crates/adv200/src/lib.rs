//! Digital twin of the Gefran ADV200 drive with the EXP-CAN/DN-ADV fieldbus card.
//!
//! * [`params`]: the parameter database (types, units, defaults, limits, read-only flags);
//! * [`drive`]: command sources, speed ramp, current, thermal model, I/O, alarms;
//! * [`alarms`]: the alarm list and its EMCY codes (§1.5);
//! * [`pdc`]: the Process Data Channel mapping rules (§1.3) and their Opt Bus Fault codes;
//! * [`fieldbus`]: the one path by which either fieldbus writes a parameter;
//! * [`ds402`]: the CiA 402 power drive state machine of `cantwin-cia402` with the card's
//!   option codes (chapter 2);
//! * [`devicenet`]: the DeviceNet personality (chapter 3);
//! * [`od`]: the card's object dictionary for the CANopen and DS402 personalities;
//! * [`station`]: the dictionary's hooks, through which the card reaches the drive;
//! * [`eds`]: their EDS files, generated from the dictionary;
//! * [`card`]: the drive and its card as one sans-IO [`cantwin_can::Node`];
//! * [`example`]: the worked example of §1.6 as a ready network.
//!
//! # Decisions where the manual is garbled or not standard
//!
//! * **Parameter numbers** the manual does not print (channel blocks, commands, I/O, motor):
//!   see [`params`]; channel M2S *n* at 4020 + 10(n−1), S2M *n* at 4180 + 10(n−1) so that
//!   `Dig Fieldbus S->Mn` lands on 4184 + 10(n−1) as §1.3.3 prints it.
//! * **SDO abort codes**: the §1.4 table is OCR-damaged; the CiA 301 codes with the same
//!   meanings are used ([`params::ParamError::abort_code`]).
//! * **§1.4 byte order**: the manual prints the index high byte first (22h 58h); on the wire
//!   it is little-endian, `23 58 22 01 E8 03 00 00` for PAR 600 = 1000.
//! * **Opt Bus Fault** travels as EMCY 0xFF11 with its sub-code in manufacturer bytes 0–1;
//!   alarms listed with a bare number n use 0xFF00 + n ([`alarms`]).
//! * **PDC**: a value-format placeholder (`ipa` = 0) closes the PDO; so does a Fill with
//!   `ipa` = 0 directly after an assigned datum, as the §1.3.1 example needs (RPDO1 and
//!   RPDO2 of 2 words each); any other Fill is padding, a CiA 301 dummy entry in an RPDO; a
//!   32-bit item that would straddle two PDOs raises the channel's size code ([`pdc`]).
//! * **Bus loss from 0x1006**: no SYNC within SYNC_PERIOD × LIFE_TIME_FACTOR (0x1006 ×
//!   0x100D, 3 when 0x100D is 0), the §1.1.3 table ([`card`]).
//! * **TPDO RTR**: COB-ID bit 30 set (no RTR), the meaning of §1.1.7; a write that clears
//!   it, and transmission types other than 1, 254, 255 (§1.1.6, §1.1.7; 252/253 need RTR),
//!   abort 0x06090030 ([`station`]).
//! * **Invalid values**: a value an enumeration does not list is 0x06090030 (DeviceNet code
//!   11), not "too high"; PAR 4006 takes 0 (factory: no address) to 127 (§1.2 "1 a 127").
//! * **0x1008** on the expedited-only card is "ADV2", what one expedited upload carries
//!   (§1.1 item 11); "ADV200" with the limit lifted ([`od`]).
//! * **Vendor IDs** (0x1018 sub 1, DeviceNet Identity attribute 1): the manual gives none
//!   and none could be sourced publicly; 0 unless [`Adv200Config`] gives them.
//! * **DeviceNet body format**: the predefined explicit connection is 8/16 (§3.4.1 addresses
//!   PAR 600 as instance 600) ([`card`]).
//! * **CiA 402**: FAULT REACTION ACTIVE while the motor coasts after a fault; QUICK STOP
//!   ACTIVE shown in a statusword before transition 12, at standstill too ([`ds402`]).
//! * **EMCY** only once the boot-up has been sent, again after every reset communication;
//!   a guarding or heartbeat loss is one EMCY, Opt Bus Fault 8130 ([`card`]).
//! * **0x1010** "save" kept in memory unless a store is given ([`memory`]).
//! * **LEDs**: AL on in every NMT state but Operational (the §1.6.2.1 table) and with Opt
//!   Bus Fault; PWR/+5VC on while the card is powered ([`card`]).
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
pub mod fieldbus;
pub mod memory;
pub mod od;
pub mod params;
pub mod pdc;
pub mod station;
mod twin;

pub use card::{Adv200, Adv200Config, Leds};
