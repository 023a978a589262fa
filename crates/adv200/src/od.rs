//! The card's object dictionary for each CANopen personality (§1.1.5, chapter 2).
//!
//! Exactly the objects of table 1.5.1: no 0x1003 error history, no TIME objects
//! (0x1012/0x1013, §1.1 item 9), one default SDO server without 0x1200 (§1.1.8), four RPDOs
//! whose communication record has sub-indices 1–2 (§1.1.6: sub 0 = 2; no event timer) and four
//! TPDOs with sub-indices 1–3 (§1.1.7: sub 0 = 3; inhibit time, no event timer), four mapping
//! entries each (a PDO carries at most 4 words), RPDO and TPDO transmission type 1
//! (synchronous when the master says nothing). Guard time 60 ms and life time factor 3 are
//! the defaults of §1.1.3. 0x1005 has bit 31 set as §1.1.9 prints it. TPDO COB-IDs have bit
//! 30 set: no remote request (§1.1.7 says RTR is not supported); clearing it, and
//! transmission types other than 1, 254 and 255, abort 0x06090030 ([`crate::station`]).
//! 0x1008 is as long as one expedited upload on the expedited-only card
//! ([`DEVICE_NAME_EXPEDITED`]).
//!
//! Every drive parameter PAR is the ARRAY 0x2000 + PAR with its value at sub-index 1 (§1.4),
//! served by the drive through the dictionary's hooks ([`crate::station`]); the dictionary
//! stores no parameter value. A channel the Process Data Channel placed has its `mon` typed
//! as wide as the channel, so that its PDO mapping, its SDO upload and the EDS agree.
//! DS402 adds 0x6040–0x6061 of chapter 2 and maps 0x6040/0x6042 into RPDO1 and 0x6041/0x6044
//! into TPDO1.

use cantwin_canopen::od::{
    Access, DataType, OdBuildError, OdBuilder, OdDescription, SubObject, Value,
};
use std::sync::{Arc, Mutex, PoisonError, Weak};

use cantwin_cia402::objects as cia402;

use crate::params::{ParamAccess, catalog, par};
use crate::pdc::{Dir, Pdc};

/// Which CANopen profile the card runs (PAR 4000).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Personality {
    /// Plain CiA 301 with the Process Data Channel.
    CanOpen,
    /// CiA 402 velocity mode.
    Ds402,
}

/// 0x1018 sub 1 by default: the manual gives no vendor-ID and none could be sourced from
/// public vendor-ID lists or Gefran EDS files, so the twin says 0 unless its configuration
/// gives one ([`CardInfo::vendor_id`]; the scenario option `vendor_id`).
pub const VENDOR_ID: u32 = 0x0000_0000;

/// 0x1008 with the SDO limit lifted: the product's name.
pub const DEVICE_NAME: &str = "ADV200";

/// 0x1008 on the card as shipped (§1.1 item 11: expedited transfers only, at most 4 data
/// bytes). Table 1.1.5 lists 0x1008 as readable, and an object of more than 4 bytes could
/// only be read segmented, which the card refuses: so the card's name is one that an
/// expedited upload carries, the product name cut to 4 bytes. The EDS states it as the
/// object's default, so its length is the one an upload returns.
pub const DEVICE_NAME_EXPEDITED: &str = "ADV2";

/// What a card's dictionary holds besides its personality and PDC: the identity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CardInfo {
    /// 0x1018 sub 4.
    pub serial: u32,
    /// 0x1018 sub 1.
    pub vendor_id: u32,
    /// The card answers expedited transfers only: 0x1008 is [`DEVICE_NAME_EXPEDITED`].
    pub expedited_only: bool,
}

impl Default for CardInfo {
    fn default() -> Self {
        CardInfo {
            serial: 0,
            vendor_id: VENDOR_ID,
            expedited_only: true,
        }
    }
}
/// 0x1018 sub 2: product code, the card type code of PAR 534 (4).
pub const PRODUCT_CODE: u32 = 4;

/// Converts `v` to a value of `ty` (wrapping to its width).
pub fn value_of(ty: DataType, v: i64) -> Value {
    match ty {
        DataType::Integer8 => Value::Integer8(v as i8),
        DataType::Integer16 => Value::Integer16(v as i16),
        DataType::Integer32 => Value::Integer32(v as i32),
        DataType::Unsigned8 => Value::Unsigned8(v as u8),
        DataType::Unsigned32 => Value::Unsigned32(v as u32),
        _ => Value::Unsigned16(v as u16),
    }
}

