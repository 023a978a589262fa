//! `cantwin replay`: a capture recorded from a scenario run replays without differences, and
//! a capture changed by one byte or one frame is reported exactly there, with a failure exit.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use cantwin_bus::{PortConfig, Recorder};
use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_capture::Record;
use cantwin_scenario::script::parse_frame;
use cantwin_scenario::{Registry, Scenario};

/// A master that only sends what the test gives it.
struct Master;

impl Node for Master {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

const EPOCH_NS: u64 = 1_700_000_000_000_000_000;

/// The master's frames: NMT start of node 5, SDO reads of 0x1017 and 0x1000, an SDO write of
/// 0x1017 = 200 ms, and SYNCs that make the operational node send its synchronous TPDOs.
const MASTER: &[(u64, &str)] = &[
    (20, "000#0105"),
    (50, "605#4017100000000000"),
    (120, "605#4000100000000000"),
    (300, "080#"),
    (400, "605#2B171000C8000000"),
    (500, "080#"),
];

/// Every frame of a run of the cia301-device scenario with the master's frames, as capture
/// records on channel can0 stamped at their end of frame.
fn record_run() -> Vec<Record> {
    let scenario = Scenario::load(scenario_file("cia301-device.toml")).unwrap();
    let mut built = scenario
        .build(&Registry::builtin(), &Default::default())
        .unwrap();
    let can0 = built.bus("can0").unwrap();
    let bus = built.sim.bus_mut(can0).unwrap();
    let master = bus.attach(Master, PortConfig::default());
    let tap = bus.add_tap(Recorder::new());
    for (ms, text) in MASTER {
        built.sim.run_until(Instant::from_nanos(ms * 1_000_000));
        built
            .sim
            .transmit(master, parse_frame(text).unwrap())
            .unwrap();
    }
    built.sim.run_until(Instant::from_nanos(900_000_000));
    let recorder = built.sim.bus(can0).unwrap().tap::<Recorder>(tap).unwrap();
    recorder
        .frames()
        .filter(|f| !f.dropped)
        .map(|f| Record::new(EPOCH_NS + f.end.as_nanos(), "can0", f.frame))
        .collect()
}

fn write_candump(path: &std::path::Path, records: &[Record]) {
    let mut w = cantwin_capture::candump::CandumpWriter::new(std::fs::File::create(path).unwrap());
    for r in records {
        w.write_record(r).unwrap();
    }
    w.flush().unwrap();
}

fn write_pcap(path: &std::path::Path, records: &[Record]) {
    let mut w =
        cantwin_capture::pcap::PcapWriter::new(std::fs::File::create(path).unwrap()).unwrap();
    for r in records {
        w.write_record(r).unwrap();
    }
    w.flush().unwrap();
}

fn replay_json(capture: &std::path::Path) -> (bool, serde_json::Value, String) {
    replay_json_with(capture, &scenario_file("cia301-device.toml"))
}

fn replay_json_with(
    capture: &std::path::Path,
    scenario: &str,
) -> (bool, serde_json::Value, String) {
    let (ok, out, err) = cantwin(&[
        "replay",
        capture.to_str().unwrap(),
        "--scenario",
        scenario,
        "--json",
    ]);
    let v = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out} {err}"));
    (ok, v, err)
}

#[test]
fn replaying_a_recorded_run_finds_no_difference() {
    let dir = temp_dir("replay-same");
    let records = record_run();
    let twin_frames = records
        .iter()
        .filter(|r| {
            !MASTER
                .iter()
                .any(|(_, m)| parse_frame(m).ok() == r.frame().copied())
        })
        .count();
    // The run has answers to compare: boot-up, heartbeats, SDO responses, TPDOs.
    assert!(twin_frames >= 12, "{twin_frames}");
    let log = dir.join("run.log");
    write_candump(&log, &records);
    let (ok, v, err) = replay_json(&log);
    assert!(ok, "{v} {err}");
    assert_eq!(v["matching"], twin_frames, "{v}");
    assert_eq!(v["missing"], 0);
    assert_eq!(v["unexpected"], 0);
    assert_eq!(v["different"], 0);
    assert_eq!(v["master_frames"], MASTER.len());
    // NMT, SYNC and the SDO requests are the master's; the node's own SDO responses and
    // heartbeats are not.
    assert_eq!(v["master_ids"], serde_json::json!(["000", "080", "605"]));

    // The same run as pcap, in text mode.
    let pcap = dir.join("run.pcap");
    write_pcap(&pcap, &records);
    let (ok, out, err) = cantwin(&[
        "replay",
        pcap.to_str().unwrap(),
        "--scenario",
        &scenario_file("cia301-device.toml"),
    ]);
    assert!(ok, "{out} {err}");
    assert!(
        out.contains(&format!(
            "{twin_frames} matching, 0 missing, 0 unexpected, 0 different"
        )),
        "{out}"
    );
}

