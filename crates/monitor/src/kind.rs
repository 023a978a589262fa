//! Device kinds: what a monitor knows about a kind of device, namely how the data of its
//! PDOs at the pre-defined COB-IDs (CiA 301 §7.3.5) reads as named values.
//!
//! A kind is plain data ([`DeviceKind`] → [`PdoLayout`] → [`Field`]), so a front end can add
//! its own next to the built-in ones ([`DeviceKind::adv200_example`],
//! [`DeviceKind::adv200_ds402`], [`DeviceKind::tm3`], [`DeviceKind::cia401`]).
//!
//! ```
//! use cantwin_can::{Frame, Id};
//! use cantwin_monitor::kind::DeviceKind;
//!
//! let drive = DeviceKind::adv200_ds402();
//! // TPDO1 of node 2: statusword 0x0237 (operation enabled), control effort 1500 rpm.
//! let frame = Frame::data(Id::standard(0x182).unwrap(), &[0x37, 0x02, 0xDC, 0x05]).unwrap();
//! let values = drive.decode(&frame, 2).unwrap();
//! assert_eq!(values[0].text, "0x0237 operation enabled");
//! assert_eq!(values[1].text, "1500 rpm");
//! ```

use cantwin_can::Frame;
use cantwin_canopen::wire::{self, Message, PdoKind};

/// How a field's bits are shown.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Format {
    /// An unsigned integer, with an optional unit.
    Unsigned(Option<String>),
    /// A two's complement integer, with an optional unit.
    Signed(Option<String>),
    /// Each bit as `0`/`1`, most significant first (a byte of digital I/O: `0010_0001`).
    Binary,
    /// Hexadecimal, followed by the names of the bits that are set: `(bit, name)`.
    Flags(Vec<(u8, String)>),
    /// A CiA 402 statusword: hexadecimal and the power drive state it encodes.
    Cia402Statusword,
}

/// One value inside a PDO's data, least significant bit first (CiA 301 §7.4.7.1: PDO data
/// is packed little-endian in mapping order).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// The name shown.
    pub name: String,
    /// The first bit, counted from bit 0 of data byte 0.
    pub offset: u16,
    /// The number of bits, 1–64.
    pub len: u8,
    /// How to show it.
    pub format: Format,
}

impl Field {
    /// A field of `len` bits at bit `offset`.
    pub fn new(name: impl Into<String>, offset: u16, len: u8, format: Format) -> Field {
        Field {
            name: name.into(),
            offset,
            len,
            format,
        }
    }

    /// The raw bits, or `None` when the data is too short to hold the field.
    pub fn raw(&self, data: &[u8]) -> Option<u64> {
        if self.len == 0 || self.len > 64 {
            return None;
        }
        let end = usize::from(self.offset) + usize::from(self.len);
        if end > data.len() * 8 {
            return None;
        }
        let mut v = 0u64;
        for i in 0..usize::from(self.len) {
            let bit = usize::from(self.offset) + i;
            if data[bit / 8] >> (bit % 8) & 1 == 1 {
                v |= 1 << i;
            }
        }
        Some(v)
    }

    /// The raw bits as a number: sign-extended for [`Format::Signed`].
    pub fn number(&self, raw: u64) -> i128 {
        match self.format {
            Format::Signed(_) if self.len < 64 && raw >> (self.len - 1) & 1 == 1 => {
                i128::from(raw) - (1i128 << self.len)
            }
            Format::Signed(_) => i128::from(raw as i64),
            _ => i128::from(raw),
        }
    }

    /// The value as text.
    pub fn show(&self, raw: u64) -> String {
        let with_unit = |n: i128, unit: &Option<String>| match unit {
            Some(u) => format!("{n} {u}"),
            None => n.to_string(),
        };
        let digits = usize::from(self.len).div_ceil(4).max(1);
        match &self.format {
            Format::Unsigned(unit) | Format::Signed(unit) => with_unit(self.number(raw), unit),
            Format::Binary => {
                let bits: String = (0..self.len)
                    .rev()
                    .map(|b| if raw >> b & 1 == 1 { '1' } else { '0' })
                    .collect();
                // Groups of four from the least significant end, as data sheets print them.
                let mut out = String::new();
                for (i, c) in bits.chars().enumerate() {
                    if i > 0 && (bits.len() - i) % 4 == 0 {
                        out.push('_');
                    }
                    out.push(c);
                }
                out
            }
            Format::Flags(names) => {
                let set: Vec<&str> = names
                    .iter()
                    .filter(|(bit, _)| *bit < 64 && raw >> bit & 1 == 1)
                    .map(|(_, n)| n.as_str())
                    .collect();
                if set.is_empty() {
                    format!("0x{raw:0digits$X}")
                } else {
                    format!("0x{raw:0digits$X} {}", set.join(", "))
                }
            }
            Format::Cia402Statusword => {
                format!("0x{raw:04X} {}", cia402_state(raw as u16))
            }
        }
    }
}

