//! ODVA Electronic Data Sheets for DeviceNet devices, written from a device's object model.
//!
//! The layout is the one DeviceNet EDS files carry (ODVA EDS specification, DeviceNet
//! flavour): `[File]`, `[Device]` with the Identity object's values, `[Device
//! Classification]` with `Class1 = DeviceNet;`, `[IO_Info]` with the I/O connections and
//! their sizes, `[ParamClass]` and `[Params]` for the Parameter object (class 0x0F).
//! `[Connection Manager]` belongs to EtherNet/IP and ControlNet EDS files and is not
//! written. Every entry ends with `;`; `$` starts a comment.
//!
//! Each `ParamN` describes Parameter object instance N and carries its link path
//! (class 0x0F, instance N, attribute 1), so a configuration tool reads and writes the
//! value there.
//!
//! ```
//! use cantwin_devicenet::eds::{CipType, DeviceEds, EdsDate, EdsParam, EdsTime, FileSection, write};
//! use cantwin_devicenet::Identity;
//!
//! let eds = DeviceEds {
//!     file: FileSection {
//!         description: "demo".into(),
//!         date: EdsDate { month: 1, day: 2, year: 2026 },
//!         time: EdsTime { hour: 12, minute: 0, second: 0 },
//!         revision: (1, 0),
//!     },
//!     identity: Identity {
//!         vendor: 0x1234, device_type: 0x02, product_code: 1, revision: (1, 0),
//!         serial: 42, product_name: "demo".into(),
//!     },
//!     vendor_name: "Vendor".into(),
//!     product_type_name: "AC Drive".into(),
//!     catalog: None,
//!     polled: Some((6, 4)),
//!     params: vec![EdsParam::new(7, "Speed", CipType::Int, 2)],
//! };
//! let text = write(&eds);
//! assert!(text.contains("[Device Classification]\n        Class1 = DeviceNet;"));
//! assert!(text.contains("PollInfo = 0x0001, 1, 1;"));
//! ```

use crate::objects::Identity;
use core::fmt::Write as _;

/// A date as EDS files write it, `MM-DD-YYYY`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdsDate {
    /// 1–12.
    pub month: u8,
    /// 1–31.
    pub day: u8,
    /// The year.
    pub year: u16,
}

/// A time of day as EDS files write it, `HH:MM:SS`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdsTime {
    /// 0–23.
    pub hour: u8,
    /// 0–59.
    pub minute: u8,
    /// 0–59.
    pub second: u8,
}

/// The `[File]` section.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileSection {
    /// `DescText`.
    pub description: String,
    /// `CreateDate` and `ModDate`.
    pub date: EdsDate,
    /// `CreateTime` and `ModTime`.
    pub time: EdsTime,
    /// The file's own revision, `Revision = major.minor`.
    pub revision: (u8, u8),
}

/// CIP elementary data types as the EDS `Data Type` field codes them (CIP Vol. 1 Appendix
/// C).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CipType {
    /// BOOL, 0xC1.
    Bool,
    /// SINT, 0xC2.
    Sint,
    /// INT, 0xC3.
    Int,
    /// DINT, 0xC4.
    Dint,
    /// USINT, 0xC6.
    Usint,
    /// UINT, 0xC7.
    Uint,
    /// UDINT, 0xC8.
    Udint,
    /// REAL, 0xCA.
    Real,
    /// WORD, 0xD2.
    Word,
    /// DWORD, 0xD3.
    Dword,
}

impl CipType {
    /// The type code.
    pub const fn code(self) -> u8 {
        match self {
            CipType::Bool => 0xC1,
            CipType::Sint => 0xC2,
            CipType::Int => 0xC3,
            CipType::Dint => 0xC4,
            CipType::Usint => 0xC6,
            CipType::Uint => 0xC7,
            CipType::Udint => 0xC8,
            CipType::Real => 0xCA,
            CipType::Word => 0xD2,
            CipType::Dword => 0xD3,
        }
    }
}

/// Parameter descriptor bits (Parameter object attribute 4, CIP Vol. 1 §5A-14).
pub mod descriptor {
    /// Supports settable path.
    pub const SETTABLE_PATH: u16 = 0x0001;
    /// Supports enumerated strings (`EnumN` entries).
    pub const ENUMERATED: u16 = 0x0002;
    /// Supports scaling.
    pub const SCALING: u16 = 0x0004;
    /// Read only.
    pub const READ_ONLY: u16 = 0x0010;
    /// Monitor parameter (the value changes by itself).
    pub const MONITOR: u16 = 0x0020;
}

