//! `cantwin replay` of a capture whose timestamps claim more time than it holds: a pcap of a
//! few seconds with one flipped timestamp byte (now spanning over a thousand hours) is
//! refused at once, naming the records around the gap, or replayed with the gap shortened;
//! either way in bounded time and memory.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant as WallInstant};

use cantwin_bus::Recorder;
use cantwin_can::Instant;
use cantwin_capture::Record;
use cantwin_scenario::{Registry, Scenario};

const EPOCH_NS: u64 = 1_700_000_000_000_000_000;

/// Two seconds of the cia301-device scenario on its own (boot-up, heartbeats every 100 ms),
/// as a pcap; the record at `flip` gets bit 6 of its seconds' third byte flipped: 2^22 s
/// (1,165 h) later.
fn flipped_pcap(path: &std::path::Path, flip: usize) -> usize {
    let scenario = Scenario::load(scenario_file("cia301-device.toml")).unwrap();
    let mut built = scenario
        .build(&Registry::builtin(), &Default::default())
        .unwrap();
    let can0 = built.bus("can0").unwrap();
    let tap = built.sim.bus_mut(can0).unwrap().add_tap(Recorder::new());
    built.sim.run_until(Instant::from_nanos(2_000_000_000));
    let records: Vec<Record> = built
        .sim
        .bus(can0)
        .unwrap()
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .filter(|f| !f.dropped)
        .map(|f| Record::new(EPOCH_NS + f.end.as_nanos(), "can0", f.frame))
        .collect();
    let mut bytes = Vec::new();
    let mut w = cantwin_capture::pcap::PcapWriter::new(&mut bytes).unwrap();
    for r in &records {
        w.write_record(r).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    // The file header is 24 bytes; each record a 16-byte header and a 16-byte can_frame.
    // The seconds are the record header's first (little-endian) word.
    bytes[24 + flip * 32 + 2] ^= 0x40;
    std::fs::write(path, &bytes).unwrap();
    assert!(bytes.len() < 4096, "a small capture: {} bytes", bytes.len());
    records.len()
}

/// Run `cantwin ARGS` with its address space limited to 1 GiB (`ulimit -v`), killed if it is
/// not done within a generous bound: (success, stdout, stderr).
fn bounded_cantwin(args: &[&str]) -> (bool, String, String) {
    let mut child = Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_cantwin"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let give_up = WallInstant::now() + Duration::from_secs(60);
    while child.try_wait().unwrap().is_none() {
        if WallInstant::now() > give_up {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("cantwin {args:?} still running after 60 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_flipped_timestamp_byte_is_refused_naming_the_records_of_the_gap() {
    let dir = temp_dir("replay-gap");
    let pcap = dir.join("flipped.pcap");
    let records = flipped_pcap(&pcap, 10);
    assert!(records > 11, "{records}");
    let scenario = scenario_file("cia301-device.toml");
    let (ok, out, err) =
        bounded_cantwin(&["replay", pcap.to_str().unwrap(), "--scenario", &scenario]);
    assert!(!ok, "{out}");
    // Record 11 (the flipped one) now lies 2^22 s earlier and sorts first.
    assert!(
        err.contains(
            "flipped.pcap has a gap of 4194303.000000 s between record 11 and record 1 \
             (counted from 1, in time order), more than the bound of 60.000000 s"
        ),
        "{err}"
    );
    assert!(
        err.contains("--max-gap SECONDS") && err.contains("--clamp-gaps"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    // Clamped, the gap is 60 s of twin time: the twins' heartbeats meanwhile have no
    // captured counterpart, and the report says so.
    let (ok, out, err) = bounded_cantwin(&[
        "replay",
        pcap.to_str().unwrap(),
        "--scenario",
        &scenario,
        "--clamp-gaps",
        "--json",
    ]);
    assert!(!ok, "{out} {err}");
    assert!(
        err.contains("between record 11 and record 1 is shortened to 60.000000 s (--clamp-gaps)"),
        "{err}"
    );
    let v: serde_json::Value =
        serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out} {err}"));
    assert_eq!(v["gaps_clamped"], 1, "{v}");
    // Heartbeats every 100 ms through the 60 s of the shortened gap.
    let unexpected = v["unexpected"].as_u64().unwrap();
    assert!((590..=610).contains(&unexpected), "{v}");
    assert!(v["matching"].as_u64().unwrap() > 10, "{v}");

    // With the bound raised to a year, the replay stops when the twins have sent far more
    // frames than the capture holds, long before the 1,165 hours, naming why.
    let (ok, out, err) = bounded_cantwin(&[
        "replay",
        pcap.to_str().unwrap(),
        "--scenario",
        &scenario,
        "--max-gap",
        "31536000",
    ]);
    assert!(!ok, "{out}");
    assert!(
        err.contains(&format!(
            "flipped.pcap spans more time than its frames account for: the twins sent more \
             than {} frames by ",
            100_000 + 100 * records
        )) && err.contains("lower --max-gap, or replay a part of the capture"),
        "{err}"
    );

    // A bound that is not a number of seconds is refused before anything is read.
    let (ok, _, err) = cantwin(&[
        "replay",
        pcap.to_str().unwrap(),
        "--scenario",
        &scenario,
        "--max-gap",
        "0",
    ]);
    assert!(
        !ok && err.contains("--max-gap must be a positive number"),
        "{err}"
    );
    // The twins run on for the tolerance after the last frame: it may not exceed the bound.
    let (ok, _, err) = cantwin(&[
        "replay",
        pcap.to_str().unwrap(),
        "--scenario",
        &scenario,
        "--tolerance-ms",
        "120000",
    ]);
    assert!(
        !ok && err.contains("--tolerance-ms 120000 is longer than --max-gap 60 s"),
        "{err}"
    );
}
