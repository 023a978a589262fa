//! PDO mapping entries and packing plans (CiA 301 §7.4.8.2, §7.5.2.36, §7.5.2.38).
//!
//! A mapping entry is `index << 16 | sub-index << 8 | length in bits`. When a mapping is
//! enabled (sub-index 0 set to the number of entries) it is checked and turned into a
//! [`Plan`]: the located value of each entry and its bit length, so that packing and
//! unpacking a PDO reads the dictionary's value storage directly, without a lookup by index
//! and without allocating.
//!
//! Bits are packed little-endian (CiA 301 §7.1.2): the first mapped object starts at bit 0 of
//! byte 0, the next one at the bit after the last bit of the previous, whatever their lengths.

use crate::abort::AbortCode;
use crate::od::{Access, DataType, EntryId, ObjectDictionary, OdDescription, OdHooks};

/// The longest a PDO's data can be: 8 bytes (CiA 301 §7.2.2.1).
pub const MAX_PDO_BITS: u32 = 64;

/// The most entries a mapping object may hold (sub-indices 1..=0x40, CiA 301 §7.5.2.36).
pub const MAX_ENTRIES: u8 = 64;

/// A decoded mapping entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MapEntry {
    /// Index of the mapped object (0x0001..=0x0007 for a dummy entry).
    pub index: u16,
    /// Sub-index of the mapped object.
    pub sub: u8,
    /// Length in bits.
    pub bits: u8,
}

impl MapEntry {
    /// Decodes the UNSIGNED32 value of a mapping object's sub-index 1..=64.
    pub const fn from_u32(v: u32) -> Self {
        MapEntry {
            index: (v >> 16) as u16,
            sub: (v >> 8) as u8,
            bits: v as u8,
        }
    }

    /// The UNSIGNED32 value a mapping object stores for this entry.
    pub const fn to_u32(self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | self.bits as u32
    }

    /// Whether it is a dummy entry: an index of a basic data type BOOLEAN..UNSIGNED32
    /// (0x0001..=0x0007), which reserves bits of an RPDO without storing them
    /// (CiA 301 §7.4.8.2).
    pub const fn is_dummy(self) -> bool {
        self.index >= 0x0001 && self.index <= 0x0007
    }
}

/// Which way a PDO goes, from the device's point of view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Receive PDO: the bus writes mapped objects.
    Rx,
    /// Transmit PDO: mapped objects are read and sent.
    Tx,
}

/// One step of a [`Plan`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Step {
    /// The value, or `None` for a dummy entry.
    target: Option<EntryId>,
    /// Length in bits (1..=64).
    bits: u8,
    /// The mapped object's size in bytes (0 for a dummy entry).
    size: u8,
    /// The object is served by the device's hooks.
    hooked: bool,
    /// A write of it needs the dictionary's value check (BOOLEAN, limits).
    checked: bool,
    /// Index and sub-index, for the hooks.
    index: u16,
    sub: u8,
}

/// Why an RPDO's data were not applied: the first mapped entry refused, with the abort
/// code an SDO download of the same bytes would get.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Refusal {
    /// Index of the refused entry's object.
    pub index: u16,
    /// Its sub-index.
    pub sub: u8,
    /// The refusal.
    pub code: AbortCode,
}

/// A checked mapping, ready to pack a TPDO or unpack an RPDO.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Plan {
    steps: Vec<Step>,
    bits: u32,
    /// Some entry is served by the device's hooks.
    any_hooked: bool,
    /// Unpacking needs more than copying bits into storage: a hooked or value-checked
    /// entry, or two entries of one object.
    screened: bool,
}

impl Plan {
    /// Total mapped length in bits.
    pub fn bits(&self) -> u32 {
        self.bits
    }

    /// The PDO's length in bytes: the mapped bits rounded up.
    pub fn len(&self) -> usize {
        self.bits.div_ceil(8) as usize
    }

    /// Whether nothing is mapped.
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// Whether an entry maps this value.
    pub(crate) fn maps(&self, id: EntryId) -> bool {
        self.steps.iter().any(|s| s.target == Some(id))
    }

