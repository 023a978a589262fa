//! The INI layer of CiA 306 (basic structure): sections, `key=value` lines and comments, with the line
//! number of everything so that later errors can point at it.

use crate::error::{ParseError, ParseErrorKind, Severity};
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

/// What the INI layer found wrong, with how serious it is; the line is skipped.
pub(crate) type Found = Vec<(Severity, ParseError)>;

/// Splits a file into sections, reading past what is malformed.
///
/// * A line whose first non-blank character is `;` or `#` is a comment (CiA 306 basic
///   structure names `;`; `#` lines are common in the field and are read the same way, with
///   a note). A `;` preceded by white space later in a line starts an inline comment, as
///   python-canopen reads EDS files (`inline_comment_prefixes=(';',)`); CiA 306 has comments
///   only on lines of their own, so each is a note. A `;` right after other characters
///   (`a;b`) is part of the value.
/// * Leading and trailing white space (tabs too) of names, keys and values is not
///   significant; CR LF and LF line ends are both read.
/// * A line before the first section (warning), a line without `=` or with an empty key
///   (error) is skipped. A malformed section header is an error and the lines up to the next
///   header are skipped with it, since they belong to a section of unknown name.
/// * A duplicate section or a duplicate key in one section is an error naming the earlier
///   line; the first one is kept, as a file that says two things about one key has no single
///   meaning and the first is what a reader that stops at it (Python's `configparser` in
///   strict mode) would have seen.
pub(crate) fn tokenize(text: &str) -> (Vec<RawSection>, Found) {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut sections: Vec<RawSection> = Vec::new();
    let mut found: Found = Vec::new();
    let mut seen: HashMap<String, usize> = HashMap::new();
    // Whether lines go to the last section (false after a malformed or duplicate header).
    let mut open = false;
    let mut hash_comment = false;
    for (i, raw) in text.split('\n').enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with(';') {
            continue;
        }
        if l.starts_with('#') {
            // Reported once, at the first such line: a tool that writes them writes many.
            if !hash_comment {
                hash_comment = true;
                let mut e = ParseError::at(line, ParseErrorKind::HashComment);
                if let Some(s) = sections.last().filter(|_| open) {
                    e = e.in_section(&s.name);
                }
                found.push((Severity::Note, e));
            }
            continue;
        }
        if let Some(rest) = l.strip_prefix('[') {
            open = false;
            let name = rest.strip_suffix(']').map(str::trim);
            let Some(name) = name.filter(|n| !n.is_empty() && !n.contains(['[', ']'])) else {
                found.push((
                    Severity::Error,
                    ParseError::at(line, ParseErrorKind::BadHeader),
                ));
                continue;
            };
            // Keyed by the lower-case name: a large EDS has thousands of sections.
            if let Some(&first) = seen.get(&name.to_ascii_lowercase()) {
                found.push((
                    Severity::Error,
                    ParseError::at(line, ParseErrorKind::DuplicateSection(first)).in_section(name),
                ));
                continue;
            }
            seen.insert(name.to_ascii_lowercase(), line);
            sections.push(RawSection {
                name: name.to_owned(),
                line,
                entries: Vec::new(),
            });
            open = true;
            continue;
        }
        let section = match sections.last_mut() {
            Some(s) if open => s,
            Some(_) => continue,
            None => {
                found.push((
                    Severity::Warning,
                    ParseError::at(line, ParseErrorKind::OutsideSection),
                ));
                continue;
            }
        };
        let Some((key, value)) = l.split_once('=') else {
            found.push((
                Severity::Error,
                ParseError::at(line, ParseErrorKind::NotKeyValue).in_section(&section.name),
            ));
            continue;
        };
        let key = key.trim();
        if key.is_empty() {
            found.push((
                Severity::Error,
                ParseError::at(line, ParseErrorKind::EmptyKey).in_section(&section.name),
            ));
            continue;
        }
        if let Some(first) = section.get(key) {
            found.push((
                Severity::Error,
                ParseError::at(line, ParseErrorKind::DuplicateKey(first.line))
                    .in_section(&section.name)
                    .with_key(key),
            ));
            continue;
        }
        let value = match inline_comment(value) {
            Some(at) => {
                found.push((
                    Severity::Note,
                    ParseError::at(line, ParseErrorKind::InlineComment)
                        .in_section(&section.name)
                        .with_key(key),
                ));
                &value[..at]
            }
            None => value,
        };
        section.entries.push(RawEntry {
            key: key.to_owned(),
            value: value.trim().to_owned(),
            line,
        });
    }
    (sections, found)
}

/// Where an inline comment starts in a value: at the first `;` that follows white space.
pub(crate) fn inline_comment(value: &str) -> Option<usize> {
    let mut prev_blank = false;
    for (i, c) in value.char_indices() {
        if c == ';' && prev_blank {
            return Some(i);
        }
        prev_blank = c.is_whitespace();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_keys_comments_and_crlf() {
        let (s, found) = tokenize(
            "\u{feff}; header\r\n[FileInfo]\r\n FileName = a.eds \t\r\n;x=1\r\n\r\n[1000]\r\nDataType=0x0007\r\n",
        );
        assert!(found.is_empty());
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
        let (s, found) = tokenize("[A]\nK=a;b\n");
        assert_eq!(s[0].entries[0].value, "a;b");
        assert!(found.is_empty());
    }

    #[test]
    fn semicolon_after_white_space_starts_an_inline_comment() {
        let (s, found) = tokenize("[A]\nK=0 ; comment\nL=x\t;y\nM= ;all comment\n");
        let values: Vec<&str> = s[0].entries.iter().map(|e| e.value.as_str()).collect();
        assert_eq!(values, ["0", "x", ""]);
        assert_eq!(found.len(), 3);
        assert_eq!(found[0].0, Severity::Note);
        assert_eq!(
            (found[0].1.line, found[0].1.kind.clone()),
            (2, ParseErrorKind::InlineComment)
        );
    }

    fn first(text: &str) -> (Severity, ParseError) {
        tokenize(text).1.remove(0)
    }

    #[test]
    fn malformed_lines_are_skipped_and_named() {
        let (s, found) = tokenize("[A]\nK=1\nk=2\n");
        assert_eq!(s[0].entries.len(), 1);
        assert_eq!(s[0].entries[0].value, "1");
        assert_eq!(found[0].1.line, 3);
        assert_eq!(found[0].1.kind, ParseErrorKind::DuplicateKey(2));
        let (sev, e) = first("[A]\n[a]\n");
        assert_eq!(
            (sev, e.line, e.kind),
            (Severity::Error, 2, ParseErrorKind::DuplicateSection(1))
        );
        assert_eq!(first("K=1\n[A]\n").1.kind, ParseErrorKind::OutsideSection);
        let (s, found) = tokenize("[A\nK=1\n[B]\nL=2\n");
        assert_eq!(found[0].1.kind, ParseErrorKind::BadHeader);
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].entries[0].key, "L");
        assert_eq!(first("[A]\nnothing\n").1.kind, ParseErrorKind::NotKeyValue);
        assert_eq!(first("[A]\n=1\n").1.kind, ParseErrorKind::EmptyKey);
        let (s, found) = tokenize("# made by a tool\n[A]\n# note\nK=1\n");
        assert_eq!(s[0].entries.len(), 1);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].0, Severity::Note);
    }
}
