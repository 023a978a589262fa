//! The coupler's object dictionary, built from the configured island (manual: "Oggetti
//! nella zona profilo di comunicazione"): exactly the manual's communication objects with
//! its attributes and defaults, then the CiA 401 objects sized by the modules.
//!
//! Choices where the manual is silent or ambiguous, each pinned by a test:
//! * PDOs beyond the fourth and the second SDO server have no default COB-ID: they start
//!   invalid (bit 31 set). PDOs 1–4 with an empty default mapping (no module of that kind)
//!   are invalid too, on their pre-defined identifier.
//! * The RPDO default table lists four objects for 0x1601–0x1603 but an entry count of 1;
//!   the count follows the objects listed (as for the TPDOs), limited to the channels the
//!   island has.
//! * 0x1027 has one sub-index per configured module; with no module it has 14 sub-indices
//!   of 0, as the manual says.
//! * 0x1201 sub 3 (client node-ID) is UNSIGNED8, as in CiA 301.

use crate::catalogue::ModuleSpec;
use crate::island::{Island, MAX_MODULES};
use cantwin_canopen::od::{
    Access, DataType, OdBuildError, OdBuilder, OdDescription, SubObject, Value,
};
use cantwin_cia401::objects as cia401;
use std::sync::Arc;

/// 0x1000 with no module: CiA 401, device-specific PDO mapping (manual bit 8 = bit 23).
pub const DEVICE_TYPE_BASE: u32 = 0x0080_0191;
/// 0x1018 sub 1, Schneider Electric.
pub const VENDOR_ID: u32 = 0x0500_005A;
/// 0x1018 sub 2.
pub const PRODUCT_CODE: u32 = 811_044;
/// 0x1018 sub 3: firmware 1.0.15 as the manual's example encodes it.
pub const REVISION: u32 = 0x0001_0015;
/// 0x100A, the same firmware version as text.
pub const SOFTWARE_VERSION: &str = "01.00.15";
/// 0x1008.
pub const DEVICE_NAME: &str = "TM3BCCO";
/// The manufacturer, as its EDS names it (`VendorName`).
pub const VENDOR_NAME: &str = "Schneider Electric";
/// Entries of 0x1003.
pub const ERROR_HISTORY: u8 = 10;
/// Receive PDOs, 0x1400–0x141C.
pub const RPDOS: u16 = 29;
/// Transmit PDOs, 0x1800–0x1837.
pub const TPDOS: u16 = 56;
/// Mapping entries per PDO (manual: range of sub-index 0 is 8).
pub const MAP_ENTRIES: u8 = 8;

/// The value of 0x1000 for `island`.
pub fn device_type(island: &Island) -> u32 {
    DEVICE_TYPE_BASE | island.layout().device_type_io_bits()
}

/// Default mappings: (PDO slot, 0 = first; mapping entries `index << 16 | sub << 8 | bits`).
pub type Mappings = Vec<(u16, Vec<u32>)>;

/// The default mappings of the manual's tables, limited to the island's channels:
/// `(rpdos, tpdos)`.
pub fn default_mappings(island: &Island) -> (Mappings, Mappings) {
    let l = island.layout();
    let entry = |index: u16, sub: u8, bits: u8| {
        u32::from(index) << 16 | u32::from(sub) << 8 | u32::from(bits)
    };
    let analog = |index: u16, n: u8| -> Vec<(u16, Vec<u32>)> {
        (0..3u8)
            .map(|k| {
                let subs = (4 * k + 1..=4 * k + 4).filter(|&s| s <= n);
                (
                    u16::from(k) + 1,
                    subs.map(|s| entry(index, s, 16)).collect(),
                )
            })
            .collect()
    };
    let mut rx = vec![(
        0,
        if l.digital_output_bytes > 0 {
            vec![entry(cia401::WRITE_OUTPUT_8, 1, 8)]
        } else {
            vec![]
        },
    )];
    rx.extend(analog(cia401::WRITE_ANALOG_OUTPUT_16, l.analog_outputs));
    let mut tx = vec![(
        0,
        if l.digital_input_bytes > 0 {
            vec![entry(cia401::READ_INPUT_8, 1, 8)]
        } else {
            vec![]
        },
    )];
    tx.extend(analog(cia401::READ_ANALOG_INPUT_16, l.analog_inputs));
    (rx, tx)
}

fn mapping_object(b: OdBuilder, index: u16, name: String, mapping: &[u32]) -> OdBuilder {
    let subs = core::iter::once((
        0,
        SubObject::new("Number of mapped objects", DataType::Unsigned8, Access::Rw)
            .default(Value::Unsigned8(mapping.len() as u8)),
    ))
    .chain((1..=MAP_ENTRIES).map(|k| {
        let v = mapping.get(usize::from(k) - 1).copied().unwrap_or(0);
        (
            k,
            SubObject::unsigned32(format!("Mapping entry {k}"), Access::Rw, v),
        )
    }));
    b.record(index, name, subs)
}

