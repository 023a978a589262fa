//! CiA 301 basic data types (§7.1.4, table 44) and typed values.

use core::fmt;
use core::str::FromStr;

/// A CiA 301 static data type, with its data type index (table 44).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u16)]
pub enum DataType {
    /// BOOLEAN (0x0001): one byte, 0 or 1.
    Boolean = 0x01,
    /// INTEGER8 (0x0002).
    Integer8 = 0x02,
    /// INTEGER16 (0x0003).
    Integer16 = 0x03,
    /// INTEGER32 (0x0004).
    Integer32 = 0x04,
    /// UNSIGNED8 (0x0005).
    Unsigned8 = 0x05,
    /// UNSIGNED16 (0x0006).
    Unsigned16 = 0x06,
    /// UNSIGNED32 (0x0007).
    Unsigned32 = 0x07,
    /// REAL32 (0x0008): IEEE 754 single precision.
    Real32 = 0x08,
    /// VISIBLE_STRING (0x0009): ISO 646 characters (beyond them, UTF-8), variable length.
    VisibleString = 0x09,
    /// OCTET_STRING (0x000A): bytes, variable length.
    OctetString = 0x0A,
    /// UNICODE_STRING (0x000B): UTF-16 code units, little-endian, variable length.
    UnicodeString = 0x0B,
    /// TIME_OF_DAY (0x000C): 28 bits of milliseconds after midnight, 16 bits of days
    /// since 1 January 1984.
    TimeOfDay = 0x0C,
    /// TIME_DIFFERENCE (0x000D): same layout as TIME_OF_DAY.
    TimeDifference = 0x0D,
    /// DOMAIN (0x000F): application-specific bytes of any length.
    Domain = 0x0F,
    /// INTEGER24 (0x0010): three bytes.
    Integer24 = 0x10,
    /// REAL64 (0x0011): IEEE 754 double precision.
    Real64 = 0x11,
    /// INTEGER40 (0x0012): five bytes.
    Integer40 = 0x12,
    /// INTEGER48 (0x0013): six bytes.
    Integer48 = 0x13,
    /// INTEGER56 (0x0014): seven bytes.
    Integer56 = 0x14,
    /// INTEGER64 (0x0015).
    Integer64 = 0x15,
    /// UNSIGNED24 (0x0016): three bytes.
    Unsigned24 = 0x16,
    /// UNSIGNED40 (0x0018): five bytes.
    Unsigned40 = 0x18,
    /// UNSIGNED48 (0x0019): six bytes.
    Unsigned48 = 0x19,
    /// UNSIGNED56 (0x001A): seven bytes.
    Unsigned56 = 0x1A,
    /// UNSIGNED64 (0x001B).
    Unsigned64 = 0x1B,
}

impl DataType {
    /// Every basic data type, in index order.
    pub const ALL: [DataType; 25] = [
        DataType::Boolean,
        DataType::Integer8,
        DataType::Integer16,
        DataType::Integer32,
        DataType::Unsigned8,
        DataType::Unsigned16,
        DataType::Unsigned32,
        DataType::Real32,
        DataType::VisibleString,
        DataType::OctetString,
        DataType::UnicodeString,
        DataType::TimeOfDay,
        DataType::TimeDifference,
        DataType::Domain,
        DataType::Integer24,
        DataType::Real64,
        DataType::Integer40,
        DataType::Integer48,
        DataType::Integer56,
        DataType::Integer64,
        DataType::Unsigned24,
        DataType::Unsigned40,
        DataType::Unsigned48,
        DataType::Unsigned56,
        DataType::Unsigned64,
    ];

    /// The data type with this object dictionary index (0x0001..=0x001B), if it is basic.
    pub fn from_index(index: u16) -> Option<DataType> {
        DataType::ALL.iter().copied().find(|t| *t as u16 == index)
    }

    /// The data type's object dictionary index (used as `DataType=` in EDS files).
    pub const fn index(self) -> u16 {
        self as u16
    }

