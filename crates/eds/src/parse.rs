//! From INI sections to the typed model (CiA 306 EDS, with the DCF additions).

use crate::error::{ParseError, ParseErrorKind};
use crate::ini::{RawEntry, RawSection, tokenize};
use crate::model::{DeviceCommissioning, DeviceInfo, Eds, Entry, FileInfo, Object, Section};
use crate::value::{EdsValue, parse_integer};
use cantwin_canopen::od::Access;
use std::collections::BTreeMap;

/// What a section name says the section is.
enum Kind {
    FileInfo,
    DeviceInfo,
    DummyUsage,
    Comments,
    List(u8),
    Commissioning,
    Object(u16),
    Sub(u16, u8),
    Names(u16),
    Values(u16),
    Denotations(u16),
    Links(u16),
    Other,
}

fn hex4(s: &str) -> Option<u16> {
    if s.len() == 4 && s.bytes().all(|b| b.is_ascii_hexdigit()) {
        u16::from_str_radix(s, 16).ok()
    } else {
        None
    }
}

fn classify(name: &str) -> Kind {
    let is = |n: &str| name.eq_ignore_ascii_case(n);
    if is("FileInfo") {
        return Kind::FileInfo;
    }
    if is("DeviceInfo") {
        return Kind::DeviceInfo;
    }
    if is("DummyUsage") {
        return Kind::DummyUsage;
    }
    if is("Comments") {
        return Kind::Comments;
    }
    if is("MandatoryObjects") {
        return Kind::List(0);
    }
    if is("OptionalObjects") {
        return Kind::List(1);
    }
    if is("ManufacturerObjects") {
        return Kind::List(2);
    }
    if is("DeviceComissioning") || is("DeviceCommissioning") {
        return Kind::Commissioning;
    }
    if let Some(i) = hex4(name) {
        return Kind::Object(i);
    }
    let (Some(head), Some(tail)) = (name.get(..4), name.get(4..)) else {
        return Kind::Other;
    };
    let Some(index) = hex4(head) else {
        return Kind::Other;
    };
    if let Some(s) = tail
        .get(..3)
        .filter(|p| p.eq_ignore_ascii_case("sub"))
        .and_then(|_| tail.get(3..))
        .filter(|s| !s.is_empty())
    {
        if s.len() <= 2 && s.bytes().all(|b| b.is_ascii_hexdigit()) {
            if let Ok(sub) = u8::from_str_radix(s, 16) {
                return Kind::Sub(index, sub);
            }
        }
        return Kind::Other;
    }
    if tail.eq_ignore_ascii_case("Name") {
        Kind::Names(index)
    } else if tail.eq_ignore_ascii_case("Value") {
        Kind::Values(index)
    } else if tail.eq_ignore_ascii_case("Denotation") {
        Kind::Denotations(index)
    } else if tail.eq_ignore_ascii_case("ObjectLinks") {
        Kind::Links(index)
    } else {
        Kind::Other
    }
}

fn int_of<T: TryFrom<i128>>(
    sec: &RawSection,
    e: &RawEntry,
    expected: &str,
) -> Result<T, ParseError> {
    parse_integer(&e.value)
        .and_then(|v| T::try_from(v).ok())
        .ok_or_else(|| ParseError::invalid(e.line, &sec.name, &e.key, &e.value, expected))
}

fn missing(sec: &RawSection, key: &str) -> ParseError {
    ParseError::at(sec.line, ParseErrorKind::MissingKey)
        .in_section(&sec.name)
        .with_key(key)
}

/// Parses a section of `count_key=n` and numbered entries into the entries by number; the
/// numbers must be exactly `first..first+n` when `dense`, or any `n` distinct numbers.
fn numbered<'a>(
    sec: &'a RawSection,
    count_key: &str,
    key_prefix: &str,
    dense: bool,
) -> Result<BTreeMap<u32, &'a RawEntry>, ParseError> {
    let mut count: Option<u32> = None;
    let mut out = BTreeMap::new();
    for e in &sec.entries {
        if e.key.eq_ignore_ascii_case(count_key) {
            count = Some(int_of(sec, e, "a count")?);
            continue;
        }
        let num = e
            .key
            .get(..key_prefix.len())
            .filter(|p| p.eq_ignore_ascii_case(key_prefix))
            .and_then(|_| e.key.get(key_prefix.len()..))
            .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|n| n.parse::<u32>().ok());
        let Some(num) = num else {
            let what = format!("`{count_key}` or `{key_prefix}<number>`");
            return Err(ParseError::invalid(
                e.line, &sec.name, &e.key, &e.key, &what,
            ));
        };
        out.insert(num, e);
    }
    let Some(count) = count else {
        return Err(missing(sec, count_key));
    };
    if dense {
        if let Some((&k, e)) = out.iter().find(|(k, _)| **k == 0 || **k > count) {
            return Err(ParseError::at(e.line, ParseErrorKind::ListEntry(k))
                .in_section(&sec.name)
                .with_key(&e.key));
        }
        if let Some(k) = (1..=count).find(|k| !out.contains_key(k)) {
            return Err(ParseError::at(sec.line, ParseErrorKind::ListEntry(k))
                .in_section(&sec.name)
                .with_key(count_key));
        }
    } else if out.len() != count as usize {
        let e = sec.get(count_key).map_or(sec.line, |e| e.line);
        return Err(ParseError::invalid(
            e,
            &sec.name,
            count_key,
            &count.to_string(),
            &format!("the number of entries ({})", out.len()),
        ));
    }
    Ok(out)
}