/// One `ParamN` entry: Parameter object instance `number`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EdsParam {
    /// N: the Parameter object instance.
    pub number: u16,
    /// Descriptor bits ([`descriptor`]); [`descriptor::ENUMERATED`] is added when `enums`
    /// is not empty.
    pub descriptor: u16,
    /// Data type.
    pub data_type: CipType,
    /// Data size in bytes.
    pub size: u8,
    /// Name.
    pub name: String,
    /// Units ("" for none).
    pub units: String,
    /// Help text.
    pub help: String,
    /// Minimum, maximum and default values (`None`: left empty).
    pub min: Option<i64>,
    /// Maximum.
    pub max: Option<i64>,
    /// Default.
    pub default: Option<i64>,
    /// Enumerated values and their names (`EnumN`).
    pub enums: Vec<(i64, String)>,
}

impl EdsParam {
    /// A read/write parameter without limits, units or help.
    pub fn new(number: u16, name: impl Into<String>, data_type: CipType, size: u8) -> Self {
        EdsParam {
            number,
            descriptor: 0,
            data_type,
            size,
            name: name.into(),
            units: String::new(),
            help: String::new(),
            min: None,
            max: None,
            default: None,
            enums: Vec::new(),
        }
    }
}

/// What an EDS says about a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceEds {
    /// `[File]`.
    pub file: FileSection,
    /// `[Device]`: the Identity object's vendor, type, product code, revision and name.
    pub identity: Identity,
    /// `VendName`.
    pub vendor_name: String,
    /// `ProdTypeStr` (e.g. "AC Drive" for device type 0x02).
    pub product_type_name: String,
    /// `Catalog`, if any.
    pub catalog: Option<String>,
    /// The polled I/O connection's sizes in bytes: (input = produced by the device,
    /// output = consumed by it); `None` if the device has none.
    pub polled: Option<(u16, u16)>,
    /// The Parameter object's instances.
    pub params: Vec<EdsParam>,
}

/// EDS strings are double-quoted; a quote inside becomes an apostrophe (the format has no
/// escape for it).
fn quoted(s: &str) -> String {
    format!("\"{}\"", s.replace('"', "'"))
}

fn opt(v: Option<i64>) -> String {
    v.map_or_else(String::new, |v| v.to_string())
}

/// The link path to Parameter object instance `n`, attribute 1: logical segments class
/// 0x20 0x0F, instance 0x24 (8-bit) or 0x25 0x00 (16-bit), attribute 0x30 0x01.
pub fn param_path(n: u16) -> Vec<u8> {
    let mut p = vec![0x20, 0x0F];
    match u8::try_from(n) {
        Ok(b) => p.extend([0x24, b]),
        Err(_) => {
            let [lo, hi] = n.to_le_bytes();
            p.extend([0x25, 0x00, lo, hi]);
        }
    }
    p.extend([0x30, 0x01]);
    p
}

fn path_text(p: &[u8]) -> String {
    let hex: Vec<String> = p.iter().map(|b| format!("{b:02X}")).collect();
    quoted(&hex.join(" "))
}

const IND: &str = "        ";

