//! Errors that point at the file, line and key a user has to fix.

use std::fmt;
use std::path::PathBuf;

/// A position in a scenario file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Located {
    /// The file (as given by the user).
    pub file: PathBuf,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// The dotted key path, e.g. `device[2].bus`, when known.
    pub key: Option<String>,
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some(key) = &self.key {
            write!(f, ": key `{key}`")?;
        }
        Ok(())
    }
}

/// Why a scenario could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not have the scenario's shape.
    #[error("{at}: {message}")]
    Syntax {
        /// Where.
        at: Located,
        /// What.
        message: String,
    },
    /// The content is well-formed but wrong (unknown bus, duplicate name, bad setting …).
    #[error("{at}: {message}")]
    Invalid {
        /// Where.
        at: Located,
        /// What.
        message: String,
    },
}

impl ScenarioError {
    /// Where the error is, when it is in the file.
    pub fn location(&self) -> Option<&Located> {
        match self {
            ScenarioError::Io { .. } => None,
            ScenarioError::Syntax { at, .. } | ScenarioError::Invalid { at, .. } => Some(at),
        }
    }
}

/// 1-based line of a byte offset in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|b| **b == b'\n')
        .count()
        + 1
}
