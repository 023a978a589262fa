//! The DeviceNet 11-bit identifier: four message groups (DeviceNet Vol. 1 §3, "Message
//! Groups"). Groups 1–3 carry a 6-bit MAC ID, group 4 (offline connection set) none.

use cantwin_can::{Frame, Id, StandardId};
use core::fmt;

/// A DeviceNet node address, 0–63.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MacId(u8);

/// A MAC ID outside 0–63.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("DeviceNet MAC ID {0} is above 63")]
pub struct MacIdError(pub u8);

impl MacId {
    /// The highest MAC ID, 63 (the default address of an unconfigured node).
    pub const MAX: MacId = MacId(63);

    /// A MAC ID, or an error above 63.
    pub const fn new(raw: u8) -> Result<MacId, MacIdError> {
        if raw <= 63 {
            Ok(MacId(raw))
        } else {
            Err(MacIdError(raw))
        }
    }

    /// The low 6 bits of `raw` as a MAC ID (how the identifier and header fields carry it).
    pub const fn from_bits(raw: u8) -> MacId {
        MacId(raw & 0x3F)
    }

    /// The address, 0–63.
    pub const fn get(self) -> u8 {
        self.0
    }
}

impl fmt::Display for MacId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// Group 1 message IDs of the Predefined Master/Slave Connection Set (slave → master).
pub mod group1 {
    /// Slave's multicast poll response.
    pub const MULTICAST_POLL_RESPONSE: u8 = 0x0C;
    /// Slave's change-of-state / cyclic message.
    pub const COS_CYCLIC: u8 = 0x0D;
    /// Slave's bit-strobe response.
    pub const BIT_STROBE_RESPONSE: u8 = 0x0E;
    /// Slave's poll response (or COS/cyclic acknowledge).
    pub const POLL_RESPONSE: u8 = 0x0F;
}

/// Group 2 message IDs of the Predefined Master/Slave Connection Set.
pub mod group2 {
    /// Master's bit-strobe command (MAC = master).
    pub const BIT_STROBE: u8 = 0;
    /// Master's multicast poll (MAC = master).
    pub const MULTICAST_POLL: u8 = 1;
    /// Master's change-of-state acknowledge (MAC = slave).
    pub const COS_ACK: u8 = 2;
    /// Slave's explicit or unconnected response (MAC = slave).
    pub const EXPLICIT_RESPONSE: u8 = 3;
    /// Master's explicit request (MAC = slave).
    pub const EXPLICIT_REQUEST: u8 = 4;
    /// Master's poll command (MAC = slave).
    pub const POLL_COMMAND: u8 = 5;
    /// Group 2 only unconnected explicit request: Allocate / Release (MAC = slave).
    pub const UNCONNECTED_REQUEST: u8 = 6;
    /// Duplicate MAC ID check request and response (MAC = the checked address).
    pub const DUP_MAC_CHECK: u8 = 7;
}

/// Group 3 message IDs reserved for the Unconnected Message Manager.
pub mod group3 {
    /// Unconnected explicit response (MAC = server).
    pub const UNCONNECTED_RESPONSE: u8 = 5;
    /// Unconnected explicit request (MAC = client).
    pub const UNCONNECTED_REQUEST: u8 = 6;
}

/// Group 4 message IDs (offline connection set).
pub mod group4 {
    /// Communication faulted response.
    pub const COMM_FAULT_RESPONSE: u8 = 0x2C;
    /// Communication faulted request.
    pub const COMM_FAULT_REQUEST: u8 = 0x2D;
    /// Offline ownership response.
    pub const OFFLINE_OWNERSHIP_RESPONSE: u8 = 0x2E;
    /// Offline ownership request.
    pub const OFFLINE_OWNERSHIP_REQUEST: u8 = 0x2F;
}

/// A decoded DeviceNet identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DnId {
    /// Group 1 (0x000–0x3FF): `0 mmmm ssssss`, 4-bit message ID, source MAC ID.
    Group1 {
        /// Message ID, 0–15.
        msg: u8,
        /// Source MAC ID.
        mac: MacId,
    },
    /// Group 2 (0x400–0x5FF): `10 MMMMMM iii`, MAC ID (source or destination), message ID.
    Group2 {
        /// MAC ID.
        mac: MacId,
        /// Message ID, 0–7.
        msg: u8,
    },
    /// Group 3 (0x600–0x7BF): `11 iii ssssss`, message ID 0–6, source MAC ID.
    Group3 {
        /// Message ID, 0–6.
        msg: u8,
        /// Source MAC ID.
        mac: MacId,
    },
    /// Group 4 (0x7C0–0x7EF): message ID 0x00–0x2F, no MAC ID.
    Group4 {
        /// Message ID, 0x00–0x2F.
        msg: u8,
    },
}