fn index_value(sec: &RawSection, e: &RawEntry) -> Result<u16, ParseError> {
    int_of(sec, e, "an object index 0x0000..=0xFFFF")
}

fn parse_entry(sec: &RawSection) -> Result<(Entry, Option<u8>, Option<u8>), ParseError> {
    let mut entry = Entry::default();
    let data_type: Option<u16> = match sec.get("DataType") {
        Some(e) => Some(int_of(sec, e, "a data type index")?),
        None => None,
    };
    let mut name = None;
    let (mut sub_number, mut compact) = (None, None);
    let value = |e: &RawEntry| {
        EdsValue::parse(data_type, &e.value)
            .map_err(|exp| ParseError::invalid(e.line, &sec.name, &e.key, &e.value, exp))
    };
    for e in &sec.entries {
        let k = e.key.as_str();
        let is = |n: &str| k.eq_ignore_ascii_case(n);
        if is("ParameterName") {
            name = Some(e.value.clone());
        } else if is("ObjectType") {
            entry.object_type = Some(int_of(sec, e, "an object code")?);
        } else if is("DataType") {
            entry.data_type = data_type;
        } else if is("AccessType") {
            entry.access_type = Some(Access::from_eds_name(&e.value).ok_or_else(|| {
                ParseError::invalid(
                    e.line,
                    &sec.name,
                    k,
                    &e.value,
                    "ro, wo, rw, rwr, rww or const",
                )
            })?);
        } else if is("DefaultValue") {
            entry.default_value = Some(value(e)?);
        } else if is("LowLimit") {
            entry.low_limit = Some(value(e)?);
        } else if is("HighLimit") {
            entry.high_limit = Some(value(e)?);
        } else if is("ParameterValue") {
            entry.parameter_value = Some(value(e)?);
        } else if is("PDOMapping") {
            entry.pdo_mapping = Some(match parse_integer(&e.value) {
                Some(0) => false,
                Some(1) => true,
                _ => {
                    return Err(ParseError::invalid(
                        e.line, &sec.name, k, &e.value, "0 or 1",
                    ));
                }
            });
        } else if is("ObjFlags") {
            entry.obj_flags = Some(int_of(sec, e, "an UNSIGNED32")?);
        } else if is("Denotation") {
            entry.denotation = Some(e.value.clone());
        } else if is("UploadFile") {
            entry.upload_file = Some(e.value.clone());
        } else if is("DownloadFile") {
            entry.download_file = Some(e.value.clone());
        } else if is("SubNumber") {
            sub_number = Some(int_of(sec, e, "a number of sub-objects 0..=255")?);
        } else if is("CompactSubObj") {
            compact = Some(int_of(sec, e, "a number of sub-objects 0..=255")?);
        } else {
            entry.extra.push((e.key.clone(), e.value.clone()));
        }
    }
    entry.parameter_name = name.ok_or_else(|| missing(sec, "ParameterName"))?;
    Ok((entry, sub_number, compact))
}