/// The ADV200's alarms by EMCY code (EXP-CAN manual, alarm table): the first alarm of a
/// shared code names it.
fn adv200_alarms() -> Vec<(u16, String)> {
    let mut out: Vec<(u16, String)> = Vec::new();
    for alarm in cantwin_adv200::alarms::Alarm::all() {
        let code = alarm.emcy_code();
        if !out.iter().any(|(c, _)| *c == code) {
            out.push((code, format!("ADV200 alarm {}", alarm.name())));
        }
    }
    out
}

/// The power drive state a CiA 402 statusword encodes (statusword bits 0–3, 5 and 6), by
/// the profile's own decoder, or "no defined state".
pub fn cia402_state(sw: u16) -> &'static str {
    cantwin_cia402::Statusword(sw).state_name()
}

/// The fields of one PDO at its pre-defined COB-ID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoLayout {
    /// Which PDO of the node (TPDO: the device sends it; RPDO: the device receives it).
    pub pdo: PdoKind,
    /// Its fields; a field the frame is too short for is left out of the values.
    pub fields: Vec<Field>,
}

/// One decoded value of a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveValue {
    /// The field's name.
    pub name: String,
    /// The PDO that carried it.
    pub pdo: PdoKind,
    /// The raw bits, for values that are numbers of at most 64 bits.
    pub raw: Option<u64>,
    /// The value as text (with its unit).
    pub text: String,
}

/// A kind of device and how its PDOs read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceKind {
    /// A short name (`ADV200`, `TM3`, `CiA 401 I/O`).
    pub name: String,
    /// The PDOs it knows.
    pub pdos: Vec<PdoLayout>,
    /// The meanings its manual gives to EMCY codes, before the generic ones of CiA 301
    /// table 21 (which say little about manufacturer-specific codes).
    pub emcy: Vec<(u16, String)>,
}

/// `TPDO1`, `RPDO2`: the usual name of a PDO.
pub fn pdo_label(kind: PdoKind) -> String {
    match kind {
        PdoKind::Transmit(n) => format!("TPDO{n}"),
        PdoKind::Receive(n) => format!("RPDO{n}"),
    }
}

fn unsigned(unit: &str) -> Format {
    Format::Unsigned((!unit.is_empty()).then(|| unit.to_string()))
}

fn signed(unit: &str) -> Format {
    Format::Signed((!unit.is_empty()).then(|| unit.to_string()))
}

fn flags(names: &[(u8, &str)]) -> Format {
    Format::Flags(names.iter().map(|(b, n)| (*b, n.to_string())).collect())
}

impl DeviceKind {
    /// The device-specific meaning of an EMCY code, if the kind has one.
    pub fn emcy_meaning(&self, code: u16) -> Option<&str> {
        self.emcy
            .iter()
            .find(|(c, _)| *c == code)
            .map(|(_, m)| m.as_str())
    }

    /// The values `frame` carries if it is one of this kind's PDOs for node `node`; `None`
    /// for other frames.
    pub fn decode(&self, frame: &Frame, node: u8) -> Option<Vec<LiveValue>> {
        let Message::Pdo { kind, node: n, .. } = wire::decode(frame) else {
            return None;
        };
        if n != node {
            return None;
        }
        let layout = self.pdos.iter().find(|l| l.pdo == kind)?;
        let data = frame.data_bytes();
        Some(
            layout
                .fields
                .iter()
                .filter_map(|f| {
                    let raw = f.raw(data)?;
                    Some(LiveValue {
                        name: f.name.clone(),
                        pdo: kind,
                        raw: Some(raw),
                        text: f.show(raw),
                    })
                })
                .collect(),
        )
    }