/// An identifier DeviceNet does not use: extended format or 0x7F0–0x7FF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("identifier {0} is not a DeviceNet identifier")]
pub struct InvalidId(pub Id);

impl DnId {
    /// Decode a CAN identifier.
    pub fn decode(id: Id) -> Result<DnId, InvalidId> {
        let Id::Standard(std) = id else {
            return Err(InvalidId(id));
        };
        let raw = std.as_raw();
        let mac = MacId::from_bits(raw as u8);
        Ok(match raw {
            0x000..=0x3FF => DnId::Group1 {
                msg: ((raw >> 6) & 0x0F) as u8,
                mac,
            },
            0x400..=0x5FF => DnId::Group2 {
                mac: MacId::from_bits((raw >> 3) as u8),
                msg: (raw & 0x07) as u8,
            },
            0x600..=0x7BF => DnId::Group3 {
                msg: ((raw >> 6) & 0x07) as u8,
                mac,
            },
            0x7C0..=0x7EF => DnId::Group4 {
                msg: (raw & 0x3F) as u8,
            },
            _ => return Err(InvalidId(id)),
        })
    }

    /// The raw 11-bit value. Out-of-range message IDs are masked to their field.
    pub const fn raw(self) -> u16 {
        match self {
            DnId::Group1 { msg, mac } => ((msg as u16 & 0x0F) << 6) | mac.0 as u16,
            DnId::Group2 { mac, msg } => 0x400 | ((mac.0 as u16) << 3) | (msg as u16 & 0x07),
            DnId::Group3 { msg, mac } => 0x600 | ((msg as u16 % 7) << 6) | mac.0 as u16,
            DnId::Group4 { msg } => 0x7C0 | (msg as u16 % 0x30),
        }
    }

    /// The CAN identifier.
    pub fn id(self) -> Id {
        // raw() is at most 0x7EF by construction.
        match StandardId::new(self.raw()) {
            Ok(std) => Id::Standard(std),
            Err(_) => Id::Standard(StandardId::MAX),
        }
    }

    /// A data frame with this identifier. `data` longer than 8 bytes is cut to 8: callers
    /// build DeviceNet frames from fragments that never exceed 8.
    pub fn frame(self, data: &[u8]) -> Frame {
        let n = data.len().min(8);
        match Frame::data(self.id(), &data[..n]) {
            Ok(f) => f,
            Err(_) => Frame::data_array(self.id(), []),
        }
    }

    /// Group 2 identifier.
    pub const fn g2(mac: MacId, msg: u8) -> DnId {
        DnId::Group2 { mac, msg }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_ranges_round_trip() {
        for raw in 0u16..=0x7EF {
            let id = Id::standard(raw).unwrap();
            let dn = DnId::decode(id).unwrap();
            assert_eq!(dn.raw(), raw, "{dn:?}");
        }
        for raw in 0x7F0u16..=0x7FF {
            assert!(DnId::decode(Id::standard(raw).unwrap()).is_err());
        }
        assert!(DnId::decode(Id::extended(0x400).unwrap()).is_err());
    }

    /// Predefined set identifiers for MAC 63 as listed in the Edwards 102TBS-DN manual:
    /// poll produced 0x3FF, poll consumed 0x5FD, explicit produced 0x5FB, consumed 0x5FC.
    #[test]
    fn predefined_identifiers_for_mac_63() {
        let m = MacId::MAX;
        assert_eq!(
            DnId::Group1 {
                msg: group1::POLL_RESPONSE,
                mac: m
            }
            .raw(),
            0x3FF
        );
        assert_eq!(DnId::g2(m, group2::POLL_COMMAND).raw(), 0x5FD);
        assert_eq!(DnId::g2(m, group2::EXPLICIT_RESPONSE).raw(), 0x5FB);
        assert_eq!(DnId::g2(m, group2::EXPLICIT_REQUEST).raw(), 0x5FC);
        assert_eq!(
            DnId::Group3 {
                msg: 6,
                mac: MacId::new(2).unwrap()
            }
            .raw(),
            0x782
        );
        assert_eq!(DnId::Group4 { msg: 0x2F }.raw(), 0x7EF);
    }

    #[test]
    fn mac_id_range() {
        assert!(MacId::new(63).is_ok());
        assert_eq!(MacId::new(64), Err(MacIdError(64)));
    }
}