#[test]
fn replay_reports_a_changed_byte_and_a_dropped_frame_exactly() {
    let dir = temp_dir("replay-diff");
    let records = record_run();
    let t0 = records[0].timestamp_ns;
    let rel = |r: &Record| (r.timestamp_ns - t0) as f64 / 1e9;

    // The answer to the read of 0x1017 (100 ms = 0x0064): change its value byte.
    let mut changed = records.clone();
    let i = changed
        .iter()
        .position(|r| r.frame().unwrap().to_string() == "585#4B17100064000000")
        .unwrap();
    changed[i].event = parse_frame("585#4B17100065000000").unwrap().into();
    let log = dir.join("changed.log");
    write_candump(&log, &changed);
    let (ok, v, err) = replay_json(&log);
    assert!(!ok);
    assert!(
        err.contains("0 missing, 0 unexpected, 1 different"),
        "{err}"
    );
    let entries = v["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 1, "{v}");
    assert_eq!(entries[0]["kind"], "different");
    assert_eq!(entries[0]["captured"]["frame"], "585#4B17100065000000");
    assert_eq!(entries[0]["replayed"]["frame"], "585#4B17100064000000");
    let t = entries[0]["captured"]["time_s"].as_f64().unwrap();
    assert!((t - rel(&records[i])).abs() < 1e-6, "{t}");

    // Drop the first heartbeat after the boot-up: the twin's frame has no captured twin.
    let j = records
        .iter()
        .position(|r| r.frame().unwrap().to_string() == "705#05")
        .unwrap();
    let mut dropped = records.clone();
    dropped.remove(j);
    let log = dir.join("dropped.log");
    write_candump(&log, &dropped);
    let (ok, v, _) = replay_json(&log);
    assert!(!ok);
    let entries = v["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 1, "{v}");
    assert_eq!(entries[0]["kind"], "unexpected");
    assert_eq!(entries[0]["replayed"]["frame"], "705#05");
    let t = entries[0]["replayed"]["time_s"].as_f64().unwrap();
    assert!((t - rel(&records[j])).abs() < 1e-5, "{t}");

    // Text mode names the frame and its time.
    let (ok, out, _) = cantwin(&[
        "replay",
        log.to_str().unwrap(),
        "--scenario",
        &scenario_file("cia301-device.toml"),
    ]);
    assert!(!ok);
    assert!(
        out.lines()
            .any(|l| l.starts_with("unexpected") && l.contains("can0 705#05")),
        "{out}"
    );
}

#[test]
fn replay_refuses_bad_tolerances_master_ids_and_foreign_channels() {
    let dir = temp_dir("replay-bad");
    let log = dir.join("run.log");
    write_candump(&log, &record_run()[..5]);
    let scenario = scenario_file("cia301-device.toml");
    let log = log.to_str().unwrap();
    let (ok, _, err) = cantwin(&["replay", log, "--scenario", &scenario, "--tolerance-ms=-1"]);
    assert!(!ok && err.contains("--tolerance-ms"), "{err}");
    let (ok, _, err) = cantwin(&[
        "replay",
        log,
        "--scenario",
        &scenario,
        "--master-ids",
        "60g",
    ]);
    assert!(
        !ok && err.contains("\"60g\" is not a hex identifier"),
        "{err}"
    );
    let two = dir.join("two.log");
    std::fs::write(&two, "(1.000000) can0 705#00\n(1.100000) can1 705#00\n").unwrap();
    let (ok, _, err) = cantwin(&["replay", two.to_str().unwrap(), "--scenario", &scenario]);
    assert!(!ok && err.contains("2 channels (can0, can1)"), "{err}");
}

#[test]
fn a_devicenet_capture_recorded_by_sim_replays_without_difference() {
    // Recorded in wall time by `cantwin sim --candump` while a scanner polls the drive
    // through socketcand: the scanner's frames (group 2 master messages, its duplicate MAC ID
    // check) are learnt as the master's, the drive's answers match.
    let dir = temp_dir("replay-dnet");
    let log = dir.join("dnet.log");
    let scenario = scenario_file("adv200-devicenet.toml");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", &scenario, "--socketcand", "0", "--duration", "4"])
        .arg("--candump")
        .arg(&log)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr = line.split_whitespace().nth(1).unwrap().to_string();
    let (ok, out, err) = cantwin(&[
        "dnet",
        "--socketcand",
        &addr,
        "poll",
        "12",
        "--out",
        "0300E803",
        "--count",
        "3",
    ]);
    assert!(ok, "{out} {err}");
    assert!(child.wait().unwrap().success());
    let (ok, v, err) = replay_json_with(&log, &scenario);
    assert!(ok, "{v} {err}");
    assert_eq!(v["missing"], 0, "{v}");
    assert_eq!(v["unexpected"], 0, "{v}");
    assert_eq!(v["different"], 0, "{v}");
    // The allocation, the explicit requests and 3 polls were answered.
    assert!(v["matching"].as_u64().unwrap() >= 6, "{v}");
    // Poll commands to MAC 12: group 2, message ID 5 (0x400 | 12 << 3 | 5).
    let ids = v["master_ids"].as_array().unwrap();
    assert!(ids.contains(&serde_json::json!("465")), "{v}");
    // The drive's responses (message ID 3) and its duplicate MAC ID checks (message ID 7)
    // are the twin's.
    assert!(!ids.contains(&serde_json::json!("463")), "{v}");
    assert!(!ids.contains(&serde_json::json!("467")), "{v}");
}
