//! A digital twin of the TDE MACNO OPEN DRIVE with application 003, "Sensorless via CAN
//! bus": a V/f sensorless inverter controlled through three CAL CMS messages
//! (CiA DS 202-2, customised by the manufacturer).
//!
//! * [`params`]: the parameters and connections with ranges, defaults and internal units
//!   (manual §1.1, §1.2, §2.3);
//! * [`model`]: the [`Drive`]: input logic (§2.2), DIP S1 (§2.3), message 0 and message 2
//!   semantics (§3.1, §3.3), alarms, and physics stepped at a fixed period;
//! * [`node`]: [`OpenDrive`], the drive on the bus behind a [`cantwin_cal::CmsServer`];
//! * [`messages`]: the messages' data typed for a master ([`messages::master`] builds a
//!   [`cantwin_cal::CmsClient`] for the drive's COB-IDs).
//!
//! # The messages (manual §3)
//!
//! | message | CMS object | request COB (drive receives) | response COB (drive sends) |
//! |---|---|---|---|
//! | 0 commands and reference | Read/Write basic variable | P180 (440 = 0x1B8) | P181 (439 = 0x1B7) |
//! | 1 alarm signalling | controlled event | P183 (430 = 0x1AE) | P184 (429 = 0x1AD) |
//! | 2 parameters | Read/Write multiplexed variable | P186 (1100 = 0x44C) | P187 (1099 = 0x44B) |
//!
//! COB-IDs are CAN identifiers; they and the bit rate (C48) are read from flash at
//! power-up. The byte layout of the CMS frames is documented in [`cantwin_cal::wire`].
//!
//! **Message 0** write: `00 cmd ref_lo ref_hi`; read: `80` (or a remote frame on P181);
//! answer `00 state ref_lo ref_hi` on P181. `cmd` holds four two-bit codes, from the most
//! significant pair: reference remote (bits 7–6), command remote (5–4), CAN-Start (3–2),
//! CAN-Reverse (1–0); `01` reset, `10` set, `00` and `11` no change. In `state` every pair
//! reads `10` (set) or `01` (reset). The reference is in 0.01 Hz (`88 13` = 50.00 Hz);
//! the answer carries the frequency reference in use.
//!
//! **Message 1**: `30` enables, `20` disables notification, confirmed with `30`/`20` on
//! P184. While enabled, every change of the handled alarms sends `10 00 flags`: byte 1 the
//! warnings (not handled: 0), byte 2 bit 7 overcurrent (A2, A3), bit 6 overtemperature
//! (A4, A5), bit 5 overvoltage (A11).
//!
//! **Message 2**: `mux|0x80` reads, `mux lo hi` writes; the answer is `mux lo hi`, or
//! `mux|0x80 code 00` with code 0 undefined error (wrong length), 1 multiplexor not valid,
//! 2 value not allowed.
//!
//! | mux | function | parameters | data |
//! |---|---|---|---|
//! | 0x00 | maximum frequency fMAX | P68 = data / (fnom × 100) | 0.01 Hz; 1000–20000 at fnom = 50 Hz (P68 20.0–400.0 %) |
//! | 0x18 | current threshold reaction | C40 = 1 for 1, 2, else 0; P94 = 1 s for 1 | 0–4 |
//! | 0x19 | thermal current limit | P70 = data × 200 % / 256 | 13–256 (P70 10.0–200.0 %) |
//! | 0x1B | stop delay | P94 = data / 10 s | 10–1000 (1–100 s) |
//! | 0x34 | software version | — | read only |
//! | 0x3A | save | C63 = 1: working values to flash | write 1 only |
//!
//! # Decisions where the manual is silent or unreadable
//!
//! * The command byte's pairs are taken in the order the manual lists them, reference
//!   remote first in the most significant pair. CAN-Start and CAN-Reverse codes are applied
//!   only when command remote is set after the byte's own command remote code; resetting
//!   command remote also resets them, so switching back to remote never restarts the motor.
//! * The maximum frequency is fMAX, P68 (defaults table: 20.0–400.0 %, default 120.0 % of
//!   the motor's rated frequency). The §3.3 table writes "P63" beside mux 0x00, a
//!   parameter no table of the manual has; the range it gives is P68's, and the defaults
//!   P73 = 83.3 % of fMAX (V/f point 1) only meet the rated frequency with fMAX = 120 %: the
//!   twin reads "P63" as P68. Ramps P21–P24 run from 0 to fMAX.
//! * Mux 0x00's data is checked against P68's range in 0.01 Hz (`ceil(200 × fnom_centi /
//!   1000)` to `floor(4000 × fnom_centi / 1000)`: 1000–20000 at 50 Hz) before it is turned
//!   into P68's 0.1 % steps, so 999 or 20001 is code 2 and cannot round into the range.
//! * Message 0 has no error data in the manual (§3.1): a reference above fMAX is taken,
//!   with its command bits, and limited to fMAX where it is used; the answer carries the
//!   reference in use. Only a write of other than 3 bytes (a malformed CMS request) gets
//!   code 0. The CAN reference is
//!   used when reference remote is set and references from the field bus are enabled
//!   (C52 or a logic input with function 114) and DIP S1 was off at power-up.
//! * Logic input meanings C01–C08 hold `function − 100`: 0 start (100), 12 reverse (112),
//!   14 field bus enable (114); the manual's defaults put start on input 4 (C04 = 0). Other
//!   functions are not modelled.
//! * Reserved entries (not loaded by DIP S1) are those the §2.3 table marks `r`. §1.3 says
//!   S1 loads "free and reserved" values, §2.3 says all but the reserved: the twin follows
//!   §2.3, which describes the procedure. The 0 → 1 change is detected against the position
//!   stored in flash at the previous power-up.
//! * Mux 0x18 reads back 0 while C40 = 0, else the code last written (1 or 2, both C40 =
//!   1; 2 reads 2 also while P94 = 1 s); after mains return, which restores C40 and P94
//!   from flash only, a STOP reaction reads 1 with P94 = 1 s and 2 otherwise. Mux 0x34 and
//!   any multiplexor not in the table answer code 1; 0x3A accepts only 1 and reads 0.
//! * Tools take each multiplexor's value in the manual's unit ([`messages::MuxEntry`]:
//!   Hz for 0x00 as message 0's reference, s for 0x1B, % for 0x19), rounded to the data's
//!   resolution.
//! * P70 and C40 are not in the manual's tables: P70 10.0–200.0 % (default 100.0 %), C40
//!   0–1 (default 0). C50's printed range is
//!   unreadable; it is taken as 0/1, default 1, like its neighbours.
//! * Ramp times P21–P24 are from 0 to the maximum frequency; acceleration or deceleration
//!   time by the direction of rotation (CW = reverse reset).
//! * Alarms: A2 overcurrent (instantaneous trip above [`DriveData::overcurrent_trip_pct`],
//!   or a start without flying restart while the motor still turns above 10 % of its rated
//!   frequency), A3 motor I²t overload when C32 = 1 (a warning only with C32 = 0), A4
//!   heatsink overtemperature, A5 power module overtemperature, A11 DC bus overvoltage.
//!   §3.2 names A4 and A5 together as the drive's ("convertitore") overtemperature and
//!   says no more; motor heating is C32's I²t (A3), so both are temperatures of the drive.
//!   The twin measures two of them: the heatsink (A4: slow, a minute, driven by the
//!   ambient and the mean current) and the output stage's junctions (A5: seconds, above the
//!   heatsink by the losses of the current), so A4 follows from a hot cabinet or poor
//!   cooling and A5 from an overload held too long at the current limit. An alarm blocks
//!   the drive; it restarts only after the start
//!   command was removed and given again. Alarms are kept in flash; with C35 = 1 they clear
//!   at mains return (the node's power-up).
//! * No communication watchdog: application 003 defines only the three CMS messages (§3),
//!   no node guarding, no time-out and no alarm for a lost master (message 1 reports
//!   overcurrent, overtemperature and overvoltage only). A drive whose master vanishes
//!   holds its last command and reference; a controller bus-off is recovered by the
//!   controller and changes nothing in the drive (`scenarios/faults/opendrive-*.toml`).
//! * Mains off/on is the node's power cycle on the bus (`Bus::set_powered`): the motor
//!   coasts, temperatures cool, working values come back from flash, events are disabled.
//! * The flash ([`Flash`]) holds the saved parameters, the latched alarms and the DIP S1
//!   position of the last power-up; [`OpenDrive::with_storage`] hands its text image to a
//!   [`FlashStorage`] whenever it changes, so it can outlive the process.
//! * Physics: a fixed step ([`node::DEFAULT_PHYSICS_PERIOD`], 1 ms), per-unit motor model:
//!   current = √(magnetising² + torque²) with torque = load + friction + inertia × ramp;
//!   above the current limit ([`DriveData::current_limit_pct`] of the drive's rated current,
//!   i.e. ÷ P61 for the motor) the ramp holds and, if needed, the frequency falls at the
//!   deceleration rate; the DC bus integrates the power the motor returns
//!   (C·V·dV/dt = −P) and never falls below the rectified mains.
//!
//! ```
//! use cantwin_can::{Duration, Frame, Instant, Node, Outbox};
//! use cantwin_opendrive::{DriveData, MotorData, OpenDrive};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut drive = OpenDrive::new(MotorData::default(), DriveData::default());
//! let mut out = Outbox::new();
//! drive.on_power_up(Instant::ZERO, &mut out);
//! // Message 0: reference remote, command remote and CAN-Start set; 0x1388 = 50.00 Hz.
//! let write = Frame::std(440, &[0x00, 0b10_10_10_00, 0x88, 0x13])?;
//! drive.on_frame(&write, Instant::ZERO, &mut out);
//! assert_eq!(out.frames()[0].to_string(), "1B7#00A98813");
//! // 3 s of physics: the default ramp P21 = 3.00 s from 0 to 50 Hz.
//! let mut t = Instant::ZERO;
//! while t < Instant::from_nanos(3_000_000_000) {
//!     t = drive.next_deadline().ok_or("no deadline")?;
//!     drive.on_tick(t, &mut out);
//! }
//! assert!((drive.drive().output_hz() - 50.0).abs() < 1e-6);
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod messages;
pub mod model;
pub mod node;
pub mod params;
mod twin;

pub use model::{Alarms, Commands, Drive, DriveData, Flash, FlashError, MotorData};
pub use node::{FlashStorage, MESSAGE_0, MESSAGE_1, MESSAGE_2, OpenDrive, bit_rate_of_c48};
pub use params::{ParId, ParamError, Params};
