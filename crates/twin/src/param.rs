//! Parameters of a device's own model (a drive's keypad parameters), by number or name.

use core::fmt;

/// A parameter, as the device's manual names it: a number (ADV200 `PAR 4006`) or a name
/// with its class (OpenDrive `"P61"`, `"C48"`).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ParameterKey {
    /// A number.
    Number(u16),
    /// A name.
    Name(String),
}

impl fmt::Display for ParameterKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParameterKey::Number(n) => write!(f, "{n}"),
            ParameterKey::Name(s) => f.write_str(s),
        }
    }
}

/// Why a parameter could not be read or written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParameterError {
    /// The device has no parameters of its own.
    #[error("no parameters")]
    None,
    /// The key does not name a parameter of the device; the message says how they are named.
    #[error("{0}")]
    BadKey(String),
    /// The device refused the read or write, saying why.
    #[error("{0}")]
    Refused(String),
}
