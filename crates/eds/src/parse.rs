//! From INI sections to the typed model (CiA 306 EDS, with the DCF additions).

use crate::check::{Report, Severity};
use crate::error::{ParseError, ParseErrorKind};
use crate::ini::{RawEntry, RawSection, tokenize};
use crate::model::{DeviceCommissioning, DeviceInfo, Eds, Entry, FileInfo, Object, Section};
use crate::value::{EdsValue, parse_integer};
use cantwin_canopen::od::Access;
use std::collections::{BTreeMap, HashMap};

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

/// What the parser found, in file order.
struct Found(crate::ini::Found);

impl Found {
    fn push(&mut self, severity: Severity, e: ParseError) {
        self.0.push((severity, e));
    }
}

fn int_of<T: TryFrom<i128>>(e: &RawEntry) -> Option<T> {
    parse_integer(&e.value).and_then(|v| T::try_from(v).ok())
}

/// Reads an integer key; what cannot be read is an error, kept among the extra keys so that
/// it is written back as found.
fn int_key<T: TryFrom<i128>>(
    f: &mut Found,
    sec: &RawSection,
    e: &RawEntry,
    expected: &str,
    extra: &mut Vec<(String, String)>,
) -> Option<T> {
    let v = int_of(e);
    if v.is_none() {
        f.push(
            Severity::Error,
            ParseError::invalid(e.line, &sec.name, &e.key, &e.value, expected),
        );
        extra.push((e.key.clone(), e.value.clone()));
    }
    v
}

fn missing(sec: &RawSection, key: &str) -> ParseError {
    ParseError::at(sec.line, ParseErrorKind::MissingKey)
        .in_section(&sec.name)
        .with_key(key)
}

/// Reads a section of `count_key=n` and numbered entries into the entries by number.
///
/// CiA 306 wants exactly `n` entries numbered `1..=n`; files in the field state counts that
/// disagree with what they list (`SupportedObjects=0` followed by `1=0x2000`). What is
/// listed is what the file means: every numbered entry is taken, and a missing or
/// disagreeing count is a warning. A key that is not a number is a warning and skipped.
fn numbered<'a>(
    f: &mut Found,
    sec: &'a RawSection,
    count_key: &str,
    key_prefix: &str,
) -> BTreeMap<u32, &'a RawEntry> {
    let mut count: Option<(u32, usize)> = None;
    let mut out = BTreeMap::new();
    for e in &sec.entries {
        if e.key.eq_ignore_ascii_case(count_key) {
            match int_of::<u32>(e) {
                Some(n) => count = Some((n, e.line)),
                None => f.push(
                    Severity::Warning,
                    ParseError::invalid(e.line, &sec.name, &e.key, &e.value, "a count"),
                ),
            }
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
            let what = format!("`{count_key}` or `{key_prefix}<number>`; skipped");
            f.push(
                Severity::Warning,
                ParseError::invalid(e.line, &sec.name, &e.key, &e.key, &what),
            );
            continue;
        };
        out.insert(num, e);
    }
    match count {
        None => f.push(Severity::Warning, missing(sec, count_key)),
        Some((n, line)) if n as usize != out.len() => f.push(
            Severity::Warning,
            ParseError::at(
                line,
                ParseErrorKind::Count {
                    stated: n,
                    listed: out.len(),
                },
            )
            .in_section(&sec.name)
            .with_key(count_key),
        ),
        Some(_) => {}
    }
    out
}

/// The object indices of an object list or `ObjectLinks` section, in listed order; an entry
/// that is not an index is an error and skipped.
fn index_list(f: &mut Found, sec: &RawSection, count_key: &str) -> Vec<u16> {
    let entries = numbered(f, sec, count_key, "");
    entries
        .into_values()
        .filter_map(|e| {
            let v = int_of::<u16>(e);
            if v.is_none() {
                f.push(
                    Severity::Error,
                    ParseError::invalid(
                        e.line,
                        &sec.name,
                        &e.key,
                        &e.value,
                        "an object index 0x0000..=0xFFFF; skipped",
                    ),
                );
            }
            v
        })
        .collect()
}

