//! CAN identifiers (ISO 11898-1 §8.4.2.2): 11-bit base format and 29-bit extended format.

use core::fmt;

/// An identifier outside the range of its format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IdError {
    /// A standard identifier above 0x7FF.
    #[error("standard CAN identifier {0:#x} is above 0x7FF")]
    StandardOutOfRange(u32),
    /// An extended identifier above 0x1FFF_FFFF.
    #[error("extended CAN identifier {0:#x} is above 0x1FFFFFFF")]
    ExtendedOutOfRange(u32),
}

/// An 11-bit identifier (base frame format).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct StandardId(u16);

impl StandardId {
    /// The highest standard identifier, 0x7FF.
    pub const MAX: StandardId = StandardId(0x7FF);

    /// A standard identifier, or an error above 0x7FF.
    pub const fn new(raw: u16) -> Result<Self, IdError> {
        if raw <= 0x7FF {
            Ok(StandardId(raw))
        } else {
            Err(IdError::StandardOutOfRange(raw as u32))
        }
    }

    /// The identifier's value, 0..=0x7FF.
    pub const fn as_raw(self) -> u16 {
        self.0
    }
}

/// A 29-bit identifier (extended frame format).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ExtendedId(u32);

impl ExtendedId {
    /// The highest extended identifier, 0x1FFF_FFFF.
    pub const MAX: ExtendedId = ExtendedId(0x1FFF_FFFF);

    /// An extended identifier, or an error above 0x1FFF_FFFF.
    pub const fn new(raw: u32) -> Result<Self, IdError> {
        if raw <= 0x1FFF_FFFF {
            Ok(ExtendedId(raw))
        } else {
            Err(IdError::ExtendedOutOfRange(raw))
        }
    }

    /// The identifier's value, 0..=0x1FFF_FFFF.
    pub const fn as_raw(self) -> u32 {
        self.0
    }

    /// The 11 most significant bits (identifier A, sent first on the wire).
    pub const fn base(self) -> u16 {
        (self.0 >> 18) as u16
    }
}

/// A CAN identifier in either format.
///
/// The derived order is not the arbitration order; use [`Id::arbitration_key`] for that.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Id {
    /// 11-bit base format.
    Standard(StandardId),
    /// 29-bit extended format.
    Extended(ExtendedId),
}

impl Id {
    /// A standard identifier, or an error above 0x7FF.
    pub const fn standard(raw: u16) -> Result<Self, IdError> {
        match StandardId::new(raw) {
            Ok(id) => Ok(Id::Standard(id)),
            Err(e) => Err(e),
        }
    }

    /// An extended identifier, or an error above 0x1FFF_FFFF.
    pub const fn extended(raw: u32) -> Result<Self, IdError> {
        match ExtendedId::new(raw) {
            Ok(id) => Ok(Id::Extended(id)),
            Err(e) => Err(e),
        }
    }

    /// The numeric value of the identifier (without any format flag).
    pub const fn as_raw(self) -> u32 {
        match self {
            Id::Standard(id) => id.0 as u32,
            Id::Extended(id) => id.0,
        }
    }

    /// Whether this is a 29-bit identifier.
    pub const fn is_extended(self) -> bool {
        matches!(self, Id::Extended(_))
    }

    /// The arbitration field as a number whose order is the order in which frames win
    /// arbitration (ISO 11898-1 §10.4.4.2): the lower key wins.
    ///
    /// The key lays the arbitration bits out left-aligned in transmission order, dominant = 0:
    /// base format `ID[10:0] RTR IDE(0)`, extended format `ID[28:18] SRR(1) IDE(1) ID[17:0] RTR`.
    /// So a data frame beats a remote frame with the same identifier, and a standard frame
    /// beats an extended frame with the same 11 leading bits, as on the wire.
    pub const fn arbitration_key(self, remote: bool) -> u32 {
        match self {
            Id::Standard(id) => ((id.0 as u32) << 21) | ((remote as u32) << 20),
            Id::Extended(id) => {
                ((id.base() as u32) << 21)
                    | (1 << 20)
                    | (1 << 19)
                    | ((id.0 & 0x3_FFFF) << 1)
                    | remote as u32
            }
        }
    }
}

impl From<StandardId> for Id {
    fn from(id: StandardId) -> Self {
        Id::Standard(id)
    }
}

impl From<ExtendedId> for Id {
    fn from(id: ExtendedId) -> Self {
        Id::Extended(id)
    }
}

impl fmt::Display for Id {
    /// candump style: three hex digits for standard, eight for extended identifiers.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Id::Standard(id) => write!(f, "{:03X}", id.0),
            Id::Extended(id) => write!(f, "{:08X}", id.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_validated() {
        assert!(Id::standard(0x7FF).is_ok());
        assert_eq!(Id::standard(0x800), Err(IdError::StandardOutOfRange(0x800)));
        assert!(Id::extended(0x1FFF_FFFF).is_ok());
        assert_eq!(
            Id::extended(0x2000_0000),
            Err(IdError::ExtendedOutOfRange(0x2000_0000))
        );
    }

    #[test]
    fn arbitration_lower_identifier_wins() {
        let a = Id::standard(0x100).unwrap().arbitration_key(false);
        let b = Id::standard(0x101).unwrap().arbitration_key(false);
        assert!(a < b);
    }

    #[test]
    fn arbitration_data_beats_remote_with_same_id() {
        let id = Id::standard(0x700).unwrap();
        assert!(id.arbitration_key(false) < id.arbitration_key(true));
        let id = Id::extended(0x1234_5678).unwrap();
        assert!(id.arbitration_key(false) < id.arbitration_key(true));
    }

    #[test]
    fn arbitration_standard_beats_extended_with_same_leading_bits() {
        let std = Id::standard(0x123).unwrap();
        let ext = Id::extended(0x123 << 18).unwrap();
        // Even a standard remote frame wins: its RTR bit meets the recessive SRR bit, and its
        // dominant IDE bit then beats the extended frame's recessive IDE bit.
        assert!(std.arbitration_key(true) < ext.arbitration_key(false));
        // But an extended frame with lower leading bits wins over a standard one.
        let ext_lower = Id::extended(0x122 << 18 | 0x3_FFFF).unwrap();
        assert!(ext_lower.arbitration_key(true) < std.arbitration_key(false));
    }

    #[test]
    fn display_is_candump_style() {
        assert_eq!(Id::standard(0x12).unwrap().to_string(), "012");
        assert_eq!(Id::extended(0x12).unwrap().to_string(), "00000012");
    }
}
