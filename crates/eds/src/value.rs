//! Values of `DefaultValue`, `ParameterValue`, `LowLimit` and `HighLimit`, parsed according
//! to the entry's `DataType` (CiA 306 object descriptions), with `$NODEID` kept symbolic.

use cantwin_canopen::od::DataType;
use core::fmt;

/// A value as an EDS/DCF file states it.
///
/// Integers keep their full range (`i128`) so that an out-of-range value survives a round
/// trip and is reported by [`crate::Eds::check`] instead of being silently changed.
#[derive(Debug, Clone)]
pub enum EdsValue {
    /// An integer (BOOLEAN and the INTEGERn/UNSIGNEDn types). Signed types given in hex as a
    /// two's-complement bit pattern (`0xFF` for INTEGER8) are stored as the negative number.
    Integer(i128),
    /// `$NODEID+offset` (CiA 306 object descriptions: the node-ID is added when the value is used); the
    /// forms `$NODEID`, `$NODEID+n` and `n+$NODEID` are accepted.
    NodeId(i128),
    /// REAL32 as a decimal number (a `0x` bit pattern is accepted on input).
    Real32(f32),
    /// REAL64 as a decimal number (a `0x` bit pattern is accepted on input).
    Real64(f64),
    /// VISIBLE_STRING or UNICODE_STRING text.
    Text(String),
    /// OCTET_STRING or DOMAIN bytes, written as hex digits.
    Bytes(Vec<u8>),
    /// Kept as written: a value of a type that is not a basic data type (or TIME_OF_DAY and
    /// TIME_DIFFERENCE, which CiA 306 gives no text form), or an empty numeric value.
    Raw(String),
}

impl PartialEq for EdsValue {
    /// Reals compare by bit pattern, so that NaN equals itself after a round trip.
    fn eq(&self, other: &Self) -> bool {
        use EdsValue::*;
        match (self, other) {
            (Integer(a), Integer(b)) | (NodeId(a), NodeId(b)) => a == b,
            (Real32(a), Real32(b)) => a.to_bits() == b.to_bits(),
            (Real64(a), Real64(b)) => a.to_bits() == b.to_bits(),
            (Text(a), Text(b)) | (Raw(a), Raw(b)) => a == b,
            (Bytes(a), Bytes(b)) => a == b,
            _ => false,
        }
    }
}

/// Parses an integer the way CiA 306 writes numbers: decimal, hexadecimal with a `0x`
/// prefix, octal with a leading `0`, optionally signed.
pub fn parse_integer(text: &str) -> Option<i128> {
    let t = text.trim();
    let (neg, body) = match t.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    if body.is_empty() || body.starts_with(['+', '-']) {
        return None;
    }
    let v = if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        if h.is_empty() || h.starts_with(['+', '-']) {
            return None;
        }
        i128::from_str_radix(h, 16).ok()?
    } else if body.len() > 1 && body.starts_with('0') {
        i128::from_str_radix(&body[1..], 8).ok()?
    } else {
        body.parse::<i128>().ok()?
    };
    Some(if neg { -v } else { v })
}

/// Parses `$NODEID`, `$NODEID+n` or `n+$NODEID` (case-insensitive, spaces allowed) into the
/// offset `n`; `None` if the text has no `$NODEID`, `Some(Err)` if it is malformed.
pub fn parse_node_id_expr(text: &str) -> Option<Result<i128, ()>> {
    let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let upper = compact.to_ascii_uppercase();
    let pos = upper.find("$NODEID")?;
    let before = &compact[..pos];
    let after = &compact[pos + "$NODEID".len()..];
    Some(match (before, after) {
        ("", "") => Ok(0),
        ("", a) => a.strip_prefix('+').and_then(parse_unsigned_term).ok_or(()),
        (b, "") => b.strip_suffix('+').and_then(parse_integer).ok_or(()),
        _ => Err(()),
    })
}

