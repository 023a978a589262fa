//! Store and restore parameters (CiA 301 §7.5.2.10 and §7.5.2.11, objects 0x1010/0x1011).
//!
//! Writing the signature "save" (0x65766173, the ASCII bytes `s a v e` little-endian) to a
//! 0x1010 sub-index stores a group of parameters; writing "load" (0x64616F6C) to a 0x1011
//! sub-index erases the stored group, so the defaults apply after the next reset (reset
//! node for application parameters, reset communication or reset node for communication
//! parameters). Any other value is refused with 0x08000020. Sub-index 1 covers all
//! parameters, 2 the communication parameters (0x1000–0x1FFF), 3 the application
//! parameters (0x6000–0x9FFF), 4 the manufacturer-specific ones (0x2000–0x5FFF).
//!
//! A group is stored as one blob: magic `CTOD`, version 1, then for each writable
//! sub-object its index (u16), sub-index (u8), length (u16) and bytes, and a trailing
//! FNV-1a checksum of everything before it. [`FileStorage`] writes each blob atomically
//! (temporary file, fsync, rename, fsync of the directory), so after a crash the store
//! holds either the old or the new blob, never half of one.

use crate::od::{Access, ObjectDictionary};
use core::ops::RangeInclusive;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The "save" signature (CiA 301 §7.5.2.10).
pub const SAVE: u32 = 0x6576_6173;
/// The "load" signature (CiA 301 §7.5.2.11).
pub const LOAD: u32 = 0x6461_6F6C;

/// A group of parameters stored together.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Group {
    /// Communication parameters, 0x1000–0x1FFF.
    Communication,
    /// Manufacturer-specific parameters, 0x2000–0x5FFF.
    Manufacturer,
    /// Standardised application (profile) parameters, 0x6000–0x9FFF.
    Application,
}

impl Group {
    /// Every group.
    pub const ALL: [Group; 3] = [
        Group::Communication,
        Group::Manufacturer,
        Group::Application,
    ];

    /// The indices the group covers.
    pub const fn range(self) -> RangeInclusive<u16> {
        match self {
            Group::Communication => 0x1000..=0x1FFF,
            Group::Manufacturer => 0x2000..=0x5FFF,
            Group::Application => 0x6000..=0x9FFF,
        }
    }

    /// A short name (the file name of [`FileStorage`]).
    pub const fn name(self) -> &'static str {
        match self {
            Group::Communication => "communication",
            Group::Manufacturer => "manufacturer",
            Group::Application => "application",
        }
    }

    /// The groups a 0x1010/0x1011 sub-index selects (1 all, 2 communication, 3
    /// application, 4 manufacturer).
    pub fn for_sub(sub: u8) -> &'static [Group] {
        match sub {
            1 => &Group::ALL,
            2 => &[Group::Communication],
            3 => &[Group::Application],
            4 => &[Group::Manufacturer],
            _ => &[],
        }
    }
}

