//! CiA 306 EDS and DCF files.
//!
//! * [`load`] reads any file, as the files in the field are written, into the typed model
//!   [`Eds`] and a [`Report`] of diagnostics (error, warning, note) naming line, section and
//!   key: nothing is refused, and [`to_od`] builds the dictionary the file evidently means
//!   from the same judgement of every value that [`Eds::check`] reports.
//! * [`parse`] reads a file into the typed model [`Eds`], refusing it at the first error: every section and key of CiA 306
//!   (`FileInfo`, `DeviceInfo` with bit rates and granularity, `DummyUsage`, `Comments`, the
//!   object lists, objects and sub-objects, `CompactSubObj` with its `Name`/`Value`/
//!   `Denotation` sections, `ObjectLinks`, DCF `ParameterValue`, `Denotation` and
//!   `[DeviceComissioning]`), with values typed by their `DataType` and `$NODEID` kept
//!   symbolic ([`EdsValue::NodeId`]); unknown sections and keys are kept in order. Errors
//!   name the line, section and key ([`ParseError`]); bad input never panics.
//! * [`write()`] writes the canonical layout; `parse(&write(&m))? == m` for every parsed `m`.
//! * [`Eds::check`] reports errors and warnings ([`Report`]).
//! * [`render_markdown`] documents a device.
//! * [`from_od`] makes the EDS of a device from its object dictionary; [`to_od`] builds an
//!   object dictionary description from an EDS, [`to_dcf`] writes a configured device's
//!   values as a DCF and [`apply_parameter_values`] loads a DCF's values into a device.
//!
//! Parsing decisions (CiA 306 leaves them open): section and key names are matched without
//! regard to case; a `;` (or, with a note, `#`) starts a comment at the start of a line,
//! and a `;` after white space starts an inline comment (with a note: python-canopen reads
//! them so, CiA 306 has none); a duplicate section, or a duplicate key in a section, is an
//! error naming both lines, and the first is kept. Files that are not UTF-8 are read as
//! Windows-1252 ([`parse_bytes`]), with a note from [`load_bytes`].
//!
//! What is written is what python-canopen's importer reads: keys in CiA 306 spelling (its
//! reader is case-sensitive), `[DeviceComissioning]` with CiA 306's spelling, integers as
//! `0x` hex or decimal (never a leading-zero octal, which Python's `int(x, 0)` refuses),
//! `$NODEID+0x..`, OCTET_STRING and DOMAIN values as bare hex digits, and a `[xxxxName]`
//! section naming every sub-object of a compact array. [`Eds::check`] warns about what that
//! reader would trip on (a `;` after white space in a value, an incomplete `[DummyUsage]`).
//!
//! ```
//! use cantwin_eds::{EdsValue, parse, write};
//!
//! let text = "\
//! [DeviceInfo]
//! VendorName=Example
//! BaudRate_500=1
//!
//! [MandatoryObjects]
//! SupportedObjects=1
//! 1=0x1000
//!
//! [1000]
//! ParameterName=Device type
//! ObjectType=0x7
//! DataType=0x0007
//! AccessType=ro
//! DefaultValue=0x00000191
//!
//! [1014]
//! ParameterName=COB-ID EMCY
//! DataType=0x0007
//! AccessType=ro
//! DefaultValue=$NODEID+0x80
//! ";
//! let eds = parse(text)?;
//! assert_eq!(eds.device_info.baud_rates(), vec![500]);
//! let emcy = eds.entry(0x1014, 0).and_then(|e| e.default_value.as_ref());
//! assert_eq!(emcy, Some(&EdsValue::NodeId(0x80)));
//! assert_eq!(emcy.and_then(|v| v.evaluate(5)), Some(0x85));
//! assert_eq!(parse(&write(&eds))?, eds);
//!
//! let err = parse("[1000]\nParameterName=x\nDataType=0x0007\nAccessType=rx\n").unwrap_err();
//! assert_eq!(err.to_string(), "line 4 [1000] AccessType: invalid value \"rx\": expected ro, wo, rw, rwr, rww or const; held as ro");
//!
//! // `load` reads what `parse` refuses, and reports.
//! let loaded = cantwin_eds::load("[1000]\nParameterName=x\nDataType=0x0007\nAccessType=rx\n");
//! assert!(loaded.eds.objects.contains_key(&0x1000));
//! assert_eq!(loaded.report.errors().count(), 1);
//! # Ok::<(), cantwin_eds::ParseError>(())
//! ```
#![forbid(unsafe_code)]

mod check;
mod doc;
mod error;
#[doc(hidden)]
pub mod fuzz;
mod ini;
mod judge;
mod model;
mod od;
mod parse;
mod pdo;
mod value;
mod write;

pub use check::{Issue, Report, Severity};
pub use doc::render_markdown;
pub use error::{ParseError, ParseErrorKind};
pub use model::{
    DeviceCommissioning, DeviceInfo, Eds, Entry, FileInfo, Object, ObjectList, Section,
};
pub use od::{
    ConvertError, apply_parameter_values, commission, configured, device_warnings, from_od,
    power_on_defaults, to_dcf, to_od,
};
pub use parse::{Loaded, decode, load, load_bytes, parse};
pub use pdo::pdo_issues;
pub use value::{EdsValue, parse_integer, parse_node_id_expr};
pub use write::write;

/// Object code DOMAIN (CiA 301 table 42).
pub const DOMAIN: u8 = 0x2;
/// Object code VAR.
pub const VAR: u8 = 0x7;
/// Object code ARRAY.
pub const ARRAY: u8 = 0x8;
/// Object code RECORD.
pub const RECORD: u8 = 0x9;

/// Parses bytes: UTF-8 when valid, Windows-1252 otherwise (see [`decode`]).
pub fn parse_bytes(bytes: &[u8]) -> Result<Eds, ParseError> {
    parse(&decode(bytes))
}