fn parse_unsigned_term(t: &str) -> Option<i128> {
    if t.starts_with(['+', '-']) {
        return None;
    }
    parse_integer(t)
}

/// The inclusive range of an integer data type, `None` for other types.
pub(crate) fn integer_range(ty: DataType) -> Option<(i128, i128)> {
    let bits = ty.fixed_size()? as u32 * 8;
    if ty == DataType::Boolean {
        Some((0, 1))
    } else if ty.is_signed() {
        Some((-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1))
    } else if ty.is_unsigned() {
        Some((0, (1i128 << bits) - 1))
    } else {
        None
    }
}

fn is_hex(t: &str) -> bool {
    let t = t.trim();
    let t = t.strip_prefix('-').unwrap_or(t);
    t.starts_with("0x") || t.starts_with("0X")
}

fn parse_hex_bytes(t: &str) -> Option<Vec<u8>> {
    let hex: String = t.chars().filter(|c| !c.is_whitespace()).collect();
    let hex = hex
        .strip_prefix("0x")
        .or_else(|| hex.strip_prefix("0X"))
        .unwrap_or(&hex);
    if hex.len() % 2 != 0 || !hex.is_ascii() {
        return None;
    }
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).ok())
        .collect()
}

impl EdsValue {
    /// Parses a value of an entry with `DataType=data_type` (its object dictionary index).
    /// The error says what was expected.
    pub fn parse(data_type: Option<u16>, text: &str) -> Result<EdsValue, &'static str> {
        let t = text.trim();
        let Some(ty) = data_type.and_then(DataType::from_index) else {
            return Ok(EdsValue::Raw(t.to_owned()));
        };
        match ty {
            DataType::VisibleString | DataType::UnicodeString => Ok(EdsValue::Text(t.to_owned())),
            DataType::OctetString | DataType::Domain => {
                parse_hex_bytes(t).map(EdsValue::Bytes).ok_or("hex bytes")
            }
            DataType::TimeOfDay | DataType::TimeDifference => Ok(EdsValue::Raw(t.to_owned())),
            _ if t.is_empty() => Ok(EdsValue::Raw(String::new())),
            DataType::Real32 => {
                if is_hex(t) {
                    let bits = parse_integer(t).and_then(|v| u32::try_from(v).ok());
                    bits.map(|b| EdsValue::Real32(f32::from_bits(b)))
                        .ok_or("a REAL32 number")
                } else {
                    t.parse::<f32>()
                        .map(EdsValue::Real32)
                        .map_err(|_| "a REAL32 number")
                }
            }
            DataType::Real64 => {
                if is_hex(t) {
                    let bits = parse_integer(t).and_then(|v| u64::try_from(v).ok());
                    bits.map(|b| EdsValue::Real64(f64::from_bits(b)))
                        .ok_or("a REAL64 number")
                } else {
                    t.parse::<f64>()
                        .map(EdsValue::Real64)
                        .map_err(|_| "a REAL64 number")
                }
            }
            // Some tools write BOOLEAN values as words.
            DataType::Boolean if t.eq_ignore_ascii_case("true") => Ok(EdsValue::Integer(1)),
            DataType::Boolean if t.eq_ignore_ascii_case("false") => Ok(EdsValue::Integer(0)),
            _ => {
                if let Some(expr) = parse_node_id_expr(t) {
                    return expr
                        .map(EdsValue::NodeId)
                        .map_err(|()| "`$NODEID`, `$NODEID+n` or `n+$NODEID`");
                }
                let v = parse_integer(t).ok_or("an integer (decimal, 0x hex or 0 octal)")?;
                // A signed value written in hex is its two's-complement bit pattern when it
                // does not fit the positive range (a common tool convention).
                if ty.is_signed()
                    && is_hex(t)
                    && let Some((lo, hi)) = integer_range(ty)
                    && v > hi
                    && v <= hi - lo
                {
                    return Ok(EdsValue::Integer(v + 2 * lo));
                }
                Ok(EdsValue::Integer(v))
            }
        }
    }

    /// Reads a value as a file states it, never refusing: what does not have the form of the
    /// type is kept as [`EdsValue::Raw`] text (judged, and reported, by [`crate::Eds::check`]
    /// and left out by [`crate::to_od`]). The note says what was read with a guess: lely's
    /// quoted strings (`"text"`) lose their quotes, and an OCTET_STRING or DOMAIN written as
    /// `@` and text (`@ABCD`) is read as the bytes of the text.
    pub fn read(data_type: Option<u16>, text: &str) -> (EdsValue, Option<&'static str>) {
        let t = text.trim();
        match data_type.and_then(DataType::from_index) {
            Some(DataType::VisibleString | DataType::UnicodeString)
                if t.len() >= 2 && t.starts_with('"') && t.ends_with('"') =>
            {
                return (
                    EdsValue::Text(t[1..t.len() - 1].to_owned()),
                    Some("quoted text: read without the quotes"),
                );
            }
            Some(DataType::OctetString | DataType::Domain) if t.starts_with('@') => {
                return (
                    EdsValue::Bytes(t.as_bytes()[1..].to_vec()),
                    Some("`@` and text: read as the bytes of the text"),
                );
            }
            _ => {}
        }
        match EdsValue::parse(data_type, t) {
            Ok(v) => (v, None),
            Err(_) => (EdsValue::Raw(t.to_owned()), None),
        }
    }

    /// The integer the value stands for on a device with this node-ID (`$NODEID` replaced);
    /// `None` for non-integers (and for a sum past the `i128` range).
    pub fn evaluate(&self, node_id: u8) -> Option<i128> {
        match self {
            EdsValue::Integer(v) => Some(*v),
            EdsValue::NodeId(off) => off.checked_add(i128::from(node_id)),
            _ => None,
        }
    }

    /// Writes the value in the canonical form for an entry of `data_type`: unsigned integers
    /// as `0x` hex, signed integers and BOOLEAN in decimal, `$NODEID+0x..`, reals in their
    /// shortest exact decimal form, bytes as contiguous upper-case hex digits (the form
    /// `bytes.fromhex` in python-canopen reads).
    pub fn to_text(&self, data_type: Option<u16>) -> String {
        let ty = data_type.and_then(DataType::from_index);
        match self {
            EdsValue::Integer(v) => {
                if *v >= 0 && ty.is_some_and(DataType::is_unsigned) {
                    format!("0x{v:X}")
                } else {
                    v.to_string()
                }
            }
            EdsValue::NodeId(0) => "$NODEID".to_owned(),
            EdsValue::NodeId(off) if *off > 0 => format!("$NODEID+0x{off:X}"),
            EdsValue::NodeId(off) => format!("{off}+$NODEID"),
            // A NaN keeps its payload and sign only as a bit pattern.
            EdsValue::Real32(v) if v.is_nan() => format!("0x{:08X}", v.to_bits()),
            EdsValue::Real64(v) if v.is_nan() => format!("0x{:016X}", v.to_bits()),
            EdsValue::Real32(v) => v.to_string(),
            EdsValue::Real64(v) => v.to_string(),
            EdsValue::Text(s) | EdsValue::Raw(s) => s.clone(),
            EdsValue::Bytes(b) => b.iter().map(|x| format!("{x:02X}")).collect(),
        }
    }
}

