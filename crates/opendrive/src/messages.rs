//! The application data of the three messages, typed, for masters and tools (manual §3):
//! what a CAL master puts into [`cantwin_cal::CmsClient`] requests and reads out of its
//! confirmations and notifications.

use cantwin_cal::{ClientObject, CmsClient, CobPair, Mux, ObjectKind, ServerObject};

use crate::params::{P180, P181, P183, P184, P186, P187, ParId};

/// The command bits of message 0 (manual §3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Commands {
    /// "riferimento Remote": the CAN reference is the frequency reference.
    pub reference_remote: bool,
    /// "comando Remote": start and reverse come from CAN.
    pub command_remote: bool,
    /// "CAN-Start" (logic function 100).
    pub can_start: bool,
    /// "CAN-Reverse" (logic function 112): rotation to the left.
    pub can_reverse: bool,
}

/// A two-bit code of message 0's command byte (manual §3.1, "Tabella codice comando").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Code {
    /// `00` (or `11`): no change.
    #[default]
    NoChange,
    /// `01`: reset.
    Reset,
    /// `10`: set.
    Set,
}

impl Code {
    const fn bits(self) -> u8 {
        match self {
            Code::NoChange => 0b00,
            Code::Reset => 0b01,
            Code::Set => 0b10,
        }
    }

    const fn from_bits(b: u8) -> Code {
        match b & 0b11 {
            0b01 => Code::Reset,
            0b10 => Code::Set,
            _ => Code::NoChange,
        }
    }

    /// `Set` for true, `Reset` for false.
    pub const fn of(on: bool) -> Code {
        if on { Code::Set } else { Code::Reset }
    }
}

/// Message 0's command byte: one code per command bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct CommandByte {
    /// "riferimento Remote" (bits 7–6).
    pub reference_remote: Code,
    /// "comando Remote" (bits 5–4).
    pub command_remote: Code,
    /// "CAN-Start" (bits 3–2); valid only with command remote set.
    pub can_start: Code,
    /// "CAN-Reverse" (bits 1–0); valid only with command remote set.
    pub can_reverse: Code,
}

impl CommandByte {
    /// The byte.
    pub const fn encode(self) -> u8 {
        self.reference_remote.bits() << 6
            | self.command_remote.bits() << 4
            | self.can_start.bits() << 2
            | self.can_reverse.bits()
    }

    /// From a byte (`11` reads as no change).
    pub const fn decode(b: u8) -> CommandByte {
        CommandByte {
            reference_remote: Code::from_bits(b >> 6),
            command_remote: Code::from_bits(b >> 4),
            can_start: Code::from_bits(b >> 2),
            can_reverse: Code::from_bits(b),
        }
    }
}

/// A frequency in 0.01 Hz, as message 0 and mux 0x00 carry it (`0x1388` = 50.00 Hz), or
/// `None` outside 0–655.35 Hz.
pub fn centi_hz(hz: f64) -> Option<u16> {
    let c = (hz * 100.0).round();
    (0.0..=65535.0).contains(&c).then_some(c as u16)
}

/// Message 0 write data: `cmd ref_lo ref_hi`.
pub fn message0_write(command: CommandByte, reference_centi_hz: u16) -> [u8; 3] {
    let [lo, hi] = reference_centi_hz.to_le_bytes();
    [command.encode(), lo, hi]
}

/// Message 0's answer: the command state and the frequency reference in use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message0State {
    /// The command bits.
    pub commands: Commands,
    /// The reference in use (0.01 Hz).
    pub reference_centi_hz: u16,
}

impl Message0State {
    /// From the answer's data (`state ref_lo ref_hi`); `None` if it is not 3 bytes or a
    /// pair is neither `10` nor `01`.
    pub fn decode(data: &[u8]) -> Option<Message0State> {
        let [state, lo, hi] = <[u8; 3]>::try_from(data).ok()?;
        let bit = |shift: u8| match (state >> shift) & 0b11 {
            0b10 => Some(true),
            0b01 => Some(false),
            _ => None,
        };
        Some(Message0State {
            commands: Commands {
                reference_remote: bit(6)?,
                command_remote: bit(4)?,
                can_start: bit(2)?,
                can_reverse: bit(0)?,
            },
            reference_centi_hz: u16::from_le_bytes([lo, hi]),
        })
    }
}

