//! Data types of reads and writes: the CiA 309-3 mnemonics, values written from text and
//! values shown the way CANopenNode's gateway shows them.

use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{DataType, Value};

use base64::Engine as _;

use crate::error::GwError;
use crate::real::printf_g;

/// The CiA 309-3 data type mnemonics and the CiA 301 types they stand for.
pub const MNEMONICS: &[(&str, DataType)] = &[
    ("b", DataType::Boolean),
    ("i8", DataType::Integer8),
    ("i16", DataType::Integer16),
    ("i24", DataType::Integer24),
    ("i32", DataType::Integer32),
    ("i40", DataType::Integer40),
    ("i48", DataType::Integer48),
    ("i56", DataType::Integer56),
    ("i64", DataType::Integer64),
    ("u8", DataType::Unsigned8),
    ("u16", DataType::Unsigned16),
    ("u24", DataType::Unsigned24),
    ("u32", DataType::Unsigned32),
    ("u40", DataType::Unsigned40),
    ("u48", DataType::Unsigned48),
    ("u56", DataType::Unsigned56),
    ("u64", DataType::Unsigned64),
    ("r32", DataType::Real32),
    ("r64", DataType::Real64),
    ("t", DataType::TimeOfDay),
    ("td", DataType::TimeDifference),
    ("vs", DataType::VisibleString),
    ("os", DataType::OctetString),
    ("us", DataType::UnicodeString),
    ("d", DataType::Domain),
];

/// The data type of a CiA 309-3 mnemonic (`u16`, `vs` …), in any letter case.
pub fn data_type(mnemonic: &str) -> Option<DataType> {
    MNEMONICS
        .iter()
        .find(|(m, _)| m.eq_ignore_ascii_case(mnemonic))
        .map(|(_, t)| *t)
}

/// A data type of a read or write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ty {
    /// A CiA 301 data type.
    Data(DataType),
    /// `x8`…`x64`: an unsigned integer of this many bytes, shown in hex.
    Hex(usize),
    /// `os`, `us`, `d`: the bytes in MIME base64 (RFC 2045), on one line, as CANopenNode's
    /// gateway writes and reads them.
    Base64,
    /// `hex` (CANopenNode's own): the bytes as upper-case hex, two digits each, separated by
    /// spaces.
    HexBytes,
}

/// The type of a mnemonic, including the gateway's own `x8`…`x64`.
pub(crate) fn ty(mnemonic: &str) -> Result<Ty, GwError> {
    match mnemonic.to_ascii_lowercase().as_str() {
        "x8" => Ok(Ty::Hex(1)),
        "x16" => Ok(Ty::Hex(2)),
        "x32" => Ok(Ty::Hex(4)),
        "x64" => Ok(Ty::Hex(8)),
        "hex" => Ok(Ty::HexBytes),
        "os" | "us" | "d" => Ok(Ty::Base64),
        // CANopenNode's gateway has no time types: its table of types ends without them.
        "t" | "td" => Err(GwError::SYNTAX),
        m => data_type(m).map(Ty::Data).ok_or(GwError::SYNTAX),
    }
}

/// A text value: `"…"` with `""` for a quote, or the text as it is.
fn text_value(rest: &str) -> Result<String, GwError> {
    let t = rest.trim();
    let Some(body) = t.strip_prefix('"') else {
        return Ok(t.to_owned());
    };
    let mut s = String::new();
    let mut chars = body.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '"' {
            if chars.peek() == Some(&'"') {
                chars.next();
                s.push('"');
            } else if chars.all(char::is_whitespace) {
                return Ok(s);
            } else {
                return Err(GwError::SYNTAX);
            }
        } else {
            s.push(c);
        }
    }
    Err(GwError::SYNTAX)
}

/// The bytes to write for `value` of type `t`.
pub(crate) fn encode(t: Ty, value: &str) -> Result<Vec<u8>, GwError> {
    match t {
        Ty::Base64 => BASE64
            .decode(value.trim().as_bytes())
            .map_err(|_| GwError::SYNTAX),
        Ty::HexBytes => hex_bytes(value),
        Ty::Hex(n) => {
            let v = number_u64(value.trim()).ok_or(GwError::SYNTAX)?;
            if n < 8 && v >> (8 * n) != 0 {
                return Err(GwError::SYNTAX);
            }
            Ok(v.to_le_bytes()[..n].to_vec())
        }
        Ty::Data(ty @ (DataType::VisibleString | DataType::UnicodeString)) => {
            let s = text_value(value)?;
            Value::parse(ty, &s)
                .map(|v| v.to_le_bytes())
                .map_err(|_| GwError::SYNTAX)
        }
        Ty::Data(DataType::Boolean) => match value.trim() {
            "0" | "false" => Ok(vec![0]),
            "1" | "true" => Ok(vec![1]),
            _ => Err(GwError::SYNTAX),
        },
        Ty::Data(ty) => {
            let v = value.trim();
            if v.is_empty() {
                return Err(GwError::SYNTAX);
            }
            Value::parse(ty, v)
                .map(|v| v.to_le_bytes())
                .map_err(|_| GwError::SYNTAX)
        }
    }
}

/// RFC 2045 base64 (the standard alphabet), padding optional on input.
const BASE64: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
    &base64::alphabet::STANDARD,
    base64::engine::GeneralPurposeConfig::new()
        .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
);

