//! The rule for every COB-ID entry of the stack (CiA 301 §7.3.5 and the entries' tables in
//! §7.5.2): [`check`] decides whether a download to one may land.
//!
//! An entry is an UNSIGNED32: bits 0..=28 the CAN-ID, bit 29 the frame format (0 = 11-bit
//! CAN-ID, 1 = 29-bit), bits 30 and 31 flags whose meaning each object's table gives:
//!
//! | entry | bit 31 | bit 30 |
//! |---|---|---|
//! | [`Entry::Sync`] 0x1005 | don't care | 1 = the device generates SYNC |
//! | [`Entry::Time`] 0x1012 | 1 = the device consumes TIME | 1 = the device produces TIME |
//! | [`Entry::Emcy`] 0x1014, [`Entry::EmcyConsumer`] 0x1028 sub 1.. | 1 = not valid | reserved (0) |
//! | [`Entry::SdoServer`] 0x1200+n, [`Entry::SdoClient`] 0x1280+n, sub 1/2 | 1 = not valid | 1 = dynamically allocated |
//! | [`Entry::Rpdo`] 0x1400+n sub 1 | 1 = not valid | reserved, not interpreted |
//! | [`Entry::Tpdo`] 0x1800+n sub 1 | 1 = not valid | 1 = no RTR allowed |
//!
//! A download is refused with 0x0609 0030 ("invalid value for parameter", which CiA 301
//! gives for a value outside an object's range) when:
//!
//! * a reserved flag is set (bit 30 of an EMCY entry; bit 30 of 0x1005/0x1012 on a device
//!   that cannot produce SYNC/TIME);
//! * bit 29 is 0 and any of bits 11..=28 is set: an 11-bit CAN-ID has no such bits;
//! * the 11-bit CAN-ID is restricted ([`is_restricted`]) and the entry is in use: always
//!   for SYNC, TIME and EMCY (their identifiers are used by every consumer, and EMCY's
//!   bit 31 only stops the producer), only with bit 31 = 0 for the others, whose
//!   identifier is not on the bus while the entry is not valid (so 0x8000 0000 disables
//!   any of them). The default SDO server's own pre-defined identifiers (0x600 +
//!   node-ID, 0x580 + node-ID) are the one use of restricted CAN-IDs the standard makes,
//!   and stay writable to 0x1200;
//! * the CAN-ID or frame format of an entry in use changes in one write from in use to in
//!   use: the entry is to be taken out of use first (bit 31 set; for SYNC, bit 30 cleared;
//!   for TIME, bits 30 and 31 cleared), then given its new identifier, then put back in use.
//!   CANopenNode (`ODR_INVALID_VALUE`) and lely (`CO_SDO_AC_PARAM_VAL`) both answer
//!   0x0609 0030 here, so the stack does too, rather than the general error 0x0800 0000.
//!
//! 29-bit CAN-IDs (bit 29 = 1) are accepted everywhere: the stack sends and receives
//! extended frames, and the restricted table lists 11-bit CAN-IDs only. 0x1016 holds
//! node-IDs, not COB-IDs, and is outside this rule.

use crate::abort::AbortCode;

/// Bit 31 of a COB-ID entry.
pub const BIT31: u32 = 1 << 31;
/// Bit 30 of a COB-ID entry.
pub const BIT30: u32 = 1 << 30;
/// Bit 29: the frame format, 1 = 29-bit CAN-ID.
pub const FRAME: u32 = 1 << 29;
/// Bits 11..=28: part of a 29-bit CAN-ID, 0 in an 11-bit one.
pub const EXTENDED_BITS: u32 = 0x1FFF_F800;
/// The CAN-ID and the frame format (bits 0..=29): what may not change while in use.
pub const IDENT: u32 = 0x3FFF_FFFF;

/// Whether an 11-bit CAN-ID is restricted (CiA 301 §7.3.5, table "restricted CAN-IDs"):
/// NMT 0x000, reserved 0x001..=0x07F, reserved 0x101..=0x180, default SDO 0x581..=0x5FF
/// and 0x601..=0x67F, reserved 0x6E0..=0x6FF, NMT error control 0x701..=0x77F and
/// reserved 0x780..=0x7FF. No configurable communication object may use one; the
/// device's own SDO and error control identifiers (0x600/0x580/0x700 + node-ID) are among
/// them.
pub const fn is_restricted(id: u16) -> bool {
    matches!(id,
        0x000..=0x07F | 0x101..=0x180 | 0x581..=0x5FF | 0x601..=0x67F
        | 0x6E0..=0x6FF | 0x701..=0x7FF)
}

