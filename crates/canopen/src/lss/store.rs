//! Where an LSS slave keeps its configuration (CiA 305 §4.4.4 store configuration): the
//! node-ID and the bit rate it powers up with.
//!
//! [`FileStore`] keeps it in one file, `lss.params`: magic `CTLS`, version 1, the node-ID
//! (u8), the bit rate in bit/s (u32, little-endian), and an FNV-1a checksum (u32) of what
//! comes before. The file is replaced atomically (temporary file, fsync, rename, fsync of
//! the directory), so a crash leaves the old or the new configuration, never half of one.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use cantwin_can::BitRate;

use crate::storage::StorageError;

/// A stored LSS configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stored {
    /// The node-ID, 1–127 or 0xFF (not configured).
    pub node_id: u8,
    /// The bit rate.
    pub bit_rate: BitRate,
}

/// Where a slave keeps its configuration. Called synchronously by the slave.
pub trait Store: Send {
    /// The stored configuration, if any.
    fn load(&mut self) -> Result<Option<Stored>, StorageError>;
    /// Replaces the stored configuration.
    fn save(&mut self, stored: &Stored) -> Result<(), StorageError>;
}

/// A configuration kept in memory: it survives resets, not the process.
#[derive(Debug, Clone, Copy, Default)]
pub struct MemoryStore {
    stored: Option<Stored>,
}

impl MemoryStore {
    /// An empty store.
    pub fn new() -> Self {
        MemoryStore::default()
    }
}

impl Store for MemoryStore {
    fn load(&mut self) -> Result<Option<Stored>, StorageError> {
        Ok(self.stored)
    }
    fn save(&mut self, stored: &Stored) -> Result<(), StorageError> {
        self.stored = Some(*stored);
        Ok(())
    }
}

/// A configuration in the file `lss.params` of a directory.
#[derive(Debug, Clone)]
pub struct FileStore {
    dir: PathBuf,
}

const MAGIC: &[u8; 4] = b"CTLS";
const VERSION: u8 = 1;
const FILE: &str = "lss.params";

fn fnv1a(data: &[u8]) -> u32 {
    data.iter().fold(0x811C_9DC5u32, |h, b| {
        (h ^ u32::from(*b)).wrapping_mul(0x0100_0193)
    })
}

/// The bytes of `stored` in the file format.
pub fn encode(stored: &Stored) -> Vec<u8> {
    let mut b = Vec::with_capacity(14);
    b.extend_from_slice(MAGIC);
    b.push(VERSION);
    b.push(stored.node_id);
    b.extend_from_slice(&stored.bit_rate.bits_per_second().to_le_bytes());
    let sum = fnv1a(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    b
}

/// The configuration in `data`, or why it cannot be used.
pub fn decode(data: &[u8]) -> Result<Stored, StorageError> {
    if data.len() != 14 || &data[..4] != MAGIC {
        return Err(StorageError::Corrupt("not an LSS configuration"));
    }
    if data[4] != VERSION {
        return Err(StorageError::Corrupt("unknown LSS configuration version"));
    }
    let sum = u32::from_le_bytes([data[10], data[11], data[12], data[13]]);
    if sum != fnv1a(&data[..10]) {
        return Err(StorageError::Corrupt("LSS configuration checksum"));
    }
    let node_id = data[5];
    if !(1..=127).contains(&node_id) && node_id != super::wire::UNCONFIGURED {
        return Err(StorageError::Corrupt("stored node-ID out of range"));
    }
    let bps = u32::from_le_bytes([data[6], data[7], data[8], data[9]]);
    let bit_rate = BitRate::from_bits_per_second(bps)
        .ok_or(StorageError::Corrupt("stored bit rate unknown"))?;
    Ok(Stored { node_id, bit_rate })
}

impl FileStore {
    /// A store in `dir` (created if missing).
    pub fn new(dir: impl Into<PathBuf>) -> Result<Self, StorageError> {
        let dir = dir.into();
        fs::create_dir_all(&dir)?;
        Ok(FileStore { dir })
    }

    /// The file that holds the configuration.
    pub fn path(&self) -> PathBuf {
        self.dir.join(FILE)
    }

    fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Store for FileStore {
    fn load(&mut self) -> Result<Option<Stored>, StorageError> {
        match fs::read(self.path()) {
            Ok(b) => decode(&b).map(Some),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e.into()),
        }
    }

    fn save(&mut self, stored: &Stored) -> Result<(), StorageError> {
        let tmp = self.dir.join(format!("{FILE}.tmp"));
        {
            let mut f = fs::File::create(&tmp)?;
            f.write_all(&encode(stored))?;
            f.sync_all()?;
        }
        fs::rename(&tmp, self.path())?;
        #[cfg(unix)]
        fs::File::open(self.dir())?.sync_all()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_configuration_round_trips_and_damage_is_refused() {
        let s = Stored {
            node_id: 42,
            bit_rate: BitRate::R250K,
        };
        let b = encode(&s);
        assert_eq!(decode(&b).unwrap(), s);
        let mut bad = b.clone();
        bad[5] = 43;
        assert!(decode(&bad).is_err());
        assert!(decode(&b[..13]).is_err());
        let dir = std::env::temp_dir().join(format!("cantwin-lss-store-{}", std::process::id()));
        let mut f = FileStore::new(&dir).unwrap();
        assert_eq!(f.load().unwrap(), None);
        f.save(&s).unwrap();
        assert_eq!(FileStore::new(&dir).unwrap().load().unwrap(), Some(s));
        fs::remove_dir_all(&dir).unwrap();
    }
}
