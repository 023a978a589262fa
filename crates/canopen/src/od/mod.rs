//! The object dictionary (CiA 301 §7.4): what a device is.
//!
//! An [`OdDescription`] says which objects exist and what they are (index, sub-index, name,
//! data type, object code, access, PDO mapping, limits, defaults including `$NODEID`-relative
//! ones, object flags): everything CiA 306 EDS/DCF files carry. It is built once with
//! [`OdBuilder`] and shared, behind an `Arc`, by every device of the same kind.
//!
//! An [`ObjectDictionary`] holds one device's values: fixed-size values packed into one byte
//! arena, strings and DOMAINs in their own growable buffers up to a declared maximum.
//! Lookup of an index/sub-index is a binary search over the objects followed by a direct or
//! binary search among the object's sub-indices; nothing on that path allocates.
//!
//! The SDO server sees a device through [`ObjectAccess`]; `ObjectDictionary` implements it
//! with the access, length and limit checks of CiA 301, and [`Hooked`] lets device code
//! ([`OdHooks`]) validate writes, react to them and serve reads dynamically for the index
//! ranges the description marks as hooked.

mod access;
mod types;

pub use access::{Hooked, ObjectAccess, OdHooks, ReadInfo};
pub use types::{DataType, TimeOfDay, Value, ValueError};

use crate::abort::AbortCode;
use core::fmt;
use core::ops::RangeInclusive;
use std::sync::Arc;

/// Access type of a sub-object (CiA 301 §7.4.5, CiA 306 `AccessType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only (`ro`): the device may change it, an SDO write is refused.
    Ro,
    /// Write only (`wo`).
    Wo,
    /// Read and write (`rw`).
    Rw,
    /// Read and write, readable from the bus side of a TPDO (`rwr`, CiA 306).
    Rwr,
    /// Read and write, writable from the bus side of an RPDO (`rww`, CiA 306).
    Rww,
    /// Read only and never changes (`const`).
    Const,
}

impl Access {
    /// Whether an SDO upload may read it.
    pub const fn readable(self) -> bool {
        !matches!(self, Access::Wo)
    }

    /// Whether an SDO download may write it.
    pub const fn writable(self) -> bool {
        matches!(self, Access::Wo | Access::Rw | Access::Rwr | Access::Rww)
    }

    /// The CiA 306 `AccessType` keyword.
    pub const fn eds_name(self) -> &'static str {
        match self {
            Access::Ro => "ro",
            Access::Wo => "wo",
            Access::Rw => "rw",
            Access::Rwr => "rwr",
            Access::Rww => "rww",
            Access::Const => "const",
        }
    }

    /// Parses a CiA 306 `AccessType` keyword (case-insensitive).
    pub fn from_eds_name(name: &str) -> Option<Access> {
        [
            Access::Ro,
            Access::Wo,
            Access::Rw,
            Access::Rwr,
            Access::Rww,
            Access::Const,
        ]
        .into_iter()
        .find(|a| a.eds_name().eq_ignore_ascii_case(name.trim()))
    }
}

impl fmt::Display for Access {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.eds_name())
    }
}

/// Object code (CiA 301 table 42, CiA 306 `ObjectType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ObjectCode {
    /// NULL (0x00): an object with no data fields.
    Null = 0x00,
    /// DOMAIN (0x02): a large variable amount of data.
    Domain = 0x02,
    /// DEFTYPE (0x05): a type definition.
    DefType = 0x05,
    /// DEFSTRUCT (0x06): a record type definition.
    DefStruct = 0x06,
    /// VAR (0x07): a single value.
    Var = 0x07,
    /// ARRAY (0x08): sub-indices 1..n of one data type, sub 0 the highest sub-index.
    Array = 0x08,
    /// RECORD (0x09): sub-indices of different types, sub 0 the highest sub-index.
    Record = 0x09,
}

impl ObjectCode {
    /// The object code with this value.
    pub fn from_u8(v: u8) -> Option<ObjectCode> {
        use ObjectCode::*;
        [Null, Domain, DefType, DefStruct, Var, Array, Record]
            .into_iter()
            .find(|c| *c as u8 == v)
    }
}

/// The description of one sub-object (or of a VAR object, which is its own sub-index 0).
#[derive(Debug, Clone, PartialEq)]
pub struct SubObject {
    /// CiA 306 `ParameterName`.
    pub name: String,
    /// CiA 306 `DataType`.
    pub data_type: DataType,
    /// CiA 306 `AccessType`.
    pub access: Access,
    /// CiA 306 `PDOMapping`: whether it may be mapped into a PDO.
    pub pdo_mappable: bool,
    /// CiA 306 `LowLimit`: downloads below it are aborted with 0x06090032.
    pub low_limit: Option<Value>,
    /// CiA 306 `HighLimit`: downloads above it are aborted with 0x06090031.
    pub high_limit: Option<Value>,
    /// CiA 306 `DefaultValue`; `None` means the type's zero value.
    pub default: Option<Value>,
    /// Whether the default is `$NODEID+default` (added to the node-ID when values are set).
    pub default_node_id_relative: bool,
    /// The largest length in bytes of a string or DOMAIN (`None`: no declared maximum).
    pub max_len: Option<usize>,
}

