//! Between EDS/DCF files and the object dictionary of `cantwin-canopen`: a device's EDS is
//! generated from its dictionary ([`from_od`]), and a dictionary description can be built
//! from an EDS ([`to_od`]) and configured from a DCF ([`apply_parameter_values`]).

use crate::model::{DeviceInfo, Eds, Entry, FileInfo, Object};
use crate::parse::expand_compact;
use crate::value::EdsValue;
use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{
    DataType, ObjectCode, ObjectDictionary, OdBuildError, OdBuilder, OdDescription, SubObject,
    Value,
};
use std::collections::BTreeMap;

/// Why an EDS cannot become an object dictionary (or a DCF value cannot be applied).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvertError {
    /// `DataType` is absent or not a basic data type the dictionary supports.
    #[error("{index:#06X}:{sub}: data type {data_type:?} is not supported")]
    DataType {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The `DataType` given, if any.
        data_type: Option<u16>,
    },
    /// `AccessType` is absent.
    #[error("{index:#06X}:{sub}: AccessType is missing")]
    Access {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// A value does not fit its type.
    #[error("{index:#06X}:{sub}: {key} {value:?} does not fit the data type")]
    Value {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// `DefaultValue`, `LowLimit`, `HighLimit` or `ParameterValue`.
        key: &'static str,
        /// The value as written.
        value: String,
    },
    /// The dictionary refused the definitions.
    #[error(transparent)]
    Build(#[from] OdBuildError),
    /// The device refused a DCF `ParameterValue`.
    #[error("{index:#06X}:{sub}: the device refused the ParameterValue: {abort}")]
    Apply {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The device's answer.
        abort: AbortCode,
    },
}

/// A typed value from an EDS value; `node_id` resolves `$NODEID` (when `None`, `$NODEID`
/// values are refused).
fn to_value(ty: DataType, v: &EdsValue, node_id: Option<u8>) -> Option<Value> {
    match v {
        EdsValue::Integer(x) => Value::from_integer(ty, *x).ok(),
        EdsValue::NodeId(off) => {
            Value::from_integer(ty, off.checked_add(i128::from(node_id?))?).ok()
        }
        EdsValue::Real32(x) if ty == DataType::Real32 => Some(Value::Real32(*x)),
        EdsValue::Real64(x) if ty == DataType::Real64 => Some(Value::Real64(*x)),
        EdsValue::Text(s) if ty == DataType::VisibleString => Some(Value::VisibleString(s.clone())),
        EdsValue::Text(s) if ty == DataType::UnicodeString => {
            Some(Value::UnicodeString(s.encode_utf16().collect()))
        }
        EdsValue::Bytes(b) if ty == DataType::OctetString => Some(Value::OctetString(b.clone())),
        EdsValue::Bytes(b) if ty == DataType::Domain => Some(Value::Domain(b.clone())),
        EdsValue::Raw(s) => Value::parse(ty, s).ok(),
        _ => None,
    }
}

fn from_value(v: &Value) -> EdsValue {
    match v {
        Value::Real32(x) => EdsValue::Real32(*x),
        Value::Real64(x) => EdsValue::Real64(*x),
        Value::VisibleString(s) => EdsValue::Text(s.clone()),
        Value::UnicodeString(u) => EdsValue::Text(String::from_utf16_lossy(u)),
        Value::OctetString(b) | Value::Domain(b) => EdsValue::Bytes(b.clone()),
        other => match other.as_i128() {
            Some(x) => EdsValue::Integer(x),
            None => EdsValue::Raw(other.to_string()),
        },
    }
}

fn sub_object(index: u16, sub: u8, e: &Entry) -> Result<SubObject, ConvertError> {
    let ty = e
        .data_type
        .and_then(DataType::from_index)
        .ok_or(ConvertError::DataType {
            index,
            sub,
            data_type: e.data_type,
        })?;
    let access = e.access_type.ok_or(ConvertError::Access { index, sub })?;
    let mut d = SubObject::new(e.parameter_name.clone(), ty, access);
    d.pdo_mappable = e.pdo_mapping.unwrap_or(false);
    let bad = |key: &'static str, v: &EdsValue| ConvertError::Value {
        index,
        sub,
        key,
        value: v.to_text(e.data_type),
    };
    match &e.default_value {
        None => {}
        Some(EdsValue::Raw(s)) if s.is_empty() => {}
        Some(EdsValue::NodeId(off)) => {
            let base = to_value(ty, &EdsValue::Integer(*off), None)
                .ok_or_else(|| bad("DefaultValue", &EdsValue::NodeId(*off)))?;
            d = d.default_node_id_plus(base);
        }
        Some(v) => d.default = Some(to_value(ty, v, None).ok_or_else(|| bad("DefaultValue", v))?),
    }
    for (key, src, dst) in [
        ("LowLimit", &e.low_limit, &mut d.low_limit),
        ("HighLimit", &e.high_limit, &mut d.high_limit),
    ] {
        match src {
            None => {}
            Some(EdsValue::Raw(s)) if s.is_empty() => {}
            Some(v) => *dst = Some(to_value(ty, v, None).ok_or_else(|| bad(key, v))?),
        }
    }
    Ok(d)
}

