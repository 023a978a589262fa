//! SDO abort codes (CiA 301 §7.2.4.3.17, table 22).
//!
//! An [`AbortCode`] is a 32-bit value sent little-endian in bytes 4..8 of an abort transfer
//! frame. Every code the standard lists is an associated constant with its description;
//! codes the standard does not list (manufacturer-specific ones, or new ones) are preserved
//! unchanged so that a trace or a client shows what was actually on the wire.

use core::fmt;

/// An SDO abort code (CiA 301 table 22). Unknown codes are kept as they are.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct AbortCode(u32);

macro_rules! abort_codes {
    ($( $(#[$doc:meta])* $name:ident = $value:literal, $text:literal; )*) => {
        impl AbortCode {
            $(
                $(#[$doc])*
                pub const $name: AbortCode = AbortCode($value);
            )*

            /// Every abort code CiA 301 table 22 lists, in numeric order.
            pub const ALL: &'static [AbortCode] = &[$(AbortCode::$name),*];

            /// The standard's description of the code, or `None` for a code it does not list.
            pub const fn description(self) -> Option<&'static str> {
                match self.0 {
                    $($value => Some($text),)*
                    _ => None,
                }
            }
        }
    };
}

abort_codes! {
    /// 0x05030000: toggle bit not alternated.
    TOGGLE_BIT_NOT_ALTERNATED = 0x0503_0000, "Toggle bit not alternated";
    /// 0x05040000: SDO protocol timed out.
    TIMEOUT = 0x0504_0000, "SDO protocol timed out";
    /// 0x05040001: client/server command specifier not valid or unknown.
    INVALID_COMMAND = 0x0504_0001, "Client/server command specifier not valid or unknown";
    /// 0x05040002: invalid block size (block mode only).
    INVALID_BLOCK_SIZE = 0x0504_0002, "Invalid block size (block mode only)";
    /// 0x05040003: invalid sequence number (block mode only).
    INVALID_SEQUENCE_NUMBER = 0x0504_0003, "Invalid sequence number (block mode only)";
    /// 0x05040004: CRC error (block mode only).
    CRC_ERROR = 0x0504_0004, "CRC error (block mode only)";
    /// 0x05040005: out of memory.
    OUT_OF_MEMORY = 0x0504_0005, "Out of memory";
    /// 0x06010000: unsupported access to an object.
    UNSUPPORTED_ACCESS = 0x0601_0000, "Unsupported access to an object";
    /// 0x06010001: attempt to read a write-only object.
    WRITE_ONLY = 0x0601_0001, "Attempt to read a write only object";
    /// 0x06010002: attempt to write a read-only object.
    READ_ONLY = 0x0601_0002, "Attempt to write a read only object";
    /// 0x06020000: object does not exist in the object dictionary.
    NO_OBJECT = 0x0602_0000, "Object does not exist in the object dictionary";
    /// 0x06040041: object cannot be mapped to the PDO.
    NOT_MAPPABLE = 0x0604_0041, "Object cannot be mapped to the PDO";
    /// 0x06040042: the number and length of the objects to be mapped would exceed PDO length.
    PDO_LENGTH_EXCEEDED = 0x0604_0042,
        "The number and length of the objects to be mapped would exceed PDO length";
    /// 0x06040043: general parameter incompatibility reason.
    PARAMETER_INCOMPATIBLE = 0x0604_0043, "General parameter incompatibility reason";
    /// 0x06040047: general internal incompatibility in the device.
    INTERNAL_INCOMPATIBILITY = 0x0604_0047, "General internal incompatibility in the device";
    /// 0x06060000: access failed due to a hardware error.
    HARDWARE_ERROR = 0x0606_0000, "Access failed due to a hardware error";
    /// 0x06070010: data type does not match, length of service parameter does not match.
    TYPE_MISMATCH = 0x0607_0010,
        "Data type does not match, length of service parameter does not match";
    /// 0x06070012: data type does not match, length of service parameter too high.
    LENGTH_TOO_HIGH = 0x0607_0012,
        "Data type does not match, length of service parameter too high";
    /// 0x06070013: data type does not match, length of service parameter too low.
    LENGTH_TOO_LOW = 0x0607_0013,
        "Data type does not match, length of service parameter too low";
    /// 0x06090011: sub-index does not exist.
    NO_SUB_INDEX = 0x0609_0011, "Sub-index does not exist";
    /// 0x06090030: invalid value for parameter (download only).
    INVALID_VALUE = 0x0609_0030, "Invalid value for parameter (download only)";
    /// 0x06090031: value of parameter written too high (download only).
    VALUE_TOO_HIGH = 0x0609_0031, "Value of parameter written too high (download only)";
    /// 0x06090032: value of parameter written too low (download only).
    VALUE_TOO_LOW = 0x0609_0032, "Value of parameter written too low (download only)";
    /// 0x06090036: maximum value is less than minimum value.
    MAX_LESS_THAN_MIN = 0x0609_0036, "Maximum value is less than minimum value";
    /// 0x060A0023: resource not available: SDO connection.
    RESOURCE_NOT_AVAILABLE = 0x060A_0023, "Resource not available: SDO connection";
    /// 0x08000000: general error.
    GENERAL_ERROR = 0x0800_0000, "General error";
    /// 0x08000020: data cannot be transferred or stored to the application.
    DATA_TRANSFER = 0x0800_0020, "Data cannot be transferred or stored to the application";
    /// 0x08000021: data cannot be transferred or stored because of local control.
    LOCAL_CONTROL = 0x0800_0021,
        "Data cannot be transferred or stored to the application because of local control";
    /// 0x08000022: data cannot be transferred or stored because of the present device state.
    DEVICE_STATE = 0x0800_0022,
        "Data cannot be transferred or stored to the application because of the present device state";
    /// 0x08000023: object dictionary dynamic generation fails or no object dictionary present.
    NO_OBJECT_DICTIONARY = 0x0800_0023,
        "Object dictionary dynamic generation fails or no object dictionary is present";
    /// 0x08000024: no data available.
    NO_DATA = 0x0800_0024, "No data available";
}

impl AbortCode {
    /// The code with this numeric value (any value: unknown codes are preserved).
    pub const fn from_u32(code: u32) -> Self {
        AbortCode(code)
    }

    /// The numeric value sent on the wire.
    pub const fn to_u32(self) -> u32 {
        self.0
    }

    /// Whether CiA 301 table 22 lists this code.
    pub const fn is_known(self) -> bool {
        self.description().is_some()
    }
}

impl From<u32> for AbortCode {
    fn from(code: u32) -> Self {
        AbortCode(code)
    }
}

impl From<AbortCode> for u32 {
    fn from(code: AbortCode) -> Self {
        code.0
    }
}

impl fmt::Debug for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AbortCode({:#010X})", self.0)
    }
}

impl fmt::Display for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.description() {
            Some(text) => write!(f, "{:#010X} ({text})", self.0),
            None => write!(f, "{:#010X} (unknown abort code)", self.0),
        }
    }
}

impl std::error::Error for AbortCode {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_22_has_every_code_once_and_in_order() {
        assert_eq!(AbortCode::ALL.len(), 31);
        assert!(AbortCode::ALL.windows(2).all(|w| w[0] < w[1]));
        assert!(AbortCode::ALL.iter().all(|c| c.is_known()));
    }

    #[test]
    fn unknown_codes_are_preserved() {
        let code = AbortCode::from_u32(0x1234_5678);
        assert_eq!(code.to_u32(), 0x1234_5678);
        assert!(!code.is_known());
        assert_eq!(code.to_string(), "0x12345678 (unknown abort code)");
    }

    #[test]
    fn display_carries_the_description() {
        assert_eq!(
            AbortCode::NO_OBJECT.to_string(),
            "0x06020000 (Object does not exist in the object dictionary)"
        );
        assert_eq!(u32::from(AbortCode::TOGGLE_BIT_NOT_ALTERNATED), 0x0503_0000);
    }
}