    /// Checks the mapping entries and builds the plan: every entry with
    /// [`check_entry`], and their total length against 64 bits (0x06040042).
    pub fn build(
        desc: &OdDescription,
        dir: Direction,
        dummy_mapping: bool,
        entries: impl IntoIterator<Item = MapEntry>,
    ) -> Result<Plan, AbortCode> {
        let mut plan = Plan::default();
        for e in entries {
            let target = check_entry(desc, dir, dummy_mapping, e)?;
            plan.bits += u32::from(e.bits);
            if plan.bits > MAX_PDO_BITS {
                return Err(AbortCode::PDO_LENGTH_EXCEEDED);
            }
            let (size, hooked, checked) = match target {
                Some(id) => {
                    let d = desc.sub_object(id);
                    let checked = d.data_type == DataType::Boolean
                        || d.low_limit.is_some()
                        || d.high_limit.is_some();
                    let size = d.data_type.fixed_size().unwrap_or(0) as u8;
                    (size, desc.is_hooked(e.index), checked)
                }
                None => (0, false, false),
            };
            let repeated = target.is_some() && plan.maps_opt(target);
            plan.any_hooked |= hooked;
            plan.screened |= hooked || checked || repeated;
            plan.steps.push(Step {
                target,
                bits: e.bits,
                size,
                hooked,
                checked,
                index: e.index,
                sub: e.sub,
            });
        }
        Ok(plan)
    }

    fn maps_opt(&self, target: Option<EntryId>) -> bool {
        self.steps.iter().any(|s| s.target == target)
    }

    /// Reads the mapped values and packs them into PDO data (the first [`Plan::len`]
    /// bytes are meaningful, the rest are zero). Objects the device's hooks serve are read
    /// through [`OdHooks::read`], so a value held by the device's model is sent as it is
    /// now; a hook that declines or fails leaves the stored value.
    #[inline]
    pub fn pack<H: OdHooks + ?Sized>(&self, od: &ObjectDictionary, hooks: &mut H) -> [u8; 8] {
        let mut acc = 0u64;
        let mut offset = 0u32;
        if !self.any_hooked {
            for s in &self.steps {
                if let Some(id) = s.target {
                    acc |= (le_u64(od.raw(id)) & mask(s.bits)) << offset;
                }
                offset += u32::from(s.bits);
            }
            return acc.to_le_bytes();
        }
        for s in &self.steps {
            if let Some(id) = s.target {
                acc |= (current(s, id, od, hooks) & mask(s.bits)) << offset;
            }
            offset += u32::from(s.bits);
        }
        acc.to_le_bytes()
    }

    /// Applies PDO data to the mapped objects. `data` must hold at least [`Plan::len`]
    /// bytes; bytes beyond are ignored. An entry shorter than its object replaces the
    /// object's low bits and keeps the others.
    ///
    /// Every entry is checked first, as an expedited SDO download of the bytes it would
    /// write (the dictionary's value checks, then [`OdHooks::validate`] for hooked
    /// objects); if one refuses, nothing is written and the first refusal is returned.
    /// Then each entry is written ([`OdHooks::write`] for hooked application objects,
    /// storage otherwise) and, in mapping order, [`OdHooks::written`] is called for the
    /// hooked ones. A refusal by [`OdHooks::write`] itself comes after the checks, so the
    /// other entries are still written (devices refuse in `validate`); the first such
    /// refusal is returned and its entry gets no `written`.
    pub fn unpack<H: OdHooks + ?Sized>(
        &self,
        data: &[u8],
        od: &mut ObjectDictionary,
        hooks: &mut H,
    ) -> Result<(), Refusal> {
        let acc = le_u64(data);
        if !self.screened {
            // Plain stored values, each mapped once: nothing can refuse.
            let mut offset = 0u32;
            for s in &self.steps {
                if let Some(id) = s.target {
                    let m = mask(s.bits);
                    let raw = od.raw(id);
                    let size = raw.len().min(8);
                    let new = (le_u64(raw) & !m) | ((acc >> offset) & m);
                    // The plan only holds fixed-size values, so the length always matches
                    // and `set_raw` cannot refuse it.
                    let _ = od.set_raw(id, &new.to_le_bytes()[..size]);
                }
                offset += u32::from(s.bits);
            }
            return Ok(());
        }
        // The value each entry writes, checked before anything is written.
        let mut values = [0u64; MAX_ENTRIES as usize];
        let mut offset = 0u32;
        for (k, s) in self.steps.iter().enumerate() {
            if let Some(id) = s.target {
                let m = mask(s.bits);
                let old = if m & mask(s.size * 8) == mask(s.size * 8) {
                    0
                } else if let Some(j) = self.steps[..k].iter().rposition(|p| p.target == s.target) {
                    // An earlier entry of this PDO writes the same object: merge into it.
                    values[j]
                } else {
                    current(s, id, od, hooks)
                };
                let new = (old & !m) | ((acc >> offset) & m);
                values[k] = new;
                let bytes = new.to_le_bytes();
                let bytes = &bytes[..usize::from(s.size)];
                let refused = |code| Refusal {
                    index: s.index,
                    sub: s.sub,
                    code,
                };
                if s.checked {
                    od.check_download(id, bytes).map_err(refused)?;
                }
                if s.hooked {
                    hooks.validate(od, s.index, s.sub, bytes).map_err(refused)?;
                }
            }
            offset += u32::from(s.bits);
        }
        let mut first = Ok(());
        let mut taken = [true; MAX_ENTRIES as usize];
        for (k, s) in self.steps.iter().enumerate() {
            let Some(id) = s.target else { continue };
            let bytes = values[k].to_le_bytes();
            let bytes = &bytes[..usize::from(s.size)];
            // Communication objects are the stack's and always stored (see `OdHooks::write`).
            let taken_by_hook = if s.hooked && s.index >= 0x2000 {
                hooks.write(od, s.index, s.sub, bytes)
            } else {
                None
            };
            match taken_by_hook {
                Some(Ok(())) => {}
                Some(Err(code)) => {
                    taken[k] = false;
                    if first.is_ok() {
                        first = Err(Refusal {
                            index: s.index,
                            sub: s.sub,
                            code,
                        });
                    }
                }
                // Fixed-size values of the right length: storing cannot refuse.
                None => {
                    let _ = od.set_raw(id, bytes);
                }
            }
        }
        for (k, s) in self.steps.iter().enumerate() {
            if s.hooked && taken[k] {
                hooks.written(od, s.index, s.sub);
            }
        }
        first
    }
}