impl SubObject {
    /// A sub-object with no limits, no PDO mapping and the type's zero value as default.
    pub fn new(name: impl Into<String>, data_type: DataType, access: Access) -> Self {
        SubObject {
            name: name.into(),
            data_type,
            access,
            pdo_mappable: false,
            low_limit: None,
            high_limit: None,
            default: None,
            default_node_id_relative: false,
            max_len: None,
        }
    }

    /// An UNSIGNED32 sub-object with a default, the most common shape of the communication
    /// objects (COB-IDs, identity, mapping entries).
    pub fn unsigned32(name: impl Into<String>, access: Access, default: u32) -> Self {
        SubObject::new(name, DataType::Unsigned32, access).default(Value::Unsigned32(default))
    }

    /// A constant VISIBLE_STRING (device name and versions, 0x1008–0x100A), sized to its text.
    pub fn const_string(name: impl Into<String>, text: &str) -> Self {
        SubObject::new(name, DataType::VisibleString, Access::Const)
            .default(Value::VisibleString(text.into()))
            .max_len(text.len())
    }

    /// Sets the default value.
    pub fn default(mut self, value: Value) -> Self {
        self.default = Some(value);
        self
    }

    /// Sets a `$NODEID+value` default.
    pub fn default_node_id_plus(mut self, value: Value) -> Self {
        self.default = Some(value);
        self.default_node_id_relative = true;
        self
    }

    /// Marks it PDO-mappable.
    pub fn mappable(mut self) -> Self {
        self.pdo_mappable = true;
        self
    }

    /// Sets low and high limits.
    pub fn limits(mut self, low: Value, high: Value) -> Self {
        self.low_limit = Some(low);
        self.high_limit = Some(high);
        self
    }

    /// Sets the largest length of a string or DOMAIN.
    pub fn max_len(mut self, max: usize) -> Self {
        self.max_len = Some(max);
        self
    }

    /// The default value as it applies to a device with this node-ID.
    pub fn default_for(&self, node_id: u8) -> Value {
        let base = self
            .default
            .clone()
            .unwrap_or_else(|| Value::zero(self.data_type));
        if !self.default_node_id_relative {
            return base;
        }
        match base.as_i128() {
            // CiA 306 §4.6.3: the value is the node-ID added to the stated number; it wraps
            // within the type as the device would compute it.
            Some(v) => {
                let sum = v + i128::from(node_id);
                let bytes = sum.to_le_bytes();
                let size = self.data_type.fixed_size().unwrap_or(1);
                Value::from_le_bytes(self.data_type, &bytes[..size]).unwrap_or(base)
            }
            None => base,
        }
    }
}

/// Where a sub-object's value lives in an [`ObjectDictionary`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Slot {
    Fixed { offset: u32, len: u8 },
    Var(u32),
}

#[derive(Debug, Clone)]
struct SubEntry {
    sub: u8,
    desc: SubObject,
    slot: Slot,
}

#[derive(Debug, Clone)]
struct ObjectEntry {
    index: u16,
    name: String,
    code: ObjectCode,
    flags: u32,
    compact: bool,
    hooked: bool,
    first: u32,
    count: u16,
}

/// An identifier of one sub-object within an [`OdDescription`], valid for every
/// [`ObjectDictionary`] built from it. Lets hot paths (PDOs) skip the lookup.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EntryId(u32);

/// One object of a description, for iteration (EDS export, docs, CLI).
#[derive(Debug, Clone, Copy)]
pub struct ObjectInfo<'a> {
    desc: &'a OdDescription,
    entry: &'a ObjectEntry,
}

