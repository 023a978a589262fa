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
//! FNV-1a checksum of everything before it.
//!
//! A store changes its groups all or none ([`Storage::commit`]): "save all" (0x1010 sub 1)
//! replaces the three groups as one. [`FileStorage`] keeps every group in one file,
//! [`STORE_FILE`] (magic `CTPS`, version 1, then per group its number (u8), length (u32)
//! and blob, and a trailing FNV-1a checksum), replaced atomically as a whole: temporary
//! file, fsync, rename, fsync of the directory. After a crash the file holds the old or
//! the new set of groups, never some of each. Stores written as one file per group
//! (`communication.params`, `manufacturer.params`, `application.params`) are read while no
//! [`STORE_FILE`] exists, and the first change moves them into it.
//!
//! A store that cannot be read (a damaged or foreign file, a directory in its place, a
//! read error) is never taken for an empty one: [`Storage::load`] says which file and why
//! ([`StorageError::Unreadable`]), the device keeps its defaults for the group and raises
//! an EMCY ([`crate::device::DeviceConfig::storage_fault`]), and [`FileStorage::check`]
//! lists the same problems for a front end to print before the device runs.

use crate::od::{Access, ObjectDictionary};
use core::ops::RangeInclusive;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The "save" signature (CiA 301 §7.5.2.10).
pub const SAVE: u32 = 0x6576_6173;
/// The "load" signature (CiA 301 §7.5.2.11).
pub const LOAD: u32 = 0x6461_6F6C;

/// The file of [`FileStorage`] that holds every stored group.
pub const STORE_FILE: &str = "parameters.store";

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

    /// A short name (the per-group file name of older stores).
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

    /// The group's number in [`STORE_FILE`] (the 0x1011/0x1010 sub-index that selects it
    /// alone).
    const fn number(self) -> u8 {
        match self {
            Group::Communication => 2,
            Group::Application => 3,
            Group::Manufacturer => 4,
        }
    }

    fn from_number(n: u8) -> Option<Group> {
        Group::ALL.into_iter().find(|g| g.number() == n)
    }

    const fn slot(self) -> usize {
        match self {
            Group::Communication => 0,
            Group::Manufacturer => 1,
            Group::Application => 2,
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
    /// A file of the store cannot be read or is not a whole store.
    #[error("stored parameters in {} cannot be used: {reason}", file.display())]
    Unreadable {
        /// The file.
        file: PathBuf,
        /// Why (an I/O error, or what is wrong with its contents).
        reason: String,
    },
}

/// A change of one group: its new blob, or `None` to erase it.
pub type Change<'a> = (Group, Option<&'a [u8]>);