/// Message 1's event data, decoded (manual §3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ErrorFlags {
    /// The warning byte (not handled by the drive: 0).
    pub warnings: u8,
    /// Bit 7: overcurrent (A2, A3).
    pub overload: bool,
    /// Bit 6: overtemperature (A4, A5).
    pub overtemperature: bool,
    /// Bit 5: overvoltage (A11).
    pub overvoltage: bool,
}

impl ErrorFlags {
    /// From the notification's 2 data bytes.
    pub fn decode(data: &[u8]) -> Option<ErrorFlags> {
        let [warnings, flags] = <[u8; 2]>::try_from(data).ok()?;
        Some(ErrorFlags {
            warnings,
            overload: flags & 0x80 != 0,
            overtemperature: flags & 0x40 != 0,
            overvoltage: flags & 0x20 != 0,
        })
    }
}

/// One entry of message 2's multiplexor table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MuxEntry {
    /// The multiplexor.
    pub mux: u8,
    /// A short name for tools.
    pub name: &'static str,
    /// What the 16-bit data means.
    pub data: &'static str,
    /// Whether it can be written.
    pub writable: bool,
    /// Whether it can be read.
    pub readable: bool,
    /// The quantity's unit as the manual gives it ("" for a code).
    pub unit: &'static str,
    /// Data per unit, as a fraction (numerator, denominator): 0.01 Hz, 0.1 s, 256 = 200 %.
    pub data_per_unit: (u32, u32),
}

impl MuxEntry {
    /// The 16-bit data for `value` in [`MuxEntry::unit`], rounded to the data's
    /// resolution; `None` if it is not a number or outside 0..=65535 once scaled.
    pub fn data_of(&self, value: f64) -> Option<u16> {
        let (num, den) = self.data_per_unit;
        let raw = (value * f64::from(num) / f64::from(den.max(1))).round();
        (raw.is_finite() && (0.0..=65535.0).contains(&raw)).then_some(raw as u16)
    }

    /// The value in [`MuxEntry::unit`] that `data` carries.
    pub fn value_of(&self, data: u16) -> f64 {
        let (num, den) = self.data_per_unit;
        f64::from(data) * f64::from(den) / f64::from(num.max(1))
    }
}

/// Message 2's multiplexors (manual §3.3).
pub const MUX_TABLE: &[MuxEntry] = &[
    MuxEntry {
        mux: 0x00,
        name: "max-frequency",
        data: "maximum frequency fMAX, Hz in 0.01 Hz, P68 20.0-400.0 % of fnom (P68)",
        writable: true,
        readable: true,
        unit: "Hz",
        data_per_unit: (100, 1),
    },
    MuxEntry {
        mux: 0x18,
        name: "current-threshold",
        data: "0 none, 1 STOP with minimum delay, 2 STOP delayed, 3-4 as 0 (C40, P94)",
        writable: true,
        readable: true,
        unit: "",
        data_per_unit: (1, 1),
    },
    MuxEntry {
        mux: 0x19,
        name: "thermal-current",
        data: "thermal current limit, % of the motor's rated current, data 256 = 200 % (P70)",
        writable: true,
        readable: true,
        unit: "%",
        data_per_unit: (32, 25),
    },
    MuxEntry {
        mux: 0x1B,
        name: "stop-delay",
        data: "stop delay, s in 0.1 s, 1-100 s (P94)",
        writable: true,
        readable: true,
        unit: "s",
        data_per_unit: (10, 1),
    },
    MuxEntry {
        mux: 0x34,
        name: "software-version",
        data: "firmware version",
        writable: false,
        readable: true,
        unit: "",
        data_per_unit: (1, 1),
    },
    MuxEntry {
        mux: 0x3A,
        name: "save",
        data: "write 1 to save to flash (C63)",
        writable: true,
        readable: true,
        unit: "",
        data_per_unit: (1, 1),
    },
];

