//! The drive's parameter memory: what "Save all parameters" (0x1010 sub 1, the card's only
//! store sub-index, §1.1 object table) keeps across a power cycle, and what a power-up finds.
//!
//! The drive parameters are not in the card's dictionary ([`crate::station`]): they live in
//! the drive. So the card's CiA 301 device is given a [`Storage`] of its own that takes the
//! dictionary's groups and hands the store to the card, which replaces the manufacturer
//! group (0x2000–0x5FFF, the §1.4 parameter window) with the drive's settable parameters,
//! each as 0x2000 + PAR sub 1 at its size, and commits all groups at once to the backend
//! (one file, replaced atomically: `cantwin_canopen::storage`). A power-up loads the
//! parameters before the drive reset latches them.
//!
//! Memory that cannot be read (a damaged or foreign file, a directory in its place, a value
//! outside its parameter's limits) leaves the drive on its factory parameters and raises
//! the alarm the manual gives for it, **Param error** (§1.5 drive alarm table, EMCY 0xFF2D:
//! [`crate::alarms::Alarm::ParamError`]), as does a save the backend refuses.

use std::sync::{Arc, Mutex, PoisonError};

use cantwin_canopen::storage::{
    Change, Group, Storage, StorageError, decode_entries, encode_entries,
};

use crate::params::{ParamAccess, ParamDb, catalog, par};
use crate::station::PARAMS_FIRST;

/// A store the card's device asked for, waiting for the drive's parameters.
type Pending = Vec<(Group, Option<Vec<u8>>)>;

/// The drive's parameter memory, shared with the card's device of every drive reset.
#[derive(Clone)]
pub struct Memory {
    backend: Arc<Mutex<Box<dyn Storage>>>,
    pending: Arc<Mutex<Option<Pending>>>,
}

impl core::fmt::Debug for Memory {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Memory").finish_non_exhaustive()
    }
}

/// The card device's view of the memory (see the [module documentation](self)).
struct CardStorage(Memory);

impl Storage for CardStorage {
    fn load(&mut self, group: Group) -> Result<Option<Vec<u8>>, StorageError> {
        // The drive parameters are loaded into the drive at power-up, not into the
        // dictionary, whose manufacturer objects are only the hooks' window onto them.
        if group == Group::Manufacturer {
            return Ok(None);
        }
        self.0.lock_backend().load(group)
    }

    fn commit(&mut self, changes: &[Change<'_>]) -> Result<(), StorageError> {
        let owned = changes
            .iter()
            .map(|(g, d)| (*g, d.map(<[u8]>::to_vec)))
            .collect();
        *self
            .0
            .pending
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(owned);
        Ok(())
    }
}

/// Whether parameter `p` is a setting the memory keeps: writable, and not a command.
fn kept(p: u16, access: ParamAccess) -> bool {
    access == ParamAccess::Rw && p != par::ALARM_RESET
}

impl Memory {
    /// A memory on `backend` (e.g. a `FileStorage` in the scenario's state directory).
    pub fn new(backend: Box<dyn Storage>) -> Self {
        Memory {
            backend: Arc::new(Mutex::new(backend)),
            pending: Arc::new(Mutex::new(None)),
        }
    }

    fn lock_backend(&self) -> std::sync::MutexGuard<'_, Box<dyn Storage>> {
        self.backend.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The storage to give the card's device.
    pub(crate) fn card_storage(&self) -> Box<dyn Storage> {
        Box::new(CardStorage(self.clone()))
    }

    /// Loads the saved parameters into `db` at power-up: all or none. `Ok(false)` when
    /// nothing was saved.
    pub fn load_params(&self, db: &mut ParamDb) -> Result<bool, StorageError> {
        let Some(blob) = self.lock_backend().load(Group::Manufacturer)? else {
            return Ok(false);
        };
        let mut values = Vec::new();
        for (index, sub, bytes) in decode_entries(&blob)? {
            let p = index.checked_sub(PARAMS_FIRST).filter(|_| sub == 1).ok_or(
                StorageError::Corrupt("an entry outside the parameter window"),
            )?;
            let v = ParamDb::decode(p, bytes)
                .map_err(|_| StorageError::Corrupt("a parameter that does not exist"))?;
            db.check(p, v)
                .map_err(|_| StorageError::Corrupt("a value outside its parameter's limits"))?;
            values.push((p, v));
        }
        for (p, v) in values {
            db.set(p, v)
                .map_err(|_| StorageError::Corrupt("a value the drive refuses"))?;
        }
        Ok(true)
    }

    /// The blob of the drive's settable parameters.
    fn params_blob(db: &ParamDb) -> Vec<u8> {
        let values: Vec<(u16, [u8; 4], usize)> = catalog()
            .iter()
            .filter(|d| kept(d.par, d.access))
            .filter_map(|d| db.encode(d.par).ok().map(|(b, n)| (d.par, b, n)))
            .collect();
        encode_entries(
            values
                .iter()
                .map(|(p, b, n)| (PARAMS_FIRST + p, 1u8, &b[..*n])),
        )
    }

    /// Completes a store the card's device asked for since the last call, with the drive's
    /// parameters in `db`. `Ok(false)` when there was none.
    pub(crate) fn flush(&self, db: &ParamDb) -> Result<bool, StorageError> {
        let Some(mut changes) = self
            .pending
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
        else {
            return Ok(false);
        };
        for (g, data) in &mut changes {
            if *g == Group::Manufacturer && data.is_some() {
                *data = Some(Self::params_blob(db));
            }
        }
        let borrowed: Vec<Change<'_>> = changes.iter().map(|(g, d)| (*g, d.as_deref())).collect();
        self.lock_backend().commit(&borrowed)?;
        Ok(true)
    }
}

/// What a power-up found wrong with the memory, in words (for a front end's warning).
pub fn describe(e: &StorageError) -> String {
    match e {
        StorageError::Corrupt(why) => format!("the saved drive parameters are damaged: {why}"),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::storage::MemoryStorage;

    #[test]
    fn saved_parameters_load_all_or_none() {
        let mut db = ParamDb::new();
        db.set(par::FIELDBUS_ADDRESS, 12).unwrap();
        let blob = Memory::params_blob(&db);
        let mut backend = MemoryStorage::new();
        backend.save(Group::Manufacturer, &blob).unwrap();
        let m = Memory::new(Box::new(backend));
        let mut fresh = ParamDb::new();
        assert!(m.load_params(&mut fresh).unwrap());
        assert_eq!(fresh.value(par::FIELDBUS_ADDRESS), 12);
        // A value outside its limits refuses the whole blob.
        let bad = encode_entries([
            (PARAMS_FIRST + par::FIELDBUS_ADDRESS, 1, &[5u8, 0][..]),
            (PARAMS_FIRST + par::FIELDBUS_ADDRESS, 1, &[0xFF, 0x7F][..]),
        ]);
        let mut backend = MemoryStorage::new();
        backend.save(Group::Manufacturer, &bad).unwrap();
        let m = Memory::new(Box::new(backend));
        let mut fresh = ParamDb::new();
        assert!(m.load_params(&mut fresh).is_err());
        assert_eq!(fresh.value(par::FIELDBUS_ADDRESS), 0);
    }
}
