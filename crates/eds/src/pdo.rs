//! The PDOs of a device built from the file (CiA 301 §7.5.2.35–38): each PDO's mapping as
//! the file sets it, checked entry by entry the way the device checks it when it loads its
//! PDOs. A PDO whose mapping cannot run stays off (and, while its COB-ID is valid, its
//! mapping and COB-ID cannot be changed, §7.5.2.36); the rest of the file's PDOs run.

use crate::error::{Issue, Severity};
use crate::model::Eds;
use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{ObjectDictionary, OdDescription};
use cantwin_canopen::pdo::{
    CobId, Direction, MAX_ENTRIES, MapEntry, Plan, RPDO_COMM, RPDO_MAP, TPDO_COMM, TPDO_MAP,
    check_entry,
};
use std::sync::Arc;

/// What the file's PDO mappings make the device do differently from what the file lists:
/// one warning per mapping entry that cannot be mapped (or per mapping that cannot run),
/// naming the PDO. `eds` is the file the device is built from (a commissioned DCF with its
/// `ParameterValue`s as defaults, see [`crate::configured`]).
pub fn pdo_issues(eds: &Eds) -> Vec<Issue> {
    let Ok(desc) = crate::to_od(eds) else {
        // A file no dictionary can hold has no PDOs; `to_od`'s refusal says why.
        return Vec::new();
    };
    let desc = Arc::new(desc);
    // Mapping entries and COB-IDs do not depend on the node-ID's value, only on the file.
    let od = ObjectDictionary::new(Arc::clone(&desc), 1);
    // `[DummyUsage]` that supports no dummy type refuses dummy entries (CiA 306 §4.5.5),
    // as the device built from the file does.
    let dummies = eds
        .dummy_usage
        .as_ref()
        .is_none_or(|d| d.values().any(|&supported| supported));
    let mut out = Vec::new();
    for (dir, comm, map, name) in [
        (Direction::Rx, RPDO_COMM, RPDO_MAP, "RPDO"),
        (Direction::Tx, TPDO_COMM, TPDO_MAP, "TPDO"),
    ] {
        for n in 0..cantwin_canopen::pdo::MAX_PDOS {
            let (ci, mi) = (comm + n, map + n);
            if desc.object(ci).is_none() || desc.object(mi).is_none() {
                continue;
            }
            let valid = od
                .get_unsigned(ci, 1)
                .is_some_and(|v| CobId(v as u32).is_valid());
            let pdo = format!("{name} {}", n + 1);
            check_mapping(eds, &desc, &od, dir, dummies, mi, &pdo, valid, &mut out);
        }
    }
    out
}

/// The consequence of a mapping that cannot run, for the message.
fn consequence(valid: bool) -> &'static str {
    if valid {
        "the PDO is off"
    } else {
        "the PDO cannot be made valid until its mapping is rewritten"
    }
}

#[allow(clippy::too_many_arguments)]
fn check_mapping(
    eds: &Eds,
    desc: &OdDescription,
    od: &ObjectDictionary,
    dir: Direction,
    dummies: bool,
    mi: u16,
    pdo: &str,
    valid: bool,
    out: &mut Vec<Issue>,
) {
    // The key that set the value: a DCF's ParameterValue, else the DefaultValue.
    let key = |sub: u8| {
        let pv = eds
            .entry(mi, sub)
            .is_some_and(|e| e.parameter_value.is_some());
        Some(if pv { "ParameterValue" } else { "DefaultValue" }.to_owned())
    };
    let section = |sub: u8| match eds.objects.get(&mi) {
        Some(o) if o.subs.is_empty() => format!("{mi:04X}"),
        _ => format!("{mi:04X}sub{sub:X}"),
    };
    let mut push = |sub: u8, message: String| {
        out.push(Issue {
            severity: Severity::Warning,
            line: None,
            section: section(sub),
            key: key(sub),
            message: format!("{pdo} {message}: {}", consequence(valid)),
        });
    };
    let count = od.get_unsigned(mi, 0).unwrap_or(0);
    if count > u64::from(MAX_ENTRIES) {
        push(
            0,
            format!("maps {count} entries, more than {MAX_ENTRIES} (0x06040042)"),
        );
        return;
    }
    let mut entries = Vec::new();
    let mut bad = false;
    for sub in 1..=count as u8 {
        let Some(raw) = od.get_unsigned(mi, sub) else {
            push(
                0,
                format!(
                    "maps {count} entries, the mapping object has no sub-index {sub} (0x06040042)"
                ),
            );
            return;
        };
        let e = MapEntry::from_u32(raw as u32);
        entries.push(e);
        if let Err(code) = check_entry(desc, dir, dummies, e) {
            bad = true;
            let what = if e.is_dummy() {
                format!(
                    "maps the dummy entry {:#06X}, which this device does not take",
                    e.index
                )
            } else if code == AbortCode::NO_OBJECT {
                format!("maps {:#06X}, which the file does not define", e.index)
            } else if code == AbortCode::NO_SUB_INDEX {
                format!(
                    "maps {:#06X} sub {}, which the file does not define",
                    e.index, e.sub
                )
            } else {
                format!(
                    "maps {:#06X} sub {} ({} bits), which cannot be mapped: not PDOMapping=1, \
                     not of a fixed size, not {} or longer than its type (0x06040041)",
                    e.index,
                    e.sub,
                    e.bits,
                    match dir {
                        Direction::Rx => "writable",
                        Direction::Tx => "readable",
                    }
                )
            };
            push(sub, what);
        }
    }
    if !bad && let Err(code) = Plan::build(desc, dir, dummies, entries) {
        push(0, format!("has a mapping that cannot run ({code})"));
    }
}
