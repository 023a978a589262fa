//! Consistency checks of a parsed file (CiA 306 object lists and object descriptions):
//! what CiA 306 does not allow and how a dictionary is built instead (errors), what it asks
//! for that the file leaves out harmlessly (warnings), and what was read with a guess
//! (notes). The values are judged by the same function [`crate::to_od`] builds from.

pub use crate::error::{Issue, Severity};
use crate::judge::judge;
use crate::model::{Eds, Entry, ObjectList};
use crate::value::EdsValue;
use cantwin_canopen::od::DataType;
use core::fmt;

/// The findings of [`Eds::check`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Report {
    /// Every finding: in the order of the file's canonical layout from [`Eds::check`], in
    /// line order from [`crate::load`].
    pub issues: Vec<Issue>,
}

impl Report {
    /// The errors.
    pub fn errors(&self) -> impl Iterator<Item = &Issue> {
        self.issues.iter().filter(|i| i.severity == Severity::Error)
    }

    /// The warnings.
    pub fn warnings(&self) -> impl Iterator<Item = &Issue> {
        self.issues
            .iter()
            .filter(|i| i.severity == Severity::Warning)
    }

    /// The notes.
    pub fn notes(&self) -> impl Iterator<Item = &Issue> {
        self.issues.iter().filter(|i| i.severity == Severity::Note)
    }

    /// Whether there is no error.
    pub fn is_ok(&self) -> bool {
        self.errors().next().is_none()
    }

    /// Orders the findings by line, those without a line last (a stable sort: findings on
    /// one line keep their order).
    pub(crate) fn sort_by_line(&mut self) {
        self.issues.sort_by_key(|i| (i.line.is_none(), i.line));
    }

    pub(crate) fn push_parse(&mut self, severity: Severity, e: &crate::ParseError) {
        self.issues.push(Issue {
            severity,
            line: Some(e.line),
            section: e.section.clone().unwrap_or_default(),
            key: e.key.clone(),
            message: e.kind.to_string(),
        });
    }

    fn push(&mut self, severity: Severity, section: &str, key: Option<&str>, message: String) {
        self.issues.push(Issue {
            severity,
            line: None,
            section: section.to_owned(),
            key: key.map(str::to_owned),
            message,
        });
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for i in &self.issues {
            writeln!(f, "{i}")?;
        }
        Ok(())
    }
}

/// Object codes CiA 301 table 42 defines.
const OBJECT_CODES: [u8; 7] = [0x0, 0x2, 0x5, 0x6, 0x7, 0x8, 0x9];