/// Builds an object dictionary description from an EDS.
///
/// VAR and DOMAIN objects become VARs, ARRAY and RECORD objects keep their sub-objects,
/// `ObjFlags` and `CompactSubObj` carry over. Type definitions (NULL, DEFTYPE, DEFSTRUCT)
/// are not values a device holds and are left out. `ParameterValue`s are not part of a
/// description; see [`apply_parameter_values`].
pub fn to_od(eds: &Eds) -> Result<OdDescription, ConvertError> {
    let mut b = OdBuilder::new();
    for (&index, o) in &eds.objects {
        let code = o.object_code();
        let composite = code == crate::ARRAY || code == crate::RECORD;
        if !composite && code != crate::VAR && code != crate::DOMAIN {
            continue;
        }
        if composite {
            let subs = o
                .subs
                .iter()
                .map(|(&s, e)| sub_object(index, s, e).map(|d| (s, d)))
                .collect::<Result<Vec<_>, _>>()?;
            let name = o.entry.parameter_name.clone();
            b = if code == crate::ARRAY {
                b.array(index, name, subs)
            } else {
                b.record(index, name, subs)
            };
        } else {
            b = b.var(index, sub_object(index, 0, &o.entry)?);
        }
        if let Some(f) = o.entry.obj_flags {
            b = b.flags(f);
        }
        if o.compact_sub_obj.is_some() {
            b = b.compact();
        }
    }
    Ok(b.build()?)
}

/// Sets the DCF `ParameterValue`s into a device's values, `$NODEID` taken as the device's
/// node-ID, as the device itself would (type and length checked, access not); returns how
/// many were set.
pub fn apply_parameter_values(eds: &Eds, od: &mut ObjectDictionary) -> Result<usize, ConvertError> {
    let node_id = od.node_id();
    let mut n = 0;
    for (&index, o) in &eds.objects {
        for (sub, e) in o.values() {
            let Some(v) = &e.parameter_value else {
                continue;
            };
            let bad = || ConvertError::Value {
                index,
                sub,
                key: "ParameterValue",
                value: v.to_text(e.data_type),
            };
            let ty = e.data_type.and_then(DataType::from_index).ok_or_else(bad)?;
            let value = to_value(ty, v, Some(node_id)).ok_or_else(bad)?;
            od.set(index, sub, &value)
                .map_err(|abort| ConvertError::Apply { index, sub, abort })?;
            n += 1;
        }
    }
    Ok(n)
}

fn entry_of(code: Option<u8>, d: &SubObject) -> Entry {
    let default = d
        .default
        .clone()
        .unwrap_or_else(|| Value::zero(d.data_type));
    let default = match (d.default_node_id_relative, default.as_i128()) {
        (true, Some(off)) => EdsValue::NodeId(off),
        _ => from_value(&default),
    };
    Entry {
        parameter_name: d.name.clone(),
        object_type: code,
        data_type: Some(d.data_type.index()),
        access_type: Some(d.access),
        default_value: Some(default),
        low_limit: d.low_limit.as_ref().map(from_value),
        high_limit: d.high_limit.as_ref().map(from_value),
        pdo_mapping: Some(d.pdo_mappable),
        ..Entry::default()
    }
}

