//! The servo's dictionary: the CiA 301 communication objects, the CiA 402 objects of
//! [`cantwin_cia402::dictionary`], and the PDOs with the pre-defined mappings of CiA 402-3
//! (the PDO set of a servo drive):
//!
//! | PDO | COB-ID | transmission type | mapping |
//! |---|---|---|---|
//! | RPDO1 | 0x200 + node-ID | 255 | 0x6040 controlword |
//! | RPDO2 | 0x300 + node-ID | 255 | 0x6040, 0x6060 modes of operation |
//! | RPDO3 | 0x400 + node-ID | 255 | 0x6040, 0x607A target position |
//! | RPDO4 | 0x500 + node-ID | 255 | 0x6040, 0x60FF target velocity |
//! | TPDO1 | 0x180 + node-ID | 255 | 0x6041 statusword |
//! | TPDO2 | 0x280 + node-ID | 255 | 0x6041, 0x6061 modes of operation display |
//! | TPDO3 | 0x380 + node-ID | 1 | 0x6041, 0x6064 position actual value |
//! | TPDO4 | 0x480 + node-ID | 1 | 0x6041, 0x606C velocity actual value |
//!
//! TPDO1 and TPDO2 are sent when the statusword or the mode displayed changes; TPDO3 and
//! TPDO4, whose actual values change every loop cycle, at every SYNC.
//!
//! Every CiA 402 object (0x6000–0x67FF) is hooked: the drive learns of each write, by SDO
//! or PDO, through the device's hooks.

use std::ops::RangeInclusive;
use std::sync::Arc;

use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{ObjectCode, OdBuildError, OdBuilder, OdDescription};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_cia402::dictionary::{ServoObjects, servo_objects};
use cantwin_cia402::{index, objects};

/// The objects the drive is told of when they are written.
pub const HOOKED: RangeInclusive<u16> = 0x6000..=0x67FF;

/// A mapping entry: `index << 16 | sub << 8 | bits`.
const fn map(index: u16, sub: u8, bits: u8) -> u32 {
    (index as u32) << 16 | (sub as u32) << 8 | bits as u32
}

/// The pre-defined PDOs of the [module table](self).
pub fn pdos() -> PdoObjects {
    let cw = map(index::CONTROLWORD, 0, 16);
    let sw = map(index::STATUSWORD, 0, 16);
    PdoObjects::new(4, 4)
        .rpdo(0, 255, &[cw])
        .rpdo(1, 255, &[cw, map(index::MODES_OF_OPERATION, 0, 8)])
        .rpdo(2, 255, &[cw, map(index::TARGET_POSITION, 0, 32)])
        .rpdo(3, 255, &[cw, map(index::TARGET_VELOCITY, 0, 32)])
        .tpdo(0, 255, &[sw])
        .tpdo(1, 255, &[sw, map(index::MODES_OF_OPERATION_DISPLAY, 0, 8)])
        .tpdo(2, 1, &[sw, map(index::POSITION_ACTUAL_VALUE, 0, 32)])
        .tpdo(3, 1, &[sw, map(index::VELOCITY_ACTUAL_VALUE, 0, 32)])
}

/// The 0x1000 device type of a servo drive: profile 402, additional information 0x0002
/// (servo drive, CiA 402-2 object 1000h).
pub const DEVICE_TYPE: u32 = 0x0002_0000 | index::PROFILE_NUMBER;

/// The built-in dictionary of a servo drive with `objects`, producing heartbeats every
/// `heartbeat_ms` (0x1017's default; 0: none).
pub fn description(
    objects: &ServoObjects,
    heartbeat_ms: u16,
) -> Result<OdDescription, OdBuildError> {
    let options = Cia301Options {
        device_type: DEVICE_TYPE,
        device_name: "cantwin servo".into(),
        heartbeat_consumers: 1,
        heartbeat_time: heartbeat_ms,
        ..Cia301Options::default()
    };
    let b = cia301_defaults(OdBuilder::new(), &options);
    let b = pdos().add_to(b);
    let b = objects::add(b, servo_objects(objects));
    b.hook(HOOKED).build()
}

/// `desc` with the CiA 402 objects hooked: a dictionary read from a vendor's EDS keeps
/// every object as the file gives it.
pub fn hooked(desc: &OdDescription) -> Result<Arc<OdDescription>, OdBuildError> {
    let mut b = OdBuilder::new();
    for o in desc.objects() {
        let subs: Vec<_> = o.subs().map(|(s, sub)| (s, sub.clone())).collect();
        b = match o.code() {
            ObjectCode::Array => b.array(o.index(), o.name(), subs),
            ObjectCode::Record => b.record(o.index(), o.name(), subs),
            code => match subs.into_iter().next() {
                Some((_, sub)) => b.var(o.index(), sub).code(code),
                None => continue,
            },
        };
        b = b.flags(o.flags());
        if o.compact_sub_obj() {
            b = b.compact();
        }
    }
    Ok(Arc::new(b.hook(HOOKED).build()?))
}
