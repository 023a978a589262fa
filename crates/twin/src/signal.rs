//! Signals: the physical quantities of a device a host sets (an input, a load, a module
//! pulled out) or reads (an output, an alarm), named by [`SignalId`], valued by
//! [`SignalValue`], described by [`SignalDescription`].

use core::fmt;

use crate::live::Role;

/// The name of a signal, as the device calls it: a word, or a word with numbers after dots
/// for a terminal (`"speed"`, `"digital_input.4"`, `"analog_input.3.0"`).
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SignalId(String);

impl SignalId {
    /// The signal named `name`.
    pub fn new(name: impl Into<String>) -> Self {
        SignalId(name.into())
    }

    /// The signal `prefix.N.M…` for a terminal numbered `numbers`.
    pub fn indexed(prefix: &str, numbers: &[u32]) -> Self {
        let mut name = prefix.to_string();
        for n in numbers {
            name.push('.');
            name.push_str(&n.to_string());
        }
        SignalId(name)
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The numbers after `prefix`: `"digital_output.2.0"` with prefix `"digital_output"` is
    /// `Some([2, 0])`; another prefix, or a part that is not a number, is `None`.
    pub fn indices(&self, prefix: &str) -> Option<Vec<u32>> {
        let rest = self.0.strip_prefix(prefix)?.strip_prefix('.')?;
        rest.split('.').map(|p| p.parse().ok()).collect()
    }
}

impl fmt::Display for SignalId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl From<&str> for SignalId {
    fn from(name: &str) -> Self {
        SignalId::new(name)
    }
}

/// The value of a signal.
#[derive(Debug, Clone, PartialEq)]
pub enum SignalValue {
    /// On or off, true or false.
    Bool(bool),
    /// A whole number (raw counts, a node-ID).
    Integer(i64),
    /// A real number in the signal's unit.
    Real(f64),
    /// A word (`"pulled"`, `"operational"`).
    Text(String),
    /// Several values (the alarms that are active).
    List(Vec<SignalValue>),
}

impl SignalValue {
    /// The value as a number, if it is one (an integer or a real).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            SignalValue::Integer(i) => Some(*i as f64),
            SignalValue::Real(r) => Some(*r),
            _ => None,
        }
    }

    /// Whether `self`, as seen on a device, matches `want`: numbers within `tolerance` of
    /// each other, anything else equal.
    pub fn matches(&self, want: &SignalValue, tolerance: f64) -> bool {
        match (self.as_f64(), want.as_f64()) {
            (Some(a), Some(b)) => (a - b).abs() <= tolerance,
            _ => self == want,
        }
    }

    /// The value as true or false for signal `id`.
    pub fn to_bool(&self, id: &SignalId) -> Result<bool, SignalError> {
        match self {
            SignalValue::Bool(b) => Ok(*b),
            _ => Err(self.wrong(id, "true or false")),
        }
    }

    /// The value as a finite number (an integer or a real) for signal `id`.
    pub fn to_f64(&self, id: &SignalId) -> Result<f64, SignalError> {
        match self {
            SignalValue::Integer(i) => Ok(*i as f64),
            SignalValue::Real(r) if r.is_finite() => Ok(*r),
            _ => Err(self.wrong(id, "a number")),
        }
    }

    /// The value as an integer in `T`'s range for signal `id`.
    pub fn to_int<T: TryFrom<i64>>(&self, id: &SignalId) -> Result<T, SignalError> {
        match self {
            SignalValue::Integer(i) => {
                T::try_from(*i).map_err(|_| self.wrong(id, "an integer in range"))
            }
            _ => Err(self.wrong(id, "an integer in range")),
        }
    }

    /// The value as a word for signal `id`.
    pub fn to_text(&self, id: &SignalId) -> Result<&str, SignalError> {
        match self {
            SignalValue::Text(s) => Ok(s),
            _ => Err(self.wrong(id, "a string")),
        }
    }

    fn wrong(&self, id: &SignalId, expected: &str) -> SignalError {
        SignalError::WrongType {
            signal: id.clone(),
            expected: expected.to_string(),
            got: self.clone(),
        }
    }
}

/// Written as in a scenario file: `true`, `12`, `2.5`, `"pulled"`, `["A2"]`.
impl fmt::Display for SignalValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SignalValue::Bool(b) => write!(f, "{b}"),
            SignalValue::Integer(i) => write!(f, "{i}"),
            SignalValue::Real(r) => {
                let text = r.to_string();
                if r.is_finite() && !text.contains(['.', 'e', 'E']) {
                    write!(f, "{text}.0")
                } else {
                    f.write_str(&text)
                }
            }
            SignalValue::Text(s) => write!(f, "{s:?}"),
            SignalValue::List(items) => {
                f.write_str("[")?;
                for (k, v) in items.iter().enumerate() {
                    if k > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{v}")?;
                }
                f.write_str("]")
            }
        }
    }
}

impl From<bool> for SignalValue {
    fn from(b: bool) -> Self {
        SignalValue::Bool(b)
    }
}

impl From<i64> for SignalValue {
    fn from(i: i64) -> Self {
        SignalValue::Integer(i)
    }
}