impl<'a> ObjectInfo<'a> {
    /// The index.
    pub fn index(&self) -> u16 {
        self.entry.index
    }
    /// CiA 306 `ParameterName` of the object.
    pub fn name(&self) -> &'a str {
        &self.entry.name
    }
    /// CiA 306 `ObjectType`.
    pub fn code(&self) -> ObjectCode {
        self.entry.code
    }
    /// CiA 306 `ObjectFlags`.
    pub fn flags(&self) -> u32 {
        self.entry.flags
    }
    /// Whether an EDS should describe it with `CompactSubObj`.
    pub fn compact_sub_obj(&self) -> bool {
        self.entry.compact
    }
    /// Whether device hooks serve it.
    pub fn hooked(&self) -> bool {
        self.entry.hooked
    }
    /// CiA 306 `SubNumber`: the number of sub-objects.
    pub fn sub_number(&self) -> usize {
        usize::from(self.entry.count)
    }
    /// The sub-objects with their sub-indices, in order.
    pub fn subs(&self) -> impl Iterator<Item = (u8, &'a SubObject)> + 'a {
        let first = self.entry.first as usize;
        self.desc.subs[first..first + usize::from(self.entry.count)]
            .iter()
            .map(|s| (s.sub, &s.desc))
    }
}

/// An error in an object dictionary definition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdBuildError {
    /// The index is defined twice.
    #[error("object {0:#06X} is defined twice")]
    Duplicate(u16),
    /// A sub-index is defined twice.
    #[error("sub-index {0:#06X}:{1} is defined twice")]
    DuplicateSub(u16, u8),
    /// A default or limit does not have the sub-object's type.
    #[error("{0:#06X}:{1}: {2} has type {3}, expected {4}")]
    WrongType(u16, u8, &'static str, DataType, DataType),
    /// The default is longer than the declared maximum.
    #[error("{0:#06X}:{1}: the default is longer than the maximum length")]
    DefaultTooLong(u16, u8),
    /// The low limit is above the high limit.
    #[error("{0:#06X}:{1}: the low limit is above the high limit")]
    LimitsInverted(u16, u8),
    /// A `$NODEID` default on a type that is not an integer.
    #[error("{0:#06X}:{1}: a $NODEID default needs an integer type")]
    NodeIdNotInteger(u16, u8),
}

/// Defines objects in code, then [`OdBuilder::build`]s an [`OdDescription`].
///
/// ```
/// use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject, Value};
///
/// let desc = OdBuilder::new()
///     .var(0x1000, SubObject::new("Device type", DataType::Unsigned32, Access::Ro)
///         .default(Value::Unsigned32(0x0001_0191)))
///     .record(0x1200, "SDO server parameter", [
///         (1, SubObject::new("COB-ID client->server", DataType::Unsigned32, Access::Ro)
///             .default_node_id_plus(Value::Unsigned32(0x600))),
///         (2, SubObject::new("COB-ID server->client", DataType::Unsigned32, Access::Ro)
///             .default_node_id_plus(Value::Unsigned32(0x580))),
///     ])
///     .build()
///     .expect("a valid dictionary");
/// assert_eq!(desc.len(), 2);
/// ```
#[derive(Debug, Default, Clone)]
pub struct OdBuilder {
    objects: Vec<PendingObject>,
    hooks: Vec<RangeInclusive<u16>>,
}

#[derive(Debug, Clone)]
struct PendingObject {
    index: u16,
    name: String,
    code: ObjectCode,
    flags: u32,
    compact: bool,
    subs: Vec<(u8, SubObject)>,
}

impl OdBuilder {
    /// An empty dictionary.
    pub fn new() -> Self {
        OdBuilder::default()
    }

    /// A VAR object; its value is sub-index 0 and its name is the sub-object's name.
    pub fn var(mut self, index: u16, sub: SubObject) -> Self {
        self.objects.push(PendingObject {
            index,
            name: sub.name.clone(),
            code: ObjectCode::Var,
            flags: 0,
            compact: false,
            subs: vec![(0, sub)],
        });
        self
    }

    /// A RECORD object. Without an explicit sub-index 0, one is added: UNSIGNED8, `const`,
    /// "Highest sub-index supported", holding the highest sub-index given.
    pub fn record(
        self,
        index: u16,
        name: impl Into<String>,
        subs: impl IntoIterator<Item = (u8, SubObject)>,
    ) -> Self {
        self.composite(
            index,
            name.into(),
            ObjectCode::Record,
            subs.into_iter().collect(),
        )
    }

    /// An ARRAY object with explicit sub-indices (sub-index 0 added as for [`Self::record`]).
    pub fn array(
        self,
        index: u16,
        name: impl Into<String>,
        subs: impl IntoIterator<Item = (u8, SubObject)>,
    ) -> Self {
        self.composite(
            index,
            name.into(),
            ObjectCode::Array,
            subs.into_iter().collect(),
        )
    }

    /// An ARRAY of `count` copies of `element` at sub-indices 1..=count, named
    /// "`element.name` k".
    pub fn array_of(
        self,
        index: u16,
        name: impl Into<String>,
        count: u8,
        element: SubObject,
    ) -> Self {
        let subs = (1..=count).map(|k| {
            let mut e = element.clone();
            e.name = format!("{} {k}", element.name);
            (k, e)
        });
        self.array(index, name, subs)
    }