impl fmt::Display for EdsValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_text(None))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia306_4_1_integer_notations() {
        assert_eq!(parse_integer("10"), Some(10));
        assert_eq!(parse_integer("0x1A"), Some(26));
        assert_eq!(parse_integer("0X1a"), Some(26));
        assert_eq!(parse_integer("010"), Some(8));
        assert_eq!(parse_integer("0"), Some(0));
        assert_eq!(parse_integer("-5"), Some(-5));
        assert_eq!(parse_integer("-0x10"), Some(-16));
        assert_eq!(parse_integer("08"), None);
        assert_eq!(parse_integer("0x"), None);
        assert_eq!(parse_integer("--1"), None);
        assert_eq!(parse_integer(""), None);
    }

    #[test]
    fn cia306_nodeid_expressions() {
        assert_eq!(parse_node_id_expr("$NODEID+0x180"), Some(Ok(0x180)));
        assert_eq!(parse_node_id_expr("0x200 + $NodeId"), Some(Ok(0x200)));
        assert_eq!(parse_node_id_expr("$NODEID"), Some(Ok(0)));
        assert_eq!(parse_node_id_expr("$NODEID-1"), Some(Err(())));
        assert_eq!(parse_node_id_expr("1+$NODEID+2"), Some(Err(())));
        assert_eq!(parse_node_id_expr("0x180"), None);
        let v = EdsValue::parse(Some(7), "$NODEID+0x180").unwrap();
        assert_eq!(v, EdsValue::NodeId(0x180));
        assert_eq!(v.evaluate(5), Some(0x185));
        assert_eq!(v.to_text(Some(7)), "$NODEID+0x180");
        assert_eq!(EdsValue::NodeId(0).to_text(Some(5)), "$NODEID");
    }

    #[test]
    fn values_parse_per_data_type() {
        assert_eq!(EdsValue::parse(Some(2), "0xFF"), Ok(EdsValue::Integer(-1)));
        assert_eq!(
            EdsValue::parse(Some(4), "0x80000000"),
            Ok(EdsValue::Integer(-(1 << 31)))
        );
        assert_eq!(EdsValue::parse(Some(4), "-12"), Ok(EdsValue::Integer(-12)));
        assert_eq!(EdsValue::parse(Some(8), "1.5"), Ok(EdsValue::Real32(1.5)));
        assert_eq!(
            EdsValue::parse(Some(8), "0x3F800000"),
            Ok(EdsValue::Real32(1.0))
        );
        assert_eq!(
            EdsValue::parse(Some(0x11), "-2.25"),
            Ok(EdsValue::Real64(-2.25))
        );
        assert_eq!(
            EdsValue::parse(Some(9), "a b"),
            Ok(EdsValue::Text("a b".into()))
        );
        assert_eq!(
            EdsValue::parse(Some(10), "01 A0"),
            Ok(EdsValue::Bytes(vec![1, 0xA0]))
        );
        assert_eq!(EdsValue::parse(Some(15), ""), Ok(EdsValue::Bytes(vec![])));
        assert_eq!(
            EdsValue::parse(Some(7), ""),
            Ok(EdsValue::Raw(String::new()))
        );
        assert_eq!(
            EdsValue::parse(Some(0x40), "xyz"),
            Ok(EdsValue::Raw("xyz".into()))
        );
        assert_eq!(EdsValue::parse(Some(1), "TRUE"), Ok(EdsValue::Integer(1)));
        assert_eq!(EdsValue::parse(Some(1), "false"), Ok(EdsValue::Integer(0)));
        assert!(EdsValue::parse(Some(7), "12z").is_err());
        assert!(EdsValue::parse(Some(10), "0A1").is_err());
        assert!(EdsValue::parse(Some(8), "one").is_err());
    }

    #[test]
    fn canonical_text() {
        assert_eq!(EdsValue::Integer(0x191).to_text(Some(7)), "0x191");
        assert_eq!(EdsValue::Integer(-3).to_text(Some(3)), "-3");
        assert_eq!(EdsValue::Integer(1).to_text(Some(1)), "1");
        assert_eq!(EdsValue::Bytes(vec![0xDE, 0xAD]).to_text(Some(10)), "DEAD");
        assert_eq!(EdsValue::Real32(f32::NAN), EdsValue::Real32(f32::NAN));
    }
}