/// A COB-ID entry of the stack, with what its object's table makes of bits 30 and 31.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Entry {
    /// 0x1005 COB-ID SYNC.
    Sync {
        /// Whether the device can generate SYNC (bit 30 may be set).
        producer: bool,
    },
    /// 0x1012 COB-ID TIME.
    Time {
        /// Whether the device can produce TIME (bit 30 may be set).
        producer: bool,
    },
    /// 0x1014 COB-ID EMCY.
    Emcy,
    /// 0x1028 sub 1.. emergency consumer.
    EmcyConsumer,
    /// 0x1200+n sub 1 or 2, SDO server parameter.
    SdoServer {
        /// The pre-defined identifier this entry has in the default SDO server (0x1200):
        /// 0x600 + node-ID for sub 1, 0x580 + node-ID for sub 2.
        predefined: Option<u16>,
    },
    /// 0x1280+n sub 1 or 2, SDO client parameter.
    SdoClient,
    /// 0x1400+n sub 1, RPDO COB-ID.
    Rpdo,
    /// 0x1800+n sub 1, TPDO COB-ID.
    Tpdo,
}

impl Entry {
    /// The COB-ID entry at `index`/`sub`, for a device with node-ID `node_id` that can or
    /// cannot produce SYNC and TIME; `None` if it is not one.
    pub const fn of(
        index: u16,
        sub: u8,
        node_id: u8,
        sync_producer: bool,
        time_producer: bool,
    ) -> Option<Entry> {
        Some(match (index, sub) {
            (0x1005, 0) => Entry::Sync {
                producer: sync_producer,
            },
            (0x1012, 0) => Entry::Time {
                producer: time_producer,
            },
            (0x1014, 0) => Entry::Emcy,
            (0x1028, 1..) => Entry::EmcyConsumer,
            (0x1200, 1) => Entry::SdoServer {
                predefined: Some(0x600 + node_id as u16),
            },
            (0x1200, 2) => Entry::SdoServer {
                predefined: Some(0x580 + node_id as u16),
            },
            (0x1201..=0x127F, 1 | 2) => Entry::SdoServer { predefined: None },
            (0x1280..=0x12FF, 1 | 2) => Entry::SdoClient,
            (0x1400..=0x15FF, 1) => Entry::Rpdo,
            (0x1800..=0x19FF, 1) => Entry::Tpdo,
            _ => return None,
        })
    }

    /// Whether it is a PDO's COB-ID (the PDO engine checks those).
    pub const fn is_pdo(self) -> bool {
        matches!(self, Entry::Rpdo | Entry::Tpdo)
    }

    /// Whether bit 30 is reserved for this entry (must be 0).
    const fn bit30_reserved(self) -> bool {
        match self {
            Entry::Sync { producer } | Entry::Time { producer } => !producer,
            Entry::Emcy | Entry::EmcyConsumer => true,
            Entry::SdoServer { .. } | Entry::SdoClient | Entry::Rpdo | Entry::Tpdo => false,
        }
    }

    /// Whether the identifier of an entry holding `v` is used on the bus.
    const fn in_use(self, v: u32) -> bool {
        match self {
            Entry::Sync { .. } | Entry::Time { .. } | Entry::Emcy => true,
            _ => v & BIT31 == 0,
        }
    }

    /// Whether the identifier of an entry holding `v` is fixed: it may only change after
    /// the entry was taken out of use.
    const fn fixed(self, v: u32) -> bool {
        match self {
            // §7.5.2.5: not while the device generates SYNC.
            Entry::Sync { .. } => v & BIT30 != 0,
            // Not while TIME is consumed or produced.
            Entry::Time { .. } => v & (BIT30 | BIT31) != 0,
            _ => v & BIT31 == 0,
        }
    }
}

