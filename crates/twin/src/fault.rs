//! Internal faults a host gives a device: defects with no cause on the bus (a card's
//! internal error), and alarms of a drive model.

use core::fmt;

/// What kind of fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultKind {
    /// An internal defect of the device's electronics, in the device's words (an ADV200
    /// card's `"FF04"`).
    Internal,
    /// An alarm of the device's model, by its name (an ADV200 `"External fault"`).
    Alarm,
}

/// A fault to inject: its kind and its name in the device's words.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Fault {
    /// The kind.
    pub kind: FaultKind,
    /// The name.
    pub name: String,
}

impl Fault {
    /// The internal defect `name`.
    pub fn internal(name: impl Into<String>) -> Self {
        Fault {
            kind: FaultKind::Internal,
            name: name.into(),
        }
    }

    /// The alarm `name`.
    pub fn alarm(name: impl Into<String>) -> Self {
        Fault {
            kind: FaultKind::Alarm,
            name: name.into(),
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

/// Why a fault could not be injected or repaired.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FaultError {
    /// The device has no faults of that kind.
    #[error("{}", none_of(*.kind))]
    None {
        /// The kind asked for.
        kind: FaultKind,
    },
    /// The device has no such fault; `reason` says which it has.
    #[error("{reason}")]
    Unknown {
        /// The fault asked for.
        fault: Fault,
        /// The device's answer, naming the faults it knows.
        reason: String,
    },
}

fn none_of(kind: FaultKind) -> &'static str {
    match kind {
        FaultKind::Internal => "no internal faults to inject",
        FaultKind::Alarm => "no alarms to raise",
    }
}