fn pdo_objects(mut b: OdBuilder, island: &Island) -> OdBuilder {
    let (rx, tx) = default_mappings(island);
    let cob = |n: u16, base: u32, mapped: bool| {
        let s = SubObject::new("COB-ID used by PDO", DataType::Unsigned32, Access::Rw);
        if n < 4 {
            let invalid = if mapped { 0 } else { 1 << 31 };
            s.default_node_id_plus(Value::Unsigned32(invalid | (base + 0x100 * u32::from(n))))
        } else {
            s.default(Value::Unsigned32(1 << 31))
        }
    };
    let u8_rw = |name: &str, v: u8| {
        SubObject::new(name, DataType::Unsigned8, Access::Rw).default(Value::Unsigned8(v))
    };
    let u16_rw = |name: &str| {
        SubObject::new(name, DataType::Unsigned16, Access::Rw).default(Value::Unsigned16(0))
    };
    for n in 0..RPDOS {
        let mapping = rx.iter().find(|d| d.0 == n).map_or(&[][..], |d| &d.1[..]);
        b = b.record(
            0x1400 + n,
            format!("Receive PDO communication parameter {}", n + 1),
            [
                (1, cob(n, 0x200, !mapping.is_empty())),
                (2, u8_rw("Transmission type", 255)),
                (5, u16_rw("Event timer")),
            ],
        );
        b = mapping_object(
            b,
            0x1600 + n,
            format!("Receive PDO mapping parameter {}", n + 1),
            mapping,
        );
    }
    for n in 0..TPDOS {
        let mapping = tx.iter().find(|d| d.0 == n).map_or(&[][..], |d| &d.1[..]);
        b = b.record(
            0x1800 + n,
            format!("Transmit PDO communication parameter {}", n + 1),
            [
                (1, cob(n, 0x180, !mapping.is_empty())),
                (2, u8_rw("Transmission type", 255)),
                (3, u16_rw("Inhibit time")),
                (5, u16_rw("Event timer")),
            ],
        );
        b = mapping_object(
            b,
            0x1A00 + n,
            format!("Transmit PDO mapping parameter {}", n + 1),
            mapping,
        );
    }
    b
}

/// The communication objects of the manual (0x1000–0x1BFF) for `island`.
pub fn communication_objects(mut b: OdBuilder, island: &Island) -> OdBuilder {
    let string = |name: &str, v: &str| {
        SubObject::new(name, DataType::VisibleString, Access::Const)
            .default(Value::VisibleString(v.into()))
            .max_len(v.len())
    };
    b = b
        .var(
            0x1000,
            SubObject::unsigned32("Device type", Access::Ro, device_type(island)),
        )
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro).mappable(),
        )
        .var(
            0x1002,
            SubObject::unsigned32("Manufacturer status register", Access::Ro, 0).mappable(),
        );
    let history = core::iter::once((
        0,
        SubObject::new("Number of errors", DataType::Unsigned8, Access::Rw)
            .default(Value::Unsigned8(0))
            .limits(Value::Unsigned8(0), Value::Unsigned8(ERROR_HISTORY)),
    ))
    .chain((1..=ERROR_HISTORY).map(|k| {
        (
            k,
            SubObject::unsigned32(format!("Standard error field {k}"), Access::Ro, 0),
        )
    }));
    b = b
        .array(0x1003, "Pre-defined error field", history)
        .var(
            0x1005,
            SubObject::unsigned32("COB-ID SYNC", Access::Rw, 0x80),
        )
        .var(
            0x1006,
            SubObject::unsigned32("Communication cycle period", Access::Rw, 0),
        )
        .var(0x1008, string("Manufacturer device name", DEVICE_NAME))
        .var(
            0x100A,
            string("Manufacturer software version", SOFTWARE_VERSION),
        )
        .var(
            0x100C,
            SubObject::new("Guard time", DataType::Unsigned16, Access::Rw)
                .default(Value::Unsigned16(0)),
        )
        .var(
            0x100D,
            SubObject::new("Life time factor", DataType::Unsigned8, Access::Rw)
                .default(Value::Unsigned8(0)),
        )
        .var(
            0x1014,
            SubObject::new("COB-ID EMCY", DataType::Unsigned32, Access::Rw)
                .default_node_id_plus(Value::Unsigned32(0x80)),
        )
        .array(
            0x1016,
            "Consumer heartbeat time",
            [
                // Manual 1016H: sub-index 0 "Numero di sottoindici", access RO.
                (
                    0,
                    SubObject::new(
                        "Highest sub-index supported",
                        DataType::Unsigned8,
                        Access::Ro,
                    )
                    .default(Value::Unsigned8(1)),
                ),
                (
                    1,
                    SubObject::unsigned32("Consumer heartbeat time", Access::Rw, 0),
                ),
            ],
        )
        .var(
            0x1017,
            SubObject::new("Producer heartbeat time", DataType::Unsigned16, Access::Rw)
                .default(Value::Unsigned16(0)),
        )
        .record(
            0x1018,
            "Identity object",
            [
                (1, SubObject::unsigned32("Vendor-ID", Access::Ro, VENDOR_ID)),
                (
                    2,
                    SubObject::unsigned32("Product code", Access::Ro, PRODUCT_CODE),
                ),
                (
                    3,
                    SubObject::unsigned32("Revision number", Access::Ro, REVISION),
                ),
                (4, SubObject::unsigned32("Serial number", Access::Ro, 0)),
            ],
        );
    let module = |k: u8, code: u16| {
        (
            k,
            SubObject::new(format!("Module {k}"), DataType::Unsigned16, Access::Ro)
                .default(Value::Unsigned16(code)),
        )
    };
    b = if island.modules().is_empty() {
        b.array(
            0x1027,
            "Module list",
            (1..=MAX_MODULES as u8).map(|k| module(k, 0)),
        )
    } else {
        b.array(
            0x1027,
            "Module list",
            island
                .modules()
                .iter()
                .zip(1u8..)
                .map(|(m, k)| module(k, m.spec.code)),
        )
    };
    b = b
        .array(
            0x1029,
            "Error behavior",
            [(
                1,
                SubObject::new("Communication error", DataType::Unsigned8, Access::Rw)
                    .default(Value::Unsigned8(0)),
            )],
        )
        .record(
            0x1200,
            "1st server SDO parameter",
            [
                (
                    1,
                    SubObject::new("COB-ID client to server", DataType::Unsigned32, Access::Ro)
                        .default_node_id_plus(Value::Unsigned32(0x600)),
                ),
                (
                    2,
                    SubObject::new("COB-ID server to client", DataType::Unsigned32, Access::Ro)
                        .default_node_id_plus(Value::Unsigned32(0x580)),
                ),
            ],
        )
        .record(
            0x1201,
            "2nd server SDO parameter",
            [
                (
                    1,
                    SubObject::unsigned32("COB-ID client to server", Access::Rw, 1 << 31),
                ),
                (
                    2,
                    SubObject::unsigned32("COB-ID server to client", Access::Rw, 1 << 31),
                ),
                (
                    3,
                    SubObject::new("Node-ID of the SDO client", DataType::Unsigned8, Access::Rw)
                        .default(Value::Unsigned8(0)),
                ),
            ],
        );
    pdo_objects(b, island)
}