    /// The Gefran ADV200 with the EXP-CAN card in its CANopen personality, wired as the
    /// manual's worked example (§1.6): RPDO1 = control word (bit 0 enable, bit 1 start,
    /// bits 8/9 digital outputs 3/4) and Ramp ref 1 in rpm; TPDO1 = status word (bit 0
    /// enable state, bit 1 drive ok, bit 2 speed is zero, bits 8/9 digital inputs 4/5),
    /// motor speed in rpm and analog input 2.
    pub fn adv200_example() -> DeviceKind {
        DeviceKind {
            name: "ADV200".into(),
            pdos: vec![
                PdoLayout {
                    pdo: PdoKind::Transmit(1),
                    fields: vec![
                        Field::new(
                            "status word",
                            0,
                            16,
                            flags(&[
                                (0, "enable state"),
                                (1, "drive ok"),
                                (2, "speed is zero"),
                                (8, "DI 4"),
                                (9, "DI 5"),
                            ]),
                        ),
                        Field::new("motor speed", 16, 16, signed("rpm")),
                        Field::new("analog input 2", 32, 16, signed("")),
                    ],
                },
                PdoLayout {
                    pdo: PdoKind::Receive(1),
                    fields: vec![
                        Field::new(
                            "control word",
                            0,
                            16,
                            flags(&[(0, "enable"), (1, "start"), (8, "DO 3"), (9, "DO 4")]),
                        ),
                        Field::new("ramp ref 1", 16, 16, signed("rpm")),
                    ],
                },
            ],
            emcy: adv200_alarms(),
        }
    }

    /// The ADV200 in its CiA 402 personality (chapter 2 of the EXP-CAN manual, velocity
    /// mode): RPDO1 = 0x6040 controlword + 0x6042 target velocity, TPDO1 = 0x6041
    /// statusword + 0x6044 control effort, both in rpm.
    pub fn adv200_ds402() -> DeviceKind {
        DeviceKind {
            name: "ADV200 DS402".into(),
            pdos: vec![
                PdoLayout {
                    pdo: PdoKind::Transmit(1),
                    fields: vec![
                        Field::new("statusword", 0, 16, Format::Cia402Statusword),
                        Field::new("control effort", 16, 16, signed("rpm")),
                    ],
                },
                PdoLayout {
                    pdo: PdoKind::Receive(1),
                    fields: vec![
                        Field::new("controlword", 0, 16, unsigned("")),
                        Field::new("target velocity", 16, 16, signed("rpm")),
                    ],
                },
            ],
            emcy: adv200_alarms(),
        }
    }

    /// A CiA 401 generic I/O device with the profile's default mapping: TPDO1 = digital
    /// inputs 0x6000 sub 1–8, RPDO1 = digital outputs 0x6200 sub 1–8 (a byte each),
    /// TPDO2–4 = analog inputs 0x6401 sub 1–12, RPDO2–4 = analog outputs 0x6411 sub 1–12
    /// (INTEGER16, four per PDO).
    pub fn cia401() -> DeviceKind {
        DeviceKind::cia401_named("CiA 401 I/O", Vec::new())
    }

    /// The Schneider TM3 CANopen bus coupler (TM3BCCO): a CiA 401 device whose default PDOs
    /// are the profile's (manual, objects 1600H/1A00H).
    pub fn tm3() -> DeviceKind {
        use cantwin_tm3::diag;
        // The coupler's own codes (manual, object 1003H table); the CiA 301 ones it also
        // raises read as table 21 says.
        let emcy = [
            (diag::ANALOG_DISABLE, "analog input interrupts disabled"),
            (diag::GENERIC_ERROR, "internal communication error"),
            (diag::RX_QUEUE_OVERRUN, "software receive queue overrun"),
            (diag::TX_QUEUE_OVERRUN, "software transmit queue overrun"),
            (diag::CONFIGURATION_TIMEOUT, "module configuration timeout"),
            (
                diag::CONFIGURATION_ERROR,
                "modules do not match the configuration",
            ),
            (diag::RUNTIME_ERROR, "module failed or removed at runtime"),
            (diag::SYNC_TIMEOUT, "SYNC timeout"),
            (
                diag::ROTARY_SWITCH_CHANGED,
                "node-ID switches changed after power-up",
            ),
            (
                diag::NOT_CONFIGURED_IN_OP,
                "operational although not configured",
            ),
        ];
        DeviceKind::cia401_named(
            "TM3",
            emcy.iter().map(|(c, m)| (*c, m.to_string())).collect(),
        )
    }