/// The value of a mapped object as the device has it: through the read hook for a hooked
/// object (the stored value if the hook declines or fails), from storage otherwise.
#[inline]
fn current<H: OdHooks + ?Sized>(
    s: &Step,
    id: EntryId,
    od: &ObjectDictionary,
    hooks: &mut H,
) -> u64 {
    if s.hooked {
        let mut buf = [0u8; 8];
        let size = usize::from(s.size).min(8);
        if let Some(Ok(info)) = hooks.read(od, s.index, s.sub, 0, &mut buf[..size])
            && info.copied == size
        {
            return u64::from_le_bytes(buf);
        }
    }
    le_u64(od.raw(id))
}

/// Checks one mapping entry (CiA 301 §7.5.2.36 and §7.5.2.38) and locates its value:
///
/// * a dummy entry (0x0001..=0x0007, sub-index 0) only in an RPDO of a device that supports
///   dummy mapping and that type (its DEFTYPE object, where the dictionary holds any), no
///   longer than its type (otherwise 0x06040041);
/// * the object must exist (0x06020000, or 0x06090011 for a missing sub-index);
/// * it must be PDO-mappable, of a fixed-size type, readable for a TPDO and writable for an
///   RPDO (0x06040041), and the length must be 1..=its size in bits (0x06040041).
pub fn check_entry(
    desc: &OdDescription,
    dir: Direction,
    dummy_mapping: bool,
    e: MapEntry,
) -> Result<Option<EntryId>, AbortCode> {
    if e.bits == 0 {
        return Err(AbortCode::NOT_MAPPABLE);
    }
    if e.is_dummy() {
        let size = DataType::from_index(e.index)
            .and_then(DataType::fixed_size)
            .unwrap_or(0);
        // A dictionary that holds DEFTYPE objects for dummies supports exactly those types
        // (CiA 301 §7.4.7.1; CiA 306 §4.5.5 `[DummyUsage]`); one without any supports all.
        let deftype = |i: u16| {
            desc.object(i)
                .is_some_and(|o| o.code() == crate::od::ObjectCode::DefType)
        };
        let supported = deftype(e.index) || !(0x0001..=0x0007).any(deftype);
        if dir == Direction::Tx
            || !dummy_mapping
            || !supported
            || e.sub != 0
            || usize::from(e.bits) > size * 8
        {
            return Err(AbortCode::NOT_MAPPABLE);
        }
        return Ok(None);
    }
    let id = desc.locate(e.index, e.sub)?;
    let d = desc.sub_object(id);
    let Some(size) = d.data_type.fixed_size() else {
        return Err(AbortCode::NOT_MAPPABLE);
    };
    let access_ok = match dir {
        Direction::Tx => d.access.readable(),
        Direction::Rx => matches!(d.access, Access::Rw | Access::Wo | Access::Rww),
    };
    if !d.pdo_mappable || !access_ok || usize::from(e.bits) > size * 8 {
        return Err(AbortCode::NOT_MAPPABLE);
    }
    Ok(Some(id))
}

#[inline]
fn mask(bits: u8) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