    fn composite(
        mut self,
        index: u16,
        name: String,
        code: ObjectCode,
        mut subs: Vec<(u8, SubObject)>,
    ) -> Self {
        if !subs.iter().any(|(s, _)| *s == 0) {
            let highest = subs.iter().map(|(s, _)| *s).max().unwrap_or(0);
            subs.push((
                0,
                SubObject::new(
                    "Highest sub-index supported",
                    DataType::Unsigned8,
                    Access::Const,
                )
                .default(Value::Unsigned8(highest)),
            ));
        }
        self.objects.push(PendingObject {
            index,
            name,
            code,
            flags: 0,
            compact: false,
            subs,
        });
        self
    }

    /// Sets CiA 306 `ObjectFlags` of the object most recently added.
    pub fn flags(mut self, flags: u32) -> Self {
        if let Some(o) = self.objects.last_mut() {
            o.flags = flags;
        }
        self
    }

    /// Marks the object most recently added to be written with `CompactSubObj` in an EDS.
    pub fn compact(mut self) -> Self {
        if let Some(o) = self.objects.last_mut() {
            o.compact = true;
        }
        self
    }

    /// Sets the object code of the object most recently added: a DEFTYPE object of an EDS
    /// (CiA 301 §7.4.7.1, e.g. the dummy entries 0x0002..=0x0007) is held like a VAR but
    /// keeps its code, so the EDS generated from the dictionary says DEFTYPE again.
    pub fn code(mut self, code: ObjectCode) -> Self {
        if let Some(o) = self.objects.last_mut() {
            o.code = code;
        }
        self
    }

    /// Routes reads and writes of the objects in `range` through the device's [`OdHooks`].
    pub fn hook(mut self, range: RangeInclusive<u16>) -> Self {
        self.hooks.push(range);
        self
    }

    /// Checks the definitions and lays out the values.
    pub fn build(self) -> Result<OdDescription, OdBuildError> {
        let mut objects = self.objects;
        objects.sort_by_key(|o| o.index);
        if let Some(w) = objects.windows(2).find(|w| w[0].index == w[1].index) {
            return Err(OdBuildError::Duplicate(w[0].index));
        }
        let mut desc = OdDescription {
            objects: Vec::new(),
            subs: Vec::new(),
            page_of: Box::new([0; 256]),
            pages: Vec::new(),
            spans: Vec::new(),
            hot: Vec::new(),
            fixed_len: 0,
            var_count: 0,
        };
        for mut o in objects {
            o.subs.sort_by_key(|(s, _)| *s);
            if let Some(w) = o.subs.windows(2).find(|w| w[0].0 == w[1].0) {
                return Err(OdBuildError::DuplicateSub(o.index, w[0].0));
            }
            let first = desc.subs.len() as u32;
            let count = o.subs.len() as u16;
            let dense = o
                .subs
                .iter()
                .enumerate()
                .all(|(i, (s, _))| usize::from(*s) == i);
            for (sub, d) in o.subs {
                check_sub(o.index, sub, &d)?;
                let slot = match d.data_type.fixed_size() {
                    Some(len) => {
                        let slot = Slot::Fixed {
                            offset: desc.fixed_len as u32,
                            len: len as u8,
                        };
                        desc.fixed_len += len;
                        slot
                    }
                    None => {
                        desc.var_count += 1;
                        Slot::Var(desc.var_count as u32 - 1)
                    }
                };
                desc.hot.push(Hot {
                    slot,
                    access: d.access,
                    sub,
                    checked: d.data_type == DataType::Boolean
                        || d.low_limit.is_some()
                        || d.high_limit.is_some(),
                });
                desc.subs.push(SubEntry { sub, desc: d, slot });
            }
            let hooked = self.hooks.iter().any(|r| r.contains(&o.index));
            let hi = usize::from(o.index >> 8);
            if desc.page_of[hi] == 0 {
                desc.pages.push([0; 256]);
                desc.page_of[hi] = desc.pages.len() as u16;
            }
            let page = usize::from(desc.page_of[hi]) - 1;
            desc.pages[page][usize::from(o.index & 0xFF)] = desc.spans.len() as u16 + 1;
            desc.spans.push(Span {
                first,
                count,
                dense,
                hooked,
            });
            desc.objects.push(ObjectEntry {
                index: o.index,
                hooked,
                name: o.name,
                code: o.code,
                flags: o.flags,
                compact: o.compact,
                first,
                count,
            });
        }
        Ok(desc)
    }
}

