//! Consistency checks of a parsed file (CiA 306 object lists and object descriptions): what a tool should refuse
//! (errors) and what it should point out (warnings).

use crate::model::{Eds, Entry, ObjectList};
use crate::value::{EdsValue, integer_range};
use cantwin_canopen::od::DataType;
use core::fmt;

/// How serious an [`Issue`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Worth fixing; readers will cope.
    Warning,
    /// The file does not describe a valid device.
    Error,
}

/// One finding of [`Eds::check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Issue {
    /// How serious it is.
    pub severity: Severity,
    /// The section it concerns (e.g. `1018sub1`, `MandatoryObjects`).
    pub section: String,
    /// The key it concerns, if one.
    pub key: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sev = match self.severity {
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        write!(f, "{sev}: [{}]", self.section)?;
        if let Some(k) = &self.key {
            write!(f, " {k}")?;
        }
        write!(f, ": {}", self.message)
    }
}

/// The findings of [`Eds::check`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Report {
    /// Every finding, in the order of the file's canonical layout.
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

    /// Whether there is no error.
    pub fn is_ok(&self) -> bool {
        self.errors().next().is_none()
    }

    fn push(&mut self, severity: Severity, section: &str, key: Option<&str>, message: String) {
        self.issues.push(Issue {
            severity,
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
    /// Checks the file: mandatory objects present, object lists agree with the objects,
    /// `SubNumber` agrees with the sub-objects, object codes, data types and access types
    /// valid, values within their type's range and within the limits.
    pub fn check(&self) -> Report {
        let mut r = Report::default();
        for m in [0x1000u16, 0x1001, 0x1018] {
            if !self.objects.contains_key(&m) {
                r.push(
                    Severity::Error,
                    &format!("{m:04X}"),
                    None,
                    format!("mandatory object {m:#06X} is missing (CiA 301 object dictionary)"),
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
                        Severity::Error,
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
                        Severity::Error,
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
                    Severity::Warning,
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
                    format!("{code:#04X} is not an object code"),
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
                    Severity::Error,
                    &sec,
                    None,
                    "an ARRAY or RECORD without sub-objects".to_owned(),
                );
            }
            if !composite && !o.subs.is_empty() {
                r.push(
                    Severity::Warning,
                    &sec,
                    None,
                    "sub-objects on an object that is not ARRAY or RECORD".to_owned(),
                );
            }
            if let Some(n) = o.sub_number
                && usize::from(n) != o.subs.len()
            {
                r.push(
                    Severity::Error,
                    &sec,
                    Some("SubNumber"),
                    format!("says {n}, the object has {} sub-objects", o.subs.len()),
                );
            }
            if o.subs.is_empty() || o.compact_sub_obj.is_some() {
                check_entry(
                    &mut r,
                    &sec,
                    &o.entry,
                    code == crate::VAR || code == crate::DOMAIN || o.compact_sub_obj.is_some(),
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
        r
    }
}

fn check_entry(r: &mut Report, sec: &str, e: &Entry, needs_type: bool) {
    let ty = match e.data_type {
        None if needs_type => {
            r.push(Severity::Error, sec, Some("DataType"), "missing".to_owned());
            None
        }
        None => None,
        Some(t) => match DataType::from_index(t) {
            Some(ty) => Some(ty),
            None if t <= 0x25F => {
                r.push(
                    Severity::Warning,
                    sec,
                    Some("DataType"),
                    format!("{t:#06X} is not a basic data type"),
                );
                None
            }
            None => {
                r.push(
                    Severity::Error,
                    sec,
                    Some("DataType"),
                    format!("{t:#06X} is not a data type index"),
                );
                None
            }
        },
    };
    if e.parameter_name.contains(';') {
        r.push(
            Severity::Warning,
            sec,
            Some("ParameterName"),
            "contains `;`, which some INI readers take for an inline comment".to_owned(),
        );
    }
    if needs_type && e.access_type.is_none() {
        r.push(
            Severity::Error,
            sec,
            Some("AccessType"),
            "missing".to_owned(),
        );
    }
    let mut range_check = |key: &str, v: &Option<EdsValue>| {
        let Some(v) = v else { return };
        if let (Some(ty), EdsValue::Integer(x)) = (ty, v)
            && let Some((lo, hi)) = integer_range(ty)
            && (*x < lo || *x > hi)
        {
            r.push(
                Severity::Error,
                sec,
                Some(key),
                format!("{x} is outside the range of {ty}"),
            );
        }
        if let (Some(ty), EdsValue::NodeId(off)) = (ty, v) {
            match integer_range(ty) {
                None => r.push(
                    Severity::Error,
                    sec,
                    Some(key),
                    format!("$NODEID on a value of type {ty}"),
                ),
                // CiA 301: node-IDs are 1..=127; the value must fit for each of them.
                Some((lo, hi)) if off.saturating_add(1) < lo || off.saturating_add(127) > hi => r
                    .push(
                        Severity::Error,
                        sec,
                        Some(key),
                        format!("$NODEID+{off} leaves the range of {ty} for some node-ID 1..=127"),
                    ),
                Some(_) => {}
            }
        }
        if let EdsValue::Raw(s) = v
            && s.is_empty()
            && ty.is_some()
        {
            r.push(Severity::Warning, sec, Some(key), "empty".to_owned());
        }
        if let EdsValue::Text(s) = v
            && s.contains(';')
        {
            r.push(
                Severity::Warning,
                sec,
                Some(key),
                "contains `;`, which some INI readers take for an inline comment".to_owned(),
            );
        }
    };
    range_check("DefaultValue", &e.default_value);
    range_check("LowLimit", &e.low_limit);
    range_check("HighLimit", &e.high_limit);
    range_check("ParameterValue", &e.parameter_value);
    let num = |v: &Option<EdsValue>| -> Option<f64> {
        match v.as_ref()? {
            EdsValue::Integer(x) => Some(*x as f64),
            EdsValue::Real32(x) => Some(f64::from(*x)),
            EdsValue::Real64(x) => Some(*x),
            _ => None,
        }
    };
    let (lo, hi) = (num(&e.low_limit), num(&e.high_limit));
    if let (Some(l), Some(h)) = (lo, hi)
        && l > h
    {
        r.push(
            Severity::Error,
            sec,
            Some("LowLimit"),
            "above HighLimit".to_owned(),
        );
    }
    for (key, v) in [
        ("DefaultValue", &e.default_value),
        ("ParameterValue", &e.parameter_value),
    ] {
        let Some(x) = num(v) else { continue };
        if lo.is_some_and(|l| x < l) {
            r.push(Severity::Error, sec, Some(key), "below LowLimit".to_owned());
        }
        if hi.is_some_and(|h| x > h) {
            r.push(
                Severity::Error,
                sec,
                Some(key),
                "above HighLimit".to_owned(),
            );
        }
    }
}