    /// The encoded size in bytes of a fixed-size type; `None` for strings and DOMAIN.
    pub const fn fixed_size(self) -> Option<usize> {
        use DataType::*;
        Some(match self {
            Boolean | Integer8 | Unsigned8 => 1,
            Integer16 | Unsigned16 => 2,
            Integer24 | Unsigned24 => 3,
            Integer32 | Unsigned32 | Real32 => 4,
            Integer40 | Unsigned40 => 5,
            Integer48 | Unsigned48 | TimeOfDay | TimeDifference => 6,
            Integer56 | Unsigned56 => 7,
            Integer64 | Unsigned64 | Real64 => 8,
            VisibleString | OctetString | UnicodeString | Domain => return None,
        })
    }

    /// Whether the value's length varies (strings and DOMAIN).
    pub const fn is_variable(self) -> bool {
        self.fixed_size().is_none()
    }

    /// Whether the type is a signed integer.
    pub const fn is_signed(self) -> bool {
        use DataType::*;
        matches!(
            self,
            Integer8
                | Integer16
                | Integer24
                | Integer32
                | Integer40
                | Integer48
                | Integer56
                | Integer64
        )
    }

    /// Whether the type is an unsigned integer.
    pub const fn is_unsigned(self) -> bool {
        use DataType::*;
        matches!(
            self,
            Unsigned8
                | Unsigned16
                | Unsigned24
                | Unsigned32
                | Unsigned40
                | Unsigned48
                | Unsigned56
                | Unsigned64
        )
    }

    /// The CiA 301 name of the type (`UNSIGNED32`, `VISIBLE_STRING`, ...).
    pub const fn name(self) -> &'static str {
        use DataType::*;
        match self {
            Boolean => "BOOLEAN",
            Integer8 => "INTEGER8",
            Integer16 => "INTEGER16",
            Integer24 => "INTEGER24",
            Integer32 => "INTEGER32",
            Integer40 => "INTEGER40",
            Integer48 => "INTEGER48",
            Integer56 => "INTEGER56",
            Integer64 => "INTEGER64",
            Unsigned8 => "UNSIGNED8",
            Unsigned16 => "UNSIGNED16",
            Unsigned24 => "UNSIGNED24",
            Unsigned32 => "UNSIGNED32",
            Unsigned40 => "UNSIGNED40",
            Unsigned48 => "UNSIGNED48",
            Unsigned56 => "UNSIGNED56",
            Unsigned64 => "UNSIGNED64",
            Real32 => "REAL32",
            Real64 => "REAL64",
            VisibleString => "VISIBLE_STRING",
            OctetString => "OCTET_STRING",
            UnicodeString => "UNICODE_STRING",
            Domain => "DOMAIN",
            TimeOfDay => "TIME_OF_DAY",
            TimeDifference => "TIME_DIFFERENCE",
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DataType {
    type Err = ValueError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        DataType::ALL
            .iter()
            .copied()
            .find(|t| t.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| ValueError::Parse(DataType::Domain, s.to_owned()))
    }
}

/// A TIME_OF_DAY or TIME_DIFFERENCE value (CiA 301 §7.1.6.5): milliseconds (28 bits) and
/// days (16 bits). For TIME_OF_DAY, milliseconds after midnight and days since 1 January 1984.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct TimeOfDay {
    /// Milliseconds; only the low 28 bits are encoded.
    pub ms: u32,
    /// Days.
    pub days: u16,
}

impl TimeOfDay {
    /// The largest encodable millisecond count (2^28 - 1).
    pub const MS_MAX: u32 = (1 << 28) - 1;

    /// The 6-byte little-endian encoding; the 4 reserved bits are sent as zero.
    pub fn to_le_bytes(self) -> [u8; 6] {
        let ms = (self.ms & Self::MS_MAX).to_le_bytes();
        let d = self.days.to_le_bytes();
        [ms[0], ms[1], ms[2], ms[3], d[0], d[1]]
    }