fn check_sub(index: u16, sub: u8, d: &SubObject) -> Result<(), OdBuildError> {
    let ty = d.data_type;
    for (what, v) in [
        ("the default", &d.default),
        ("the low limit", &d.low_limit),
        ("the high limit", &d.high_limit),
    ] {
        if let Some(v) = v
            && v.data_type() != ty
        {
            return Err(OdBuildError::WrongType(index, sub, what, v.data_type(), ty));
        }
    }
    if let (Some(max), Some(v)) = (d.max_len, &d.default)
        && v.encoded_len() > max
    {
        return Err(OdBuildError::DefaultTooLong(index, sub));
    }
    if d.default_node_id_relative && !(ty.is_signed() || ty.is_unsigned()) {
        return Err(OdBuildError::NodeIdNotInteger(index, sub));
    }
    if let (Some(lo), Some(hi)) = (
        d.low_limit.as_ref().and_then(Value::num),
        d.high_limit.as_ref().and_then(Value::num),
    ) && lo.partial_cmp(hi) == Some(core::cmp::Ordering::Greater)
    {
        return Err(OdBuildError::LimitsInverted(index, sub));
    }
    Ok(())
}

/// What objects a kind of device has: shared by all devices of that kind.
#[derive(Debug, Clone)]
pub struct OdDescription {
    objects: Vec<ObjectEntry>,
    subs: Vec<SubEntry>,
    /// The hot path is kept apart from the descriptive (cold) data, so a lookup touches a
    /// few cache lines only: the index table, the objects' sub-index spans, and per
    /// sub-object the storage slot, access and sub-index.
    /// Two-level index → object table: the high byte of the index selects a page (0: none,
    /// else page number + 1), the low byte an object in it (0: none, else position + 1).
    /// Two dependent loads instead of a binary search; a page is 512 bytes and a typical
    /// device uses fewer than 16 of them.
    page_of: Box<[u16; 256]>,
    pages: Vec<[u16; 256]>,
    spans: Vec<Span>,
    hot: Vec<Hot>,
    fixed_len: usize,
    var_count: usize,
}

#[derive(Debug, Clone, Copy)]
struct Span {
    first: u32,
    count: u16,
    /// Sub-indices are exactly 0..count, so the sub-index is the offset.
    dense: bool,
    hooked: bool,
}

#[derive(Debug, Clone, Copy)]
struct Hot {
    slot: Slot,
    access: Access,
    sub: u8,
    /// Downloads need a value check (BOOLEAN, or limits).
    checked: bool,
}

impl OdDescription {
    /// The number of objects (indices).
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    /// Whether it has no objects.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// The objects in index order.
    pub fn objects(&self) -> impl Iterator<Item = ObjectInfo<'_>> {
        self.objects
            .iter()
            .map(move |entry| ObjectInfo { desc: self, entry })
    }

    /// The object at `index`.
    pub fn object(&self, index: u16) -> Option<ObjectInfo<'_>> {
        let i = self
            .objects
            .binary_search_by_key(&index, |o| o.index)
            .ok()?;
        Some(ObjectInfo {
            desc: self,
            entry: &self.objects[i],
        })
    }

    /// Finds a sub-object: 0x06020000 if the index does not exist, 0x06090011 if the
    /// sub-index does not (CiA 301 table 22).
    #[inline]
    pub fn locate(&self, index: u16, sub: u8) -> Result<EntryId, AbortCode> {
        self.locate_hooked(index, sub).map(|(id, _)| id)
    }

    /// [`Self::locate`], also telling whether the object is served by device hooks.
    #[inline]
    pub fn locate_hooked(&self, index: u16, sub: u8) -> Result<(EntryId, bool), AbortCode> {
        let oi = self.position(index).ok_or(AbortCode::NO_OBJECT)?;
        let o = self.spans[oi];
        self.sub_in(o, sub).map(|id| (id, o.hooked))
    }

    #[inline]
    fn sub_in(&self, o: Span, sub: u8) -> Result<EntryId, AbortCode> {
        let first = o.first as usize;
        if o.dense {
            if u16::from(sub) < o.count {
                return Ok(EntryId(o.first + u32::from(sub)));
            }
            return Err(AbortCode::NO_SUB_INDEX);
        }
        self.hot[first..first + usize::from(o.count)]
            .binary_search_by_key(&sub, |s| s.sub)
            .map(|i| EntryId((first + i) as u32))
            .map_err(|_| AbortCode::NO_SUB_INDEX)
    }

    /// The position of object `index` in index order.
    #[inline]
    fn position(&self, index: u16) -> Option<usize> {
        let page = usize::from(self.page_of[usize::from(index >> 8)]).checked_sub(1)?;
        let slot = self.pages.get(page)?[usize::from(index & 0xFF)];
        usize::from(slot).checked_sub(1)
    }

    /// Whether reads and writes of `index` go through device hooks.
    #[inline]
    pub fn is_hooked(&self, index: u16) -> bool {
        self.position(index).is_some_and(|i| self.spans[i].hooked)
    }

    /// The description of a located sub-object.
    pub fn sub_object(&self, id: EntryId) -> &SubObject {
        &self.subs[id.0 as usize].desc
    }

    /// The access type of a located sub-object (from the hot table).
    #[inline]
    pub fn access(&self, id: EntryId) -> Access {
        self.hot[id.0 as usize].access
    }

    #[inline]
    fn slot(&self, id: EntryId) -> Slot {
        self.hot[id.0 as usize].slot
    }

    /// The description of the sub-object at `index`/`sub`.
    pub fn get(&self, index: u16, sub: u8) -> Option<&SubObject> {
        self.locate(index, sub).ok().map(|id| self.sub_object(id))
    }

    /// Bytes of per-device storage for fixed-size values.
    pub fn fixed_storage_len(&self) -> usize {
        self.fixed_len
    }
}

