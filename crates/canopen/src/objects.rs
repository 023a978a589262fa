//! The CiA 301 communication objects every device starts from (§7.5.2), with the
//! standard's defaults: [`cia301_defaults`].
//!
//! | index | object | default |
//! |---|---|---|
//! | 0x1000 | device type | [`Cia301Options::device_type`] |
//! | 0x1001 | error register | 0 |
//! | 0x1003 | pre-defined error field, [`Cia301Options::error_history`] entries | empty |
//! | 0x1005 | COB-ID SYNC | 0x80 |
//! | 0x1006 | communication cycle period (µs) | 0 |
//! | 0x1007 | synchronous window length (µs) | 0 |
//! | 0x1008/0x1009/0x100A | manufacturer device name, hardware and software version | options |
//! | 0x100C/0x100D | guard time (ms), life time factor | 0, 0 |
//! | 0x1010/0x1011 | store / restore parameters, sub-indices 1..=4 | 1 (on command) |
//! | 0x1012 | COB-ID TIME | 0x100 |
//! | 0x1014 | COB-ID EMCY | 0x80 + node-ID |
//! | 0x1015 | inhibit time EMCY (100 µs) | 0 |
//! | 0x1016 | consumer heartbeat time, [`Cia301Options::heartbeat_consumers`] entries | 0 |
//! | 0x1017 | producer heartbeat time (ms) | [`Cia301Options::heartbeat_time`] |
//! | 0x1018 | identity | options |
//! | 0x1019 | synchronous counter overflow value | 0 |
//! | 0x1028 | emergency consumer, [`Cia301Options::emcy_consumers`] entries | 0x80000000 |
//! | 0x1029 | error behaviour, sub 1 communication error | 0 (pre-operational) |
//! | 0x1200 | SDO server 1: 0x600 + node-ID / 0x580 + node-ID | `ro` |
//! | 0x1201.. | further SDO servers, [`Cia301Options::extra_sdo_servers`] | not valid |
//!
//! PDO objects come from [`crate::pdo::PdoObjects`].

use crate::od::{Access, DataType, OdBuilder, SubObject, Value};

/// What [`cia301_defaults`] puts into the dictionary.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cia301Options {
    /// 0x1000: device profile number (bits 0..15) and additional information.
    pub device_type: u32,
    /// 0x1018 sub 1.
    pub vendor_id: u32,
    /// 0x1018 sub 2.
    pub product_code: u32,
    /// 0x1018 sub 3.
    pub revision: u32,
    /// 0x1018 sub 4.
    pub serial: u32,
    /// 0x1008.
    pub device_name: String,
    /// 0x1009.
    pub hardware_version: String,
    /// 0x100A.
    pub software_version: String,
    /// Entries of 0x1003 (0 leaves the object out; CiA 301 allows up to 254).
    pub error_history: u8,
    /// Entries of 0x1016 (0 leaves the object out).
    pub heartbeat_consumers: u8,
    /// Entries of 0x1028 (0 leaves the object out).
    pub emcy_consumers: u8,
    /// SDO servers besides the default one (0x1201..).
    pub extra_sdo_servers: u8,
    /// Whether 0x1010/0x1011 exist (the device has parameter storage).
    pub storage: bool,
    /// The default of 0x1017, producer heartbeat time in ms.
    pub heartbeat_time: u16,
}

impl Default for Cia301Options {
    fn default() -> Self {
        Cia301Options {
            device_type: 0,
            vendor_id: 0,
            product_code: 0,
            revision: 0,
            serial: 0,
            device_name: "cantwin".into(),
            hardware_version: "1.0".into(),
            software_version: env!("CARGO_PKG_VERSION").into(),
            error_history: 8,
            heartbeat_consumers: 4,
            emcy_consumers: 0,
            extra_sdo_servers: 0,
            storage: true,
            heartbeat_time: 0,
        }
    }
}

fn u32_rw(name: &str, v: u32) -> SubObject {
    SubObject::unsigned32(name, Access::Rw, v)
}

fn u32_ro(name: &str, v: u32) -> SubObject {
    SubObject::unsigned32(name, Access::Ro, v)
}

