//! Between EDS/DCF files and the object dictionary of `cantwin-canopen`: a device's EDS is
//! generated from its dictionary ([`from_od`]), and a dictionary description can be built
//! from an EDS ([`to_od`]) and configured from a DCF ([`apply_parameter_values`]).

use crate::check::{Issue, Severity};
use crate::judge::{Default, judge, outside, value_of};
use crate::model::{DeviceInfo, Eds, Entry, FileInfo, Object};
use crate::parse::expand_compact;
use crate::value::EdsValue;
use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{
    Access, DataType, ObjectCode, ObjectDictionary, OdBuildError, OdBuilder, OdDescription,
    SubObject, Value,
};
use std::collections::BTreeMap;

/// Why an EDS cannot become an object dictionary (or a DCF value cannot be applied).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvertError {
    /// `DataType` is absent from an entry that holds a value: no dictionary can hold it.
    #[error("{index:#06X}:{sub}: data type {data_type:?} is not supported")]
    DataType {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The `DataType` given, if any.
        data_type: Option<u16>,
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

fn from_value(v: &Value) -> EdsValue {
    match v {
        Value::Real32(x) => EdsValue::Real32(*x),
        Value::Real64(x) => EdsValue::Real64(*x),
        Value::VisibleString(s) => EdsValue::Text(s.clone()),
        Value::UnicodeString(u) => EdsValue::Text(String::from_utf16_lossy(u)),
        Value::OctetString(b) | Value::Domain(b) => EdsValue::Bytes(b.clone()),
        // `days ms`, the form tools write and the loader reads back (CiA 306 gives these
        // types no text form of its own).
        Value::TimeOfDay(t) | Value::TimeDifference(t) => {
            EdsValue::Raw(format!("{} {}", t.days, t.ms))
        }
        other => match other.as_i128() {
            Some(x) => EdsValue::Integer(x),
            None => EdsValue::Raw(other.to_string()),
        },
    }
}

fn sub_object(index: u16, sub: u8, e: &Entry) -> Result<SubObject, ConvertError> {
    let j = judge(e, true);
    let ty = j.ty.ok_or(ConvertError::DataType {
        index,
        sub,
        data_type: e.data_type,
    })?;
    let mut d = SubObject::new(e.parameter_name.clone(), ty, j.access);
    d.pdo_mappable = e.pdo_mapping.unwrap_or(false);
    match j.default {
        None => {}
        Some(Default::NodeId(base)) => d = d.default_node_id_plus(base),
        Some(Default::Value(v)) => d.default = Some(v),
    }
    d.low_limit = j.low;
    d.high_limit = j.high;
    Ok(d)
}

/// The sub-objects of an ARRAY or RECORD as the dictionary holds them: a missing sub-index 0
/// is added as CiA 301 defines it (UNSIGNED8, read-only, the highest sub-index), and an
/// object without sub-objects gets that sub-index 0 alone.
fn composite_subs(index: u16, o: &Object) -> Result<Vec<(u8, SubObject)>, ConvertError> {
    let mut subs = o
        .subs
        .iter()
        .map(|(&s, e)| sub_object(index, s, e).map(|d| (s, d)))
        .collect::<Result<Vec<_>, _>>()?;
    if !o.subs.contains_key(&0) {
        let highest = o.subs.keys().next_back().copied().unwrap_or(0);
        let s0 = SubObject::new(
            "Highest sub-index supported",
            DataType::Unsigned8,
            Access::Ro,
        )
        .default(Value::Unsigned8(highest));
        subs.insert(0, (0, s0));
    }
    Ok(subs)
}

/// The length in bits of a basic data type, the value a DEFTYPE entry holds (CiA 301
/// §7.4.7.1); variable-length types hold 0.
fn type_bits(index: u16) -> u32 {
    DataType::from_index(index)
        .and_then(DataType::fixed_size)
        .map_or(0, |n| if index == 0x0001 { 1 } else { n as u32 * 8 })
}

/// Builds an object dictionary description from an EDS, as the file evidently means it
/// (the judgement [`crate::Eds::check`] reports is the one applied here).
///
/// VAR and DOMAIN objects become VARs, ARRAY and RECORD objects keep their sub-objects (a
/// VAR with sub-objects is held as a RECORD), `ObjFlags` and `CompactSubObj` carry over.
/// DEFTYPE objects of the basic types (the dummy entries 0x0001..=0x0007 among them) are
/// held as read-only UNSIGNED32 values with the type's length in bits (CiA 301 §7.4.7.1) and
/// keep their object code. Values that do not fit their type are left out, a `LowLimit`
/// above `HighLimit` is taken swapped, and a default outside the limits is kept (the
/// object starts there, as the file says); an undefined data type is held as DOMAIN; a missing or
/// unreadable access type as read-only. Only an entry without any data type makes a
/// dictionary impossible. NULL and DEFSTRUCT objects, and objects with an unknown object
/// code, are left out. `ParameterValue`s are not part of a description; see
/// [`apply_parameter_values`].
pub fn to_od(eds: &Eds) -> Result<OdDescription, ConvertError> {
    let mut b = OdBuilder::new();
    // `[DummyUsage]` says which dummy types the device supports (CiA 306 §4.5.5); a supported
    // one is the DEFTYPE object of its type (CiA 301 §7.4.7.1), with or without its section.
    let dummy = |index: u16| {
        eds.dummy_usage
            .as_ref()
            .and_then(|d| d.get(&index).copied())
    };
    for index in 0x0001..=0x0007u16 {
        let declared = eds
            .objects
            .get(&index)
            .is_some_and(|o| o.object_code() == 0x5);
        if dummy(index) == Some(true)
            && !declared
            && let Some(ty) = DataType::from_index(index)
        {
            let mut d = SubObject::unsigned32(ty.to_string(), Access::Ro, type_bits(index));
            d.access = Access::Const;
            b = b.var(index, d).code(ObjectCode::DefType);
        }
    }
    for (&index, o) in &eds.objects {
        let code = o.object_code();
        if code == 0x5 {
            if DataType::from_index(index).is_none() || dummy(index) == Some(false) {
                continue;
            }
            let mut d =
                SubObject::unsigned32(o.entry.parameter_name.clone(), Access::Ro, type_bits(index));
            d.access = Access::Const;
            b = b.var(index, d).code(ObjectCode::DefType);
            continue;
        }
        let composite = code == crate::ARRAY || code == crate::RECORD;
        let var_like = code == crate::VAR || code == crate::DOMAIN;
        if !composite && !var_like {
            continue;
        }
        let name = o.entry.parameter_name.clone();
        if code == crate::ARRAY {
            b = b.array(index, name, composite_subs(index, o)?);
        } else if composite || !o.subs.is_empty() {
            b = b.record(index, name, composite_subs(index, o)?);
        } else {
            b = b.var(index, sub_object(index, 0, &o.entry)?);
            if code == crate::DOMAIN {
                b = b.code(ObjectCode::Domain);
            }
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
/// many were set. A value [`crate::Eds::check`] reports as not fitting its entry is left
/// out, as [`to_od`] leaves out such a default; one the device refuses is an error.
pub fn apply_parameter_values(eds: &Eds, od: &mut ObjectDictionary) -> Result<usize, ConvertError> {
    let node_id = od.node_id();
    let mut n = 0;
    for (&index, o) in &eds.objects {
        for (sub, e) in o.values() {
            let Some(v) = &e.parameter_value else {
                continue;
            };
            let Some(value) = judged_value(e, v, node_id) else {
                continue;
            };
            od.set(index, sub, &value)
                .map_err(|abort| ConvertError::Apply { index, sub, abort })?;
            n += 1;
        }
    }
    Ok(n)
}

/// `v` (a value of entry `e`) as the dictionary holds it on node `node_id`, if the judgement
/// of the entry keeps it.
fn judged_value(e: &Entry, v: &EdsValue, node_id: u8) -> Option<Value> {
    DataType::from_index(e.data_type?)?;
    let ty = judge(e, true).ty?;
    value_of(ty, v, node_id).ok().flatten()
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
    // The dummy types the device supports are its DEFTYPE objects 0x0001..=0x0007
    // (CiA 301 §7.4.7.1), which `[DummyUsage]` lists (CiA 306 §4.5.5).
    let dummies: BTreeMap<u16, bool> = (0x0001..=0x0007u16)
        .map(|i| {
            (
                i,
                desc.object(i)
                    .is_some_and(|o| o.code() == ObjectCode::DefType),
            )
        })
        .collect();
    if dummies.values().any(|&on| on) {
        eds.dummy_usage = Some(dummies);
    }
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

/// `eds` (typically from [`from_od`]) with the power-on values of `od`'s writable
/// communication parameters (0x1000–0x1FFF) as their `DefaultValue` where they differ from
/// the description's default on `od`'s node: the values a twin sets itself at every reset
/// communication (a scenario's heartbeat time, for one) are what the device has after a
/// reset, which is what CiA 306 §4.6.3 calls the default. A value that equals the
/// node-relative default keeps its `$NODEID` form; values of other objects (inputs, status)
/// are not defaults and stay as described.
pub fn power_on_defaults(eds: &mut Eds, od: &ObjectDictionary) {
    let desc = od.description();
    let node = i128::from(od.node_id());
    for (&index, o) in eds.objects.range_mut(0x1000..=0x1FFF) {
        let entries: Vec<(u8, &mut Entry)> = if o.subs.is_empty() {
            vec![(0, &mut o.entry)]
        } else {
            o.subs.iter_mut().map(|(&sub, e)| (sub, e)).collect()
        };
        for (sub, e) in entries {
            let Some(d) = desc.get(index, sub) else {
                continue;
            };
            if !d.access.writable() {
                continue;
            }
            let Ok(now) = od.get(index, sub) else {
                continue;
            };
            let described = d
                .default
                .clone()
                .unwrap_or_else(|| Value::zero(d.data_type));
            let same = match (
                d.default_node_id_relative,
                described.as_i128(),
                now.as_i128(),
            ) {
                (true, Some(offset), Some(v)) => v == offset + node,
                _ => now == described,
            };
            if !same {
                e.default_value = Some(from_value(&now));
            }
        }
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

/// The DCF of node `node_id` made from an EDS or a DCF, without a device: each entry's
/// `ParameterValue` is its value on that node — the file's own `ParameterValue` where it has
/// one (a DCF given as input keeps its configuration), else its `DefaultValue` — with
/// `$NODEID` resolved, as [`crate::Eds::check`] judges it. What is left unset, or changed,
/// is said in the returned findings:
///
/// * an entry with neither value, an empty `DefaultValue`, or a value the judgement leaves
///   out gets no `ParameterValue` (a note): a value is never invented;
/// * a `DefaultValue` outside the entry's limits gets none either (a warning naming the
///   value and the limits): the node cannot take it back (CiA 301 §7.2.4.3.17), so the
///   integrator gives the value;
/// * a DCF made for another node (`[DeviceComissioning] NodeID`, or else the node most of
///   its node-relative values are evidently for) whose `ParameterValue` is that node's
///   `$NODEID`-based default (a COB-ID `0x187` of node 7) is written for the new node (a
///   note); one the integrator changed (not the old node's default) is kept, with a warning
///   that it is node-specific.
///
/// Text is kept as written.
pub fn commission(
    eds: &Eds,
    node_id: u8,
    commissioning: crate::DeviceCommissioning,
) -> (Eds, Vec<Issue>) {
    let mut found = Vec::new();
    let stated = eds.commissioning.as_ref().and_then(|c| c.node_id);
    let old_node = stated.or_else(|| written_for(eds));
    if let (None, Some(n)) = (stated, old_node) {
        found.push(Issue {
            severity: Severity::Note,
            line: None,
            section: "DeviceComissioning".to_owned(),
            key: Some("NodeID".to_owned()),
            message: format!(
                "the file names no node; its node-relative ParameterValues are evidently \
                 for node {n}"
            ),
        });
    }
    let mut dcf = eds.clone();
    for (&index, o) in dcf.objects.iter_mut() {
        let code = o.object_code();
        if !matches!(
            code,
            crate::VAR | crate::DOMAIN | crate::ARRAY | crate::RECORD
        ) {
            continue;
        }
        let single = o.subs.is_empty();
        let entries: Vec<(u8, &mut Entry)> = if single {
            vec![(0, &mut o.entry)]
        } else {
            o.subs.iter_mut().map(|(s, e)| (*s, e)).collect()
        };
        for (sub, e) in entries {
            let section = if single {
                format!("{index:04X}")
            } else {
                format!("{index:04X}sub{sub:X}")
            };
            let mut say = |severity, message: String| {
                found.push(Issue {
                    severity,
                    line: None,
                    section: section.clone(),
                    key: Some("ParameterValue".to_owned()),
                    message,
                });
            };
            e.parameter_value = match e.parameter_value.clone() {
                Some(pv) => kept_value(e, &pv, old_node, node_id, &mut say),
                None => default_as_value(e, index, sub, node_id, &mut say),
            };
        }
    }
    dcf.commissioning = Some(commissioning);
    (dcf, found)
}

/// The node a file's `ParameterValue`s were written for when it does not say
/// (`[DeviceComissioning] NodeID`): the node-ID most of its node-relative entries
/// (`DefaultValue=$NODEID+n`) evidently hold (`ParameterValue` minus `n` in 1..=127), when
/// one node-ID is the most common; `None` if none or a tie.
fn written_for(eds: &Eds) -> Option<u8> {
    let mut count = [0usize; 128];
    for o in eds.objects.values() {
        for e in std::iter::once(&o.entry).chain(o.subs.values()) {
            if let (Some(EdsValue::NodeId(off)), Some(EdsValue::Integer(pv))) =
                (&e.default_value, &e.parameter_value)
                && let Ok(n) = u8::try_from(pv - off)
                && (1..=127).contains(&n)
            {
                count[usize::from(n)] += 1;
            }
        }
    }
    let best = *count.iter().max()?;
    let mut at = (1..=127u8).filter(|&n| count[usize::from(n)] == best);
    match (best, at.next(), at.next()) {
        (1.., Some(n), None) => Some(n),
        _ => None,
    }
}

/// The `ParameterValue` `pv` of a file made for node `old_node`, for node `node_id`.
fn kept_value(
    e: &Entry,
    pv: &EdsValue,
    old_node: Option<u8>,
    node_id: u8,
    say: &mut impl FnMut(Severity, String),
) -> Option<EdsValue> {
    let Some(now) = judged_value(e, pv, node_id) else {
        say(
            Severity::Note,
            "the ParameterValue does not fit the entry; left unset".to_owned(),
        );
        return None;
    };
    if let EdsValue::NodeId(_) = pv {
        return Some(from_value(&now));
    }
    // A value of a node-relative entry (COB-IDs, CiA 301 §7.5.2.35/37) was written for the
    // node the file was made for.
    let Some(off @ EdsValue::NodeId(o)) = &e.default_value else {
        return Some(pv.clone());
    };
    if old_node == Some(node_id) || judged_value(e, off, node_id).as_ref() == Some(&now) {
        return Some(pv.clone());
    }
    let old_default = old_node.and_then(|n| judged_value(e, off, n));
    match (old_node, old_default) {
        (Some(old), Some(d)) if d == now => {
            let new = judged_value(e, off, node_id)?;
            say(
                Severity::Note,
                format!(
                    "{} is the DefaultValue $NODEID+{o:#X} of node {old}; written for node \
                     {node_id} ({})",
                    pv.to_text(e.data_type),
                    from_value(&new).to_text(e.data_type)
                ),
            );
            Some(from_value(&new))
        }
        (old, _) => {
            let made_for = old.map_or("another node".to_owned(), |n| format!("node {n}"));
            say(
                Severity::Warning,
                format!(
                    "{} is kept, but it is node-specific: the DefaultValue is $NODEID+{o:#X} \
                     and the file was made for {made_for}; check it for node {node_id}",
                    pv.to_text(e.data_type)
                ),
            );
            Some(pv.clone())
        }
    }
}

/// The `DefaultValue` of `e` as its `ParameterValue` on node `node_id`, if it can be one.
fn default_as_value(
    e: &Entry,
    index: u16,
    sub: u8,
    node_id: u8,
    say: &mut impl FnMut(Severity, String),
) -> Option<EdsValue> {
    let dv = match &e.default_value {
        None => {
            say(
                Severity::Note,
                "no DefaultValue and no ParameterValue; left unset".to_owned(),
            );
            return None;
        }
        Some(EdsValue::Raw(t)) if t.trim().is_empty() => {
            say(
                Severity::Note,
                "the DefaultValue is empty and there is no ParameterValue; left unset".to_owned(),
            );
            return None;
        }
        Some(dv) => dv,
    };
    let Some(x) = judged_value(e, dv, node_id) else {
        say(
            Severity::Note,
            "the DefaultValue does not fit the entry; left unset".to_owned(),
        );
        return None;
    };
    let j = judge(e, true);
    if let Some(m) = outside(&x, j.low.as_ref(), j.high.as_ref()) {
        let bound = |v: &Option<Value>| v.as_ref().map_or(String::new(), |v| v.to_string());
        say(
            Severity::Warning,
            format!(
                "the DefaultValue {x} is {m} (limits {}..={}), which the node cannot take; \
                 left unset: give the node's value with --set {index:#06X}:{sub}=VALUE",
                bound(&j.low),
                bound(&j.high)
            ),
        );
        return None;
    }
    Some(match dv {
        EdsValue::NodeId(_) => from_value(&x),
        other => other.clone(),
    })
}

/// What a device built from the file does that a user of the file should be told, with no
/// lines (see [`crate::load`] for them): a PDO whose mapping cannot run stays off
/// ([`crate::pdo_issues`]), and an object whose `DefaultValue` lies outside its limits
/// starts there, as the file says. `eds` is the file the device is built from.
pub fn device_warnings(eds: &Eds) -> Vec<Issue> {
    let mut out = Vec::new();
    for (&index, o) in &eds.objects {
        let code = o.object_code();
        let var_like = code == crate::VAR || code == crate::DOMAIN;
        let composite = code == crate::ARRAY || code == crate::RECORD;
        let entries: Vec<(String, &Entry)> = if o.subs.is_empty() && var_like {
            vec![(format!("{index:04X}"), &o.entry)]
        } else if composite || var_like {
            o.subs
                .iter()
                .map(|(s, e)| (format!("{index:04X}sub{s:X}"), e))
                .collect()
        } else {
            Vec::new()
        };
        for (section, e) in entries {
            if let Some(m) = judge(e, true).default_outside {
                out.push(Issue {
                    severity: Severity::Warning,
                    line: None,
                    section,
                    key: Some("DefaultValue".to_owned()),
                    message: m,
                });
            }
        }
    }
    out.extend(crate::pdo::pdo_issues(eds));
    out
}

/// The file with each DCF `ParameterValue` as the entry's `DefaultValue`, where the
/// judgement keeps the value (one that does not fit leaves the default as it is): the
/// values a commissioned device comes up with after power-on and after every reset
/// (CiA 306 DCF).
pub fn configured(eds: &Eds) -> Eds {
    let mut out = eds.clone();
    for o in out.objects.values_mut() {
        let entries = std::iter::once(&mut o.entry).chain(o.subs.values_mut());
        for e in entries {
            let Some(v) = e.parameter_value.clone() else {
                continue;
            };
            // Judged for the lowest and the highest node-ID, as a default is.
            if judged_value(e, &v, 1).is_some() && judged_value(e, &v, 127).is_some() {
                e.default_value = Some(v);
            }
        }
    }
    out
}