impl From<f64> for SignalValue {
    fn from(r: f64) -> Self {
        SignalValue::Real(r)
    }
}

impl From<&str> for SignalValue {
    fn from(s: &str) -> Self {
        SignalValue::Text(s.to_string())
    }
}

/// Setting or reading, for [`SignalError::Unknown`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// A host sets the signal.
    Set,
    /// A host reads the signal.
    Read,
}

impl fmt::Display for Direction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Direction::Set => "set",
            Direction::Read => "read",
        })
    }
}

/// Why a signal could not be set or read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SignalError {
    /// The device has no such signal in that direction; `known` lists those it has (empty
    /// when it has none).
    #[error("no signal {:?} to {direction}{}", .signal.as_str(), known_list(.known))]
    Unknown {
        /// The signal asked for.
        signal: SignalId,
        /// Set or read.
        direction: Direction,
        /// The signals the device knows, for the reader of the message.
        known: String,
    },
    /// The value has the wrong type for the signal.
    #[error("signal {:?} takes {expected}, not {got}", .signal.as_str())]
    WrongType {
        /// The signal.
        signal: SignalId,
        /// What it takes (`"true or false"`, `"a number"`).
        expected: String,
        /// The value given.
        got: SignalValue,
    },
    /// The value is of the right type but outside what the signal accepts.
    #[error("signal {:?} takes {range}, not {got}", .signal.as_str())]
    OutOfRange {
        /// The signal.
        signal: SignalId,
        /// What it accepts (`"-10–10 V"`, `"1-127"`).
        range: String,
        /// The value given.
        got: SignalValue,
    },
    /// The device refused the change, saying why.
    #[error("{reason}")]
    Refused {
        /// The signal.
        signal: SignalId,
        /// The device's reason.
        reason: String,
    },
}

fn known_list(known: &str) -> String {
    if known.is_empty() {
        String::new()
    } else {
        format!(" (signals: {known})")
    }
}

impl SignalError {
    /// [`SignalError::Unknown`] for `signal` in `direction`, naming the `known` signals.
    pub fn unknown(signal: &SignalId, direction: Direction, known: impl Into<String>) -> Self {
        SignalError::Unknown {
            signal: signal.clone(),
            direction,
            known: known.into(),
        }
    }

    /// [`SignalError::Refused`] for `signal` with the device's `reason`.
    pub fn refused(signal: &SignalId, reason: impl fmt::Display) -> Self {
        SignalError::Refused {
            signal: signal.clone(),
            reason: reason.to_string(),
        }
    }
}

/// The type and range of a signal's values.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueKind {
    /// True or false.
    Bool,
    /// A whole number within `min..=max`.
    Integer {
        /// The smallest value.
        min: i64,
        /// The largest value.
        max: i64,
    },
    /// A real number within `min..=max`.
    Real {
        /// The smallest value.
        min: f64,
        /// The largest value.
        max: f64,
    },
    /// One of the words listed (any word when empty).
    Text(Vec<&'static str>),
    /// A list of values.
    List,
}

/// Where a terminal signal is wired: the channel, on an expansion module when the device
/// has them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Terminal {
    /// The expansion module (1-based), `None` on a device without modules.
    pub module: Option<u32>,
    /// The channel as the device numbers it.
    pub channel: u32,
}

/// One signal of a device: its name, what it takes and gives, its unit and role.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalDescription {
    /// Its name.
    pub id: SignalId,
    /// What a host may set it to; `None` when it cannot be set.
    pub set: Option<ValueKind>,
    /// What reading it gives; `None` when it cannot be read as a signal.
    pub read: Option<ValueKind>,
    /// Its unit (empty for on/off signals, raw counts and words).
    pub unit: &'static str,
    /// What it is, for signals that are also live values.
    pub role: Option<Role>,
    /// The terminal it is, for wired inputs and outputs.
    pub terminal: Option<Terminal>,
}

impl SignalDescription {
    /// A signal a host sets to values of `kind` and cannot read back.
    pub fn input(id: SignalId, kind: ValueKind) -> Self {
        SignalDescription {
            id,
            set: Some(kind),
            read: None,
            unit: "",
            role: None,
            terminal: None,
        }
    }

    /// A signal a host reads as values of `kind` and cannot set.
    pub fn output(id: SignalId, kind: ValueKind) -> Self {
        SignalDescription {
            id,
            set: None,
            read: Some(kind),
            unit: "",
            role: None,
            terminal: None,
        }
    }

    /// The same signal with `unit`.
    pub fn unit(self, unit: &'static str) -> Self {
        SignalDescription { unit, ..self }
    }

    /// The same signal, also a live value in `role`.
    pub fn role(self, role: Role) -> Self {
        SignalDescription {
            role: Some(role),
            ..self
        }
    }

    /// The same signal, wired as `channel` (on `module`, if any).
    pub fn terminal(self, module: Option<u32>, channel: u32) -> Self {
        SignalDescription {
            terminal: Some(Terminal { module, channel }),
            ..self
        }
    }

    /// The same signal, also readable as values of `kind`.
    pub fn readable(self, kind: ValueKind) -> Self {
        SignalDescription {
            read: Some(kind),
            ..self
        }
    }
}
