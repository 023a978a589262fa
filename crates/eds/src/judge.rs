//! The one judgement of an entry's type, access and values: [`crate::Eds::check`] reports
//! what it finds and [`crate::to_od`] builds the dictionary from what it keeps, so the
//! checker and the loader never disagree about a value.

use crate::error::Severity;
use crate::model::Entry;
use crate::value::EdsValue;
use cantwin_canopen::od::{Access, DataType, TimeOfDay, Value};
use core::cmp::Ordering;

/// A finding about one key of an entry.
pub(crate) type Finding = (Severity, &'static str, String);

/// What an entry means for a dictionary.
#[derive(Debug, Clone)]
pub(crate) struct Judged {
    /// The data type the dictionary holds it with; `None` when the entry has no usable one
    /// (no `DataType` at all), which makes a dictionary impossible.
    pub ty: Option<DataType>,
    /// The access type (read-only when the file gives none that can be read).
    pub access: Access,
    /// The default: a value, or an offset added to the node-ID.
    pub default: Option<Default>,
    /// `LowLimit`, kept only when it bounds a number type (the lower of the two limits when
    /// the file has them upside down).
    pub low: Option<Value>,
    /// `HighLimit`, kept likewise (the higher of the two).
    pub high: Option<Value>,
    /// What the file says that CiA 306 does not allow, or that was read with a guess.
    pub findings: Vec<Finding>,
    /// Where the default lies outside the limits (`below LowLimit 1`): the device starts
    /// there, as the file says.
    pub default_outside: Option<String>,
}

/// A usable default value.
#[derive(Debug, Clone)]
pub(crate) enum Default {
    /// A plain value.
    Value(Value),
    /// `$NODEID+offset`: the offset as a value of the type.
    NodeId(Value),
}

/// Reads TIME_OF_DAY / TIME_DIFFERENCE text: `days ms` (two numbers, the form tools write,
/// e.g. `365 43200000`), or `<days>d <ms>ms` (the dictionary's own display form). CiA 306
/// gives these types no text form of its own.
fn time_of_day(text: &str) -> Option<TimeOfDay> {
    let t = text.trim();
    let t = t.replace("ms", " ").replace('d', " ");
    let mut parts = t.split_whitespace();
    let days = crate::value::parse_integer(parts.next()?)?;
    let ms = crate::value::parse_integer(parts.next()?)?;
    if parts.next().is_some() {
        return None;
    }
    Some(TimeOfDay {
        days: u16::try_from(days).ok()?,
        ms: u32::try_from(ms).ok().filter(|m| *m <= TimeOfDay::MS_MAX)?,
    })
}

/// What the text of a value must look like for a type, for messages.
fn expected(ty: DataType) -> &'static str {
    match ty {
        DataType::OctetString | DataType::Domain => "hex bytes (or `@` and text)",
        DataType::TimeOfDay | DataType::TimeDifference => "`days ms`",
        DataType::Real32 | DataType::Real64 => "a number",
        DataType::VisibleString | DataType::UnicodeString => "text",
        _ => "an integer (decimal, 0x hex or 0 octal) or `$NODEID+n`",
    }
}

/// The value `v` stands for as a value of `ty`, `$NODEID` resolved with `node_id`.
/// `Ok(None)`: the file gives no value (an empty text).
pub(crate) fn value_of(ty: DataType, v: &EdsValue, node_id: u8) -> Result<Option<Value>, String> {
    let fits = |x: i128| {
        Value::from_integer(ty, x).map_err(|_| format!("{x} is outside the range of {ty}"))
    };
    let wrong = |text: String| format!("{text:?} is not {}", expected(ty));
    match v {
        EdsValue::Raw(s) if s.trim().is_empty() => Ok(None),
        EdsValue::Integer(x) if ty.is_signed() || ty.is_unsigned() || ty == DataType::Boolean => {
            fits(*x).map(Some)
        }
        EdsValue::NodeId(off) if ty.is_signed() || ty.is_unsigned() => {
            fits(off.saturating_add(i128::from(node_id))).map(Some)
        }
        EdsValue::NodeId(_) => Err(format!("$NODEID on a value of type {ty}")),
        EdsValue::Real32(x) if ty == DataType::Real32 => Ok(Some(Value::Real32(*x))),
        EdsValue::Real64(x) if ty == DataType::Real64 => Ok(Some(Value::Real64(*x))),
        EdsValue::Text(s) if ty == DataType::VisibleString => {
            Ok(Some(Value::VisibleString(s.clone())))
        }
        EdsValue::Text(s) if ty == DataType::UnicodeString => {
            Ok(Some(Value::UnicodeString(s.encode_utf16().collect())))
        }
        EdsValue::Bytes(b) if ty == DataType::OctetString => {
            Ok(Some(Value::OctetString(b.clone())))
        }
        EdsValue::Bytes(b) if ty == DataType::Domain => Ok(Some(Value::Domain(b.clone()))),
        EdsValue::Raw(s) if ty == DataType::TimeOfDay || ty == DataType::TimeDifference => {
            match time_of_day(s) {
                Some(t) if ty == DataType::TimeOfDay => Ok(Some(Value::TimeOfDay(t))),
                Some(t) => Ok(Some(Value::TimeDifference(t))),
                None => Err(wrong(s.clone())),
            }
        }
        other => Err(wrong(other.to_text(Some(ty.index())))),
    }
}