impl Eds {
    /// Checks the file: `EDSVersion`, mandatory objects present, object lists agree with the
    /// objects, `SubNumber` agrees with the sub-objects, sub-index 0 of ARRAY and RECORD,
    /// object codes, data types and access types valid, values within their type's range and
    /// within the limits, limits in order, and the PDO mappings the device would run
    /// ([`crate::pdo_issues`]: a DCF's with its `ParameterValue`s). The findings carry no
    /// lines; [`crate::load`] adds them.
    pub fn check(&self) -> Report {
        let mut r = Report::default();
        match self.file_info.eds_version.as_deref() {
            Some("4.0") => {}
            Some(v) => r.push(
                Severity::Note,
                "FileInfo",
                Some("EDSVersion"),
                format!("{v:?} is not a CiA 306 version (4.0); read as 4.0"),
            ),
            None => r.push(
                Severity::Note,
                "FileInfo",
                Some("EDSVersion"),
                "missing; read as 4.0".to_owned(),
            ),
        }
        for m in [0x1000u16, 0x1001, 0x1018] {
            if !self.objects.contains_key(&m) {
                r.push(
                    Severity::Warning,
                    &format!("{m:04X}"),
                    None,
                    format!(
                        "mandatory object {m:#06X} is missing (CiA 301 object dictionary); \
                         the device answers it with 0x06020000"
                    ),
                );
            }
        }
        let lists = [
            (
                "MandatoryObjects",
                &self.mandatory_objects,
                ObjectList::Mandatory,
            ),
            (
                "OptionalObjects",
                &self.optional_objects,
                ObjectList::Optional,
            ),
            (
                "ManufacturerObjects",
                &self.manufacturer_objects,
                ObjectList::Manufacturer,
            ),
        ];
        for (name, list, kind) in lists {
            for (i, index) in list.iter().enumerate() {
                let key = (i + 1).to_string();
                if !self.objects.contains_key(index) {
                    r.push(
                        Severity::Warning,
                        name,
                        Some(&key),
                        format!("lists {index:#06X}, which has no section"),
                    );
                }
                if Eds::list_for(*index) != kind {
                    r.push(
                        Severity::Warning,
                        name,
                        Some(&key),
                        format!("{index:#06X} belongs in another list (CiA 306 object lists)"),
                    );
                }
                if list[..i].contains(index) {
                    r.push(
                        Severity::Warning,
                        name,
                        Some(&key),
                        format!("lists {index:#06X} twice"),
                    );
                }
            }
        }
        for (&index, o) in &self.objects {
            let sec = format!("{index:04X}");
            let listed = lists.iter().any(|(_, l, _)| l.contains(&index));
            if !listed && index >= 0x1000 {
                r.push(
                    Severity::Note,
                    &sec,
                    None,
                    "not named in any object list".to_owned(),
                );
            }
            let code = o.object_code();
            if !OBJECT_CODES.contains(&code) {
                r.push(
                    Severity::Error,
                    &sec,
                    Some("ObjectType"),
                    format!("{code:#04X} is not an object code; the object is left out"),
                );
            }
            let composite = code == crate::ARRAY || code == crate::RECORD;
            if o.compact_sub_obj.is_some() && code != crate::ARRAY {
                r.push(
                    Severity::Warning,
                    &sec,
                    Some("CompactSubObj"),
                    "only an ARRAY can be described compactly".to_owned(),
                );
            }
            if composite && o.subs.is_empty() {
                r.push(
                    Severity::Warning,
                    &sec,
                    None,
                    "an ARRAY or RECORD without sub-objects; held with sub-index 0 = 0 only"
                        .to_owned(),
                );
            }
            if composite && !o.subs.is_empty() && !o.subs.contains_key(&0) {
                r.push(
                    Severity::Warning,
                    &sec,
                    None,
                    "no sub-index 0; held with one (UNSIGNED8 ro, the highest sub-index)"
                        .to_owned(),
                );
            }
            if !composite && !o.subs.is_empty() && OBJECT_CODES.contains(&code) {
                r.push(
                    Severity::Warning,
                    &sec,
                    Some("ObjectType"),
                    "sub-objects on an object that is not ARRAY or RECORD; held as a RECORD"
                        .to_owned(),
                );
            }
            // CiA 306: SubNumber counts the sub-objects there are (sparse sub-indices are
            // allowed); a count that disagrees is taken to mean the sub-objects listed.
            if let Some(n) = o.sub_number
                && usize::from(n) != o.subs.len()
            {
                r.push(
                    Severity::Warning,
                    &sec,
                    Some("SubNumber"),
                    format!(
                        "says {n}, the object has {} sub-objects; the ones there are taken",
                        o.subs.len()
                    ),
                );
            }
            if o.subs.is_empty() {
                check_entry(
                    &mut r,
                    &sec,
                    &o.entry,
                    code == crate::VAR || code == crate::DOMAIN,
                );
            }
            for (sub, e) in &o.subs {
                check_entry(&mut r, &format!("{index:04X}sub{sub:X}"), e, true);
            }
            if composite
                && let Some(s0) = o.subs.get(&0)
                && s0.data_type != Some(0x0005)
            {
                r.push(
                    Severity::Warning,
                    &format!("{index:04X}sub0"),
                    Some("DataType"),
                    "sub-index 0 of an ARRAY or RECORD is UNSIGNED8 (CiA 301)".to_owned(),
                );
            }
        }
        for (index, links) in &self.object_links {
            let sec = format!("{index:04X}ObjectLinks");
            if !self.objects.contains_key(index) {
                r.push(
                    Severity::Warning,
                    &sec,
                    None,
                    format!("links from {index:#06X}, which has no section"),
                );
            }
            for (i, l) in links.iter().enumerate() {
                if !self.objects.contains_key(l) {
                    let key = (i + 1).to_string();
                    r.push(
                        Severity::Warning,
                        &sec,
                        Some(&key),
                        format!("links to {l:#06X}, which has no section"),
                    );
                }
            }
        }
        if let Some(d) = &self.dummy_usage {
            // CiA 306 dummy usage lists Dummy0001..Dummy0007; python-canopen reads all seven keys
            // whenever the section exists and fails on a missing one.
            for t in 1u16..=7 {
                if !d.contains_key(&t) {
                    r.push(
                        Severity::Warning,
                        "DummyUsage",
                        Some(&format!("Dummy{t:04X}")),
                        "missing; some readers require all of Dummy0001..Dummy0007".to_owned(),
                    );
                }
            }
            for t in d.keys() {
                if DataType::from_index(*t).is_none() {
                    r.push(
                        Severity::Warning,
                        "DummyUsage",
                        Some(&format!("Dummy{t:04X}")),
                        "not a basic data type".to_owned(),
                    );
                }
            }
        }
        // The PDOs the device built from the file runs, with a DCF's values as it is
        // configured with them.
        let configured;
        let source = if self.is_dcf() {
            configured = crate::configured(self);
            &configured
        } else {
            self
        };
        r.issues.extend(crate::pdo::pdo_issues(source));
        r
    }
}

fn check_entry(r: &mut Report, sec: &str, e: &Entry, needs_type: bool) {
    for (severity, key, message) in judge(e, needs_type).findings {
        r.push(severity, sec, Some(key), message);
    }
    // A `;` after white space starts an inline comment for python-canopen's reader (and for
    // `crate::load`): what follows it would be lost on reading the file back.
    let cut = |t: &str| crate::ini::inline_comment(t).is_some();
    if cut(&e.parameter_name) {
        r.push(
            Severity::Warning,
            sec,
            Some("ParameterName"),
            "contains ` ;`, which INI readers take for the start of an inline comment".to_owned(),
        );
    }
    for (key, v) in [
        ("DefaultValue", &e.default_value),
        ("ParameterValue", &e.parameter_value),
    ] {
        if let Some(EdsValue::Text(s)) = v
            && cut(s)
        {
            r.push(
                Severity::Warning,
                sec,
                Some(key),
                "contains ` ;`, which INI readers take for the start of an inline comment"
                    .to_owned(),
            );
        }
    }
}
