//! The canonical CiA 306 layout.
//!
//! Sections in this order: `[FileInfo]`, `[DeviceInfo]`, `[DeviceComissioning]` (DCF),
//! `[DummyUsage]`, `[Comments]`, the three object lists, then every object in index order,
//! each followed by its sub-object sections (or, for a compact array, its `Name`, `Value`
//! and `Denotation` sections) and its `ObjectLinks`, then the sections the model has no
//! type for, in their original order. Keys are written with CiA 306 spelling, one blank
//! line after each section, `\n` line ends, numbers in the forms python-canopen's importer
//! reads (`0x` hex or decimal, never a leading-zero octal).

use crate::model::{Eds, Entry, Object};
use crate::parse::expand_compact;
use crate::value::EdsValue;
use std::collections::BTreeMap;
use std::fmt::Write as _;

struct Out(String);

impl Out {
    fn section(&mut self, name: &str, entries: &[(String, String)]) {
        let _ = writeln!(self.0, "[{name}]");
        for (k, v) in entries {
            let _ = writeln!(self.0, "{k}={v}");
        }
        self.0.push('\n');
    }
}

fn kv(k: &str, v: impl Into<String>) -> (String, String) {
    (k.to_owned(), v.into())
}

fn entry_keys(e: &Entry, sub_number: Option<u8>, compact: Option<u8>) -> Vec<(String, String)> {
    let dt = e.data_type;
    let mut v = vec![kv("ParameterName", e.parameter_name.as_str())];
    if let Some(t) = e.object_type {
        v.push(kv("ObjectType", format!("0x{t:X}")));
    }
    if let Some(n) = sub_number {
        v.push(kv("SubNumber", format!("0x{n:X}")));
    }
    if let Some(n) = compact {
        v.push(kv("CompactSubObj", format!("0x{n:X}")));
    }
    if let Some(t) = dt {
        v.push(kv("DataType", format!("0x{t:04X}")));
    }
    if let Some(a) = e.access_type {
        v.push(kv("AccessType", a.eds_name()));
    }
    let val = |x: &EdsValue| x.to_text(dt);
    if let Some(x) = &e.default_value {
        v.push(kv("DefaultValue", val(x)));
    }
    if let Some(p) = e.pdo_mapping {
        v.push(kv("PDOMapping", if p { "1" } else { "0" }));
    }
    if let Some(x) = &e.low_limit {
        v.push(kv("LowLimit", val(x)));
    }
    if let Some(x) = &e.high_limit {
        v.push(kv("HighLimit", val(x)));
    }
    if let Some(f) = e.obj_flags {
        v.push(kv("ObjFlags", format!("0x{f:X}")));
    }
    if let Some(x) = &e.parameter_value {
        v.push(kv("ParameterValue", val(x)));
    }
    if let Some(d) = &e.denotation {
        v.push(kv("Denotation", d.as_str()));
    }
    if let Some(f) = &e.upload_file {
        v.push(kv("UploadFile", f.as_str()));
    }
    if let Some(f) = &e.download_file {
        v.push(kv("DownloadFile", f.as_str()));
    }
    // An extra key is written unless a typed field already wrote one of that name (an
    // unreadable value of a defined key is kept there and written back as found).
    for (k, x) in &e.extra {
        if !v.iter().any(|(w, _)| w.eq_ignore_ascii_case(k)) {
            v.push((k.clone(), x.clone()));
        }
    }
    v
}

/// The names, values and denotations a compact object's sub-objects would be written with,
/// if [`expand_compact`] of them gives the sub-objects back exactly.
type Compacted = (
    BTreeMap<u8, String>,
    BTreeMap<u8, EdsValue>,
    BTreeMap<u8, String>,
);

fn recompact(o: &Object) -> Option<(u8, Compacted)> {
    let n = o.compact_sub_obj?;
    let mut names = BTreeMap::new();
    let mut values = BTreeMap::new();
    let mut denots = BTreeMap::new();
    for (&s, e) in o.subs.range(1..) {
        names.insert(s, e.parameter_name.clone());
        if let Some(v) = &e.parameter_value {
            values.insert(s, v.clone());
        }
        if let Some(d) = &e.denotation {
            denots.insert(s, d.clone());
        }
    }
    (expand_compact(&o.entry, n, &names, &values, &denots) == o.subs)
        .then_some((n, (names, values, denots)))
}