/// Bytes written as hex: two digits make a byte, a space or the end after a single digit
/// ends that byte (`01 2 30 456789 0A b0 0 ff`: 01 02 30 45 67 89 0A B0 00 FF).
fn hex_bytes(value: &str) -> Result<Vec<u8>, GwError> {
    let mut out = Vec::new();
    for token in value.split_whitespace() {
        let digits = token.as_bytes();
        for pair in digits.chunks(2) {
            let text = core::str::from_utf8(pair).map_err(|_| GwError::SYNTAX)?;
            out.push(u8::from_str_radix(text, 16).map_err(|_| GwError::SYNTAX)?);
        }
    }
    if out.is_empty() {
        return Err(GwError::SYNTAX);
    }
    Ok(out)
}

fn number_u64(t: &str) -> Option<u64> {
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

/// The answer to a read: the value as CANopenNode's gateway shows it.
pub(crate) fn show(t: Option<Ty>, data: &[u8]) -> Result<String, GwError> {
    let hex_bytes = |d: &[u8]| {
        d.iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    match t {
        None | Some(Ty::HexBytes) => Ok(hex_bytes(data)),
        Some(Ty::Base64) => Ok(BASE64.encode(data)),
        Some(Ty::Hex(n)) => {
            if data.len() != n {
                return Err(GwError::Abort(AbortCode::TYPE_MISMATCH));
            }
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(data);
            Ok(format!("0x{:0w$X}", u64::from_le_bytes(b), w = 2 * n))
        }
        Some(Ty::Data(ty)) => {
            let v = Value::from_le_bytes(ty, data)
                .map_err(|_| GwError::Abort(AbortCode::TYPE_MISMATCH))?;
            Ok(match v {
                Value::Boolean(b) => u8::from(b).to_string(),
                Value::VisibleString(_) | Value::UnicodeString(_) => {
                    format!("\"{}\"", v.to_string().replace('"', "\"\""))
                }
                Value::Real32(x) => printf_g(f64::from(x)),
                Value::Real64(x) => printf_g(x),
                other => other.to_string(),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CANopenNode's gateway: `os`, `us`, `d` in base64, `hex` as its help text shows it.
    #[test]
    fn cia309_3_written_bytes_in_base64_and_hex() {
        let e = |m: &str, v: &str| encode(ty(m).unwrap(), v);
        assert_eq!(e("os", "Aas=").unwrap(), [1, 0xAB]);
        assert_eq!(e("os", "Aas").unwrap(), [1, 0xAB]);
        assert_eq!(e("d", "Y2FudHdpbg==").unwrap(), b"cantwin");
        assert_eq!(e("us", "QQBCAA==").unwrap(), [0x41, 0, 0x42, 0]);
        assert_eq!(e("os", "not base64!").err(), Some(GwError::SYNTAX));
        assert_eq!(
            e("hex", "01 2 30 456789 0A b0 0 ff").unwrap(),
            [0x01, 0x02, 0x30, 0x45, 0x67, 0x89, 0x0A, 0xB0, 0x00, 0xFF]
        );
        assert_eq!(e("hex", "0g").err(), Some(GwError::SYNTAX));
        assert_eq!(ty("t").err(), Some(GwError::SYNTAX));
        assert_eq!(ty("td").err(), Some(GwError::SYNTAX));
    }

    #[test]
    fn cia309_3_read_values_shown_like_the_reference_gateway() {
        let d = |m: &str| Some(ty(m).unwrap());
        assert_eq!(show(d("u16"), &[0xE8, 0x03]).unwrap(), "1000");
        assert_eq!(show(d("x32"), &[0x91, 0x01, 0, 0]).unwrap(), "0x00000191");
        assert_eq!(show(d("i8"), &[0xFE]).unwrap(), "-2");
        assert_eq!(show(d("b"), &[1]).unwrap(), "1");
        assert_eq!(show(d("vs"), b"a \"b\"").unwrap(), "\"a \"\"b\"\"\"");
        assert_eq!(show(d("os"), &[1, 0xAB]).unwrap(), "Aas=");
        assert_eq!(show(d("d"), b"cantwin").unwrap(), "Y2FudHdpbg==");
        assert_eq!(show(d("us"), &[0x41, 0, 0x42, 0]).unwrap(), "QQBCAA==");
        assert_eq!(
            show(d("hex"), &[0xC8, 0x3D, 0xBB, 0]).unwrap(),
            "C8 3D BB 00"
        );
        assert_eq!(show(None, &[1, 0xAB]).unwrap(), "01 AB");
        // REAL32/REAL64 as C's `%g`: 6 significant digits, the exponent form when large.
        assert_eq!(
            show(d("r32"), &core::f32::consts::PI.to_le_bytes()).unwrap(),
            "3.14159"
        );
        assert_eq!(show(d("r64"), &1e300_f64.to_le_bytes()).unwrap(), "1e+300");
        assert_eq!(show(d("r32"), &1e8_f32.to_le_bytes()).unwrap(), "1e+08");
        assert_eq!(show(d("r64"), &(-0.0_f64).to_le_bytes()).unwrap(), "-0");
        assert_eq!(
            show(d("u32"), &[1, 2]).err(),
            Some(GwError::Abort(AbortCode::TYPE_MISMATCH))
        );
    }
}