/// The sub-objects `CompactSubObj=n` stands for (CiA 306 compact storage): sub-index 0 "NrOfObjects"
/// (UNSIGNED8, ro, default n) and sub-indices 1..=n with the object's type, access, PDO
/// mapping, limits, default and flags, named from `[xxxxName]` or else the object's name
/// followed by the sub-index, with DCF values and denotations from `[xxxxValue]` and
/// `[xxxxDenotation]`.
pub(crate) fn expand_compact(
    entry: &Entry,
    n: u8,
    names: &BTreeMap<u8, String>,
    values: &BTreeMap<u8, EdsValue>,
    denotations: &BTreeMap<u8, String>,
) -> BTreeMap<u8, Entry> {
    let mut subs = BTreeMap::new();
    subs.insert(
        0,
        Entry {
            parameter_name: "NrOfObjects".to_owned(),
            object_type: Some(crate::VAR),
            data_type: Some(0x0005),
            access_type: Some(Access::Ro),
            default_value: Some(EdsValue::Integer(i128::from(n))),
            pdo_mapping: Some(false),
            ..Entry::default()
        },
    );
    for k in 1..=n {
        subs.insert(
            k,
            Entry {
                parameter_name: names
                    .get(&k)
                    .cloned()
                    .unwrap_or_else(|| format!("{}{k}", entry.parameter_name)),
                object_type: Some(crate::VAR),
                data_type: entry.data_type,
                access_type: entry.access_type,
                default_value: entry.default_value.clone(),
                low_limit: entry.low_limit.clone(),
                high_limit: entry.high_limit.clone(),
                pdo_mapping: entry.pdo_mapping,
                obj_flags: entry.obj_flags,
                parameter_value: values.get(&k).cloned(),
                denotation: denotations.get(&k).cloned(),
                ..Entry::default()
            },
        );
    }
    subs
}

/// Entries of a `[xxxxName]`, `[xxxxValue]` or `[xxxxDenotation]` section keyed by
/// sub-index (decimal keys, `NrOfEntries` of them).
fn by_sub(sec: &RawSection) -> Result<BTreeMap<u8, &RawEntry>, ParseError> {
    let m = numbered(sec, "NrOfEntries", "", false)?;
    m.into_iter()
        .map(|(k, e)| match u8::try_from(k) {
            Ok(s) => Ok((s, e)),
            Err(_) => Err(ParseError::invalid(
                e.line,
                &sec.name,
                &e.key,
                &e.key,
                "a sub-index 0..=255",
            )),
        })
        .collect()
}

/// Decodes bytes: UTF-8 if valid, else ISO 8859-1 (each byte one character), the encoding
/// of most EDS files in the field.
pub fn decode(bytes: &[u8]) -> String {
    match core::str::from_utf8(bytes) {
        Ok(s) => s.to_owned(),
        Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
    }
}

/// Parses an EDS or DCF file.
pub fn parse(text: &str) -> Result<Eds, ParseError> {
    let sections = tokenize(text)?;
    let mut eds = Eds::default();
    let mut subs: Vec<(u16, u8, &RawSection)> = Vec::new();
    let mut helpers: Vec<(u8, u16, &RawSection)> = Vec::new();
    let mut commissioning_line = None;
    for sec in &sections {
        match classify(&sec.name) {
            Kind::FileInfo => eds.file_info = FileInfo::from_raw(sec)?,
            Kind::DeviceInfo => eds.device_info = DeviceInfo::from_raw(sec)?,
            Kind::Commissioning => {
                // Both spellings in one file would be two commissioning sections.
                if let Some(first) = commissioning_line {
                    return Err(
                        ParseError::at(sec.line, ParseErrorKind::DuplicateSection(first))
                            .in_section(&sec.name),
                    );
                }
                commissioning_line = Some(sec.line);
                eds.commissioning = Some(DeviceCommissioning::from_raw(sec)?);
            }
            Kind::DummyUsage => {
                let mut map = BTreeMap::new();
                for e in &sec.entries {
                    let ty = e
                        .key
                        .get(..5)
                        .filter(|p| p.eq_ignore_ascii_case("Dummy"))
                        .and_then(|_| e.key.get(5..))
                        .and_then(hex4)
                        .ok_or_else(|| {
                            ParseError::invalid(
                                e.line,
                                &sec.name,
                                &e.key,
                                &e.key,
                                "a key `Dummyxxxx`",
                            )
                        })?;
                    let on = match parse_integer(&e.value) {
                        Some(0) => false,
                        Some(1) => true,
                        _ => {
                            return Err(ParseError::invalid(
                                e.line, &sec.name, &e.key, &e.value, "0 or 1",
                            ));
                        }
                    };
                    map.insert(ty, on);
                }
                eds.dummy_usage = Some(map);
            }
            Kind::Comments => {
                let lines = numbered(sec, "Lines", "Line", true)?;
                eds.comments = Some(lines.into_values().map(|e| e.value.clone()).collect());
            }
            Kind::List(which) => {
                let entries = numbered(sec, "SupportedObjects", "", true)?;
                let list = entries
                    .into_values()
                    .map(|e| index_value(sec, e))
                    .collect::<Result<Vec<u16>, _>>()?;
                match which {
                    0 => eds.mandatory_objects = list,
                    1 => eds.optional_objects = list,
                    _ => eds.manufacturer_objects = list,
                }
            }
            Kind::Object(index) => {
                let (entry, sub_number, compact_sub_obj) = parse_entry(sec)?;
                eds.objects.insert(
                    index,
                    Object {
                        entry,
                        sub_number,
                        compact_sub_obj,
                        subs: BTreeMap::new(),
                    },
                );
            }
            Kind::Sub(index, sub) => subs.push((index, sub, sec)),
            Kind::Names(i) => helpers.push((0, i, sec)),
            Kind::Values(i) => helpers.push((1, i, sec)),
            Kind::Denotations(i) => helpers.push((2, i, sec)),
            Kind::Links(index) => {
                let entries = numbered(sec, "ObjectLinks", "", true)?;
                let list = entries
                    .into_values()
                    .map(|e| index_value(sec, e))
                    .collect::<Result<Vec<u16>, _>>()?;
                eds.object_links.insert(index, list);
            }
            Kind::Other => eds.other_sections.push(Section {
                name: sec.name.clone(),
                entries: sec
                    .entries
                    .iter()
                    .map(|e| (e.key.clone(), e.value.clone()))
                    .collect(),
            }),
        }
    }
    // Sub-object sections may come before their object section; attach them afterwards.
    let mut sub_lines: BTreeMap<(u16, u8), usize> = BTreeMap::new();
    for (index, sub, sec) in subs {
        // `[1000sub1]` and `[1000sub01]` name the same sub-object.
        if let Some(first) = sub_lines.insert((index, sub), sec.line) {
            return Err(
                ParseError::at(sec.line, ParseErrorKind::DuplicateSection(first))
                    .in_section(&sec.name),
            );
        }
        let Some(obj) = eds.objects.get_mut(&index) else {
            return Err(
                ParseError::at(sec.line, ParseErrorKind::NoObject(index)).in_section(&sec.name)
            );
        };
        if obj.compact_sub_obj.is_some() {
            return Err(
                ParseError::at(sec.line, ParseErrorKind::CompactWithSubs(index))
                    .in_section(&sec.name),
            );
        }
        let (entry, sub_number, compact) = parse_entry(sec)?;
        // SubNumber and CompactSubObj have no meaning on a sub-object; keep them as written.
        let mut entry = entry;
        if let Some(n) = sub_number {
            entry.extra.push(("SubNumber".to_owned(), n.to_string()));
        }
        if let Some(n) = compact {
            entry
                .extra
                .push(("CompactSubObj".to_owned(), n.to_string()));
        }
        obj.subs.insert(sub, entry);
    }
    expand_all(&mut eds, &helpers)?;
    Ok(eds)
}