/// Adds the CiA 301 communication objects (see the [module documentation](self)) to
/// `builder`.
pub fn cia301_defaults(builder: OdBuilder, o: &Cia301Options) -> OdBuilder {
    let mut b = builder
        .var(0x1000, u32_ro("Device type", o.device_type))
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro).mappable(),
        );
    if o.error_history > 0 {
        let mut subs = vec![(
            0,
            SubObject::new("Number of errors", DataType::Unsigned8, Access::Rw)
                .default(Value::Unsigned8(0)),
        )];
        subs.extend((1..=o.error_history).map(|k| {
            (
                k,
                SubObject::new(
                    format!("Standard error field {k}"),
                    DataType::Unsigned32,
                    Access::Ro,
                ),
            )
        }));
        b = b.array(0x1003, "Pre-defined error field", subs);
    }
    b = b
        .var(0x1005, u32_rw("COB-ID SYNC", 0x80))
        .var(0x1006, u32_rw("Communication cycle period", 0))
        .var(0x1007, u32_rw("Synchronous window length", 0))
        .var(
            0x1008,
            SubObject::const_string("Manufacturer device name", &o.device_name),
        )
        .var(
            0x1009,
            SubObject::const_string("Manufacturer hardware version", &o.hardware_version),
        )
        .var(
            0x100A,
            SubObject::const_string("Manufacturer software version", &o.software_version),
        )
        .var(
            0x100C,
            SubObject::new("Guard time", DataType::Unsigned16, Access::Rw),
        )
        .var(
            0x100D,
            SubObject::new("Life time factor", DataType::Unsigned8, Access::Rw),
        );
    if o.storage {
        let names = [
            "all parameters",
            "communication parameters",
            "application parameters",
            "manufacturer defined parameters",
        ];
        // Bit 0 = 1: the device saves parameters on command (§7.5.2.10, table 58).
        b = b
            .array(
                0x1010,
                "Store parameters",
                (1..=4u8).map(|k| (k, u32_rw(&format!("Save {}", names[usize::from(k - 1)]), 1))),
            )
            .array(
                0x1011,
                "Restore default parameters",
                (1..=4u8).map(|k| {
                    (
                        k,
                        u32_rw(&format!("Restore {}", names[usize::from(k - 1)]), 1),
                    )
                }),
            );
    }
    b = b
        .var(0x1012, u32_rw("COB-ID time stamp object", 0x100))
        .var(
            0x1014,
            SubObject::new("COB-ID EMCY", DataType::Unsigned32, Access::Rw)
                .default_node_id_plus(Value::Unsigned32(0x80)),
        )
        .var(
            0x1015,
            SubObject::new("Inhibit time EMCY", DataType::Unsigned16, Access::Rw),
        );
    if o.heartbeat_consumers > 0 {
        b = b.array_of(
            0x1016,
            "Consumer heartbeat time",
            o.heartbeat_consumers,
            u32_rw("Consumer heartbeat time", 0),
        );
    }
    b = b
        .var(
            0x1017,
            SubObject::new("Producer heartbeat time", DataType::Unsigned16, Access::Rw)
                .default(Value::Unsigned16(o.heartbeat_time)),
        )
        .record(
            0x1018,
            "Identity object",
            [
                (1, u32_ro("Vendor-ID", o.vendor_id)),
                (2, u32_ro("Product code", o.product_code)),
                (3, u32_ro("Revision number", o.revision)),
                (4, u32_ro("Serial number", o.serial)),
            ],
        )
        .var(
            0x1019,
            SubObject::new(
                "Synchronous counter overflow value",
                DataType::Unsigned8,
                Access::Rw,
            ),
        );
    if o.emcy_consumers > 0 {
        b = b.array_of(
            0x1028,
            "Emergency consumer object",
            o.emcy_consumers,
            u32_rw("Emergency consumer", 0x8000_0000),
        );
    }
    b = b
        .array(
            0x1029,
            "Error behavior object",
            [(
                1,
                SubObject::new("Communication error", DataType::Unsigned8, Access::Rw),
            )],
        )
        .record(
            0x1200,
            "SDO server parameter",
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
        );
    for k in 1..=u16::from(o.extra_sdo_servers.min(127)) {
        b = b.record(
            0x1200 + k,
            format!("SDO server parameter {}", k + 1),
            [
                (1, u32_rw("COB-ID client to server", 0x8000_0000)),
                (2, u32_rw("COB-ID server to client", 0x8000_0000)),
                (
                    3,
                    SubObject::new("Node-ID of the SDO client", DataType::Unsigned8, Access::Rw),
                ),
            ],
        );
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::ObjectDictionary;
    use std::sync::Arc;

    #[test]
    fn defaults_build_and_follow_the_node_id() {
        let desc = cia301_defaults(
            OdBuilder::new(),
            &Cia301Options {
                emcy_consumers: 2,
                extra_sdo_servers: 1,
                ..Cia301Options::default()
            },
        )
        .build()
        .unwrap();
        let od = ObjectDictionary::new(Arc::new(desc), 0x22);
        assert_eq!(od.get(0x1014, 0).unwrap(), Value::Unsigned32(0xA2));
        assert_eq!(od.get(0x1200, 1).unwrap(), Value::Unsigned32(0x622));
        assert_eq!(od.get(0x1200, 2).unwrap(), Value::Unsigned32(0x5A2));
        assert_eq!(od.get(0x1005, 0).unwrap(), Value::Unsigned32(0x80));
        assert_eq!(od.get(0x1010, 1).unwrap(), Value::Unsigned32(1));
        assert_eq!(od.get(0x1016, 0).unwrap(), Value::Unsigned8(4));
        assert_eq!(od.get(0x1028, 2).unwrap(), Value::Unsigned32(0x8000_0000));
        assert_eq!(od.get(0x1201, 0).unwrap(), Value::Unsigned8(3));
        assert_eq!(od.get(0x1003, 0).unwrap(), Value::Unsigned8(0));
    }
}