/// The whole dictionary description of a coupler carrying `island`.
pub fn description(island: &Island) -> Result<OdDescription, OdBuildError> {
    // The communication objects whose values the manual restricts go through the
    // coupler's `ManualLimits` hooks.
    let b = communication_objects(OdBuilder::new(), island)
        .hook(0x1005..=0x1016)
        .hook(0x1029..=0x1029)
        .hook(0x1201..=0x1201)
        .hook(0x1400..=0x1BFF);
    cia401::add_objects(b, &island.layout()).build()
}

/// The description of one island's dictionary, to be shared by every coupler carrying the
/// same modules in the same order (see [`crate::coupler::Tm3Coupler::with_description`]).
///
/// The dictionary follows from the modules alone: the node-ID only enters through
/// `$NODEID` defaults, which each coupler's values resolve, and whether a module is
/// optional changes its status, not the objects.
#[derive(Debug, Clone)]
pub struct IslandDescription {
    modules: Vec<ModuleSpec>,
    desc: Arc<OdDescription>,
}

impl IslandDescription {
    /// Builds the description of `island`.
    pub fn new(island: &Island) -> Result<Self, OdBuildError> {
        Ok(IslandDescription {
            modules: Self::specs(island).collect(),
            desc: Arc::new(description(island)?),
        })
    }

    fn specs(island: &Island) -> impl Iterator<Item = ModuleSpec> + '_ {
        island.modules().iter().map(|m| *m.spec)
    }

    /// Whether this is the description of `island`'s dictionary.
    pub fn fits(&self, island: &Island) -> bool {
        Self::specs(island).eq(self.modules.iter().copied())
    }

    /// The description.
    pub fn description(&self) -> &Arc<OdDescription> {
        &self.desc
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::island::ModuleSlot;

    #[test]
    fn a_description_fits_the_same_modules_whichever_are_optional() {
        let island = Island::from_references(&["TM3DI16", "TM3AI4"]).unwrap();
        let shared = IslandDescription::new(&island).unwrap();
        assert!(shared.fits(&island));
        let mut slots = island.modules().to_vec();
        slots[1] = ModuleSlot {
            optional: true,
            ..slots[1]
        };
        assert!(shared.fits(&Island::new(slots).unwrap()));
        for other in [
            &["TM3AI4", "TM3DI16"][..],
            &["TM3DI16"],
            &["TM3DI16", "TM3AI4", "TM3DQ8R"],
            &[],
        ] {
            assert!(
                !shared.fits(&Island::from_references(other).unwrap()),
                "{other:?}"
            );
        }
    }
}