/// The widest and narrowest value of an integer type.
fn type_range(ty: DataType) -> (i64, i64) {
    match ty {
        DataType::Integer16 => (i64::from(i16::MIN), i64::from(i16::MAX)),
        DataType::Integer32 => (i64::from(i32::MIN), i64::from(i32::MAX)),
        DataType::Unsigned32 => (0, i64::from(u32::MAX)),
        _ => (0, i64::from(u16::MAX)),
    }
}

/// Every parameter as 0x2000 + PAR sub 1, served by the drive's hooks. The `mon` of a
/// channel the PDC placed is typed as wide as the channel and carries that type's limits,
/// so that the EDS states what the PDOs carry.
fn param_objects(mut b: OdBuilder, pdc: &Pdc) -> OdBuilder {
    let rww: [u16; 16] = core::array::from_fn(|i| par::m2s_mon(i as u16 + 1));
    let placed: Vec<(u16, DataType)> = pdc
        .m2s
        .items()
        .filter(|i| !i.fill)
        .map(|i| (par::m2s_mon(i.channel), i.data_type()))
        .chain(
            pdc.s2m
                .items()
                .map(|i| (par::s2m_mon(i.channel), i.data_type())),
        )
        .collect();
    for d in catalog() {
        let access = if rww.contains(&d.par) {
            Access::Rww
        } else if d.access == ParamAccess::Ro {
            Access::Ro
        } else {
            Access::Rw
        };
        let mapped = placed.iter().find(|(p, _)| *p == d.par).map(|(_, ty)| *ty);
        let ty = mapped.unwrap_or(d.ty.data_type());
        let mut s = SubObject::new(d.name.clone(), ty, access)
            .default(value_of(ty, d.default))
            .mappable();
        if d.access == ParamAccess::Rw {
            s = s.limits(value_of(ty, d.min), value_of(ty, d.max));
        } else if mapped.is_some() {
            let (lo, hi) = type_range(ty);
            s = s.limits(value_of(ty, lo), value_of(ty, hi));
        }
        b = b.array(d.sdo_index(), d.name.clone(), [(1, s)]);
    }
    b.hook(crate::station::PARAMS_FIRST..=crate::station::PARAMS_LAST)
}

fn pdo_objects(mut b: OdBuilder, rx: &[Vec<u32>], tx: &[Vec<u32>]) -> OdBuilder {
    for n in 0..4u16 {
        let map = rx.get(usize::from(n)).cloned().unwrap_or_default();
        let invalid = if map.is_empty() { 0x8000_0000 } else { 0 };
        b = b.record(
            0x1400 + n,
            format!("Receive PDO{} parameter", n + 1),
            [
                (
                    1,
                    SubObject::new("COB-ID used by PDO", DataType::Unsigned32, Access::Rw)
                        .default_node_id_plus(Value::Unsigned32(
                            invalid | (0x200 + 0x100 * u32::from(n)),
                        )),
                ),
                (
                    2,
                    SubObject::new("Transmission type", DataType::Unsigned8, Access::Rw)
                        .default(Value::Unsigned8(1)),
                ),
            ],
        );
        b = mapping(
            b,
            0x1600 + n,
            format!("Receive PDO{} mapping parameter", n + 1),
            &map,
        );
    }
    for n in 0..4u16 {
        let map = tx.get(usize::from(n)).cloned().unwrap_or_default();
        // §1.1.7: RTR is not supported; CiA 301 says so with bit 30 = 1 (the manual prints
        // 0 for "not supported", the meaning the twin follows).
        let invalid = if map.is_empty() {
            0xC000_0000
        } else {
            0x4000_0000
        };
        b = b.record(
            0x1800 + n,
            format!("Transmit PDO{} parameter", n + 1),
            [
                (
                    1,
                    SubObject::new("COB-ID used by PDO", DataType::Unsigned32, Access::Rw)
                        .default_node_id_plus(Value::Unsigned32(
                            invalid | (0x180 + 0x100 * u32::from(n)),
                        )),
                ),
                (
                    2,
                    SubObject::new("Transmission type", DataType::Unsigned8, Access::Rw)
                        .default(Value::Unsigned8(1)),
                ),
                (
                    3,
                    SubObject::new("Inhibit time", DataType::Unsigned16, Access::Rw)
                        .default(Value::Unsigned16(0)),
                ),
            ],
        );
        b = mapping(
            b,
            0x1A00 + n,
            format!("Transmit PDO{} mapping parameter", n + 1),
            &map,
        );
    }
    b.hook(0x1400..=0x1BFF)
}

fn mapping(b: OdBuilder, index: u16, name: String, map: &[u32]) -> OdBuilder {
    let mut subs = vec![(
        0u8,
        SubObject::new("Number of mapped objects", DataType::Unsigned8, Access::Rw)
            .default(Value::Unsigned8(map.len() as u8)),
    )];
    for k in 1..=4u8 {
        let v = map.get(usize::from(k) - 1).copied().unwrap_or(0);
        subs.push((
            k,
            SubObject::unsigned32(format!("Mapping entry {k}"), Access::Rw, v),
        ));
    }
    b.record(index, name, subs)
}