/// A failure of the storage backend or a stored blob that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StorageError {
    /// The backend failed.
    #[error("parameter storage: {0}")]
    Io(#[from] std::io::Error),
    /// A stored blob is damaged or not a cantwin parameter blob.
    #[error("stored parameters are damaged: {0}")]
    Corrupt(&'static str),
}

/// Where a device keeps its stored parameters. Called synchronously when 0x1010/0x1011 are
/// written and at every reset.
pub trait Storage: Send {
    /// The stored blob of `group`, if any.
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError>;
    /// Replaces the stored blob of `group`.
    fn save(&mut self, group: Group, data: &[u8]) -> Result<(), StorageError>;
    /// Removes the stored blob of `group` (the defaults apply after the next reset).
    fn erase(&mut self, group: Group) -> Result<(), StorageError>;
}

/// Parameters kept in memory: they survive resets of the device, not of the process.
#[derive(Debug, Clone, Default)]
pub struct MemoryStorage {
    blobs: [Option<Vec<u8>>; 3],
}

fn slot(group: Group) -> usize {
    match group {
        Group::Communication => 0,
        Group::Manufacturer => 1,
        Group::Application => 2,
    }
}

impl MemoryStorage {
    /// An empty store.
    pub fn new() -> Self {
        MemoryStorage::default()
    }
}

impl Storage for MemoryStorage {
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError> {
        Ok(self.blobs[slot(group)].clone())
    }
    fn save(&mut self, group: Group, data: &[u8]) -> Result<(), StorageError> {
        self.blobs[slot(group)] = Some(data.to_vec());
        Ok(())
    }
    fn erase(&mut self, group: Group) -> Result<(), StorageError> {
        self.blobs[slot(group)] = None;
        Ok(())
    }
}

/// Parameters in files, one per group, in a directory, written atomically.
#[derive(Debug, Clone)]
pub struct FileStorage {
    dir: PathBuf,
}

impl FileStorage {
    /// A store in `dir` (created if missing).
    pub fn new(dir: impl Into<PathBuf>) -> Result<Self, StorageError> {
        let dir = dir.into();
        fs::create_dir_all(&dir)?;
        Ok(FileStorage { dir })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn path(&self, group: Group) -> PathBuf {
        self.dir.join(format!("{}.params", group.name()))
    }

    /// Makes a rename or removal in the directory durable.
    fn sync_dir(&self) -> Result<(), StorageError> {
        // Directories can be opened and fsynced on Unix; elsewhere the rename is what we get.
        #[cfg(unix)]
        fs::File::open(&self.dir)?.sync_all()?;
        Ok(())
    }
}

impl Storage for FileStorage {
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError> {
        match fs::read(self.path(group)) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e.into()),
        }
    }

    fn save(&mut self, group: Group, data: &[u8]) -> Result<(), StorageError> {
        let path = self.path(group);
        let tmp = self.dir.join(format!("{}.params.tmp", group.name()));
        {
            let mut f = fs::File::create(&tmp)?;
            f.write_all(data)?;
            f.sync_all()?;
        }
        fs::rename(&tmp, &path)?;
        self.sync_dir()
    }

    fn erase(&mut self, group: Group) -> Result<(), StorageError> {
        match fs::remove_file(self.path(group)) {
            Ok(()) => self.sync_dir(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(e.into()),
        }
    }
}

const MAGIC: &[u8; 4] = b"CTOD";
const VERSION: u8 = 1;

fn fnv1a(data: &[u8]) -> u32 {
    data.iter().fold(0x811C_9DC5u32, |h, b| {
        (h ^ u32::from(*b)).wrapping_mul(0x0100_0193)
    })
}

/// Whether a sub-object is a stored parameter: writable, and not one of the command
/// objects (0x1003 error field, 0x1010 store, 0x1011 restore).
fn stored(index: u16, access: Access) -> bool {
    access.writable() && !matches!(index, 0x1003 | 0x1010 | 0x1011)
}

/// The blob of `group`'s parameters in `od`.
pub fn encode(od: &ObjectDictionary, group: Group) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    let desc = od.description();
    let range = group.range();
    for obj in desc.objects().filter(|o| range.contains(&o.index())) {
        for (sub, d) in obj.subs() {
            if !stored(obj.index(), d.access) {
                continue;
            }
            let Ok(id) = od.locate(obj.index(), sub) else {
                continue;
            };
            let raw = od.raw(id);
            let Ok(len) = u16::try_from(raw.len()) else {
                continue;
            };
            out.extend_from_slice(&obj.index().to_le_bytes());
            out.push(sub);
            out.extend_from_slice(&len.to_le_bytes());
            out.extend_from_slice(raw);
        }
    }
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// Applies a blob to `od`: every entry for an existing stored parameter of `group` with a
/// fitting length is set; others (objects a newer firmware dropped) are skipped. Returns
/// how many values were set. A damaged blob sets nothing.
pub fn apply(od: &mut ObjectDictionary, group: Group, blob: &[u8]) -> Result<usize, StorageError> {
    let body_len = blob
        .len()
        .checked_sub(4)
        .ok_or(StorageError::Corrupt("too short"))?;
    let (body, sum) = blob.split_at(body_len);
    if sum != fnv1a(body).to_le_bytes() {
        return Err(StorageError::Corrupt("checksum mismatch"));
    }
    let rest = body
        .strip_prefix(MAGIC.as_slice())
        .ok_or(StorageError::Corrupt("not a parameter blob"))?;
    let [version, tail @ ..] = rest else {
        return Err(StorageError::Corrupt("no version"));
    };
    let mut rest: &[u8] = tail;
    if *version != VERSION {
        return Err(StorageError::Corrupt("unknown version"));
    }
    // Validate the whole layout before touching the dictionary.
    let mut entries = Vec::new();
    while !rest.is_empty() {
        let [i0, i1, sub, l0, l1, tail @ ..] = rest else {
            return Err(StorageError::Corrupt("truncated entry"));
        };
        let len = usize::from(u16::from_le_bytes([*l0, *l1]));
        if tail.len() < len {
            return Err(StorageError::Corrupt("truncated value"));
        }
        let (value, tail) = tail.split_at(len);
        entries.push((u16::from_le_bytes([*i0, *i1]), *sub, value));
        rest = tail;
    }
    let range = group.range();
    let mut set = 0;
    for (index, sub, value) in entries {
        if !range.contains(&index) {
            continue;
        }
        let Ok(id) = od.locate(index, sub) else {
            continue;
        };
        if stored(index, od.sub_object(id).access) && od.set_raw(id, value).is_ok() {
            set += 1;
        }
    }
    Ok(set)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::{DataType, OdBuilder, SubObject, Value};
    use std::sync::Arc;

    fn od() -> ObjectDictionary {
        let d = OdBuilder::new()
            .var(
                0x1017,
                SubObject::new("HB", DataType::Unsigned16, Access::Rw),
            )
            .var(
                0x1018,
                SubObject::new("Id", DataType::Unsigned32, Access::Ro),
            )
            .var(
                0x2000,
                SubObject::new("P", DataType::Unsigned32, Access::Rw),
            )
            .var(
                0x2001,
                SubObject::new("S", DataType::VisibleString, Access::Rw).max_len(16),
            )
            .build()
            .unwrap();
        ObjectDictionary::new(Arc::new(d), 3)
    }

    #[test]
    fn cia301_7_5_2_10_signatures_spell_save_and_load() {
        assert_eq!(SAVE.to_le_bytes(), *b"save");
        assert_eq!(LOAD.to_le_bytes(), *b"load");
    }

    #[test]
    fn blob_round_trip_per_group() {
        let mut a = od();
        a.set(0x1017, 0, &Value::Unsigned16(500)).unwrap();
        a.set(0x2000, 0, &Value::Unsigned32(7)).unwrap();
        a.set(0x2001, 0, &Value::VisibleString("abc".into()))
            .unwrap();
        let comm = encode(&a, Group::Communication);
        let mfr = encode(&a, Group::Manufacturer);
        let mut b = od();
        assert_eq!(apply(&mut b, Group::Communication, &comm).unwrap(), 1);
        assert_eq!(b.get(0x1017, 0).unwrap(), Value::Unsigned16(500));
        assert_eq!(b.get(0x2000, 0).unwrap(), Value::Unsigned32(0));
        assert_eq!(apply(&mut b, Group::Manufacturer, &mfr).unwrap(), 2);
        assert_eq!(
            b.get(0x2001, 0).unwrap(),
            Value::VisibleString("abc".into())
        );
        let mut bad = mfr.clone();
        bad[6] ^= 1;
        assert!(matches!(
            apply(&mut b, Group::Manufacturer, &bad),
            Err(StorageError::Corrupt(_))
        ));
        assert!(apply(&mut b, Group::Manufacturer, &[]).is_err());
    }
}
