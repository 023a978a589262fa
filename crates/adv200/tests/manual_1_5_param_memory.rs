//! "Save all parameters" (0x1010 sub 1, §1.1 object table) keeps the drive parameters across a
//! power cycle; a memory that cannot be read leaves the drive on the parameters it has and
//! raises the drive alarm Param error (§1.5 drive alarm table: EMCY 0xFF2D, alarm 45).
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::alarms::Alarm;
use cantwin_adv200::memory::Memory;
use cantwin_adv200::params::par;
use cantwin_canopen::storage::{FileStorage, STORE_FILE};
use common::*;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-adv200-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn drive_on(dir: &Path) -> H {
    H::canopen(|d| d.set_memory(Memory::new(Box::new(FileStorage::new(dir).unwrap()))))
}

#[test]
fn manual_1_1_save_all_keeps_the_drive_parameters_across_a_power_cycle() {
    let dir = scratch("save");
    let mut h = drive_on(&dir);
    // PAR 600 Dig ramp ref 1 = 1000 (§1.4 example), heartbeat 0x1017 = 200 ms, then save.
    assert_eq!(h.send("60C#2B582201E8030000"), ["58C#6058220100000000"]);
    assert_eq!(h.send("60C#2B171000C8000000"), ["58C#6017100000000000"]);
    assert_eq!(h.send("60C#2310100173617665"), ["58C#6010100100000000"]);
    assert!(dir.join(STORE_FILE).is_file());
    // A new drive from the factory, on the same memory.
    let h = drive_on(&dir);
    assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(1000));
    assert!(h.d.memory_error().is_none());
    assert!(
        !h.frames().iter().any(|f| f.starts_with("08C#")),
        "{:?}",
        h.frames()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn manual_1_5_unreadable_memory_raises_param_error_and_keeps_the_parameters() {
    let dir = scratch("damaged");
    let mut h = drive_on(&dir);
    assert_eq!(h.send("60C#2B582201E8030000"), ["58C#6058220100000000"]);
    assert_eq!(h.send("60C#2310100173617665"), ["58C#6010100100000000"]);
    let whole = std::fs::read(dir.join(STORE_FILE)).unwrap();
    let mut flipped = whole.clone();
    flipped[whole.len() / 2] ^= 0x10;
    for (what, bytes) in [
        ("truncated", &whole[..whole.len() - 3]),
        ("empty", &[][..]),
        ("flipped", &flipped[..]),
    ] {
        std::fs::write(dir.join(STORE_FILE), bytes).unwrap();
        let h = drive_on(&dir);
        // Factory value of PAR 600, and Param error: EMCY 0xFF2D, error register bit 7
        // (manufacturer) and bit 0.
        assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(0), "{what}");
        assert!(h.d.drive().alarms().contains(&Alarm::ParamError), "{what}");
        let emcy: Vec<String> = h
            .frames()
            .into_iter()
            .filter(|f| f.starts_with("08C#"))
            .collect();
        assert_eq!(emcy, ["08C#2DFF810000000000"], "{what}");
        assert!(h.d.memory_error().is_some(), "{what}");
    }
    // A directory in the memory's place.
    std::fs::remove_file(dir.join(STORE_FILE)).unwrap();
    std::fs::create_dir(dir.join(STORE_FILE)).unwrap();
    let h = drive_on(&dir);
    assert!(h.d.drive().alarms().contains(&Alarm::ParamError));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn manual_1_1_5_store_parameters_without_a_state_directory_keeps_them_in_memory() {
    // No memory given: 0x1010 sub 1 "save" is accepted and kept across a power cycle.
    let mut h = H::canopen(|_| {});
    assert_eq!(h.send("60C#4010100100000000"), ["58C#4310100101000000"]);
    assert_eq!(h.send("60C#2B582201E8030000"), ["58C#6058220100000000"]);
    assert_eq!(h.send("60C#2310100173617665"), ["58C#6010100100000000"]);
    assert_eq!(h.send("60C#2B5822010A000000"), ["58C#6058220100000000"]);
    let mut out = cantwin_can::Outbox::new();
    cantwin_can::Node::on_power_up(&mut h.d, cantwin_can::Instant::from_nanos(h.now), &mut out);
    assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(1000));
    assert!(h.d.memory_error().is_none());
}