/// One device's object dictionary values, on top of a shared [`OdDescription`].
#[derive(Debug, Clone)]
pub struct ObjectDictionary {
    desc: Arc<OdDescription>,
    node_id: u8,
    fixed: Vec<u8>,
    vars: Vec<Vec<u8>>,
    /// Receives segmented and block downloads before they are validated and committed.
    staging: Vec<u8>,
    staging_limit: usize,
}

/// The default largest segmented or block download the dictionary buffers.
pub const DEFAULT_STAGING_LIMIT: usize = 1 << 20;

/// Never reserve more than this for a download on the strength of an indicated size alone.
const MAX_PRERESERVE: usize = 64 * 1024;

impl ObjectDictionary {
    /// The values of a device with node-ID `node_id`, all at their defaults.
    pub fn new(desc: Arc<OdDescription>, node_id: u8) -> Self {
        let mut od = ObjectDictionary {
            fixed: vec![0; desc.fixed_len],
            vars: vec![Vec::new(); desc.var_count],
            desc,
            node_id,
            staging: Vec::new(),
            staging_limit: DEFAULT_STAGING_LIMIT,
        };
        od.restore_defaults(0..=0xFFFF);
        od
    }

    /// The shared description.
    pub fn description(&self) -> &Arc<OdDescription> {
        &self.desc
    }

    /// The node-ID `$NODEID` defaults are computed with.
    pub fn node_id(&self) -> u8 {
        self.node_id
    }

    /// Changes the node-ID used by later [`Self::restore_defaults`] (e.g. on NMT reset
    /// communication after a node-ID change); values are not touched.
    pub fn set_node_id(&mut self, node_id: u8) {
        self.node_id = node_id;
    }

    /// Sets every sub-object of the objects in `range` back to its default.
    pub fn restore_defaults(&mut self, range: RangeInclusive<u16>) {
        let desc = Arc::clone(&self.desc);
        for o in desc.objects.iter().filter(|o| range.contains(&o.index)) {
            let first = o.first as usize;
            for s in &desc.subs[first..first + usize::from(o.count)] {
                let v = s.desc.default_for(self.node_id);
                self.store_value(s.slot, &v);
            }
        }
    }

    fn store_value(&mut self, slot: Slot, v: &Value) {
        match slot {
            Slot::Fixed { offset, len } => {
                let o = offset as usize;
                v.encode_into(&mut self.fixed[o..o + usize::from(len)]);
            }
            Slot::Var(i) => {
                let buf = &mut self.vars[i as usize];
                buf.clear();
                buf.resize(v.encoded_len(), 0);
                v.encode_into(buf);
            }
        }
    }

    /// Finds a sub-object (0x06020000 / 0x06090011 if absent).
    #[inline]
    pub fn locate(&self, index: u16, sub: u8) -> Result<EntryId, AbortCode> {
        self.desc.locate(index, sub)
    }

    /// The description of a located sub-object.
    pub fn sub_object(&self, id: EntryId) -> &SubObject {
        self.desc.sub_object(id)
    }

    #[inline]
    pub(crate) fn desc_access(&self, id: EntryId) -> Access {
        self.desc.access(id)
    }

    /// The encoded bytes of a value.
    #[inline]
    pub fn raw(&self, id: EntryId) -> &[u8] {
        match self.desc.slot(id) {
            Slot::Fixed { offset, len } => {
                let o = offset as usize;
                &self.fixed[o..o + usize::from(len)]
            }
            Slot::Var(i) => &self.vars[i as usize],
        }
    }

