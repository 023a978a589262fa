//! `cantwin sim --pcap --candump` ended by each signal a service manager or a user sends:
//! SIGINT, SIGTERM and SIGHUP stop it cleanly (captures closed and whole, the summary
//! printed); after SIGKILL the captures are still readable and miss at most the last second,
//! as they are flushed twice a second. The captures are read back with `cantwin dump` and,
//! when it is installed, with tshark.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::io::Read as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Reads the child's standard error until it has printed `line`'s start, or panics after the
/// guard time.
fn wait_for(stderr: &mut impl std::io::Read, what: &str) -> String {
    let mut seen = Vec::new();
    let mut b = [0u8; 256];
    let give_up = Instant::now() + Duration::from_secs(30);
    while !String::from_utf8_lossy(&seen).contains(what) {
        assert!(
            Instant::now() < give_up,
            "no {what:?} in {}",
            String::from_utf8_lossy(&seen)
        );
        let n = stderr.read(&mut b).unwrap();
        assert!(
            n > 0,
            "stderr closed before {what:?}: {}",
            String::from_utf8_lossy(&seen)
        );
        seen.extend_from_slice(&b[..n]);
    }
    String::from_utf8_lossy(&seen).into_owned()
}

/// `cantwin dump FILE --json`: the records' timestamps, or the error.
fn dump(file: &Path) -> Vec<u64> {
    let (ok, out, err) = cantwin(&["dump", file.to_str().unwrap(), "--json"]);
    assert!(ok, "cantwin dump {}: {err}", file.display());
    out.lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            v["timestamp_ns"].as_u64().unwrap()
        })
        .collect()
}

/// How many packets tshark reads from `file`, or `None` when tshark is not installed.
fn tshark_packets(file: &Path) -> Option<usize> {
    let out = Command::new("tshark")
        .args([
            "-r",
            file.to_str().unwrap(),
            "-T",
            "fields",
            "-e",
            "frame.number",
        ])
        .output()
        .ok()?;
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark -r {}: {err}", file.display());
    // A capture cut in the middle of a packet is reported, though tshark exits 0 for it.
    assert!(
        !err.contains("cut short"),
        "tshark -r {}: {err}",
        file.display()
    );
    Some(String::from_utf8_lossy(&out.stdout).lines().count())
}

/// Run the device scenario with both captures, let it record for a while, send `signal`
/// (a `kill -s` name) and check what it left.
fn end_with(signal: &str) {
    let dir = temp_dir(&format!("sim-signal-{signal}"));
    let pcap = dir.join("run.pcap");
    let log = dir.join("run.log");
    let mut child = Killed(
        Command::new(env!("CARGO_BIN_EXE_cantwin"))
            .args(["sim", &scenario_file("cia301-device.toml")])
            .args([
                "--pcap",
                pcap.to_str().unwrap(),
                "--candump",
                log.to_str().unwrap(),
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut stderr = child.stderr.take().unwrap();
    wait_for(&mut stderr, "paced to the wall clock");
    // Heartbeats every 100 ms: about a dozen frames, and at least two flushes.
    std::thread::sleep(Duration::from_millis(1_200));
    let killed_at = SystemTime::now().duration_since(UNIX_EPOCH).unwrap();
    let status = Command::new("kill")
        .args(["-s", signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success(), "kill -s {signal}");
    let give_up = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            Instant::now() < give_up,
            "sim still running 30 s after SIG{signal}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).unwrap();
    let pcap_times = dump(&pcap);
    let log_times = dump(&log);
    assert!(
        pcap_times.len() >= 5,
        "SIG{signal}: {} records",
        pcap_times.len()
    );
    if signal == "KILL" {
        assert!(!status.success());
        // Flushed twice a second: what is missing is at most the last second (and a second
        // of scheduling slack for a loaded machine).
        for times in [&pcap_times, &log_times] {
            let last = Duration::from_nanos(*times.last().unwrap());
            assert!(
                last + Duration::from_secs(2) >= killed_at,
                "SIG{signal}: the last record is {:?} before the kill",
                killed_at.saturating_sub(last)
            );
        }
    } else {
        assert!(status.success(), "SIG{signal}: {status} {rest}");
        assert!(
            rest.contains("cantwin sim: stopped after"),
            "SIG{signal}: {rest}"
        );
        // Both captures closed whole: the same records in each.
        assert_eq!(pcap_times.len(), log_times.len(), "SIG{signal}");
    }
    match tshark_packets(&pcap) {
        Some(n) => assert_eq!(n, pcap_times.len(), "SIG{signal}: tshark and cantwin dump"),
        None => {
            println!("tshark is not installed: SIG{signal}'s capture read with cantwin dump only")
        }
    }
}

#[test]
fn captures_survive_each_signal() {
    // The four runs at once: they take their time in wall-clock waits.
    let runs: Vec<_> = ["INT", "TERM", "HUP", "KILL"]
        .into_iter()
        .map(|s| (s, std::thread::spawn(move || end_with(s))))
        .collect();
    let failed: Vec<&str> = runs
        .into_iter()
        .filter_map(|(s, h)| h.join().is_err().then_some(s))
        .collect();
    assert!(failed.is_empty(), "failed for SIG{failed:?}");
}
