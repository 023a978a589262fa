//! The PDO communication and mapping objects a device declares (CiA 301 §7.5.2.35–38),
//! with the pre-defined connection set's default COB-IDs (§7.3.5).

use super::{RPDO_COMM, RPDO_MAP, TPDO_COMM, TPDO_MAP};
use crate::od::{Access, DataType, OdBuilder, SubObject, Value};

/// The PDO objects of a device: `rpdos` RPDOs and `tpdos` TPDOs with up to
/// [`PdoObjects::max_entries`] mapping entries each, and default mappings.
///
/// Defaults (CiA 301 §7.3.5, pre-defined connection set): RPDO1..4 on 0x200/0x300/0x400/
/// 0x500 + node-ID, TPDO1..4 on 0x180/0x280/0x380/0x480 + node-ID; a PDO is valid by
/// default only if it has a default mapping. PDOs beyond the fourth have no default
/// identifier and are invalid (COB-ID 0x80000000). Transmission type 255 unless given.
/// All parameters are `rw`; [`PdoObjects::add_to`] routes 0x1400..=0x1BFF through the
/// device's hooks so that [`super::PdoEngine::validate_write`] sees every download.
#[derive(Debug, Clone)]
pub struct PdoObjects {
    rpdos: u16,
    tpdos: u16,
    entries: u8,
    rx: Vec<(u16, u8, Vec<u32>)>,
    tx: Vec<(u16, u8, Vec<u32>)>,
    /// Default COB-IDs given for TPDOs beyond the pre-defined connection set: (slot, id).
    tx_ids: Vec<(u16, u32)>,
    /// The default event timer (sub 5) of every TPDO, in ms.
    event_timer_ms: u16,
}

impl PdoObjects {
    /// `rpdos` RPDOs and `tpdos` TPDOs (each at most 512), 8 mapping entries each.
    pub fn new(rpdos: u16, tpdos: u16) -> Self {
        PdoObjects {
            rpdos: rpdos.min(super::MAX_PDOS),
            tpdos: tpdos.min(super::MAX_PDOS),
            entries: 8,
            rx: Vec::new(),
            tx: Vec::new(),
            tx_ids: Vec::new(),
            event_timer_ms: 0,
        }
    }

    /// The default identifier of TPDO slot `n` (0x1800 + n sub 1, without `$NODEID`), for a
    /// device whose application assigns TPDOs beyond the four of the pre-defined connection
    /// set (CiA 301 §7.3.5); valid when the TPDO has a default mapping.
    pub fn tpdo_cob_id(mut self, n: u16, id: u32) -> Self {
        self.tx_ids.retain(|&(m, _)| m != n);
        self.tx_ids.push((n, id));
        self
    }

    /// The default event timer of every TPDO (0x1800 + n sub 5, CiA 301 §7.5.2.35), in ms.
    pub fn event_timer(mut self, ms: u16) -> Self {
        self.event_timer_ms = ms;
        self
    }

    /// The number of mapping entries each mapping object has (1..=64).
    pub fn max_entries(mut self, entries: u8) -> Self {
        self.entries = entries.clamp(1, super::MAX_ENTRIES);
        self
    }

    /// The default transmission type and mapping (`index << 16 | sub << 8 | bits` entries)
    /// of RPDO slot `n` (communication object 0x1400 + n).
    pub fn rpdo(mut self, n: u16, transmission_type: u8, mapping: &[u32]) -> Self {
        self.rx.push((n, transmission_type, mapping.to_vec()));
        self
    }

    /// The default transmission type and mapping of TPDO slot `n` (0x1800 + n).
    pub fn tpdo(mut self, n: u16, transmission_type: u8, mapping: &[u32]) -> Self {
        self.tx.push((n, transmission_type, mapping.to_vec()));
        self
    }