    /// Stores encoded bytes as the device itself would: no access or limit check, only the
    /// length (0x06070010/12/13; above the maximum of a string or DOMAIN 0x06070012).
    pub fn set_raw(&mut self, id: EntryId, data: &[u8]) -> Result<(), AbortCode> {
        let entry = &self.desc.subs[id.0 as usize];
        check_length(&entry.desc, data.len())?;
        match entry.slot {
            Slot::Fixed { offset, len } => {
                let o = offset as usize;
                self.fixed[o..o + usize::from(len)].copy_from_slice(data);
            }
            Slot::Var(i) => {
                let buf = &mut self.vars[i as usize];
                buf.clear();
                buf.extend_from_slice(data);
            }
        }
        Ok(())
    }

    /// The value at `index`/`sub`, as the device sees it (no access check).
    pub fn get(&self, index: u16, sub: u8) -> Result<Value, AbortCode> {
        let id = self.locate(index, sub)?;
        Value::from_le_bytes(self.sub_object(id).data_type, self.raw(id))
            .map_err(|_| AbortCode::TYPE_MISMATCH)
    }

    /// Sets the value at `index`/`sub` as the device itself would: the type must match
    /// (0x06070010), access and limits are not checked.
    pub fn set(&mut self, index: u16, sub: u8, value: &Value) -> Result<(), AbortCode> {
        let id = self.locate(index, sub)?;
        let d = self.sub_object(id);
        if value.data_type() != d.data_type {
            return Err(AbortCode::TYPE_MISMATCH);
        }
        check_length(d, value.encoded_len())?;
        let slot = self.desc.subs[id.0 as usize].slot;
        self.store_value(slot, value);
        Ok(())
    }

    /// An unsigned integer value (UNSIGNED8..64, BOOLEAN) widened to `u64`.
    pub fn get_unsigned(&self, index: u16, sub: u8) -> Option<u64> {
        let id = self.locate(index, sub).ok()?;
        let ty = self.sub_object(id).data_type;
        if !(ty.is_unsigned() || ty == DataType::Boolean) {
            return None;
        }
        let mut b = [0u8; 8];
        let raw = self.raw(id);
        b[..raw.len()].copy_from_slice(raw);
        Some(u64::from_le_bytes(b))
    }

    /// The checks of an SDO download (CiA 301 §7.2.4.3, table 22), in the order the
    /// standard's situations arise: existence, writability, length, value range.
    pub fn check_download(&self, id: EntryId, data: &[u8]) -> Result<(), AbortCode> {
        let d = self.sub_object(id);
        if !d.access.writable() {
            return Err(AbortCode::READ_ONLY);
        }
        check_length(d, data.len())?;
        check_value(d, data)
    }

    /// An SDO-style download into the stored value, with all checks of
    /// [`Self::check_download`].
    #[inline]
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let id = self.locate(index, sub)?;
        let hot = self.desc.hot[id.0 as usize];
        let Slot::Fixed { offset, len } = hot.slot else {
            self.check_download(id, data)?;
            return self.set_raw(id, data);
        };
        // Fixed-size values: the same checks as `check_download`, from the hot table.
        if !hot.access.writable() {
            return Err(AbortCode::READ_ONLY);
        }
        let len = usize::from(len);
        if data.len() > len {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        if data.len() < len {
            return Err(AbortCode::LENGTH_TOO_LOW);
        }
        if hot.checked {
            check_value(self.sub_object(id), data)?;
        }
        let o = offset as usize;
        copy_small(&mut self.fixed[o..o + len], data);
        Ok(())
    }

    /// Sets the largest segmented or block download this device buffers (default
    /// [`DEFAULT_STAGING_LIMIT`]); a longer one is aborted with 0x05040005 (out of memory).
    pub fn set_staging_limit(&mut self, bytes: usize) {
        self.staging_limit = bytes;
    }

    /// The bytes of a segmented or block download received so far.
    pub fn staged(&self) -> &[u8] {
        &self.staging
    }

    /// Starts staging a download (see [`ObjectAccess::write_begin`]).
    pub fn stage_begin(
        &mut self,
        index: u16,
        sub: u8,
        size: Option<usize>,
    ) -> Result<EntryId, AbortCode> {
        let id = self.locate(index, sub)?;
        let d = self.sub_object(id);
        if !d.access.writable() {
            return Err(AbortCode::READ_ONLY);
        }
        if let Some(size) = size {
            check_length(d, size)?;
            if size > self.staging_limit {
                return Err(AbortCode::OUT_OF_MEMORY);
            }
        }
        self.staging.clear();
        let reserve = size.unwrap_or(0).min(MAX_PRERESERVE);
        self.staging
            .try_reserve(reserve)
            .map_err(|_| AbortCode::OUT_OF_MEMORY)?;
        Ok(id)
    }