    /// Decodes the 6-byte encoding, ignoring the reserved bits.
    pub fn from_le_bytes(b: [u8; 6]) -> Self {
        TimeOfDay {
            ms: u32::from_le_bytes([b[0], b[1], b[2], b[3]]) & Self::MS_MAX,
            days: u16::from_le_bytes([b[4], b[5]]),
        }
    }
}

impl fmt::Display for TimeOfDay {
    /// `<days>d <ms>ms`, the form [`Value::parse`] accepts back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}d {}ms", self.days, self.ms)
    }
}

/// A value that cannot be decoded, encoded or parsed as the requested type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ValueError {
    /// The byte length does not fit the type.
    #[error("{ty} takes {expected} bytes, not {actual}")]
    Length {
        /// The type.
        ty: DataType,
        /// Its encoded size.
        expected: usize,
        /// The length given.
        actual: usize,
    },
    /// UNICODE_STRING bytes of odd length.
    #[error("UNICODE_STRING needs an even number of bytes, not {0}")]
    OddUnicodeLength(usize),
    /// Text that does not parse as a value of the type.
    #[error("cannot parse {1:?} as {0}")]
    Parse(DataType, String),
    /// The value is out of the type's range.
    #[error("{1} is out of range for {0}")]
    Range(DataType, String),
}

/// A typed value of any CiA 301 basic data type.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// BOOLEAN.
    Boolean(bool),
    /// INTEGER8.
    Integer8(i8),
    /// INTEGER16.
    Integer16(i16),
    /// INTEGER24, sign-extended into an `i32` (range −2^23 .. 2^23−1).
    Integer24(i32),
    /// INTEGER32.
    Integer32(i32),
    /// INTEGER40, sign-extended into an `i64`.
    Integer40(i64),
    /// INTEGER48, sign-extended into an `i64`.
    Integer48(i64),
    /// INTEGER56, sign-extended into an `i64`.
    Integer56(i64),
    /// INTEGER64.
    Integer64(i64),
    /// UNSIGNED8.
    Unsigned8(u8),
    /// UNSIGNED16.
    Unsigned16(u16),
    /// UNSIGNED24 (range 0 .. 2^24−1).
    Unsigned24(u32),
    /// UNSIGNED32.
    Unsigned32(u32),
    /// UNSIGNED40.
    Unsigned40(u64),
    /// UNSIGNED48.
    Unsigned48(u64),
    /// UNSIGNED56.
    Unsigned56(u64),
    /// UNSIGNED64.
    Unsigned64(u64),
    /// REAL32.
    Real32(f32),
    /// REAL64.
    Real64(f64),
    /// VISIBLE_STRING. Each byte on the wire is one `char` U+0000..=U+00FF, so any bytes
    /// round-trip; characters above U+00FF encode as `?`.
    VisibleString(String),
    /// OCTET_STRING.
    OctetString(Vec<u8>),
    /// UNICODE_STRING as UTF-16 code units (kept as units so that any bytes round-trip).
    UnicodeString(Vec<u16>),
    /// DOMAIN.
    Domain(Vec<u8>),
    /// TIME_OF_DAY.
    TimeOfDay(TimeOfDay),
    /// TIME_DIFFERENCE.
    TimeDifference(TimeOfDay),
}

/// A numeric view of a value, for comparisons against limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Num {
    Int(i128),
    Float(f64),
}

impl Num {
    pub(crate) fn partial_cmp(self, other: Num) -> Option<core::cmp::Ordering> {
        match (self, other) {
            (Num::Int(a), Num::Int(b)) => Some(a.cmp(&b)),
            (Num::Float(a), Num::Float(b)) => a.partial_cmp(&b),
            (Num::Int(a), Num::Float(b)) => (a as f64).partial_cmp(&b),
            (Num::Float(a), Num::Int(b)) => a.partial_cmp(&(b as f64)),
        }
    }
}

fn sign_extend(raw: u64, bits: u32) -> i64 {
    let shift = 64 - bits;
    ((raw << shift) as i64) >> shift
}