#[inline]
fn le_u64(raw: &[u8]) -> u64 {
    let mut b = [0u8; 8];
    let n = raw.len().min(8);
    b[..n].copy_from_slice(&raw[..n]);
    u64::from_le_bytes(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::NoHooks;
    use crate::od::{OdBuilder, SubObject, Value};
    use std::sync::Arc;

    fn od() -> ObjectDictionary {
        let desc = OdBuilder::new()
            .var(
                0x2000,
                SubObject::new("a", DataType::Unsigned8, Access::Rw).mappable(),
            )
            .var(
                0x2001,
                SubObject::new("b", DataType::Unsigned16, Access::Rw).mappable(),
            )
            .var(
                0x2002,
                SubObject::new("c", DataType::Unsigned32, Access::Ro).mappable(),
            )
            .var(
                0x2003,
                SubObject::new("not mappable", DataType::Unsigned8, Access::Rw),
            )
            .var(
                0x2004,
                SubObject::new("s", DataType::VisibleString, Access::Rw).mappable(),
            )
            .build()
            .unwrap();
        ObjectDictionary::new(Arc::new(desc), 1)
    }

    fn e(index: u16, sub: u8, bits: u8) -> MapEntry {
        MapEntry { index, sub, bits }
    }

    #[test]
    fn entry_round_trips_through_u32() {
        let v = 0x6000_0108;
        assert_eq!(MapEntry::from_u32(v), e(0x6000, 1, 8));
        assert_eq!(MapEntry::from_u32(v).to_u32(), v);
    }

    #[test]
    fn checks_follow_cia301_abort_codes() {
        let od = od();
        let d = od.description();
        let chk = |dir, x| check_entry(d, dir, true, x);
        assert_eq!(
            chk(Direction::Tx, e(0x3000, 0, 8)),
            Err(AbortCode::NO_OBJECT)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x2000, 1, 8)),
            Err(AbortCode::NO_SUB_INDEX)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x2003, 0, 8)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x2004, 0, 8)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x2000, 0, 9)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x2000, 0, 0)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        // A read-only object can be sent but not received.
        assert!(chk(Direction::Tx, e(0x2002, 0, 32)).is_ok());
        assert_eq!(
            chk(Direction::Rx, e(0x2002, 0, 32)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        // Dummy entries: receive only, no longer than their type.
        assert_eq!(chk(Direction::Rx, e(0x0005, 0, 8)), Ok(None));
        assert_eq!(
            chk(Direction::Rx, e(0x0005, 0, 9)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        assert_eq!(
            chk(Direction::Tx, e(0x0005, 0, 8)),
            Err(AbortCode::NOT_MAPPABLE)
        );
        assert_eq!(
            check_entry(d, Direction::Rx, false, e(0x0005, 0, 8)),
            Err(AbortCode::NOT_MAPPABLE)
        );
    }

    #[test]
    fn total_length_above_64_bits_is_refused() {
        let od = od();
        let entries = [e(0x2002, 0, 32), e(0x2002, 0, 32), e(0x2000, 0, 1)];
        assert_eq!(
            Plan::build(od.description(), Direction::Tx, true, entries),
            Err(AbortCode::PDO_LENGTH_EXCEEDED)
        );
    }

    #[test]
    fn bit_granular_packing_is_little_endian() {
        let mut od = od();
        od.set(0x2000, 0, &Value::Unsigned8(0b101)).unwrap();
        od.set(0x2001, 0, &Value::Unsigned16(0xABCD)).unwrap();
        // 3 bits of 0x2000, 16 bits of 0x2001: 0xABCD << 3 | 0b101 = 0x55E6D.
        let plan = Plan::build(
            od.description(),
            Direction::Tx,
            true,
            [e(0x2000, 0, 3), e(0x2001, 0, 16)],
        )
        .unwrap();
        assert_eq!(plan.len(), 3);
        assert_eq!(
            plan.pack(&od, &mut NoHooks),
            [0x6D, 0x5E, 0x05, 0, 0, 0, 0, 0]
        );
    }

    #[test]
    fn unpack_keeps_unmapped_high_bits_and_skips_dummies() {
        let mut od = od();
        od.set(0x2001, 0, &Value::Unsigned16(0xFF00)).unwrap();
        let plan = Plan::build(
            od.description(),
            Direction::Rx,
            true,
            [e(0x0005, 0, 4), e(0x2001, 0, 4), e(0x2000, 0, 8)],
        )
        .unwrap();
        plan.unpack(&[0x7F, 0x12], &mut od, &mut NoHooks).unwrap();
        assert_eq!(od.get(0x2001, 0).unwrap(), Value::Unsigned16(0xFF07));
        assert_eq!(od.get(0x2000, 0).unwrap(), Value::Unsigned8(0x12));
    }
}
