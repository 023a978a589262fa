//! Stored parameters that cannot be read (CiA 301 §7.5.2.10): the device keeps its
//! defaults, raises EMCY 0x5000 (device hardware) with the generic bit of the error register
//! (§7.5.2.2), and [`FileStorage::check`] names the file and why; "save all" keeps every
//! group in one file, and stores written one file per group are read and moved into it.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_canopen::device::Event;
use cantwin_canopen::storage::{FileStorage, Group, SAVE, STORE_FILE, Storage, StorageError};
use device_harness::*;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-damage-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A device powered on the store in `dir`.
fn powered_on(dir: &Path) -> Harness {
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(FileStorage::new(dir).unwrap()));
    h.power_up(ms(0));
    h.run_until(ms(1));
    h
}

/// A whole store in `dir` holding 0x1017 = 100 and 0x2000 = 42.
fn good_store(dir: &Path) -> Vec<u8> {
    let mut h = powered_on(dir);
    h.write(ms(1), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(1), 0x2000, 0, &42u32.to_le_bytes()).unwrap();
    h.write(ms(1), 0x1010, 1, &SAVE.to_le_bytes()).unwrap();
    std::fs::read(dir.join(STORE_FILE)).unwrap()
}

fn unreadable_reason(dir: &Path) -> String {
    let problems = FileStorage::new(dir).unwrap().check();
    assert_eq!(problems.len(), 1, "{problems:?}");
    match &problems[0] {
        StorageError::Unreadable { file, reason } => {
            assert_eq!(file, &dir.join(STORE_FILE));
            let text = problems[0].to_string();
            assert!(text.contains(STORE_FILE), "{text}");
            reason.clone()
        }
        other => panic!("{other:?}"),
    }
}

/// Every group failed: EMCY 0x5000, register 0x01 (generic), groups 2|3|4 as bits.
const EMCY_ALL_GROUPS: &str = "085#0050011C00000000";

fn assert_defaults_and_emcy(h: &mut Harness) {
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 0);
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x01);
    assert_eq!(h.take(), at_ms(&[(0, "705#00"), (0, EMCY_ALL_GROUPS)]));
    let events = h.events();
    for g in Group::ALL {
        assert!(events.contains(&Event::StorageLoadFailed(g)), "{events:?}");
    }
}

#[test]
fn cia301_7_5_2_10_a_truncated_store_is_reported_with_emcy_5000_and_defaults() {
    let dir = scratch("truncated");
    let whole = good_store(&dir);
    // Every cut of the file, not only one.
    for cut in 0..whole.len() {
        std::fs::write(dir.join(STORE_FILE), &whole[..cut]).unwrap();
        let reason = unreadable_reason(&dir);
        assert!(
            reason.contains("truncated") || reason.contains("empty") || reason.contains("magic"),
            "cut {cut}: {reason}"
        );
    }
    std::fs::write(dir.join(STORE_FILE), &whole[..whole.len() / 2]).unwrap();
    assert_defaults_and_emcy(&mut powered_on(&dir));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cia301_7_5_2_10_random_bytes_empty_file_and_directory_are_reported() {
    let dir = scratch("kinds");
    let whole = good_store(&dir);
    let path = dir.join(STORE_FILE);
    let mut x: u32 = 0x1234_5678;
    let random: Vec<u8> = (0..300)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect();
    let mut flipped = whole.clone();
    flipped[whole.len() / 2] ^= 0x40;
    let cases: [(&str, &[u8], &str); 3] = [
        ("random", &random, "magic"),
        ("empty", &[], "empty"),
        ("flipped", &flipped, "checksum mismatch"),
    ];
    for (what, bytes, why) in cases {
        std::fs::write(&path, bytes).unwrap();
        let reason = unreadable_reason(&dir);
        assert!(reason.contains(why), "{what}: {reason}");
        assert_defaults_and_emcy(&mut powered_on(&dir));
    }
    std::fs::remove_file(&path).unwrap();
    std::fs::create_dir(&path).unwrap();
    let reason = unreadable_reason(&dir);
    assert!(!reason.is_empty());
    let mut h = powered_on(&dir);
    assert_defaults_and_emcy(&mut h);
    // Saving cannot replace a directory: the protocol's answer, the directory untouched.
    assert_eq!(
        h.write(ms(2), 0x1010, 1, &SAVE.to_le_bytes()),
        Err(cantwin_canopen::abort::AbortCode::HARDWARE_ERROR)
    );
    assert!(path.is_dir());
    assert!(!dir.join(format!("{STORE_FILE}.tmp")).exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cia301_7_5_2_10_a_damaged_group_inside_a_whole_file_is_reported_alone() {
    let dir = scratch("group");
    good_store(&dir);
    let mut s = FileStorage::new(&dir).unwrap();
    s.save(Group::Manufacturer, b"CTOD\x01garbage").unwrap();
    let problems = s.check();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].to_string().contains("manufacturer"),
        "{}",
        problems[0]
    );
    let mut h = powered_on(&dir);
    // The communication group still loads; the manufacturer one keeps its default.
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 100);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    let sent = h.take();
    assert!(
        sent.contains(&(0, "085#0050011000000000".to_string())),
        "{sent:?}"
    );
    // A save makes the store whole again and clears the error (EMCY 0x0000).
    h.write(ms(2), 0x1010, 1, &SAVE.to_le_bytes()).unwrap();
    h.run_until(ms(3));
    assert_eq!(h.take(), at_ms(&[(2, "085#0000000000000000")]));
    assert!(FileStorage::new(&dir).unwrap().check().is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn stores_of_one_file_per_group_are_read_and_moved_into_one_file() {
    let dir = scratch("legacy");
    let whole = good_store(&dir);
    // The same groups, written the older way.
    let h = powered_on(&dir);
    let comm = cantwin_canopen::storage::encode(h.dev.od(), Group::Communication);
    let mfr = cantwin_canopen::storage::encode(h.dev.od(), Group::Manufacturer);
    std::fs::remove_file(dir.join(STORE_FILE)).unwrap();
    std::fs::write(dir.join("communication.params"), &comm).unwrap();
    std::fs::write(dir.join("manufacturer.params"), &mfr).unwrap();
    let mut h = powered_on(&dir);
    assert_eq!(h.read_u32(0x1017, 0).unwrap(), 100);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    assert!(
        h.events()
            .iter()
            .all(|e| !matches!(e, Event::StorageLoadFailed(_)))
    );
    // Storing the communication group alone moves the manufacturer group along.
    h.write(ms(2), 0x1010, 2, &SAVE.to_le_bytes()).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, [STORE_FILE]);
    let mut h = powered_on(&dir);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 42);
    let mut s = FileStorage::new(&dir).unwrap();
    assert_eq!(s.load(Group::Manufacturer).unwrap().unwrap(), mfr);
    // The application group was not in the older store and is not in the new one.
    assert_eq!(s.load(Group::Application).unwrap(), None);
    assert!(whole.len() > std::fs::read(dir.join(STORE_FILE)).unwrap().len());
    std::fs::remove_dir_all(&dir).unwrap();
}