/// Whether a download of `new` to the COB-ID entry `entry`, which holds `old`, may land;
/// 0x0609 0030 if not. See the [module documentation](self) for the rule.
pub const fn check(entry: Entry, old: u32, new: u32) -> Result<(), AbortCode> {
    let invalid = Err(AbortCode::INVALID_VALUE);
    if entry.bit30_reserved() && new & BIT30 != 0 {
        return invalid;
    }
    if new & FRAME == 0 && new & EXTENDED_BITS != 0 {
        return invalid;
    }
    if new & FRAME == 0 && entry.in_use(new) {
        let id = (new & 0x7FF) as u16;
        let predefined = match entry {
            Entry::SdoServer { predefined } => predefined,
            _ => None,
        };
        let own = match predefined {
            Some(p) => p == id,
            None => false,
        };
        if is_restricted(id) && !own {
            return invalid;
        }
    }
    if entry.fixed(old) && entry.fixed(new) && (old ^ new) & IDENT != 0 {
        return invalid;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_3_5_restricted_table_bounds() {
        for id in [
            0x000, 0x001, 0x07F, 0x101, 0x180, 0x581, 0x5FF, 0x601, 0x67F, 0x6E0, 0x6FF, 0x701,
            0x77F, 0x780, 0x7FF,
        ] {
            assert!(is_restricted(id), "{id:#X}");
        }
        for id in [
            0x080, 0x0FF, 0x100, 0x181, 0x1FF, 0x200, 0x580, 0x600, 0x680, 0x6DF, 0x700,
        ] {
            assert!(!is_restricted(id), "{id:#X}");
        }
        assert_eq!((0..0x800u16).filter(|&i| is_restricted(i)).count(), 797);
    }

    #[test]
    fn cia301_7_5_2_5_sync_bit31_is_dont_care_and_bit30_needs_a_producer() {
        let producer = Entry::Sync { producer: true };
        let consumer = Entry::Sync { producer: false };
        assert_eq!(check(producer, 0x80, 0x8000_0080), Ok(()));
        assert_eq!(check(producer, 0x80, 0x4000_0080), Ok(()));
        assert_eq!(
            check(consumer, 0x80, 0x4000_0080),
            Err(AbortCode::INVALID_VALUE)
        );
        // Fixed while generating; free again once bit 30 is cleared.
        assert_eq!(
            check(producer, 0x4000_0080, 0x4000_0081),
            Err(AbortCode::INVALID_VALUE)
        );
        assert_eq!(check(producer, 0x4000_0080, 0x0000_0080), Ok(()));
        assert_eq!(check(producer, 0x80, 0x81), Ok(()));
    }

    #[test]
    fn cia301_7_3_5_bits_11_to_28_need_bit_29() {
        for entry in [
            Entry::Sync { producer: true },
            Entry::Time { producer: true },
        ] {
            assert_eq!(check(entry, 0x80, 0x18BE), Err(AbortCode::INVALID_VALUE));
            assert_eq!(check(entry, 0x80, 0x3D6C), Err(AbortCode::INVALID_VALUE));
            assert_eq!(check(entry, 0x80, 0x2000_18BE), Ok(()));
        }
    }

    #[test]
    fn cia301_7_3_5_own_predefined_sdo_identifiers_stay_writable_to_0x1200() {
        let rx = Entry::of(0x1200, 1, 5, true, true).unwrap();
        assert_eq!(check(rx, 0x605, 0x605), Ok(()));
        assert_eq!(check(rx, 0x605, 0x606), Err(AbortCode::INVALID_VALUE));
        let extra = Entry::of(0x1201, 1, 5, true, true).unwrap();
        assert_eq!(check(extra, BIT31, 0x605), Err(AbortCode::INVALID_VALUE));
        assert_eq!(check(extra, BIT31, BIT31 | 0x605), Ok(()));
        assert_eq!(check(extra, BIT31, 0x6A5), Ok(()));
    }

    #[test]
    fn entries_of_the_stack() {
        assert_eq!(Entry::of(0x1016, 1, 5, true, true), None);
        assert_eq!(Entry::of(0x1400, 2, 5, true, true), None);
        assert_eq!(Entry::of(0x12FF, 2, 5, true, true), Some(Entry::SdoClient));
        assert_eq!(Entry::of(0x19FF, 1, 5, true, true), Some(Entry::Tpdo));
    }
}