/// The table entry named `name` or numbered `mux`.
pub fn mux_entry(name_or_number: &str) -> Option<&'static MuxEntry> {
    let s = name_or_number.trim();
    let number = s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .map(|h| u8::from_str_radix(h, 16))
        .unwrap_or_else(|| s.parse());
    MUX_TABLE
        .iter()
        .find(|e| e.name.eq_ignore_ascii_case(s) || number.as_ref().is_ok_and(|n| *n == e.mux))
}

/// The multiplexor of an entry.
pub fn mux(entry: &MuxEntry) -> Option<Mux> {
    Mux::new(entry.mux)
}

/// A message 2 error code's meaning (manual §3.3).
pub fn error_text(code: u16) -> &'static str {
    match code {
        0 => "undefined error",
        1 => "multiplexor not valid",
        2 => "value not allowed",
        _ => "unknown error code",
    }
}

/// The CMS objects of the three messages with the COB-IDs of P180–P187.
pub fn cms_objects(p: impl Fn(ParId) -> i32) -> Result<[ServerObject; 3], cantwin_cal::CobIdError> {
    let pair = |rx, tx| {
        let raw = |id| u16::try_from(p(id)).unwrap_or(u16::MAX);
        CobPair::new(raw(rx), raw(tx))
    };
    Ok([
        ServerObject {
            kind: ObjectKind::BasicVariable,
            cobs: pair(P180, P181)?,
        },
        ServerObject {
            kind: ObjectKind::ControlledEvent,
            cobs: pair(P183, P184)?,
        },
        ServerObject {
            kind: ObjectKind::MultiplexedVariable,
            cobs: pair(P186, P187)?,
        },
    ])
}

/// A CAL master for a drive whose COB-IDs are given by `param` (P180–P187), objects in the
/// order [`crate::MESSAGE_0`], [`crate::MESSAGE_1`], [`crate::MESSAGE_2`]; remote reads of
/// message 0 ask for its 4 bytes.
pub fn master(param: impl Fn(ParId) -> i32) -> Result<CmsClient, cantwin_cal::CobIdError> {
    let mut objects: Vec<ClientObject> = cms_objects(param)?
        .iter()
        .map(|o| ClientObject::new(o.kind, o.cobs))
        .collect();
    if let Some(m0) = objects.first_mut() {
        m0.remote_dlc = 4;
    }
    Ok(CmsClient::new(objects))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    #[test]
    fn command_byte_round_trip_and_manual_example() {
        let c = CommandByte {
            reference_remote: Code::Set,
            command_remote: Code::Set,
            can_start: Code::Set,
            can_reverse: Code::Reset,
        };
        assert_eq!(c.encode(), 0b10_10_10_01);
        assert_eq!(CommandByte::decode(0b10_10_10_01), c);
        assert_eq!(CommandByte::decode(0xFF), CommandByte::default());
        assert_eq!(
            message0_write(c, centi_hz(50.0).unwrap()),
            [0xA9, 0x88, 0x13]
        );
        assert_eq!(centi_hz(655.36), None);
    }

    #[test]
    fn state_and_flags_decode() {
        let s = Message0State::decode(&[0xA9, 0x88, 0x13]).unwrap();
        assert!(s.commands.can_start && !s.commands.can_reverse);
        assert_eq!(s.reference_centi_hz, 5000);
        assert_eq!(Message0State::decode(&[0xA8, 0, 0]), None);
        let f = ErrorFlags::decode(&[0, 0xA0]).unwrap();
        assert!(f.overload && !f.overtemperature && f.overvoltage);
    }

    #[test]
    fn mux_lookup_by_name_or_number() {
        assert_eq!(mux_entry("save").map(|e| e.mux), Some(0x3A));
        assert_eq!(mux_entry("0x19").map(|e| e.name), Some("thermal-current"));
        assert_eq!(mux_entry("27").map(|e| e.mux), Some(0x1B));
        assert_eq!(mux_entry("0x01"), None);
        let p = Params::default();
        let m = master(|id| p.get(id)).unwrap();
        assert_eq!(m.objects()[2].cobs.request.as_raw(), 1100);
        assert_eq!(m.objects()[0].remote_dlc, 4);
    }
}