fn ds402_objects(b: OdBuilder) -> OdBuilder {
    // The PDO-mappable CiA 402 values state their type's whole range as their limits, as
    // the PDC channels do, so that the EDS says what a PDO can carry.
    let var = |name: &str, ty: DataType, access: Access, v: i64| {
        let (lo, hi) = type_range(ty);
        SubObject::new(name, ty, access)
            .default(value_of(ty, v))
            .limits(value_of(ty, lo), value_of(ty, hi))
            .mappable()
    };
    let ramp = |b: OdBuilder, index: u16, name: &str| {
        b.record(
            index,
            name,
            [
                (
                    1,
                    SubObject::unsigned32("Delta speed", Access::Rw, 1000).mappable(),
                ),
                (
                    2,
                    SubObject::new("Delta time", DataType::Unsigned16, Access::Rw)
                        .default(Value::Unsigned16(1))
                        .limits(Value::Unsigned16(1), Value::Unsigned16(u16::MAX))
                        .mappable(),
                ),
            ],
        )
    };
    let b = b
        .var(
            cia402::CONTROLWORD,
            var("Controlword", DataType::Unsigned16, Access::Rw, 0),
        )
        .var(
            cia402::STATUSWORD,
            var("Statusword", DataType::Unsigned16, Access::Ro, 0x0240),
        )
        .var(
            cia402::VL_TARGET_VELOCITY,
            var("vl target velocity", DataType::Integer16, Access::Rw, 0),
        )
        .var(
            cia402::VL_VELOCITY_DEMAND,
            var("vl velocity demand", DataType::Integer16, Access::Ro, 0),
        )
        .var(
            cia402::VL_VELOCITY_ACTUAL_VALUE,
            var("vl control effort", DataType::Integer16, Access::Ro, 0),
        )
        .array(
            cia402::VL_VELOCITY_MIN_MAX_AMOUNT,
            "vl velocity min max amount",
            [
                (
                    1,
                    SubObject::unsigned32("vl velocity min amount", Access::Rw, 0).mappable(),
                ),
                (
                    2,
                    SubObject::unsigned32("vl velocity max amount", Access::Rw, 8000).mappable(),
                ),
            ],
        );
    let b = ramp(
        b,
        cia402::VL_VELOCITY_ACCELERATION,
        "vl velocity acceleration",
    );
    let b = ramp(
        b,
        cia402::VL_VELOCITY_DECELERATION,
        "vl velocity deceleration",
    );
    // The statusword and the vl actual values are the drive's, computed when read; the
    // commands are stored, and the hooks learn of every write.
    b.hook(cia402::CONTROLWORD..=cia402::VL_VELOCITY_DECELERATION)
        .var(
            cia402::MODES_OF_OPERATION,
            SubObject::new("Modes of operation", DataType::Integer8, Access::Rw)
                .default(Value::Integer8(2))
                .limits(Value::Integer8(2), Value::Integer8(2)),
        )
        .var(
            cia402::MODES_OF_OPERATION_DISPLAY,
            SubObject::new("Modes of operation display", DataType::Integer8, Access::Ro)
                .default(Value::Integer8(2))
                .mappable(),
        )
}

/// A PDO mapping entry of sub-index 0 of `index` with `bits`.
const fn entry(index: u16, bits: u32) -> u32 {
    (index as u32) << 16 | bits
}

