//! Parse errors: every one names the line, and the section and key when there is one.

use core::fmt;

/// What is wrong (see [`ParseError`] for where).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseErrorKind {
    /// A `key=value` line before the first section header.
    #[error("a line outside any section")]
    OutsideSection,
    /// A `[` line without its `]`, or an empty name.
    #[error("malformed section header")]
    BadHeader,
    /// A line in a section that is neither a comment nor `key=value`.
    #[error("expected `key=value`")]
    NotKeyValue,
    /// `=value` without a key.
    #[error("empty key")]
    EmptyKey,
    /// The section already appeared (section names are case-insensitive).
    #[error("duplicate section, first defined at line {0}")]
    DuplicateSection(usize),
    /// The key already appeared in this section (key names are case-insensitive).
    #[error("duplicate key, first defined at line {0}")]
    DuplicateKey(usize),
    /// A key CiA 306 requires is absent (or a count key of a list).
    #[error("missing required key")]
    MissingKey,
    /// The value does not have the form the key needs.
    #[error("invalid value {value:?}: expected {expected}")]
    InvalidValue {
        /// The text found.
        value: String,
        /// What was expected.
        expected: String,
    },
    /// A sub-object section for an index that has no object section.
    #[error("no object section [{0:04X}] for this section; the object is taken as a RECORD")]
    NoObject(u16),
    /// Sub-object sections next to `CompactSubObj`, which already defines the sub-objects.
    #[error(
        "object {0:04X} uses CompactSubObj and also has sub-object sections; the sections are taken as written"
    )]
    CompactWithSubs(u16),
    /// A count (`SupportedObjects`, `ObjectLinks`, `NrOfEntries`, `Lines`) that disagrees
    /// with the entries listed.
    #[error("says {stated}, {listed} entries are listed; the listed entries are taken")]
    Count {
        /// The count the file states.
        stated: u32,
        /// The entries it lists.
        listed: usize,
    },
    /// A line starting with `#` (CiA 306 comments start with `;`); read as a comment.
    #[error("a line starting with `#` (CiA 306 comments start with `;`); read as a comment")]
    HashComment,
    /// A `;` after white space in a value: read as the start of a comment.
    #[error(
        "`;` after white space read as the start of an inline comment (CiA 306 has comments only on lines of their own)"
    )]
    InlineComment,
    /// A file that is not UTF-8, read as Windows-1252.
    #[error("not UTF-8 from here: the file is read as Windows-1252")]
    Windows1252,
    /// A value read with a guess at what the file means.
    #[error("{0}")]
    Interpreted(String),
}

/// An error in an EDS or DCF file, at a line (1-based), in a section and key where known.
///
/// Displays as `line 12 [1018sub1] DataType: invalid value ...`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParseError {
    /// The line the error is on (1-based).
    pub line: usize,
    /// The section the line belongs to.
    pub section: Option<String>,
    /// The key concerned.
    pub key: Option<String>,
    /// What is wrong.
    pub kind: ParseErrorKind,
}

impl ParseError {
    pub(crate) fn at(line: usize, kind: ParseErrorKind) -> Self {
        ParseError {
            line,
            section: None,
            key: None,
            kind,
        }
    }

    pub(crate) fn in_section(mut self, section: &str) -> Self {
        self.section = Some(section.to_owned());
        self
    }

    pub(crate) fn with_key(mut self, key: &str) -> Self {
        self.key = Some(key.to_owned());
        self
    }

    pub(crate) fn invalid(
        line: usize,
        section: &str,
        key: &str,
        value: &str,
        expected: &str,
    ) -> Self {
        ParseError::at(
            line,
            ParseErrorKind::InvalidValue {
                value: value.to_owned(),
                expected: expected.to_owned(),
            },
        )
        .in_section(section)
        .with_key(key)
    }
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}", self.line)?;
        if let Some(s) = &self.section {
            write!(f, " [{s}]")?;
        }
        if let Some(k) = &self.key {
            write!(f, " {k}")?;
        }
        write!(f, ": {}", self.kind)
    }
}

impl std::error::Error for ParseError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_line_section_and_key() {
        let e = ParseError::invalid(12, "1018sub1", "DataType", "x", "a number");
        assert_eq!(
            e.to_string(),
            "line 12 [1018sub1] DataType: invalid value \"x\": expected a number"
        );
    }
}

/// How serious a finding ([`crate::Issue`]) is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Something read with a guess, or left as it is; worth knowing.
    Note,
    /// Not what CiA 306 asks for, but harmless: readers cope and the dictionary is the one
    /// the file evidently means.
    Warning,
    /// What CiA 306 does not allow, with a consequence: a value or key is ignored (the
    /// diagnostic says how the dictionary is built instead), or, for an entry without a
    /// data type, the file cannot become a dictionary at all.
    Error,
}

/// One finding of [`crate::Eds::check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Issue {
    /// How serious it is.
    pub severity: Severity,
    /// The line (1-based) of the key, or of the section, where the file has one (set by
    /// [`crate::load`]; [`crate::Eds::check`] of a model alone knows no lines).
    pub line: Option<usize>,
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
            Severity::Note => "note",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        write!(f, "{sev}:")?;
        if let Some(l) = self.line {
            write!(f, " line {l}")?;
        }
        // A line outside any section has no section to name.
        if !self.section.is_empty() {
            write!(f, " [{}]", self.section)?;
        }
        if let Some(k) = &self.key {
            write!(f, " {k}")?;
        }
        write!(f, ": {}", self.message)
    }
}