fn le_uint(bytes: &[u8]) -> u64 {
    let mut b = [0u8; 8];
    b[..bytes.len()].copy_from_slice(bytes);
    u64::from_le_bytes(b)
}

impl Value {
    /// The value's data type.
    pub fn data_type(&self) -> DataType {
        use Value::*;
        match self {
            Boolean(_) => DataType::Boolean,
            Integer8(_) => DataType::Integer8,
            Integer16(_) => DataType::Integer16,
            Integer24(_) => DataType::Integer24,
            Integer32(_) => DataType::Integer32,
            Integer40(_) => DataType::Integer40,
            Integer48(_) => DataType::Integer48,
            Integer56(_) => DataType::Integer56,
            Integer64(_) => DataType::Integer64,
            Unsigned8(_) => DataType::Unsigned8,
            Unsigned16(_) => DataType::Unsigned16,
            Unsigned24(_) => DataType::Unsigned24,
            Unsigned32(_) => DataType::Unsigned32,
            Unsigned40(_) => DataType::Unsigned40,
            Unsigned48(_) => DataType::Unsigned48,
            Unsigned56(_) => DataType::Unsigned56,
            Unsigned64(_) => DataType::Unsigned64,
            Real32(_) => DataType::Real32,
            Real64(_) => DataType::Real64,
            VisibleString(_) => DataType::VisibleString,
            OctetString(_) => DataType::OctetString,
            UnicodeString(_) => DataType::UnicodeString,
            Domain(_) => DataType::Domain,
            TimeOfDay(_) => DataType::TimeOfDay,
            TimeDifference(_) => DataType::TimeDifference,
        }
    }

    /// The zero/empty value of a type.
    pub fn zero(ty: DataType) -> Value {
        use DataType as T;
        match ty {
            T::Boolean => Value::Boolean(false),
            T::Integer8 => Value::Integer8(0),
            T::Integer16 => Value::Integer16(0),
            T::Integer24 => Value::Integer24(0),
            T::Integer32 => Value::Integer32(0),
            T::Integer40 => Value::Integer40(0),
            T::Integer48 => Value::Integer48(0),
            T::Integer56 => Value::Integer56(0),
            T::Integer64 => Value::Integer64(0),
            T::Unsigned8 => Value::Unsigned8(0),
            T::Unsigned16 => Value::Unsigned16(0),
            T::Unsigned24 => Value::Unsigned24(0),
            T::Unsigned32 => Value::Unsigned32(0),
            T::Unsigned40 => Value::Unsigned40(0),
            T::Unsigned48 => Value::Unsigned48(0),
            T::Unsigned56 => Value::Unsigned56(0),
            T::Unsigned64 => Value::Unsigned64(0),
            T::Real32 => Value::Real32(0.0),
            T::Real64 => Value::Real64(0.0),
            T::VisibleString => Value::VisibleString(String::new()),
            T::OctetString => Value::OctetString(Vec::new()),
            T::UnicodeString => Value::UnicodeString(Vec::new()),
            T::Domain => Value::Domain(Vec::new()),
            T::TimeOfDay => Value::TimeOfDay(TimeOfDay::default()),
            T::TimeDifference => Value::TimeDifference(TimeOfDay::default()),
        }
    }