fn numbered<T>(
    count_key: &str,
    items: &BTreeMap<u8, T>,
    f: impl Fn(&T) -> String,
) -> Vec<(String, String)> {
    let mut v = vec![kv(count_key, items.len().to_string())];
    v.extend(items.iter().map(|(s, x)| (s.to_string(), f(x))));
    v
}

fn list(count_key: &str, items: &[u16]) -> Vec<(String, String)> {
    let mut v = vec![kv(count_key, items.len().to_string())];
    v.extend(
        items
            .iter()
            .enumerate()
            .map(|(i, x)| ((i + 1).to_string(), format!("0x{x:04X}"))),
    );
    v
}

/// Writes the file in the canonical layout.
pub fn write(eds: &Eds) -> String {
    let mut out = Out(String::new());
    out.section("FileInfo", &eds.file_info.to_entries());
    out.section("DeviceInfo", &eds.device_info.to_entries());
    if let Some(c) = &eds.commissioning {
        out.section("DeviceComissioning", &c.to_entries());
    }
    if let Some(d) = &eds.dummy_usage {
        let e: Vec<_> = d
            .iter()
            .map(|(t, on)| {
                (
                    format!("Dummy{t:04X}"),
                    if *on { "1" } else { "0" }.to_owned(),
                )
            })
            .collect();
        out.section("DummyUsage", &e);
    }
    if let Some(lines) = &eds.comments {
        let mut e = vec![kv("Lines", lines.len().to_string())];
        e.extend(
            lines
                .iter()
                .enumerate()
                .map(|(i, l)| (format!("Line{}", i + 1), l.clone())),
        );
        out.section("Comments", &e);
    }
    out.section(
        "MandatoryObjects",
        &list("SupportedObjects", &eds.mandatory_objects),
    );
    out.section(
        "OptionalObjects",
        &list("SupportedObjects", &eds.optional_objects),
    );
    out.section(
        "ManufacturerObjects",
        &list("SupportedObjects", &eds.manufacturer_objects),
    );
    for (&index, o) in &eds.objects {
        write_object(&mut out, index, o);
        if let Some(links) = eds.object_links.get(&index) {
            out.section(
                &format!("{index:04X}ObjectLinks"),
                &list("ObjectLinks", links),
            );
        }
    }
    // Links of indices that have no object are kept too.
    for (index, links) in eds.object_links.range(..) {
        if !eds.objects.contains_key(index) {
            out.section(
                &format!("{index:04X}ObjectLinks"),
                &list("ObjectLinks", links),
            );
        }
    }
    for s in &eds.other_sections {
        out.section(&s.name, &s.entries);
    }
    out.0
}

fn write_object(out: &mut Out, index: u16, o: &Object) {
    let dt = o.entry.data_type;
    if let Some((n, (names, values, denots))) = recompact(o) {
        out.section(
            &format!("{index:04X}"),
            &entry_keys(&o.entry, o.sub_number, Some(n)),
        );
        // Every name is listed, not only the ones that differ from the derived default:
        // python-canopen reads `1..=NrOfEntries` and needs each key.
        out.section(
            &format!("{index:04X}Name"),
            &numbered("NrOfEntries", &names, String::clone),
        );
        if !values.is_empty() {
            out.section(
                &format!("{index:04X}Value"),
                &numbered("NrOfEntries", &values, |v| v.to_text(dt)),
            );
        }
        if !denots.is_empty() {
            out.section(
                &format!("{index:04X}Denotation"),
                &numbered("NrOfEntries", &denots, String::clone),
            );
        }
        return;
    }
    // `SubNumber` is written as stated; only a compact object that can no longer be written
    // compactly gets one computed, as CiA 306 object descriptions require it of expanded ARRAYs.
    let sub_number = match (o.sub_number, o.compact_sub_obj) {
        (Some(n), _) => Some(n),
        (None, Some(_)) => Some(u8::try_from(o.subs.len()).unwrap_or(u8::MAX)),
        (None, None) => None,
    };
    out.section(
        &format!("{index:04X}"),
        &entry_keys(&o.entry, sub_number, None),
    );
    for (sub, e) in &o.subs {
        out.section(
            &format!("{index:04X}sub{sub:X}"),
            &entry_keys(e, None, None),
        );
    }
}
