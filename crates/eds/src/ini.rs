//! The INI layer of CiA 306 (basic structure): sections, `key=value` lines and comments, with the line
//! number of everything so that later errors can point at it.

use crate::error::{ParseError, ParseErrorKind};
use std::collections::HashMap;

/// One `key=value` line.
#[derive(Debug, Clone)]
pub(crate) struct RawEntry {
    pub key: String,
    pub value: String,
    pub line: usize,
}

/// One `[name]` section with its entries in file order.
#[derive(Debug, Clone)]
pub(crate) struct RawSection {
    pub name: String,
    pub line: usize,
    pub entries: Vec<RawEntry>,
}

impl RawSection {
    /// The entry whose key matches `key` case-insensitively (CiA 306 basic structure: key names are not
    /// case-sensitive).
    pub fn get(&self, key: &str) -> Option<&RawEntry> {
        self.entries
            .iter()
            .find(|e| e.key.eq_ignore_ascii_case(key))
    }
}

/// Splits a file into sections.
///
/// * A line whose first non-blank character is `;` is a comment (CiA 306 basic structure); a `;` later
///   in a line is part of the value.
/// * Leading and trailing white space of names, keys and values is not significant.
/// * A line before the first section, a line without `=`, an empty key, a duplicate section or
///   a duplicate key in one section is an error naming the line (and the earlier line for
///   duplicates): a file that says two things about one key has no single meaning, and
///   common readers (Python's `configparser` in strict mode) reject it too.
pub(crate) fn tokenize(text: &str) -> Result<Vec<RawSection>, ParseError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut sections: Vec<RawSection> = Vec::new();
    let mut seen: HashMap<String, usize> = HashMap::new();
    for (i, raw) in text.split('\n').enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with(';') {
            continue;
        }
        if let Some(rest) = l.strip_prefix('[') {
            let Some(name) = rest.strip_suffix(']') else {
                return Err(ParseError::at(line, ParseErrorKind::BadHeader));
            };
            let name = name.trim();
            if name.is_empty() || name.contains(['[', ']']) {
                return Err(ParseError::at(line, ParseErrorKind::BadHeader));
            }
            // Keyed by the lower-case name: a large EDS has thousands of sections.
            if let Some(&first) = seen.get(&name.to_ascii_lowercase()) {
                return Err(
                    ParseError::at(line, ParseErrorKind::DuplicateSection(first)).in_section(name),
                );
            }
            seen.insert(name.to_ascii_lowercase(), line);
            sections.push(RawSection {
                name: name.to_owned(),
                line,
                entries: Vec::new(),
            });
            continue;
        }
        let Some(section) = sections.last_mut() else {
            return Err(ParseError::at(line, ParseErrorKind::OutsideSection));
        };
        let Some((key, value)) = l.split_once('=') else {
            return Err(ParseError::at(line, ParseErrorKind::NotKeyValue).in_section(&section.name));
        };
        let key = key.trim();
        if key.is_empty() {
            return Err(ParseError::at(line, ParseErrorKind::EmptyKey).in_section(&section.name));
        }
        if let Some(first) = section.get(key) {
            return Err(
                ParseError::at(line, ParseErrorKind::DuplicateKey(first.line))
                    .in_section(&section.name)
                    .with_key(key),
            );
        }
        section.entries.push(RawEntry {
            key: key.to_owned(),
            value: value.trim().to_owned(),
            line,
        });
    }
    Ok(sections)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_keys_comments_and_crlf() {
        let s = tokenize("\u{feff}; header\r\n[FileInfo]\r\n FileName = a.eds \r\n;x=1\r\n\r\n[1000]\r\nDataType=0x0007\r\n").unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].name, "FileInfo");
        assert_eq!(s[0].line, 2);
        assert_eq!(s[0].entries[0].key, "FileName");
        assert_eq!(s[0].entries[0].value, "a.eds");
        assert_eq!(s[0].entries[0].line, 3);
        assert_eq!(s[1].get("datatype").unwrap().value, "0x0007");
    }

    #[test]
    fn semicolon_inside_a_value_is_data() {
        let s = tokenize("[A]\nK=a;b\n").unwrap();
        assert_eq!(s[0].entries[0].value, "a;b");
    }

    #[test]
    fn errors_name_the_line() {
        let e = tokenize("[A]\nK=1\nk=2\n").unwrap_err();
        assert_eq!(e.line, 3);
        assert_eq!(e.kind, ParseErrorKind::DuplicateKey(2));
        let e = tokenize("[A]\n[a]\n").unwrap_err();
        assert_eq!((e.line, e.kind), (2, ParseErrorKind::DuplicateSection(1)));
        assert_eq!(
            tokenize("K=1\n").unwrap_err().kind,
            ParseErrorKind::OutsideSection
        );
        assert_eq!(
            tokenize("[A\n").unwrap_err().kind,
            ParseErrorKind::BadHeader
        );
        assert_eq!(
            tokenize("[A]\nnothing\n").unwrap_err().kind,
            ParseErrorKind::NotKeyValue
        );
        assert_eq!(
            tokenize("[A]\n=1\n").unwrap_err().kind,
            ParseErrorKind::EmptyKey
        );
    }
}