    /// Builds a value of an integer type from an `i128`, checking the type's range.
    pub fn from_integer(ty: DataType, v: i128) -> Result<Value, ValueError> {
        let range = || ValueError::Range(ty, v.to_string());
        let (lo, hi): (i128, i128) = match ty {
            DataType::Boolean => (0, 1),
            t if t.is_signed() => {
                let bits = t.fixed_size().unwrap_or(8) as u32 * 8;
                (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
            }
            t if t.is_unsigned() => {
                let bits = t.fixed_size().unwrap_or(8) as u32 * 8;
                (0, (1i128 << bits) - 1)
            }
            _ => return Err(range()),
        };
        if v < lo || v > hi {
            return Err(range());
        }
        let mut bytes = [0u8; 16];
        bytes.copy_from_slice(&v.to_le_bytes());
        let size = ty.fixed_size().unwrap_or(1);
        Value::from_le_bytes(ty, &bytes[..size])
    }

    /// The value as an integer, for integer and boolean types.
    pub fn as_i128(&self) -> Option<i128> {
        match self.num()? {
            Num::Int(v) => Some(v),
            Num::Float(_) => None,
        }
    }

    /// The numeric view used for limit checks (`None` for non-numeric types).
    pub(crate) fn num(&self) -> Option<Num> {
        use Value::*;
        Some(match *self {
            Boolean(v) => Num::Int(i128::from(v)),
            Integer8(v) => Num::Int(v.into()),
            Integer16(v) => Num::Int(v.into()),
            Integer24(v) | Integer32(v) => Num::Int(v.into()),
            Integer40(v) | Integer48(v) | Integer56(v) | Integer64(v) => Num::Int(v.into()),
            Unsigned8(v) => Num::Int(v.into()),
            Unsigned16(v) => Num::Int(v.into()),
            Unsigned24(v) | Unsigned32(v) => Num::Int(v.into()),
            Unsigned40(v) | Unsigned48(v) | Unsigned56(v) | Unsigned64(v) => Num::Int(v.into()),
            Real32(v) => Num::Float(v.into()),
            Real64(v) => Num::Float(v),
            TimeOfDay(_) | TimeDifference(_) => return None,
            VisibleString(_) | OctetString(_) | UnicodeString(_) | Domain(_) => return None,
        })
    }

    /// The numeric view of an encoded fixed-size value, without allocating.
    pub(crate) fn num_of(ty: DataType, bytes: &[u8]) -> Option<Num> {
        if ty.fixed_size() != Some(bytes.len()) {
            return None;
        }
        let raw = le_uint(bytes);
        let bits = bytes.len() as u32 * 8;
        match ty {
            DataType::Real32 => Some(Num::Float(f32::from_bits(raw as u32).into())),
            DataType::Real64 => Some(Num::Float(f64::from_bits(raw))),
            t if t.is_signed() => Some(Num::Int(sign_extend(raw, bits).into())),
            t if t.is_unsigned() || t == DataType::Boolean => Some(Num::Int(raw.into())),
            _ => None,
        }
    }

    /// The encoded length in bytes.
    pub fn encoded_len(&self) -> usize {
        match self {
            Value::VisibleString(s) => s.len(),
            Value::OctetString(b) | Value::Domain(b) => b.len(),
            Value::UnicodeString(u) => u.len() * 2,
            v => v.data_type().fixed_size().unwrap_or(0),
        }
    }

    /// The little-endian encoding (CiA 301 §7.1.6).
    pub fn to_le_bytes(&self) -> Vec<u8> {
        let mut out = vec![0u8; self.encoded_len()];
        self.encode_into(&mut out);
        out
    }

    /// Encodes into `out`, which must be exactly [`Value::encoded_len`] bytes long.
    pub(crate) fn encode_into(&self, out: &mut [u8]) {
        use Value::*;
        let n = out.len();
        let mut put = |raw: u64| out.copy_from_slice(&raw.to_le_bytes()[..n]);
        match self {
            Boolean(v) => put(u64::from(*v)),
            Integer8(v) => put(*v as u64),
            Integer16(v) => put(*v as u64),
            Integer24(v) | Integer32(v) => put(*v as u64),
            Integer40(v) | Integer48(v) | Integer56(v) | Integer64(v) => put(*v as u64),
            Unsigned8(v) => put(u64::from(*v)),
            Unsigned16(v) => put(u64::from(*v)),
            Unsigned24(v) | Unsigned32(v) => put(u64::from(*v)),
            Unsigned40(v) | Unsigned48(v) | Unsigned56(v) | Unsigned64(v) => put(*v),
            Real32(v) => put(u64::from(v.to_bits())),
            Real64(v) => put(v.to_bits()),
            TimeOfDay(t) | TimeDifference(t) => out.copy_from_slice(&t.to_le_bytes()),
            // ISO 646 text is one byte a character; beyond it (CiA 301 §7.1.6 defines
            // none) the text's UTF-8 bytes, so a vendor's `€` survives a round trip.
            VisibleString(s) => out.copy_from_slice(s.as_bytes()),
            OctetString(b) | Domain(b) => out.copy_from_slice(b),
            UnicodeString(u) => {
                for (o, c) in out.chunks_exact_mut(2).zip(u) {
                    o.copy_from_slice(&c.to_le_bytes());
                }
            }
        }
    }

    /// Decodes the little-endian encoding of a value of type `ty`.
    pub fn from_le_bytes(ty: DataType, bytes: &[u8]) -> Result<Value, ValueError> {
        if let Some(size) = ty.fixed_size()
            && bytes.len() != size
        {
            return Err(ValueError::Length {
                ty,
                expected: size,
                actual: bytes.len(),
            });
        }
        use DataType as T;
        let raw = || le_uint(bytes);
        let s = |bits| sign_extend(le_uint(bytes), bits);
        Ok(match ty {
            T::Boolean => Value::Boolean(bytes[0] != 0),
            T::Integer8 => Value::Integer8(bytes[0] as i8),
            T::Integer16 => Value::Integer16(s(16) as i16),
            T::Integer24 => Value::Integer24(s(24) as i32),
            T::Integer32 => Value::Integer32(s(32) as i32),
            T::Integer40 => Value::Integer40(s(40)),
            T::Integer48 => Value::Integer48(s(48)),
            T::Integer56 => Value::Integer56(s(56)),
            T::Integer64 => Value::Integer64(s(64)),
            T::Unsigned8 => Value::Unsigned8(bytes[0]),
            T::Unsigned16 => Value::Unsigned16(raw() as u16),
            T::Unsigned24 => Value::Unsigned24(raw() as u32),
            T::Unsigned32 => Value::Unsigned32(raw() as u32),
            T::Unsigned40 => Value::Unsigned40(raw()),
            T::Unsigned48 => Value::Unsigned48(raw()),
            T::Unsigned56 => Value::Unsigned56(raw()),
            T::Unsigned64 => Value::Unsigned64(raw()),
            T::Real32 => Value::Real32(f32::from_bits(raw() as u32)),
            T::Real64 => Value::Real64(f64::from_bits(raw())),
            T::TimeOfDay | T::TimeDifference => {
                let mut b = [0u8; 6];
                b.copy_from_slice(bytes);
                let t = TimeOfDay::from_le_bytes(b);
                if ty == T::TimeOfDay {
                    Value::TimeOfDay(t)
                } else {
                    Value::TimeDifference(t)
                }
            }
            // UTF-8 as encoded; bytes that are not UTF-8 read as ISO 8859-1, one character
            // each (the raw bytes stay in the dictionary as written).
            T::VisibleString => Value::VisibleString(match std::str::from_utf8(bytes) {
                Ok(s) => s.to_owned(),
                Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
            }),
            T::OctetString => Value::OctetString(bytes.to_vec()),
            T::Domain => Value::Domain(bytes.to_vec()),
            T::UnicodeString => {
                if bytes.len() % 2 != 0 {
                    return Err(ValueError::OddUnicodeLength(bytes.len()));
                }
                Value::UnicodeString(
                    bytes
                        .chunks_exact(2)
                        .map(|c| u16::from_le_bytes([c[0], c[1]]))
                        .collect(),
                )
            }
        })
    }

    /// Parses text as a value of type `ty` (the inverse of `Display`): integers in decimal
    /// or `0x` hex, reals, strings as they are, OCTET_STRING/DOMAIN as hex bytes (spaces
    /// allowed), TIME_OF_DAY/TIME_DIFFERENCE as `<days>d <ms>ms`.
    pub fn parse(ty: DataType, text: &str) -> Result<Value, ValueError> {
        let err = || ValueError::Parse(ty, text.to_owned());
        let t = text.trim();
        match ty {
            DataType::Boolean => match t.to_ascii_lowercase().as_str() {
                "true" | "1" => Ok(Value::Boolean(true)),
                "false" | "0" => Ok(Value::Boolean(false)),
                _ => Err(err()),
            },
            DataType::Real32 => t.parse::<f32>().map(Value::Real32).map_err(|_| err()),
            DataType::Real64 => t.parse::<f64>().map(Value::Real64).map_err(|_| err()),
            DataType::VisibleString => Ok(Value::VisibleString(text.to_owned())),
            DataType::UnicodeString => Ok(Value::UnicodeString(text.encode_utf16().collect())),
            DataType::OctetString | DataType::Domain => {
                let hex: String = t.chars().filter(|c| !c.is_whitespace()).collect();
                let hex = hex.strip_prefix("0x").unwrap_or(&hex);
                if hex.len() % 2 != 0 || !hex.is_ascii() {
                    return Err(err());
                }
                let bytes = (0..hex.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&hex[i..i + 2], 16))
                    .collect::<Result<Vec<u8>, _>>()
                    .map_err(|_| err())?;
                Ok(if ty == DataType::Domain {
                    Value::Domain(bytes)
                } else {
                    Value::OctetString(bytes)
                })
            }
            DataType::TimeOfDay | DataType::TimeDifference => {
                let (d, rest) = t.split_once('d').ok_or_else(err)?;
                let ms = rest.trim().strip_suffix("ms").ok_or_else(err)?;
                let tod = TimeOfDay {
                    days: d.trim().parse().map_err(|_| err())?,
                    ms: ms.trim().parse().map_err(|_| err())?,
                };
                if tod.ms > TimeOfDay::MS_MAX {
                    return Err(ValueError::Range(ty, text.to_owned()));
                }
                Ok(if ty == DataType::TimeOfDay {
                    Value::TimeOfDay(tod)
                } else {
                    Value::TimeDifference(tod)
                })
            }
            _ => Value::from_integer(ty, parse_int(t).ok_or_else(err)?),
        }
    }
}