fn parse_entry(f: &mut Found, sec: &RawSection) -> (Entry, Option<u8>, Option<u8>) {
    let mut entry = Entry::default();
    let mut extra = Vec::new();
    let data_type: Option<u16> = sec
        .get("DataType")
        .and_then(|e| int_key(f, sec, e, "a data type index", &mut extra));
    let mut name = None;
    let (mut sub_number, mut compact) = (None, None);
    let value = |f: &mut Found, e: &RawEntry| {
        let (v, note) = EdsValue::read(data_type, &e.value);
        if let Some(note) = note {
            f.push(
                Severity::Note,
                ParseError::at(e.line, ParseErrorKind::Interpreted(note.to_owned()))
                    .in_section(&sec.name)
                    .with_key(&e.key),
            );
        }
        Some(v)
    };
    for e in &sec.entries {
        let k = e.key.as_str();
        let is = |n: &str| k.eq_ignore_ascii_case(n);
        if is("ParameterName") {
            name = Some(e.value.clone());
        } else if is("ObjectType") {
            entry.object_type = int_key(f, sec, e, "an object code", &mut extra);
        } else if is("DataType") {
            entry.data_type = data_type;
        } else if is("AccessType") {
            entry.access_type = Access::from_eds_name(&e.value);
            if entry.access_type.is_none() {
                f.push(
                    Severity::Error,
                    ParseError::invalid(
                        e.line,
                        &sec.name,
                        k,
                        &e.value,
                        "ro, wo, rw, rwr, rww or const; held as ro",
                    ),
                );
                extra.push((e.key.clone(), e.value.clone()));
            }
        } else if is("DefaultValue") {
            entry.default_value = value(f, e);
        } else if is("LowLimit") {
            entry.low_limit = value(f, e);
        } else if is("HighLimit") {
            entry.high_limit = value(f, e);
        } else if is("ParameterValue") {
            entry.parameter_value = value(f, e);
        } else if is("PDOMapping") {
            entry.pdo_mapping = match int_of::<u8>(e) {
                Some(0) => Some(false),
                Some(1) => Some(true),
                _ => {
                    f.push(
                        Severity::Error,
                        ParseError::invalid(e.line, &sec.name, k, &e.value, "0 or 1; taken as 0"),
                    );
                    extra.push((e.key.clone(), e.value.clone()));
                    None
                }
            };
        } else if is("ObjFlags") {
            entry.obj_flags = int_key(f, sec, e, "an UNSIGNED32", &mut extra);
        } else if is("Denotation") {
            entry.denotation = Some(e.value.clone());
        } else if is("UploadFile") {
            entry.upload_file = Some(e.value.clone());
        } else if is("DownloadFile") {
            entry.download_file = Some(e.value.clone());
        } else if is("SubNumber") {
            sub_number = int_key(f, sec, e, "a number of sub-objects 0..=255", &mut extra);
        } else if is("CompactSubObj") {
            compact = int_key(f, sec, e, "a number of sub-objects 0..=255", &mut extra);
        } else {
            extra.push((e.key.clone(), e.value.clone()));
        }
    }
    entry.extra = extra;
    entry.parameter_name = name.unwrap_or_else(|| {
        f.push(Severity::Warning, missing(sec, "ParameterName"));
        String::new()
    });
    (entry, sub_number, compact)
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
fn by_sub<'a>(f: &mut Found, sec: &'a RawSection) -> BTreeMap<u8, &'a RawEntry> {
    let m = numbered(f, sec, "NrOfEntries", "");
    let mut out = BTreeMap::new();
    for (k, e) in m {
        match u8::try_from(k) {
            Ok(s) => {
                out.insert(s, e);
            }
            Err(_) => f.push(
                Severity::Warning,
                ParseError::invalid(
                    e.line,
                    &sec.name,
                    &e.key,
                    &e.key,
                    "a sub-index 0..=255; skipped",
                ),
            ),
        }
    }
    out
}

/// The characters Windows-1252 puts at 0x80..=0x9F (the code page's published table); the
/// five bytes it leaves undefined (0x81, 0x8D, 0x8F, 0x90, 0x9D) stand for the control
/// characters of the same number, as ISO 8859-1 has them.
const CP1252_80_9F: [char; 32] = [
    '\u{20AC}', '\u{0081}', '\u{201A}', '\u{0192}', '\u{201E}', '\u{2026}', '\u{2020}', '\u{2021}',
    '\u{02C6}', '\u{2030}', '\u{0160}', '\u{2039}', '\u{0152}', '\u{008D}', '\u{017D}', '\u{008F}',
    '\u{0090}', '\u{2018}', '\u{2019}', '\u{201C}', '\u{201D}', '\u{2022}', '\u{2013}', '\u{2014}',
    '\u{02DC}', '\u{2122}', '\u{0161}', '\u{203A}', '\u{0153}', '\u{009D}', '\u{017E}', '\u{0178}',
];

/// One Windows-1252 byte as its character: ISO 8859-1 apart from 0x80..=0x9F.
fn cp1252(b: u8) -> char {
    match b {
        0x80..=0x9F => CP1252_80_9F[usize::from(b - 0x80)],
        _ => char::from(b),
    }
}