/// The order of two numbers (integers exactly, reals as `f64`); `None` for other values.
fn order(a: &Value, b: &Value) -> Option<Ordering> {
    let real = |v: &Value| match v {
        Value::Real32(x) => Some(f64::from(*x)),
        Value::Real64(x) => Some(*x),
        other => other.as_i128().map(|i| i as f64),
    };
    match (a.as_i128(), b.as_i128()) {
        (Some(x), Some(y)) => Some(x.cmp(&y)),
        _ => real(a)?.partial_cmp(&real(b)?),
    }
}

/// Where `x` lies outside `low..=high`, said in words (`below LowLimit 1`); `None` inside.
pub(crate) fn outside(x: &Value, low: Option<&Value>, high: Option<&Value>) -> Option<String> {
    if let Some(l) = low
        && order(x, l) == Some(Ordering::Less)
    {
        return Some(format!("below LowLimit {l}"));
    }
    if let Some(h) = high
        && order(x, h) == Some(Ordering::Greater)
    {
        return Some(format!("above HighLimit {h}"));
    }
    None
}

/// Judges a value for every node-ID (1..=127) a `$NODEID` may be resolved with.
fn value_for_any_node(ty: DataType, v: &EdsValue) -> Result<Option<Value>, String> {
    if let EdsValue::NodeId(off) = v {
        value_of(ty, v, 1)?;
        value_of(ty, v, 127).map_err(|_| {
            format!("$NODEID+{off} leaves the range of {ty} for some node-ID 1..=127")
        })?;
    }
    value_of(ty, v, 1)
}

/// One value of an entry, judged; `typed`: the entry's data type is a basic one (values of
/// an undefined type cannot be read).
fn read<'a>(
    ty: DataType,
    typed: bool,
    key: &'static str,
    v: &'a Option<EdsValue>,
    findings: &mut Vec<Finding>,
) -> Option<(Value, &'a EdsValue)> {
    let v = v.as_ref()?;
    if !typed {
        if !matches!(v, EdsValue::Raw(s) if s.is_empty()) {
            findings.push((
                Severity::Note,
                key,
                "ignored: the data type has no definition here".to_owned(),
            ));
        }
        return None;
    }
    match value_for_any_node(ty, v) {
        Ok(x) => x.map(|x| (x, v)),
        Err(m) => {
            findings.push((Severity::Error, key, format!("{m}; ignored")));
            None
        }
    }
}