/// The EDS of a device, generated from its object dictionary description.
///
/// Every object is written with `ObjectType`, `DataType` (`0x0007` form), `AccessType`,
/// `DefaultValue` (`$NODEID+0x..` where relative) and `PDOMapping`, as python-canopen's
/// importer expects; the object lists are rebuilt from the objects; `VendorNumber`,
/// `ProductNumber` and `RevisionNumber` are taken from 0x1018's defaults when `device_info`
/// leaves them out. An object marked compact in the dictionary is written with
/// `CompactSubObj` when its sub-objects 1..=n share one description apart from the name.
pub fn from_od(desc: &OdDescription, mut device_info: DeviceInfo, file_info: FileInfo) -> Eds {
    let mut eds = Eds {
        file_info,
        ..Eds::default()
    };
    for o in desc.objects() {
        let code = o.code() as u8;
        let mut obj = match o.code() {
            ObjectCode::Array | ObjectCode::Record => {
                let subs: BTreeMap<u8, Entry> = o
                    .subs()
                    .map(|(s, d)| (s, entry_of(Some(crate::VAR), d)))
                    .collect();
                Object {
                    entry: Entry {
                        parameter_name: o.name().to_owned(),
                        object_type: Some(code),
                        ..Entry::default()
                    },
                    sub_number: u8::try_from(subs.len()).ok(),
                    compact_sub_obj: None,
                    subs,
                }
            }
            _ => {
                let mut entry = o
                    .subs()
                    .next()
                    .map(|(_, d)| entry_of(Some(code), d))
                    .unwrap_or_default();
                entry.parameter_name = o.name().to_owned();
                entry.object_type = Some(code);
                Object::var(entry)
            }
        };
        if o.flags() != 0 {
            obj.entry.obj_flags = Some(o.flags());
        }
        if o.compact_sub_obj() && o.code() == ObjectCode::Array {
            compact(&mut obj);
        }
        eds.objects.insert(o.index(), obj);
    }
    let ident = |sub| match eds.entry(0x1018, sub)?.default_value.as_ref()? {
        EdsValue::Integer(v) => u32::try_from(*v).ok(),
        _ => None,
    };
    device_info.vendor_number = device_info.vendor_number.or_else(|| ident(1));
    device_info.product_number = device_info.product_number.or_else(|| ident(2));
    device_info.revision_number = device_info.revision_number.or_else(|| ident(3));
    eds.device_info = device_info;
    eds.rebuild_lists();
    eds
}

/// Turns an ARRAY into its `CompactSubObj` form when the sub-objects allow it.
fn compact(obj: &mut Object) {
    let Some(n) = obj.subs.keys().next_back().copied() else {
        return;
    };
    if obj.subs.len() != usize::from(n) + 1 {
        return;
    }
    let Some(first) = obj.subs.get(&1) else {
        return;
    };
    let entry = Entry {
        parameter_name: obj.entry.parameter_name.clone(),
        object_type: obj.entry.object_type,
        obj_flags: obj.entry.obj_flags,
        ..first.clone()
    };
    let names: BTreeMap<u8, String> = obj
        .subs
        .range(1..)
        .map(|(&s, e)| (s, e.parameter_name.clone()))
        .collect();
    let expanded = expand_compact(&entry, n, &names, &BTreeMap::new(), &BTreeMap::new());
    let same = obj.subs.iter().all(|(s, e)| {
        let Some(x) = expanded.get(s) else {
            return false;
        };
        *s == 0
            || (e.data_type == x.data_type
                && e.access_type == x.access_type
                && e.default_value == x.default_value
                && e.low_limit == x.low_limit
                && e.high_limit == x.high_limit
                && e.pdo_mapping == x.pdo_mapping)
    });
    if same {
        obj.entry = entry;
        obj.sub_number = None;
        obj.compact_sub_obj = Some(n);
        obj.subs = expanded;
    }
}

/// The DCF of a configured device: `eds` (typically from [`from_od`]) with every
/// sub-object's current value from `od` as its `ParameterValue` and `commissioning` as
/// `[DeviceComissioning]`. [`apply_parameter_values`] loads it back into a device.
/// Sub-objects `od` does not have (or whose value it cannot decode) get no `ParameterValue`.
pub fn to_dcf(eds: &Eds, od: &ObjectDictionary, commissioning: crate::DeviceCommissioning) -> Eds {
    let mut dcf = eds.clone();
    for (&index, o) in dcf.objects.iter_mut() {
        let value = |sub: u8| od.get(index, sub).ok().map(|v| from_value(&v));
        if o.subs.is_empty() {
            o.entry.parameter_value = value(0);
        } else {
            for (&sub, e) in o.subs.iter_mut() {
                e.parameter_value = value(sub);
            }
        }
    }
    dcf.commissioning = Some(commissioning);
    dcf
}