    /// Appends bytes to a staged download; a length above the type's or the declared
    /// maximum is refused with 0x06070012 as soon as it is reached.
    pub fn stage_append(&mut self, id: EntryId, data: &[u8]) -> Result<(), AbortCode> {
        let d = self.sub_object(id);
        let len = self.staging.len() + data.len();
        let max = d.data_type.fixed_size().or(d.max_len);
        if max.is_some_and(|m| len > m) {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        self.staging
            .try_reserve(data.len())
            .map_err(|_| AbortCode::OUT_OF_MEMORY)?;
        self.staging.extend_from_slice(data);
        Ok(())
    }

    /// Validates the staged bytes as a download and makes them the value. A string or
    /// DOMAIN buffer is swapped in, not copied.
    pub fn stage_commit(&mut self, id: EntryId) -> Result<(), AbortCode> {
        self.stage_check(id)?;
        let entry = &self.desc.subs[id.0 as usize];
        match entry.slot {
            Slot::Fixed { offset, len } => {
                let o = offset as usize;
                self.fixed[o..o + usize::from(len)].copy_from_slice(&self.staging);
            }
            Slot::Var(i) => core::mem::swap(&mut self.vars[i as usize], &mut self.staging),
        }
        self.staging.clear();
        Ok(())
    }

    /// The length and value checks of a download, applied to the staged bytes.
    pub fn stage_check(&self, id: EntryId) -> Result<(), AbortCode> {
        let d = self.sub_object(id);
        check_length(d, self.staging.len())?;
        check_value(d, &self.staging)
    }

    /// Drops a staged download.
    pub fn stage_cancel(&mut self) {
        self.staging.clear();
    }

    /// Bytes of heap this dictionary's values use (not counting the shared description).
    pub fn heap_bytes(&self) -> usize {
        self.fixed.capacity()
            + self.vars.capacity() * core::mem::size_of::<Vec<u8>>()
            + self.vars.iter().map(Vec::capacity).sum::<usize>()
            + self.staging.capacity()
    }
}

/// Copies `src` into `dst` (same length). Small copies of a constant size compile to
/// single moves: no call to memcpy, and a wide load of the bytes just written forwards
/// from the store.
#[inline]
pub(crate) fn copy_small(dst: &mut [u8], src: &[u8]) {
    match src.len() {
        1 => dst[0] = src[0],
        2 => dst[..2].copy_from_slice(&src[..2]),
        4 => dst[..4].copy_from_slice(&src[..4]),
        7 => dst[..7].copy_from_slice(&src[..7]),
        8 => dst[..8].copy_from_slice(&src[..8]),
        _ => dst.copy_from_slice(src),
    }
}

/// Length rules of a download (CiA 301 table 22): a fixed-size type takes exactly its size
/// (0x06070012 above, 0x06070013 below); a string or DOMAIN at most its declared maximum
/// (0x06070012); a UNICODE_STRING an even number of bytes (0x06070010).
fn check_length(d: &SubObject, len: usize) -> Result<(), AbortCode> {
    match d.data_type.fixed_size() {
        Some(size) if len > size => Err(AbortCode::LENGTH_TOO_HIGH),
        Some(size) if len < size => Err(AbortCode::LENGTH_TOO_LOW),
        Some(_) => Ok(()),
        None if d.max_len.is_some_and(|m| len > m) => Err(AbortCode::LENGTH_TOO_HIGH),
        None if d.data_type == DataType::UnicodeString && len % 2 != 0 => {
            Err(AbortCode::TYPE_MISMATCH)
        }
        None => Ok(()),
    }
}

/// Value rules of a download: BOOLEAN is 0 or 1 (0x06090030); limits (0x06090031 above the
/// high limit, 0x06090032 below the low one). NaN is outside any limit.
fn check_value(d: &SubObject, data: &[u8]) -> Result<(), AbortCode> {
    if d.data_type == DataType::Boolean && data.first().is_some_and(|b| *b > 1) {
        return Err(AbortCode::INVALID_VALUE);
    }
    if d.low_limit.is_none() && d.high_limit.is_none() {
        return Ok(());
    }
    let Some(v) = Value::num_of(d.data_type, data) else {
        return Ok(());
    };
    use core::cmp::Ordering::{Greater, Less};
    if let Some(hi) = d.high_limit.as_ref().and_then(Value::num) {
        match v.partial_cmp(hi) {
            Some(Greater) => return Err(AbortCode::VALUE_TOO_HIGH),
            None => return Err(AbortCode::INVALID_VALUE),
            _ => {}
        }
    }
    if let Some(lo) = d.low_limit.as_ref().and_then(Value::num) {
        match v.partial_cmp(lo) {
            Some(Less) => return Err(AbortCode::VALUE_TOO_LOW),
            None => return Err(AbortCode::INVALID_VALUE),
            _ => {}
        }
    }
    Ok(())
}
