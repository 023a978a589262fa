//! CiA 301 §7.5.2.10/§7.5.2.11: store and restore parameters, through memory and files.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_canopen::ObjectAccess;
use cantwin_canopen::abort::AbortCode;
use cantwin_canopen::device::Event;
use cantwin_canopen::storage::{FileStorage, Group, LOAD, MemoryStorage, SAVE, Storage};
use device_harness::*;
use std::path::PathBuf;

fn sig(v: u32) -> [u8; 4] {
    v.to_le_bytes()
}

fn with_memory() -> Harness {
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(MemoryStorage::new()));
    h.power_up(ms(0));
    assert_eq!(h.take(), at_ms(&[(0, "705#00")]));
    h
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-canopen-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn cia301_7_5_2_10_store_then_reset_node_then_load() {
    let mut h = with_memory();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(1), 0x1010, 1, &sig(SAVE)).unwrap();
    h.write(ms(2), 0x1017, 0, &0u16.to_le_bytes()).unwrap();
    h.write(ms(2), 0x2000, 0, &43u32.to_le_bytes()).unwrap();
    h.rx(ms(10), "000#8105");
    h.run_until(ms(250));
    // The stored producer time is back: a heartbeat every 100 ms after the boot-up.
    assert_eq!(
        h.take(),
        at_ms(&[(10, "705#00"), (110, "705#7F"), (210, "705#7F")])
    );
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 100);
}

#[test]
fn cia301_7_5_2_10_only_the_signature_save_stores() {
    let mut h = with_memory();
    assert_eq!(h.read_u32(0x1010, 1).unwrap(), 1);
    for wrong in [0, 0x6576_6174, LOAD] {
        assert_eq!(
            h.write(ms(0), 0x1010, 1, &sig(wrong)),
            Err(AbortCode::DATA_TRANSFER)
        );
    }
    assert_eq!(
        h.write(ms(0), 0x1011, 1, &sig(SAVE)),
        Err(AbortCode::DATA_TRANSFER)
    );
    // The command objects keep reading their capability.
    h.write(ms(0), 0x1010, 1, &sig(SAVE)).unwrap();
    assert_eq!(h.read_u32(0x1010, 1).unwrap(), 1);
}

#[test]
fn cia301_7_5_2_10_sub_indices_select_the_parameter_groups() {
    let mut h = with_memory();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    // Sub-index 2: communication parameters only.
    h.write(ms(0), 0x1010, 2, &sig(SAVE)).unwrap();
    h.rx(ms(10), "000#8105");
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 100);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    // Sub-index 4: manufacturer-specific parameters.
    h.write(ms(20), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(20), 0x1010, 4, &sig(SAVE)).unwrap();
    h.rx(ms(30), "000#8105");
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
}

#[test]
fn cia301_7_5_2_11_restore_defaults_takes_effect_after_the_next_reset() {
    let mut h = with_memory();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(0), 0x1010, 1, &sig(SAVE)).unwrap();
    assert_eq!(
        h.write(ms(1), 0x1011, 1, &sig(0x6461_6F6D)),
        Err(AbortCode::DATA_TRANSFER)
    );
    h.write(ms(1), 0x1011, 1, &sig(LOAD)).unwrap();
    // Nothing changes until a reset.
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 100);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    // Reset communication: communication defaults; application values untouched.
    h.rx(ms(10), "000#8205");
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 0);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    // Reset node: application defaults too.
    h.rx(ms(20), "000#8105");
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
}

#[test]
fn cia301_7_5_2_10_without_a_storage_backend_parameters_are_kept_in_memory() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    assert_eq!(h.write(ms(0), 0x1010, 1, &sig(SAVE)), Ok(()));
    h.write(ms(0), 0x2000, 0, &43u32.to_le_bytes()).unwrap();
    // Reset node and a power cycle of the same device restore the stored value.
    h.rx(ms(10), "000#8105");
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    h.write(ms(20), 0x2000, 0, &44u32.to_le_bytes()).unwrap();
    h.power_up(ms(30));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    // "load" erases it: the default after the next reset.
    assert_eq!(h.write(ms(40), 0x1011, 1, &sig(LOAD)), Ok(()));
    h.rx(ms(50), "000#8105");
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
}

#[test]
fn cia301_7_5_2_10_storage_moves_to_a_device_that_replaces_this_one() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(0), 0x1010, 1, &sig(SAVE)).unwrap();
    let storage = h.dev.take_storage();
    let mut next = Harness::new();
    next.dev.set_storage(storage);
    next.power_up(ms(10));
    assert_eq!(next.read_u32(0x2000, 0).unwrap(), 42);
    // What stays behind is an empty store.
    h.power_up(ms(20));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
}

#[test]
fn file_storage_survives_a_power_cycle_and_leaves_no_temporary_file() {
    let dir = scratch("power-cycle");
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(FileStorage::new(&dir).unwrap()));
    h.power_up(ms(0));
    h.write(ms(0), 0x1017, 0, &250u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(1), 0x1010, 1, &sig(SAVE)).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // One file holds every group ("save all" replaces them as one).
    assert_eq!(names, ["parameters.store"]);
    // A new device (a power cycle) with the same store.
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(FileStorage::new(&dir).unwrap()));
    h.power_up(ms(0));
    h.run_until(ms(300));
    assert_eq!(h.take(), at_ms(&[(0, "705#00"), (250, "705#7F")]));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    // "load" removes the files; the next power-up runs on defaults.
    h.write(ms(300), 0x1011, 1, &sig(LOAD)).unwrap();
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(FileStorage::new(&dir).unwrap()));
    h.power_up(ms(0));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn file_storage_damaged_blob_is_reported_and_defaults_apply() {
    let dir = scratch("damaged");
    let mut store = FileStorage::new(&dir).unwrap();
    store.save(Group::Manufacturer, b"CTOD\x01garbage").unwrap();
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(store));
    h.power_up(ms(0));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    assert!(
        h.events()
            .contains(&Event::StorageLoadFailed(Group::Manufacturer))
    );
    // A save replaces it whole.
    h.write(ms(1), 0x1010, 4, &sig(SAVE)).unwrap();
    let mut h2 = Harness::new();
    h2.dev
        .set_storage(Box::new(FileStorage::new(&dir).unwrap()));
    h2.power_up(ms(0));
    assert!(
        h2.events()
            .iter()
            .all(|e| !matches!(e, Event::StorageLoadFailed(_)))
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn file_storage_replaces_atomically() {
    let dir = scratch("atomic");
    let mut s = FileStorage::new(&dir).unwrap();
    s.save(Group::Communication, b"first").unwrap();
    // A stale temporary file from an interrupted save is neither read nor in the way.
    std::fs::write(dir.join("parameters.store.tmp"), b"half").unwrap();
    assert_eq!(s.load(Group::Communication).unwrap().unwrap(), b"first");
    s.save(Group::Communication, b"second").unwrap();
    assert_eq!(s.load(Group::Communication).unwrap().unwrap(), b"second");
    assert!(!dir.join("parameters.store.tmp").exists());
    s.erase(Group::Communication).unwrap();
    assert_eq!(s.load(Group::Communication).unwrap(), None);
    s.erase(Group::Communication).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn read_of_store_objects_through_object_access() {
    let mut h = with_memory();
    let mut b = [0u8; 4];
    let info = h.dev.read(0x1011, 4, 0, &mut b).unwrap();
    assert_eq!((info.size, b), (4, [1, 0, 0, 0]));
}