fn expand_all(eds: &mut Eds, helpers: &[(u8, u16, &RawSection)]) -> Result<(), ParseError> {
    let mut names: BTreeMap<u16, BTreeMap<u8, String>> = BTreeMap::new();
    let mut values: BTreeMap<u16, BTreeMap<u8, EdsValue>> = BTreeMap::new();
    let mut denots: BTreeMap<u16, BTreeMap<u8, String>> = BTreeMap::new();
    for &(what, index, sec) in helpers {
        let compact = eds
            .objects
            .get(&index)
            .filter(|o| o.compact_sub_obj.is_some());
        let Some(obj) = compact else {
            // Not attached to a compact object: keep it as an unknown section.
            eds.other_sections.push(Section {
                name: sec.name.clone(),
                entries: sec
                    .entries
                    .iter()
                    .map(|e| (e.key.clone(), e.value.clone()))
                    .collect(),
            });
            continue;
        };
        let entries = by_sub(sec)?;
        match what {
            0 => {
                names.insert(
                    index,
                    entries
                        .into_iter()
                        .map(|(s, e)| (s, e.value.clone()))
                        .collect(),
                );
            }
            1 => {
                let dt = obj.entry.data_type;
                let mut m = BTreeMap::new();
                for (s, e) in entries {
                    let v = EdsValue::parse(dt, &e.value).map_err(|exp| {
                        ParseError::invalid(e.line, &sec.name, &e.key, &e.value, exp)
                    })?;
                    m.insert(s, v);
                }
                values.insert(index, m);
            }
            _ => {
                denots.insert(
                    index,
                    entries
                        .into_iter()
                        .map(|(s, e)| (s, e.value.clone()))
                        .collect(),
                );
            }
        }
    }
    let empty_s = BTreeMap::new();
    let empty_v = BTreeMap::new();
    for (index, obj) in eds.objects.iter_mut() {
        if let Some(n) = obj.compact_sub_obj {
            obj.subs = expand_compact(
                &obj.entry,
                n,
                names.get(index).unwrap_or(&empty_s),
                values.get(index).unwrap_or(&empty_v),
                denots.get(index).unwrap_or(&empty_s),
            );
        }
    }
    Ok(())
}
