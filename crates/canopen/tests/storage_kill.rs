//! Crash safety of [`FileStorage`] (CiA 301 §7.5.2.10 "store parameters"): a process killed
//! at any moment of a store leaves the old or the new parameter set, never a mix or garbage.
//!
//! The test re-runs its own binary as a child that stores two parameter sets alternately, as
//! fast as it can, and reports each completed store on stdout. The parent lets it complete a
//! seeded random number of stores, kills it (SIGKILL on Unix: no destructor, no flush) while
//! it is in the middle of the next one, and loads the store. `CANTWIN_KILL_CYCLES` raises
//! the number of cycles for a long campaign.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use cantwin_canopen::storage::{FileStorage, Group, Storage};

const CHILD_DIR: &str = "CANTWIN_STORAGE_KILL_DIR";
/// Large enough that a store takes several write calls' time.
const SET_LEN: usize = 256 * 1024;

/// Parameter set `k` (0 or 1): a header naming it, then a pattern that differs everywhere
/// between the sets, so any mix of the two is detected.
fn set(k: u8) -> Vec<u8> {
    let mut v = Vec::with_capacity(SET_LEN);
    v.extend_from_slice(b"CTOD-set-");
    v.push(b'0' + k);
    let mut x: u32 = 0x9E37_79B9 ^ u32::from(k);
    while v.len() < SET_LEN {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        v.push((x as u8) ^ (k * 0x5A));
    }
    v
}

/// The child: stores set 0 and set 1 alternately until killed.
#[test]
#[ignore = "run by file_storage_survives_a_kill_during_store as its child process"]
fn storage_kill_child() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else {
        return;
    };
    let mut storage = FileStorage::new(PathBuf::from(dir)).unwrap();
    let sets = [set(0), set(1)];
    let mut out = std::io::stdout().lock();
    for n in 0u64.. {
        let k = (n % 2) as usize;
        storage.save(Group::Manufacturer, &sets[k]).unwrap();
        writeln!(out, "stored {k}").unwrap();
        out.flush().unwrap();
    }
}

fn cycles() -> u32 {
    std::env::var("CANTWIN_KILL_CYCLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20)
}

fn load(dir: &Path) -> Option<Vec<u8>> {
    FileStorage::new(dir)
        .unwrap()
        .load(Group::Manufacturer)
        .unwrap()
}

#[test]
fn file_storage_survives_a_kill_during_store() {
    let dir = std::env::temp_dir().join(format!("cantwin-storage-kill-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let sets = [set(0), set(1)];
    // The store starts with set 0, so that "old" exists from the first cycle on.
    FileStorage::new(&dir)
        .unwrap()
        .save(Group::Manufacturer, &sets[0])
        .unwrap();
    let exe = std::env::current_exe().unwrap();
    let mut rng: u64 = 0x5EED_0301;
    let mut seen = [0u32; 2];
    // Kills that left a temporary file behind: they hit a store between create and rename.
    let mut interrupted = 0u32;
    for cycle in 0..cycles() {
        rng = rng
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let stores_before_kill = 1 + (rng >> 59); // 1..=32
        let mut child = Command::new(&exe)
            .args([
                "--ignored",
                "--exact",
                "storage_kill_child",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_DIR, &dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let mut last = None;
        let mut stores = 0;
        for line in BufReader::new(stdout).lines() {
            let line = line.unwrap();
            if let Some(k) = line.strip_prefix("stored ") {
                last = Some(k.parse::<usize>().unwrap());
                stores += 1;
                if stores == stores_before_kill {
                    // The child is already writing the next set.
                    break;
                }
            }
        }
        child.kill().unwrap();
        child.wait().unwrap();
        if dir.join("parameters.store.tmp").exists() {
            interrupted += 1;
        }
        let got = load(&dir).expect("the store vanished");
        let which = sets.iter().position(|s| *s == got).unwrap_or_else(|| {
            panic!(
                "cycle {cycle}: the store holds {} bytes that are neither set (header {:?})",
                got.len(),
                String::from_utf8_lossy(&got[..got.len().min(10)])
            )
        });
        seen[which] += 1;
        assert!(last.is_some(), "cycle {cycle}: the child stored nothing");
    }
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(seen[0] + seen[1], cycles(), "{seen:?}");
    eprintln!(
        "{} kills during stores ({interrupted} between create and rename): set 0 found {} times, set 1 {} times",
        cycles(),
        seen[0],
        seen[1]
    );
}