/// Where a device keeps its stored parameters. Called synchronously when 0x1010/0x1011 are
/// written and at every reset.
pub trait Storage: Send {
    /// The stored blob of `group`, if any. A store that exists but cannot be read is an
    /// error, not `None`.
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError>;
    /// Applies `changes` all or none: after a crash the store holds every change or
    /// none of them.
    fn commit(&mut self, changes: &[Change<'_>]) -> Result<(), StorageError>;
    /// Replaces the stored blob of `group`.
    fn save(&mut self, group: Group, data: &[u8]) -> Result<(), StorageError> {
        self.commit(&[(group, Some(data))])
    }
    /// Removes the stored blob of `group` (the defaults apply after the next reset).
    fn erase(&mut self, group: Group) -> Result<(), StorageError> {
        self.commit(&[(group, None)])
    }
}

/// Parameters kept in memory: they survive resets of the device, not of the process.
#[derive(Debug, Clone, Default)]
pub struct MemoryStorage {
    blobs: [Option<Vec<u8>>; 3],
}

impl MemoryStorage {
    /// An empty store.
    pub fn new() -> Self {
        MemoryStorage::default()
    }
}

impl Storage for MemoryStorage {
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError> {
        Ok(self.blobs[group.slot()].clone())
    }
    fn commit(&mut self, changes: &[Change<'_>]) -> Result<(), StorageError> {
        for (g, data) in changes {
            self.blobs[g.slot()] = data.map(<[u8]>::to_vec);
        }
        Ok(())
    }
}

/// Parameters in one file in a directory, [`STORE_FILE`], replaced atomically as a whole.
#[derive(Debug, Clone)]
pub struct FileStorage {
    dir: PathBuf,
}

/// The groups of a store as read: a blob per group, or nothing.
type Blobs = [Option<Vec<u8>>; 3];

/// What one file of a store holds, or why it cannot be used.
enum Read {
    Missing,
    Blobs(Blobs),
    Unreadable(StorageError),
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

    /// The file holding every group.
    pub fn path(&self) -> PathBuf {
        self.dir.join(STORE_FILE)
    }

    fn legacy_path(&self, group: Group) -> PathBuf {
        self.dir.join(format!("{}.params", group.name()))
    }

    /// Every problem a device would meet loading this store: the file it cannot read or
    /// use and why, including a group blob that is damaged inside a whole file. Empty when
    /// the store is whole or there is none.
    pub fn check(&self) -> Vec<StorageError> {
        let mut problems = Vec::new();
        let (file, read) = self.read_current();
        match read {
            Read::Unreadable(e) => problems.push(e),
            Read::Blobs(blobs) => {
                for (g, blob) in Group::ALL.iter().zip(&blobs) {
                    let Some(blob) = blob else { continue };
                    if let Err(e) = entries(blob) {
                        let name = file.clone().unwrap_or_else(|| self.legacy_path(*g));
                        problems.push(StorageError::Unreadable {
                            file: name,
                            reason: format!("the {} parameters: {e}", g.name()),
                        });
                    }
                }
            }
            Read::Missing => {}
        }
        problems
    }

    /// The current contents: [`STORE_FILE`] if it exists (and its path), else the per-group
    /// files of older stores (path `None`).
    fn read_current(&self) -> (Option<PathBuf>, Read) {
        let path = self.path();
        match read_file(&path) {
            Ok(None) => {}
            Ok(Some(bytes)) => {
                let read = match parse_store(&bytes) {
                    Ok(blobs) => Read::Blobs(blobs),
                    Err(reason) => Read::Unreadable(StorageError::Unreadable {
                        file: path.clone(),
                        reason: reason.into(),
                    }),
                };
                return (Some(path), read);
            }
            Err(e) => return (Some(path), Read::Unreadable(e)),
        }
        let mut blobs: Blobs = Default::default();
        let mut any = false;
        for g in Group::ALL {
            match read_file(&self.legacy_path(g)) {
                Ok(Some(b)) => {
                    blobs[g.slot()] = Some(b);
                    any = true;
                }
                Ok(None) => {}
                Err(e) => return (None, Read::Unreadable(e)),
            }
        }
        (
            None,
            if any {
                Read::Blobs(blobs)
            } else {
                Read::Missing
            },
        )
    }

    /// Makes a rename or removal in the directory durable.
    fn sync_dir(&self) -> Result<(), StorageError> {
        // Directories can be opened and fsynced on Unix; elsewhere the rename is what we get.
        #[cfg(unix)]
        fs::File::open(&self.dir)?.sync_all()?;
        Ok(())
    }

    /// Removes the per-group files of an older store, now that [`STORE_FILE`] replaces
    /// them.
    fn remove_legacy(&self) -> Result<(), StorageError> {
        let mut removed = false;
        for g in Group::ALL {
            match fs::remove_file(self.legacy_path(g)) {
                Ok(()) => removed = true,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e.into()),
            }
        }
        if removed {
            self.sync_dir()?;
        }
        Ok(())
    }
}

/// The bytes of `path`; `None` if there is no such file. Any other failure (a directory in
/// its place, no permission) names the file.
fn read_file(path: &Path) -> Result<Option<Vec<u8>>, StorageError> {
    match fs::read(path) {
        Ok(b) => Ok(Some(b)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(StorageError::Unreadable {
            file: path.to_path_buf(),
            reason: e.to_string(),
        }),
    }
}

impl Storage for FileStorage {
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError> {
        match self.read_current() {
            (_, Read::Missing) => Ok(None),
            (_, Read::Unreadable(e)) => Err(e),
            (_, Read::Blobs(mut blobs)) => Ok(blobs[group.slot()].take()),
        }
    }

    fn commit(&mut self, changes: &[Change<'_>]) -> Result<(), StorageError> {
        // Groups the commit leaves alone keep their stored blob; those of a store that
        // cannot be read were not in effect (the device runs on its defaults for them),
        // so they are not carried over.
        let (_, read) = self.read_current();
        let mut blobs = match read {
            Read::Blobs(b) => b,
            Read::Missing | Read::Unreadable(_) => Default::default(),
        };
        for (g, data) in changes {
            blobs[g.slot()] = data.map(<[u8]>::to_vec);
        }
        let path = self.path();
        if blobs.iter().all(Option::is_none) {
            match fs::remove_file(&path) {
                Ok(()) => self.sync_dir()?,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e.into()),
            }
            return self.remove_legacy();
        }
        let tmp = self.dir.join(format!("{STORE_FILE}.tmp"));
        {
            let mut f = fs::File::create(&tmp)?;
            f.write_all(&encode_store(&blobs))?;
            f.sync_all()?;
        }
        if let Err(e) = fs::rename(&tmp, &path) {
            // Something that is not a file is in the store's place (a directory): it stays,
            // and so does nothing of this attempt.
            let _ = fs::remove_file(&tmp);
            return Err(e.into());
        }
        self.sync_dir()?;
        // A crash before this point leaves the older files beside a whole STORE_FILE, which
        // is read first; the next commit removes them.
        self.remove_legacy()
    }
}

const MAGIC: &[u8; 4] = b"CTOD";
const VERSION: u8 = 1;
const STORE_MAGIC: &[u8; 4] = b"CTPS";
const STORE_VERSION: u8 = 1;

fn fnv1a(data: &[u8]) -> u32 {
    data.iter().fold(0x811C_9DC5u32, |h, b| {
        (h ^ u32::from(*b)).wrapping_mul(0x0100_0193)
    })
}

fn encode_store(blobs: &Blobs) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + blobs.iter().flatten().map(Vec::len).sum::<usize>());
    out.extend_from_slice(STORE_MAGIC);
    out.push(STORE_VERSION);
    for g in Group::ALL {
        let Some(blob) = &blobs[g.slot()] else {
            continue;
        };
        out.push(g.number());
        // A blob holds at most the values of one dictionary; u32 lengths cover any.
        out.extend_from_slice(&(blob.len() as u32).to_le_bytes());
        out.extend_from_slice(blob);
    }
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// The groups of a [`STORE_FILE`], or what is wrong with it. The checksum covers the whole
/// file, so a torn or mixed file is refused as a whole.
fn parse_store(bytes: &[u8]) -> Result<Blobs, &'static str> {
    if bytes.is_empty() {
        return Err("the file is empty");
    }
    let body_len = bytes.len().checked_sub(4).ok_or("the file is truncated")?;
    let (body, sum) = bytes.split_at(body_len);
    let rest = body
        .strip_prefix(STORE_MAGIC.as_slice())
        .ok_or("not a parameter store (wrong magic)")?;
    if sum != fnv1a(body).to_le_bytes() {
        return Err("checksum mismatch (the file is truncated or damaged)");
    }
    let [version, tail @ ..] = rest else {
        return Err("no version");
    };
    let mut rest: &[u8] = tail;
    if *version != STORE_VERSION {
        return Err("unknown store version");
    }
    let mut blobs: Blobs = Default::default();
    while let [n, l0, l1, l2, l3, tail @ ..] = rest {
        let group = Group::from_number(*n).ok_or("unknown group")?;
        let len = u32::from_le_bytes([*l0, *l1, *l2, *l3]) as usize;
        if tail.len() < len {
            return Err("a group is truncated");
        }
        let (blob, tail) = tail.split_at(len);
        if blobs[group.slot()].replace(blob.to_vec()).is_some() {
            return Err("a group appears twice");
        }
        rest = tail;
    }
    if !rest.is_empty() {
        return Err("trailing bytes after the groups");
    }
    Ok(blobs)
}

/// Whether a sub-object is a stored parameter: writable, and not one of the command
/// objects (0x1003 error field, 0x1010 store, 0x1011 restore).
fn stored(index: u16, access: Access) -> bool {
    access.writable() && !matches!(index, 0x1003 | 0x1010 | 0x1011)
}

/// The blob of `group`'s parameters in `od`.
pub fn encode(od: &ObjectDictionary, group: Group) -> Vec<u8> {
    let desc = od.description();
    let range = group.range();
    let mut entries = Vec::new();
    for obj in desc.objects().filter(|o| range.contains(&o.index())) {
        for (sub, d) in obj.subs() {
            if !stored(obj.index(), d.access) {
                continue;
            }
            let Ok(id) = od.locate(obj.index(), sub) else {
                continue;
            };
            entries.push((obj.index(), sub, od.raw(id)));
        }
    }
    encode_entries(entries)
}

/// A blob of the values `entries` (index, sub-index, bytes), for a device that keeps the
/// parameters outside its dictionary (values longer than 65535 bytes are left out).
pub fn encode_entries<'a>(entries: impl IntoIterator<Item = Entry<'a>>) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    for (index, sub, raw) in entries {
        let Ok(len) = u16::try_from(raw.len()) else {
            continue;
        };
        out.extend_from_slice(&index.to_le_bytes());
        out.push(sub);
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(raw);
    }
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// The values of a blob made by [`encode`] or [`encode_entries`], or what is wrong with
/// it (checksum, magic, version, layout).
pub fn decode_entries(blob: &[u8]) -> Result<Vec<Entry<'_>>, StorageError> {
    entries(blob)
}