    fn cia401_named(name: &str, emcy: Vec<(u16, String)>) -> DeviceKind {
        let bytes = |what: &str, pdo| PdoLayout {
            pdo,
            fields: (0..8u16)
                .map(|i| Field::new(format!("{what} {}", i + 1), i * 8, 8, Format::Binary))
                .collect(),
        };
        let analog = |what: &str, pdo, first: u16| PdoLayout {
            pdo,
            fields: (0..4u16)
                .map(|i| Field::new(format!("{what} {}", first + i), i * 16, 16, signed("")))
                .collect(),
        };
        let mut pdos = vec![
            bytes("DI byte", PdoKind::Transmit(1)),
            bytes("DO byte", PdoKind::Receive(1)),
        ];
        for n in 2..=4u8 {
            let first = u16::from(n - 2) * 4 + 1;
            pdos.push(analog("AI", PdoKind::Transmit(n), first));
            pdos.push(analog("AO", PdoKind::Receive(n), first));
        }
        DeviceKind {
            name: name.into(),
            pdos,
            emcy,
        }
    }

    /// A kind recognised from what the bus told about a device: its device type (0x1000)
    /// and its manufacturer device name (0x1008). `None` when nothing fits.
    pub fn identify(device_type: Option<u32>, device_name: Option<&str>) -> Option<DeviceKind> {
        let name = device_name.unwrap_or("");
        // Device type bits 0–15: the device profile number (CiA 301 §7.5.2.1).
        let profile = device_type.map(|t| t & 0xFFFF);
        // The EXP-CAN card serves expedited SDO only (seed 000 §1.1, point 11): its 0x1008
        // is the name's first four bytes, "ADV2"; a card with segmented transfer has all.
        if name.starts_with("ADV200") || name == "ADV2" {
            return Some(match profile {
                Some(402) => DeviceKind::adv200_ds402(),
                _ => DeviceKind::adv200_example(),
            });
        }
        if name.starts_with("TM3") {
            return Some(DeviceKind::tm3());
        }
        match profile {
            Some(401) => Some(DeviceKind::cia401()),
            _ => None,
        }
    }