/// Judges an entry. `needs_type`: the entry holds a value (a VAR, DOMAIN or sub-object), so
/// it needs a data type and an access type.
pub(crate) fn judge(e: &Entry, needs_type: bool) -> Judged {
    let mut findings: Vec<Finding> = Vec::new();
    let ty = match e.data_type {
        None if needs_type && e.object_code() == crate::DOMAIN => {
            findings.push((
                Severity::Warning,
                "DataType",
                "missing; a DOMAIN object is held as DOMAIN (0x000F)".to_owned(),
            ));
            Some(DataType::Domain)
        }
        None if needs_type => {
            findings.push((
                Severity::Error,
                "DataType",
                "missing: the object cannot be part of a dictionary".to_owned(),
            ));
            None
        }
        None => None,
        Some(t) => match DataType::from_index(t) {
            Some(ty) => Some(ty),
            // CiA 301 table 44: 0x0020..=0x025F are complex, manufacturer and profile types;
            // without their definition the size is unknown, and DOMAIN holds any bytes.
            None => {
                if needs_type {
                    findings.push((
                        Severity::Warning,
                        "DataType",
                        format!("{t:#06X} is not a basic data type; held as DOMAIN"),
                    ));
                }
                Some(DataType::Domain)
            }
        },
    };
    // An AccessType that cannot be read was reported where it stands (and kept as written);
    // either way the dictionary holds the entry read-only, the access that changes nothing.
    let access = match e.access_type {
        Some(a) => a,
        None => {
            if needs_type && e.extra_value("AccessType").is_none() {
                findings.push((
                    Severity::Error,
                    "AccessType",
                    "missing; held as ro".to_owned(),
                ));
            }
            Access::Ro
        }
    };
    let Some(ty) = ty.filter(|_| needs_type) else {
        return Judged {
            ty,
            access,
            default: None,
            low: None,
            high: None,
            findings,
            default_outside: None,
        };
    };
    let typed = e.data_type.and_then(DataType::from_index).is_some();
    let default =
        read(ty, typed, "DefaultValue", &e.default_value, &mut findings).map(|(x, v)| match v {
            EdsValue::NodeId(off) => match Value::from_integer(ty, *off) {
                Ok(base) => Default::NodeId(base),
                Err(_) => Default::Value(x),
            },
            _ => Default::Value(x),
        });
    let numeric =
        ty.is_signed() || ty.is_unsigned() || ty == DataType::Real32 || ty == DataType::Real64;
    let limit = |key: &'static str, v: &Option<EdsValue>, findings: &mut Vec<Finding>| {
        let x = read(ty, typed, key, v, findings)?.0;
        if !numeric {
            findings.push((Severity::Note, key, format!("ignored: {ty} has no order")));
            return None;
        }
        Some(x)
    };
    let mut low = limit("LowLimit", &e.low_limit, &mut findings);
    let mut high = limit("HighLimit", &e.high_limit, &mut findings);
    // LowLimit above HighLimit: the two were written in each other's place (the evident
    // intent of a range); they are taken swapped, the same in check and dictionary.
    if let (Some(l), Some(h)) = (&low, &high)
        && order(l, h) == Some(Ordering::Greater)
    {
        findings.push((
            Severity::Warning,
            "LowLimit",
            format!("{l} is above HighLimit {h}; the limits are taken swapped ({h}..={l})"),
        ));
        core::mem::swap(&mut low, &mut high);
    }
    // An object without a DefaultValue would start at 0 (CiA 306 §4.6.3 leaves the value
    // open); where 0 lies outside the file's own limits the device could not even take its
    // own value back (CiA 301 §7.2.4.3.17, 0x06090031/32), so it starts at the nearest limit.
    let mut default = default;
    if default.is_none() && e.default_value.is_none() {
        let zero = match ty {
            DataType::Real32 => Some(Value::Real32(0.0)),
            DataType::Real64 => Some(Value::Real64(0.0)),
            _ => Value::from_integer(ty, 0).ok(),
        };
        if let Some(zero) = zero {
            let start = if low.as_ref().and_then(|l| order(&zero, l)) == Some(Ordering::Less) {
                low.clone().map(|l| (l, "LowLimit", "below"))
            } else if high.as_ref().and_then(|h| order(&zero, h)) == Some(Ordering::Greater) {
                high.clone().map(|h| (h, "HighLimit", "above"))
            } else {
                None
            };
            if let Some((v, key, side)) = start {
                findings.push((
                    Severity::Note,
                    "DefaultValue",
                    format!("missing and 0 is {side} {key}; the object starts at {key} ({v})"),
                ));
                default = Some(Default::Value(v));
            }
        }
    }
    let pv = read(
        ty,
        typed,
        "ParameterValue",
        &e.parameter_value,
        &mut findings,
    )
    .map(|(x, _)| x);
    let dv = match &default {
        Some(Default::Value(v)) => Some(v.clone()),
        _ => None,
    };
    // A DefaultValue outside the limits is what the file says the device starts with: the
    // device starts there (and refuses a download of the same value, CiA 301 §7.2.4.3.17),
    // which is worth a warning. A ParameterValue outside them is a configuration the device
    // would refuse.
    let default_outside = dv.and_then(|x| {
        let m = outside(&x, low.as_ref(), high.as_ref())?;
        Some(format!(
            "{x} is {m}; the device starts at {x}, as the file says"
        ))
    });
    if let Some(m) = &default_outside {
        findings.push((Severity::Warning, "DefaultValue", m.clone()));
    }
    if let Some(x) = pv
        && let Some(m) = outside(&x, low.as_ref(), high.as_ref())
    {
        findings.push((Severity::Error, "ParameterValue", format!("{x} is {m}")));
    }
    Judged {
        ty: Some(ty),
        access,
        default,
        low,
        high,
        findings,
        default_outside,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_of_day_as_days_and_ms() {
        let v = value_of(
            DataType::TimeOfDay,
            &EdsValue::Raw("365 43200000".into()),
            1,
        );
        assert_eq!(
            v,
            Ok(Some(Value::TimeOfDay(TimeOfDay {
                days: 365,
                ms: 43_200_000
            })))
        );
        let v = value_of(DataType::TimeDifference, &EdsValue::Raw("2d 5ms".into()), 1);
        assert_eq!(
            v,
            Ok(Some(Value::TimeDifference(TimeOfDay { days: 2, ms: 5 })))
        );
        assert!(value_of(DataType::TimeOfDay, &EdsValue::Raw("noon".into()), 1).is_err());
        assert!(value_of(DataType::TimeOfDay, &EdsValue::Raw("1 268435456".into()), 1).is_err());
    }
}