/// The EDS text.
pub fn write(eds: &DeviceEds) -> String {
    let mut s = String::new();
    let f = &eds.file;
    let date = format!("{:02}-{:02}-{:04}", f.date.month, f.date.day, f.date.year);
    let time = format!(
        "{:02}:{:02}:{:02}",
        f.time.hour, f.time.minute, f.time.second
    );
    let _ = writeln!(s, "$ DeviceNet Electronic Data Sheet\n");
    let _ = writeln!(s, "[File]");
    let _ = writeln!(s, "{IND}DescText = {};", quoted(&f.description));
    let _ = writeln!(s, "{IND}CreateDate = {date};");
    let _ = writeln!(s, "{IND}CreateTime = {time};");
    let _ = writeln!(s, "{IND}ModDate = {date};");
    let _ = writeln!(s, "{IND}ModTime = {time};");
    let _ = writeln!(s, "{IND}Revision = {}.{};\n", f.revision.0, f.revision.1);

    let id = &eds.identity;
    let _ = writeln!(s, "[Device]");
    let _ = writeln!(s, "{IND}VendCode = {};", id.vendor);
    let _ = writeln!(s, "{IND}VendName = {};", quoted(&eds.vendor_name));
    let _ = writeln!(s, "{IND}ProdType = {};", id.device_type);
    let _ = writeln!(s, "{IND}ProdTypeStr = {};", quoted(&eds.product_type_name));
    let _ = writeln!(s, "{IND}ProdCode = {};", id.product_code);
    let _ = writeln!(s, "{IND}MajRev = {};", id.revision.0);
    let _ = writeln!(s, "{IND}MinRev = {};", id.revision.1);
    let _ = writeln!(s, "{IND}ProdName = {};", quoted(&id.product_name));
    if let Some(c) = &eds.catalog {
        let _ = writeln!(s, "{IND}Catalog = {};", quoted(c));
    }
    s.push('\n');

    let _ = writeln!(s, "[Device Classification]");
    let _ = writeln!(s, "{IND}Class1 = DeviceNet;\n");

    if let Some((input, output)) = eds.polled {
        // Connection mask bit 0: polled. The I/O data has no assembly path on this kind
        // of device: path size 0.
        let _ = writeln!(s, "[IO_Info]");
        let _ = writeln!(s, "{IND}Default = 0x0001;                $ polled");
        let _ = writeln!(
            s,
            "{IND}PollInfo = 0x0001, 1, 1;        $ polled, Input1, Output1"
        );
        let _ = writeln!(
            s,
            "{IND}Input1 = {input}, 0, 0x0001, \"Poll response\", 0, \"\", \"Data the device produces\";"
        );
        let _ = writeln!(
            s,
            "{IND}Output1 = {output}, 0, 0x0001, \"Poll command\", 0, \"\", \"Data the device consumes\";\n"
        );
    }

    if !eds.params.is_empty() {
        let max = eds.params.iter().map(|p| p.number).max().unwrap_or(0);
        // Class descriptor bit 0: the class has Parameter instances; no configuration
        // assembly.
        let _ = writeln!(s, "[ParamClass]");
        let _ = writeln!(s, "{IND}MaxInst = {max};");
        let _ = writeln!(s, "{IND}Descriptor = 0x01;");
        let _ = writeln!(s, "{IND}CfgAssembly = 0;\n");
        let _ = writeln!(s, "[Params]");
        for p in &eds.params {
            let path = param_path(p.number);
            let mut desc = p.descriptor;
            if !p.enums.is_empty() {
                desc |= descriptor::ENUMERATED;
            }
            let _ = writeln!(s, "{IND}Param{} =", p.number);
            let i2 = "                ";
            let _ = writeln!(s, "{i2}0,{:<24}$ reserved", "");
            let _ = writeln!(
                s,
                "{i2}{}, {},{:<4}$ link path size, link path",
                path.len(),
                path_text(&path),
                ""
            );
            let _ = writeln!(s, "{i2}0x{desc:04X},{:<17}$ descriptor", "");
            let _ = writeln!(
                s,
                "{i2}0x{:02X}, {},{:<16}$ data type, size",
                p.data_type.code(),
                p.size,
                ""
            );
            let _ = writeln!(s, "{i2}{},", quoted(&p.name));
            let _ = writeln!(s, "{i2}{},", quoted(&p.units));
            let _ = writeln!(s, "{i2}{},", quoted(&p.help));
            let _ = writeln!(
                s,
                "{i2}{},{},{},{:<10}$ min, max, default",
                opt(p.min),
                opt(p.max),
                opt(p.default),
                ""
            );
            let _ = writeln!(s, "{i2},,,,{:<20}$ scaling: mult, div, base, offset", "");
            let _ = writeln!(s, "{i2},,,,{:<20}$ links: mult, div, base, offset", "");
            let _ = writeln!(s, "{i2}0;{:<23}$ decimal places", "");
            if !p.enums.is_empty() {
                let list: Vec<String> = p
                    .enums
                    .iter()
                    .map(|(v, n)| format!("{v}, {}", quoted(n)))
                    .collect();
                let _ = writeln!(s, "{IND}Enum{} = {};", p.number, list.join(", "));
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn param_paths_use_8_and_16_bit_instance_segments() {
        assert_eq!(param_path(7), [0x20, 0x0F, 0x24, 7, 0x30, 1]);
        assert_eq!(
            param_path(600),
            [0x20, 0x0F, 0x25, 0x00, 0x58, 0x02, 0x30, 1]
        );
    }

    #[test]
    fn strings_are_quoted_without_inner_quotes() {
        assert_eq!(quoted("a \"b\""), "\"a 'b'\"");
    }
}