/// Decodes bytes: UTF-8 if valid, else Windows-1252 (each byte one character), the encoding
/// most EDS files in the field are written in by Windows tools; its printable characters
/// are a superset of ISO 8859-1's (`€` and `‰` among the additions).
pub fn decode(bytes: &[u8]) -> String {
    decode_with_line(bytes).0
}

/// [`decode`], with the line of the first byte that is not UTF-8 when the file is read as
/// Windows-1252.
fn decode_with_line(bytes: &[u8]) -> (String, Option<usize>) {
    match core::str::from_utf8(bytes) {
        Ok(s) => (s.to_owned(), None),
        Err(e) => {
            let line = 1 + bytes[..e.valid_up_to()]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
            (bytes.iter().map(|&b| cp1252(b)).collect(), Some(line))
        }
    }
}

/// An EDS or DCF file read as far as it can be, with what was found on the way.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The file's content.
    pub eds: Eds,
    /// Every diagnostic: what the parser read past or guessed, then [`Eds::check`]'s
    /// findings, each with its line where the file has one.
    pub report: Report,
}

/// Reads an EDS or DCF file the way the files in the field are written: nothing is refused.
/// What CiA 306 does not allow, or what had to be guessed, is a diagnostic in
/// [`Loaded::report`] naming line, section and key; [`crate::to_od`] then builds the
/// dictionary from what the file evidently means. The same report is what
/// `cantwin eds check` prints.
pub fn load(text: &str) -> Loaded {
    let (eds, found, sections) = read(text);
    let mut report = Report::default();
    for (severity, e) in found {
        report.push_parse(severity, &e);
    }
    let lines = SourceLines::new(&sections);
    for mut issue in eds.check().issues {
        issue.line = lines.find(&issue.section, issue.key.as_deref());
        report.issues.push(issue);
    }
    report.sort_by_line();
    Loaded { eds, report }
}

/// [`load`] of bytes: UTF-8 when valid, Windows-1252 otherwise (see [`decode`]), with a
/// note at the line of the first byte that is not UTF-8.
pub fn load_bytes(bytes: &[u8]) -> Loaded {
    let (text, line) = decode_with_line(bytes);
    let mut loaded = load(&text);
    if let Some(line) = line {
        let e = ParseError::at(line, ParseErrorKind::Windows1252);
        loaded.report.push_parse(Severity::Note, &e);
        loaded.report.sort_by_line();
    }
    loaded
}

/// Parses an EDS or DCF file, refusing it at the first error the parser reads past (a
/// malformed line, a duplicate, a key whose value cannot be read); warnings and notes do not
/// refuse it. [`load`] reads every file and reports instead.
pub fn parse(text: &str) -> Result<Eds, ParseError> {
    let (eds, found, _) = read(text);
    match found.into_iter().find(|(s, _)| *s == Severity::Error) {
        Some((_, e)) => Err(e),
        None => Ok(eds),
    }
}

/// Where each section and key is in the file, by the names [`Eds::check`] gives them
/// (`1018sub1` for `[1018SUB01]`).
struct SourceLines(HashMap<String, (usize, Vec<(String, usize)>)>);

impl SourceLines {
    fn canonical(name: &str) -> String {
        match classify(name) {
            Kind::Object(i) => format!("{i:04X}"),
            Kind::Sub(i, s) => format!("{i:04X}sub{s:X}"),
            _ => name.to_ascii_lowercase(),
        }
    }

    fn new(sections: &[RawSection]) -> Self {
        SourceLines(
            sections
                .iter()
                .map(|s| {
                    let keys = s.entries.iter().map(|e| (e.key.clone(), e.line)).collect();
                    (Self::canonical(&s.name), (s.line, keys))
                })
                .collect(),
        )
    }

    fn find(&self, section: &str, key: Option<&str>) -> Option<usize> {
        let (line, keys) = self.0.get(&Self::canonical(section))?;
        let at_key = key.and_then(|k| {
            keys.iter()
                .find(|(n, _)| n.eq_ignore_ascii_case(k))
                .map(|(_, l)| *l)
        });
        Some(at_key.unwrap_or(*line))
    }
}

fn read(text: &str) -> (Eds, crate::ini::Found, Vec<RawSection>) {
    let (sections, found) = tokenize(text);
    let mut f = Found(found);
    let eds = build(&mut f, &sections);
    (eds, f.0, sections)
}

/// A typed `[FileInfo]`/`[DeviceInfo]`/`[DeviceComissioning]` section: a key whose value
/// cannot be read is a warning and kept as an extra key.
fn keyed<T>(
    f: &mut Found,
    sec: &RawSection,
    from_raw: impl Fn(&RawSection) -> (T, Vec<ParseError>),
) -> T {
    let (v, bad) = from_raw(sec);
    for e in bad {
        f.push(Severity::Warning, e);
    }
    v
}

