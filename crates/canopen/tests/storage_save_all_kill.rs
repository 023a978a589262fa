//! "Save all" (CiA 301 §7.5.2.10, 0x1010 sub 1) is atomic as a whole: a device process killed
//! (SIGKILL: no destructor, no flush) at a random moment around a store leaves the three
//! groups of the old set or of the new set, never some of each and never a torn file.
//!
//! The test re-runs its own binary as a child: a device on a [`FileStorage`] that sets
//! a communication (0x1017), a manufacturer (0x2000) and an application (0x6200) parameter to
//! the same generation number and stores all, over and over, reporting each completed
//! store on stdout. The parent kills it a seeded random time after a seeded random number
//! of stores, then powers a new device on the store: it must load without a fault, every
//! group must hold one generation, and that generation must be the last reported one or
//! the next. 100 kills by default; `CANTWIN_KILL_CAMPAIGN=N` runs N (a long campaign).
#![allow(clippy::unwrap_used)]

mod device_harness;

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use cantwin_canopen::device::Event;
use cantwin_canopen::storage::{FileStorage, SAVE, STORE_FILE};
use device_harness::*;

const CHILD_DIR: &str = "CANTWIN_SAVE_ALL_KILL_DIR";

fn powered_on(dir: &Path) -> Harness {
    let mut h = Harness::new();
    h.dev.set_storage(Box::new(FileStorage::new(dir).unwrap()));
    h.power_up(ms(0));
    h
}

/// Sets every group's parameter to generation `g` and stores all.
fn store_generation(h: &mut Harness, g: u64) {
    h.write(ms(1), 0x1017, 0, &(g as u16).to_le_bytes())
        .unwrap();
    h.write(ms(1), 0x2000, 0, &(g as u32).to_le_bytes())
        .unwrap();
    h.write(ms(1), 0x6200, 0, &[g as u8]).unwrap();
    h.write(ms(1), 0x1010, 1, &SAVE.to_le_bytes()).unwrap();
}

/// The child: stores generation after generation until killed.
#[test]
#[ignore = "run by save_all_survives_kills_around_the_store as its child process"]
fn save_all_kill_child() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else {
        return;
    };
    let dir = Path::new(&dir);
    let mut h = powered_on(dir);
    let first = generation_of(&mut h).map_or(1, |g| g + 1);
    let mut out = std::io::stdout().lock();
    for g in first.. {
        store_generation(&mut h, g);
        writeln!(out, "stored {g}").unwrap();
        out.flush().unwrap();
    }
}

/// The generation a device holds, if all three groups agree (0x1017 holds its low 16 bits,
/// 0x6200 its low 8); panics on a mix.
fn generation_of(h: &mut Harness) -> Option<u64> {
    let comm = h.read_u32(0x1017, 0).unwrap();
    let mfr = h.read_u32(0x2000, 0).unwrap();
    let app = h.read_u32(0x6200, 0).unwrap();
    if (comm, mfr, app) == (0, 7, 0) {
        return None;
    }
    assert!(
        comm == mfr & 0xFFFF && app == mfr & 0xFF,
        "a mixed parameter set: 0x1017 = {comm}, 0x2000 = {mfr}, 0x6200 = {app}"
    );
    Some(u64::from(comm))
}

fn kills() -> u32 {
    std::env::var("CANTWIN_KILL_CAMPAIGN")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100)
}

#[test]
fn save_all_survives_kills_around_the_store() {
    let dir = std::env::temp_dir().join(format!("cantwin-save-all-kill-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    store_generation(&mut powered_on(&dir), 0);
    let exe = std::env::current_exe().unwrap();
    let mut rng: u64 = 0x5A7E_A110;
    let mut next = || {
        rng = rng
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        rng >> 33
    };
    let (mut old, mut new, mut interrupted) = (0u32, 0u32, 0u32);
    let started = Instant::now();
    let n = kills();
    for kill in 0..n {
        let stores_before_kill = 1 + next() % 4;
        // Up to 3 ms after the last reported store: before, inside or after the next one.
        let delay = Duration::from_micros(next() % 3000);
        let mut child = Command::new(&exe)
            .args([
                "--ignored",
                "--exact",
                "save_all_kill_child",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_DIR, &dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let mut last = None;
        let mut stores = 0;
        while stores < stores_before_kill {
            let Some(line) = lines.next() else { break };
            if let Some(g) = line.unwrap().strip_prefix("stored ") {
                last = Some(g.parse::<u64>().unwrap());
                stores += 1;
            }
        }
        std::thread::sleep(delay);
        child.kill().unwrap();
        child.wait().unwrap();
        let last = last.unwrap_or_else(|| panic!("kill {kill}: the child stored nothing"));
        if dir.join(format!("{STORE_FILE}.tmp")).exists() {
            interrupted += 1;
        }
        let mut h = powered_on(&dir);
        let events = h.events();
        assert!(
            events
                .iter()
                .all(|e| !matches!(e, Event::StorageLoadFailed(_))),
            "kill {kill}: the store does not load: {:?}",
            FileStorage::new(&dir).unwrap().check()
        );
        let got = generation_of(&mut h).expect("the store vanished");
        // The child may have finished stores it had no time to report, never lost one it
        // reported.
        assert!(
            got >= last,
            "kill {kill}: generation {got} after {last} was reported"
        );
        if got == last {
            old += 1;
        } else {
            new += 1;
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    eprintln!(
        "save all: {n} SIGKILLs in {:.1} s; found the last reported set {old} times, a newer whole set {new} times; {interrupted} kills left a temporary file (a store cut between create and rename); 0 mixed, 0 torn",
        started.elapsed().as_secs_f64()
    );
}