/// One stored value: index, sub-index, bytes.
pub type Entry<'a> = (u16, u8, &'a [u8]);

/// The entries of a blob, or what is wrong with it.
fn entries(blob: &[u8]) -> Result<Vec<Entry<'_>>, StorageError> {
    if blob.is_empty() {
        return Err(StorageError::Corrupt("empty"));
    }
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
    Ok(entries)
}

/// Applies a blob to `od`: every entry for an existing stored parameter of `group` with a
/// fitting length is set; others (objects a newer firmware dropped) are skipped. Returns
/// how many values were set. A damaged blob sets nothing.
pub fn apply(od: &mut ObjectDictionary, group: Group, blob: &[u8]) -> Result<usize, StorageError> {
    // The whole layout is validated before the dictionary is touched.
    let entries = entries(blob)?;
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

    #[test]
    fn store_file_refuses_every_cut_and_every_flipped_bit() {
        let blobs: Blobs = [Some(b"comm".to_vec()), None, Some(b"application".to_vec())];
        let file = encode_store(&blobs);
        assert_eq!(parse_store(&file).unwrap(), blobs);
        for cut in 0..file.len() {
            assert!(parse_store(&file[..cut]).is_err(), "cut {cut}");
        }
        for bit in 0..file.len() * 8 {
            let mut bad = file.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            assert!(parse_store(&bad).is_err(), "bit {bit}");
        }
    }

    #[test]
    fn memory_storage_commits_every_change() {
        let mut m = MemoryStorage::new();
        m.commit(&[
            (Group::Communication, Some(b"a")),
            (Group::Manufacturer, Some(b"b")),
        ])
        .unwrap();
        m.commit(&[(Group::Communication, None)]).unwrap();
        assert_eq!(m.load(Group::Communication).unwrap(), None);
        assert_eq!(m.load(Group::Manufacturer).unwrap().unwrap(), b"b");
    }
}