fn build(f: &mut Found, sections: &[RawSection]) -> Eds {
    let mut eds = Eds::default();
    let mut subs: Vec<(u16, u8, &RawSection)> = Vec::new();
    let mut helpers: Vec<(u8, u16, &RawSection)> = Vec::new();
    let mut commissioning_line = None;
    for sec in sections {
        match classify(&sec.name) {
            Kind::FileInfo => eds.file_info = keyed(f, sec, FileInfo::from_raw),
            Kind::DeviceInfo => eds.device_info = keyed(f, sec, DeviceInfo::from_raw),
            Kind::Commissioning => {
                // Both spellings in one file would be two commissioning sections.
                if let Some(first) = commissioning_line {
                    f.push(
                        Severity::Error,
                        ParseError::at(sec.line, ParseErrorKind::DuplicateSection(first))
                            .in_section(&sec.name),
                    );
                    continue;
                }
                commissioning_line = Some(sec.line);
                eds.commissioning = Some(keyed(f, sec, DeviceCommissioning::from_raw));
            }
            Kind::DummyUsage => {
                let mut map = BTreeMap::new();
                for e in &sec.entries {
                    let ty = e
                        .key
                        .get(..5)
                        .filter(|p| p.eq_ignore_ascii_case("Dummy"))
                        .and_then(|_| e.key.get(5..))
                        .and_then(hex4);
                    let Some(ty) = ty else {
                        f.push(
                            Severity::Warning,
                            ParseError::invalid(
                                e.line,
                                &sec.name,
                                &e.key,
                                &e.key,
                                "a key `Dummyxxxx`; skipped",
                            ),
                        );
                        continue;
                    };
                    match int_of::<u8>(e) {
                        Some(0) => {
                            map.insert(ty, false);
                        }
                        Some(1) => {
                            map.insert(ty, true);
                        }
                        _ => f.push(
                            Severity::Error,
                            ParseError::invalid(
                                e.line,
                                &sec.name,
                                &e.key,
                                &e.value,
                                "0 or 1; skipped",
                            ),
                        ),
                    }
                }
                eds.dummy_usage = Some(map);
            }
            Kind::Comments => {
                let lines = numbered(f, sec, "Lines", "Line");
                eds.comments = Some(lines.into_values().map(|e| e.value.clone()).collect());
            }
            Kind::List(which) => {
                let list = index_list(f, sec, "SupportedObjects");
                match which {
                    0 => eds.mandatory_objects = list,
                    1 => eds.optional_objects = list,
                    _ => eds.manufacturer_objects = list,
                }
            }
            Kind::Object(index) => {
                let (entry, sub_number, compact_sub_obj) = parse_entry(f, sec);
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
                let list = index_list(f, sec, "ObjectLinks");
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
            f.push(
                Severity::Error,
                ParseError::at(sec.line, ParseErrorKind::DuplicateSection(first))
                    .in_section(&sec.name),
            );
            continue;
        }
        let obj = eds.objects.entry(index).or_insert_with(|| {
            // The sub-objects say the object is there: a RECORD, the object code that
            // allows sub-objects of any type.
            f.push(
                Severity::Warning,
                ParseError::at(sec.line, ParseErrorKind::NoObject(index)).in_section(&sec.name),
            );
            Object {
                entry: Entry {
                    object_type: Some(crate::RECORD),
                    ..Entry::default()
                },
                ..Object::default()
            }
        });
        // CiA 306 describes the sub-objects one way or the other; both at once is an error
        // (and `parse` refuses it), read with the sections winning.
        if obj.compact_sub_obj.is_some() {
            f.push(
                Severity::Error,
                ParseError::at(sec.line, ParseErrorKind::CompactWithSubs(index))
                    .in_section(&sec.name),
            );
        }
        let (entry, sub_number, compact) = parse_entry(f, sec);
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
    expand_all(f, &mut eds, &helpers);
    eds
}

fn expand_all(f: &mut Found, eds: &mut Eds, helpers: &[(u8, u16, &RawSection)]) {
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
        let dt = obj.entry.data_type;
        let entries = by_sub(f, sec);
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
                let m = entries
                    .into_iter()
                    .map(|(s, e)| (s, EdsValue::read(dt, &e.value).0))
                    .collect();
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
            let mut subs = expand_compact(
                &obj.entry,
                n,
                names.get(index).unwrap_or(&empty_s),
                values.get(index).unwrap_or(&empty_v),
                denots.get(index).unwrap_or(&empty_s),
            );
            // Sub-object sections beside `CompactSubObj` say more about those sub-objects
            // than the compact description: they are taken as written.
            subs.extend(std::mem::take(&mut obj.subs));
            obj.subs = subs;
        }
    }
}