/// Parses a decimal or `0x`-prefixed hexadecimal integer, with an optional sign.
pub(crate) fn parse_int(t: &str) -> Option<i128> {
    let (neg, body) = match t.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    let v = if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        i128::from_str_radix(h, 16).ok()?
    } else {
        body.parse::<i128>().ok()?
    };
    Some(if neg { -v } else { v })
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use Value::*;
        match self {
            Boolean(v) => write!(f, "{v}"),
            Integer8(v) => write!(f, "{v}"),
            Integer16(v) => write!(f, "{v}"),
            Integer24(v) | Integer32(v) => write!(f, "{v}"),
            Integer40(v) | Integer48(v) | Integer56(v) | Integer64(v) => write!(f, "{v}"),
            Unsigned8(v) => write!(f, "{v}"),
            Unsigned16(v) => write!(f, "{v}"),
            Unsigned24(v) | Unsigned32(v) => write!(f, "{v}"),
            Unsigned40(v) | Unsigned48(v) | Unsigned56(v) | Unsigned64(v) => write!(f, "{v}"),
            Real32(v) => write!(f, "{v}"),
            Real64(v) => write!(f, "{v}"),
            VisibleString(s) => f.write_str(s),
            UnicodeString(u) => f.write_str(&String::from_utf16_lossy(u)),
            OctetString(b) | Domain(b) => {
                for (i, byte) in b.iter().enumerate() {
                    if i > 0 {
                        f.write_str(" ")?;
                    }
                    write!(f, "{byte:02X}")?;
                }
                Ok(())
            }
            TimeOfDay(t) | TimeDifference(t) => write!(f, "{t}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_1_6_odd_sized_integers_take_3_5_6_7_bytes() {
        assert_eq!(Value::Integer24(-2).to_le_bytes(), [0xFE, 0xFF, 0xFF]);
        assert_eq!(
            Value::from_le_bytes(DataType::Integer24, &[0xFE, 0xFF, 0xFF]),
            Ok(Value::Integer24(-2))
        );
        assert_eq!(
            Value::Unsigned40(0x01_0203_0405).to_le_bytes(),
            [5, 4, 3, 2, 1]
        );
        assert_eq!(Value::Integer48(-1).to_le_bytes(), [0xFF; 6]);
        assert_eq!(Value::Unsigned56(1).to_le_bytes(), [1, 0, 0, 0, 0, 0, 0]);
        assert_eq!(
            Value::from_le_bytes(DataType::Integer56, &[0, 0, 0, 0, 0, 0, 0x80]),
            Ok(Value::Integer56(-(1 << 55)))
        );
    }

    #[test]
    fn cia301_7_1_6_5_time_of_day_layout() {
        let t = TimeOfDay {
            ms: 0x0ABC_DEF1,
            days: 0x1234,
        };
        assert_eq!(
            Value::TimeOfDay(t).to_le_bytes(),
            [0xF1, 0xDE, 0xBC, 0x0A, 0x34, 0x12]
        );
        // The 4 reserved bits are ignored on decode.
        assert_eq!(
            TimeOfDay::from_le_bytes([0xF1, 0xDE, 0xBC, 0xFA, 0x34, 0x12]),
            t
        );
    }

    #[test]
    fn unicode_string_is_utf16le() {
        let v = Value::parse(DataType::UnicodeString, "Aé").unwrap();
        assert_eq!(v.to_le_bytes(), [0x41, 0x00, 0xE9, 0x00]);
        assert_eq!(
            Value::from_le_bytes(DataType::UnicodeString, &[1, 2, 3]),
            Err(ValueError::OddUnicodeLength(3))
        );
    }

    #[test]
    fn length_is_checked_for_fixed_types() {
        assert_eq!(
            Value::from_le_bytes(DataType::Unsigned32, &[1, 2]),
            Err(ValueError::Length {
                ty: DataType::Unsigned32,
                expected: 4,
                actual: 2
            })
        );
    }

    #[test]
    fn parse_and_display_round_trip() {
        for (ty, text) in [
            (DataType::Integer24, "-8388608"),
            (DataType::Unsigned64, "18446744073709551615"),
            (DataType::Boolean, "true"),
            (DataType::Real32, "1.5"),
            (DataType::OctetString, "01 AB FF"),
            (DataType::TimeDifference, "3d 1000ms"),
            (DataType::VisibleString, "ADV200"),
        ] {
            let v = Value::parse(ty, text).unwrap();
            assert_eq!(v.data_type(), ty);
            assert_eq!(v.to_string(), text);
        }
        assert_eq!(
            Value::parse(DataType::Unsigned8, "0x1F"),
            Ok(Value::Unsigned8(0x1F))
        );
        assert!(matches!(
            Value::parse(DataType::Integer24, "8388608"),
            Err(ValueError::Range(..))
        ));
        assert!(Value::parse(DataType::Unsigned8, "x").is_err());
    }

    #[test]
    fn visible_strings_beyond_iso_646_keep_their_characters() {
        let euro = Value::VisibleString("5 € pro Stück".into());
        let bytes = euro.to_le_bytes();
        assert_eq!(bytes, "5 € pro Stück".as_bytes());
        assert_eq!(euro.encoded_len(), bytes.len());
        assert_eq!(
            Value::from_le_bytes(DataType::VisibleString, &bytes),
            Ok(euro)
        );
        // A device's Latin-1 byte, not UTF-8, reads as its character.
        assert_eq!(
            Value::from_le_bytes(DataType::VisibleString, b"25 \xB0C"),
            Ok(Value::VisibleString("25 °C".into()))
        );
    }

    #[test]
    fn data_type_indices_match_table_44() {
        assert_eq!(DataType::from_index(0x1B), Some(DataType::Unsigned64));
        assert_eq!(DataType::from_index(0x17), None);
        assert_eq!(DataType::Domain.index(), 0x0F);
        assert_eq!("unsigned32".parse::<DataType>(), Ok(DataType::Unsigned32));
    }
}