    /// The built-in kind called `name` (`adv200`, `adv200-ds402`, `tm3`, `cia401`), as
    /// scenario files name device kinds.
    pub fn builtin(name: &str) -> Option<DeviceKind> {
        match name {
            "adv200" => Some(DeviceKind::adv200_example()),
            "adv200-ds402" => Some(DeviceKind::adv200_ds402()),
            "tm3" => Some(DeviceKind::tm3()),
            "cia401" => Some(DeviceKind::cia401()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;

    fn frame(id: u16, data: &[u8]) -> Frame {
        Frame::data(Id::standard(id).unwrap(), data).unwrap()
    }

    #[test]
    fn fields_read_little_endian_bits_and_sign() {
        let f = Field::new("x", 4, 8, signed(""));
        // Bits 4..12 of 0xF0 0x0F: 0xFF = -1.
        assert_eq!(f.raw(&[0xF0, 0x0F]), Some(0xFF));
        assert_eq!(f.show(0xFF), "-1");
        assert_eq!(f.raw(&[0xF0]), None, "too short");
        let u = Field::new("u", 0, 16, unsigned("rpm"));
        assert_eq!(u.show(u.raw(&[0xDC, 0x05]).unwrap()), "1500 rpm");
        let b = Field::new("b", 0, 8, Format::Binary);
        assert_eq!(b.show(0x21), "0010_0001");
        let wide = Field::new("w", 0, 64, signed(""));
        assert_eq!(wide.show(u64::MAX), "-1");
        assert_eq!(Field::new("z", 0, 0, Format::Binary).raw(&[1]), None);
    }

    #[test]
    fn cia402_statusword_states() {
        assert_eq!(cia402_state(0x0000), "not ready to switch on");
        assert_eq!(cia402_state(0x0240), "switch on disabled");
        assert_eq!(cia402_state(0x0231), "ready to switch on");
        assert_eq!(cia402_state(0x0233), "switched on");
        assert_eq!(cia402_state(0x0637), "operation enabled");
        assert_eq!(cia402_state(0x0217), "quick stop active");
        assert_eq!(cia402_state(0x021F), "fault reaction active");
        assert_eq!(cia402_state(0x0218), "fault");
        assert_eq!(cia402_state(0x0001), "no defined state");
        assert_eq!(cia402_state(0x0250), "switch on disabled");
    }

    #[test]
    fn adv200_example_tpdo1_names_status_bits_and_speed() {
        let kind = DeviceKind::adv200_example();
        // Status 0x0107: enable state, drive ok, speed is zero, DI 4; speed -20 rpm; AI2 819.
        let values = kind
            .decode(&frame(0x18C, &[0x07, 0x01, 0xEC, 0xFF, 0x33, 0x03]), 12)
            .unwrap();
        let texts: Vec<(&str, &str)> = values
            .iter()
            .map(|v| (v.name.as_str(), v.text.as_str()))
            .collect();
        assert_eq!(
            texts,
            [
                (
                    "status word",
                    "0x0107 enable state, drive ok, speed is zero, DI 4"
                ),
                ("motor speed", "-20 rpm"),
                ("analog input 2", "819")
            ]
        );
        // Another node's TPDO1, SDO and unknown PDOs are not this device's values.
        assert_eq!(kind.decode(&frame(0x18D, &[0; 6]), 12), None);
        assert_eq!(kind.decode(&frame(0x58C, &[0; 8]), 12), None);
        assert_eq!(kind.decode(&frame(0x28C, &[0; 8]), 12), None);
    }

    #[test]
    fn cia401_values_follow_the_frame_length() {
        let kind = DeviceKind::cia401();
        let values = kind.decode(&frame(0x183, &[0x21]), 3).unwrap();
        assert_eq!(values.len(), 1);
        assert_eq!(values[0].name, "DI byte 1");
        assert_eq!(values[0].text, "0010_0001");
        let ai = kind
            .decode(&frame(0x383, &[0xB0, 0x04, 0xD7, 0x00, 0, 0, 0, 0]), 3)
            .unwrap();
        assert_eq!(ai[0].name, "AI 5");
        assert_eq!(ai[0].text, "1200");
        assert_eq!(ai[1].text, "215");
    }

    #[test]
    fn kinds_are_identified_from_device_type_and_name() {
        assert_eq!(
            DeviceKind::identify(Some(0x0002_0192), Some("ADV200")).map(|k| k.name),
            Some("ADV200 DS402".to_string())
        );
        assert_eq!(
            DeviceKind::identify(Some(0), Some("ADV200")).map(|k| k.name),
            Some("ADV200".to_string())
        );
        assert_eq!(
            DeviceKind::identify(Some(0), Some("ADV2")).map(|k| k.name),
            Some("ADV200".to_string())
        );
        assert_eq!(DeviceKind::identify(Some(0), Some("ADV20")), None);
        assert_eq!(
            DeviceKind::identify(Some(0x0083_0191), Some("TM3BCCO")).map(|k| k.name),
            Some("TM3".to_string())
        );
        assert_eq!(
            DeviceKind::identify(Some(0x000F_0191), None).map(|k| k.name),
            Some("CiA 401 I/O".to_string())
        );
        assert_eq!(DeviceKind::identify(Some(0x0000_012D), None), None);
        assert_eq!(DeviceKind::identify(None, None), None);
        assert_eq!(
            DeviceKind::builtin("tm3").map(|k| k.name),
            Some("TM3".into())
        );
        assert_eq!(DeviceKind::builtin("generator"), None);
    }

    #[test]
    fn kinds_name_their_manufacturer_emcy_codes() {
        let tm3 = DeviceKind::tm3();
        assert_eq!(
            tm3.emcy_meaning(0x0080),
            Some("analog input interrupts disabled")
        );
        assert_eq!(tm3.emcy_meaning(0x8130), None);
        let adv = DeviceKind::adv200_example();
        let overvoltage = adv.emcy_meaning(0x3210).unwrap();
        assert!(overvoltage.starts_with("ADV200 alarm "), "{overvoltage}");
        assert_eq!(DeviceKind::cia401().emcy_meaning(0x0080), None);
    }
}