/// The dictionary of `personality` with the PDC layout `pdc` (CANopen) as the default PDO
/// mappings.
pub fn build(
    personality: Personality,
    pdc: &Pdc,
    info: CardInfo,
) -> Result<OdDescription, OdBuildError> {
    let serial = info.serial;
    let name = if info.expedited_only {
        DEVICE_NAME_EXPEDITED
    } else {
        DEVICE_NAME
    };
    let device_type = match personality {
        Personality::CanOpen => 0,
        Personality::Ds402 => 0x192,
    };
    let mut b = OdBuilder::new()
        .var(
            0x1000,
            SubObject::unsigned32("Device type", Access::Ro, device_type),
        )
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro).mappable(),
        )
        .var(
            0x1002,
            SubObject::unsigned32("Manufacturer status register", Access::Ro, 0),
        )
        .var(
            0x1005,
            SubObject::unsigned32("COB-ID SYNC", Access::Rw, 0x8000_0080),
        )
        .var(
            0x1006,
            SubObject::unsigned32("Communication cycle period", Access::Rw, 0),
        )
        .var(
            0x1008,
            SubObject::const_string("Manufacturer device name", name),
        )
        .var(
            0x1009,
            SubObject::const_string("Manufacturer hardware version", "1.0"),
        )
        .var(
            0x100A,
            SubObject::const_string("Manufacturer software version", "1.0"),
        )
        .var(
            0x100C,
            SubObject::new("Guard time", DataType::Unsigned16, Access::Rw)
                .default(Value::Unsigned16(60)),
        )
        .var(
            0x100D,
            SubObject::new("Life time factor", DataType::Unsigned8, Access::Rw)
                .default(Value::Unsigned8(3)),
        )
        .record(
            0x1010,
            "Store parameters",
            [(
                1,
                SubObject::unsigned32("Save all parameters", Access::Rw, 1),
            )],
        )
        .var(
            0x1014,
            SubObject::new("COB-ID EMCY", DataType::Unsigned32, Access::Rw)
                .default_node_id_plus(Value::Unsigned32(0x80)),
        )
        .array(
            0x1016,
            "Consumer heartbeat time",
            [(
                1,
                SubObject::unsigned32("Consumer heartbeat time", Access::Rw, 0),
            )],
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
                (
                    1,
                    SubObject::unsigned32("Vendor-ID", Access::Ro, info.vendor_id),
                ),
                (
                    2,
                    SubObject::unsigned32("Product code", Access::Ro, PRODUCT_CODE),
                ),
                (
                    3,
                    SubObject::unsigned32("Revision number", Access::Ro, 0x0001_0000),
                ),
                (
                    4,
                    SubObject::unsigned32("Serial number", Access::Ro, serial),
                ),
            ],
        );
    let (rx, tx): (Vec<Vec<u32>>, Vec<Vec<u32>>) = match personality {
        Personality::CanOpen => (
            pdc.m2s
                .pdos
                .iter()
                .map(|p| p.iter().map(|i| i.mapping_entry(Dir::M2S)).collect())
                .collect(),
            pdc.s2m
                .pdos
                .iter()
                .map(|p| p.iter().map(|i| i.mapping_entry(Dir::S2M)).collect())
                .collect(),
        ),
        Personality::Ds402 => (
            vec![vec![
                entry(cia402::CONTROLWORD, 16),
                entry(cia402::VL_TARGET_VELOCITY, 16),
            ]],
            vec![vec![
                entry(cia402::STATUSWORD, 16),
                entry(cia402::VL_VELOCITY_ACTUAL_VALUE, 16),
            ]],
        ),
    };
    b = pdo_objects(b, &rx, &tx);
    b = param_objects(b, pdc);
    if personality == Personality::Ds402 {
        b = ds402_objects(b);
    }
    b.build()
}

/// What a card's dictionary follows from. The node-ID is not part of it: it only enters
/// through `$NODEID` defaults, which each card's values resolve.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Key {
    personality: Personality,
    /// The PDC's default mappings; DS402 has fixed ones and ignores the PDC.
    pdc: Pdc,
    info: CardInfo,
}

/// The descriptions drives built ([`build`]), so that drives of the same personality, PDC
/// layout and serial number share one while any of them uses it: the description, with
/// one object per drive parameter, is most of a drive's memory.
///
/// A drive builds its dictionary at every drive reset from parameters that may have
/// changed, so this keeps descriptions only while a drive uses them.
#[derive(Debug, Default)]
pub struct Descriptions {
    built: Mutex<Vec<(Key, Weak<OdDescription>)>>,
}

impl Descriptions {
    /// None built yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The dictionary of `personality` with the PDC layout `pdc` and identity `info`, the
    /// one a drive already uses if there is one.
    pub fn get(
        &self,
        personality: Personality,
        pdc: &Pdc,
        info: CardInfo,
    ) -> Result<Arc<OdDescription>, OdBuildError> {
        let key = Key {
            personality,
            pdc: match personality {
                Personality::CanOpen => pdc.clone(),
                Personality::Ds402 => Pdc::default(),
            },
            info,
        };
        // A poisoned lock only means another build panicked; the list is still valid.
        let mut built = self.built.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(d) = built
            .iter()
            .find(|(k, _)| *k == key)
            .and_then(|(_, d)| d.upgrade())
        {
            return Ok(d);
        }
        let d = Arc::new(build(personality, &key.pdc, info)?);
        built.retain(|(k, d)| d.strong_count() > 0 && *k != key);
        built.push((key, Arc::downgrade(&d)));
        Ok(d)
    }

    /// How many descriptions drives use.
    pub fn in_use(&self) -> usize {
        let built = self.built.lock().unwrap_or_else(PoisonError::into_inner);
        built.iter().filter(|(_, d)| d.strong_count() > 0).count()
    }
}