    /// Adds the objects to a dictionary definition.
    pub fn add_to(&self, mut b: OdBuilder) -> OdBuilder {
        let u8_rw = |name: &str, v: u8| {
            SubObject::new(name, DataType::Unsigned8, Access::Rw).default(Value::Unsigned8(v))
        };
        let u16_rw = |name: &str| {
            SubObject::new(name, DataType::Unsigned16, Access::Rw).default(Value::Unsigned16(0))
        };
        let cob = |n: u16, base: u32, mapped: bool| {
            let invalid = if mapped { 0 } else { super::CobId::INVALID };
            let s = SubObject::new("COB-ID used by PDO", DataType::Unsigned32, Access::Rw);
            if n < 4 {
                s.default_node_id_plus(Value::Unsigned32(invalid | (base + 0x100 * u32::from(n))))
            } else {
                s.default(Value::Unsigned32(super::CobId::INVALID))
            }
        };
        for n in 0..self.rpdos {
            let def = self.rx.iter().find(|d| d.0 == n);
            let ttype = def.map_or(255, |d| d.1);
            let mapping = def.map_or(&[][..], |d| &d.2[..]);
            b = b.record(
                RPDO_COMM + n,
                format!("RPDO communication parameter {}", n + 1),
                [
                    (1, cob(n, 0x200, !mapping.is_empty())),
                    (2, u8_rw("Transmission type", ttype)),
                    (5, u16_rw("Event timer")),
                ],
            );
            b = self.mapping(b, RPDO_MAP + n, "RPDO", n, mapping);
        }
        for n in 0..self.tpdos {
            let def = self.tx.iter().find(|d| d.0 == n);
            let ttype = def.map_or(255, |d| d.1);
            let mapping = def.map_or(&[][..], |d| &d.2[..]);
            let cob_id = match self.tx_ids.iter().find(|&&(m, _)| m == n) {
                Some(&(_, id)) => {
                    let invalid = if mapping.is_empty() {
                        super::CobId::INVALID
                    } else {
                        0
                    };
                    SubObject::new("COB-ID used by PDO", DataType::Unsigned32, Access::Rw)
                        .default(Value::Unsigned32(invalid | id))
                }
                None => cob(n, 0x180, !mapping.is_empty()),
            };
            b = b.record(
                TPDO_COMM + n,
                format!("TPDO communication parameter {}", n + 1),
                [
                    (1, cob_id),
                    (2, u8_rw("Transmission type", ttype)),
                    (3, u16_rw("Inhibit time")),
                    (
                        5,
                        SubObject::new("Event timer", DataType::Unsigned16, Access::Rw)
                            .default(Value::Unsigned16(self.event_timer_ms)),
                    ),
                    (6, u8_rw("SYNC start value", 0)),
                ],
            );
            b = self.mapping(b, TPDO_MAP + n, "TPDO", n, mapping);
        }
        b.hook(RPDO_COMM..=TPDO_MAP + (super::MAX_PDOS - 1))
    }

    fn mapping(&self, b: OdBuilder, index: u16, kind: &str, n: u16, mapping: &[u32]) -> OdBuilder {
        let count = mapping.len().min(usize::from(self.entries)) as u8;
        let subs = core::iter::once((
            0,
            SubObject::new("Number of mapped objects", DataType::Unsigned8, Access::Rw)
                .default(Value::Unsigned8(count)),
        ))
        .chain((1..=self.entries).map(|k| {
            let v = mapping.get(usize::from(k) - 1).copied().unwrap_or(0);
            (
                k,
                SubObject::new(
                    format!("Mapping entry {k}"),
                    DataType::Unsigned32,
                    Access::Rw,
                )
                .default(Value::Unsigned32(v)),
            )
        }));
        b.record(index, format!("{kind} mapping parameter {}", n + 1), subs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::ObjectDictionary;
    use std::sync::Arc;

    #[test]
    fn predefined_connection_set_defaults() {
        let b = OdBuilder::new().var(
            0x6000,
            SubObject::new("in", DataType::Unsigned8, Access::Ro).mappable(),
        );
        let b = PdoObjects::new(5, 5).tpdo(1, 1, &[0x6000_0008]).add_to(b);
        let od = ObjectDictionary::new(Arc::new(b.build().unwrap()), 0x22);
        let cob = |i| od.get_unsigned(i, 1).unwrap();
        assert_eq!(cob(0x1400), 0x8000_0222);
        assert_eq!(cob(0x1403), 0x8000_0522);
        assert_eq!(cob(0x1404), 0x8000_0000);
        assert_eq!(cob(0x1800), 0x8000_01A2);
        assert_eq!(cob(0x1801), 0x0000_02A2);
        assert_eq!(cob(0x1803), 0x8000_04A2);
        assert_eq!(od.get_unsigned(0x1801, 2), Some(1));
        assert_eq!(od.get_unsigned(0x1A01, 0), Some(1));
        assert_eq!(od.get_unsigned(0x1A01, 1), Some(0x6000_0008));
        assert_eq!(od.get_unsigned(0x1A01, 8), Some(0));
        assert_eq!(od.get_unsigned(0x1800, 0), Some(6));
        assert_eq!(od.get_unsigned(0x1400, 0), Some(5));
        assert!(od.description().is_hooked(0x1A04));
    }

    #[test]
    fn tpdos_beyond_the_predefined_set_take_their_given_identifier_and_event_timer() {
        let desc = PdoObjects::new(0, 6)
            .tpdo(5, 255, &[0x6000_0110])
            .tpdo_cob_id(5, 0x1C5)
            .tpdo_cob_id(4, 0x1C4)
            .event_timer(8)
            .add_to(OdBuilder::new().array_of(
                0x6000,
                "Inputs",
                1,
                SubObject::new("Input", DataType::Unsigned16, Access::Ro).mappable(),
            ))
            .build()
            .unwrap();
        let od = ObjectDictionary::new(Arc::new(desc), 0x22);
        // §7.5.2.35: valid (bit 31 clear) only with a mapping; no $NODEID for given ones.
        assert_eq!(od.get_unsigned(0x1805, 1), Some(0x1C5));
        assert_eq!(od.get_unsigned(0x1804, 1), Some(0x8000_01C4));
        assert_eq!(od.get_unsigned(0x1800, 1), Some(0x8000_01A2));
        assert_eq!(od.get_unsigned(0x1805, 5), Some(8));
        assert_eq!(od.get_unsigned(0x1800, 5), Some(8));
    }
}
