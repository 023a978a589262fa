//! Wireshark reads what cantwin writes: `tshark` decodes the LINKTYPE_CAN_SOCKETCAN packets
//! of a cantwin pcap and pcapng with the identifiers, lengths and flags that were written.
//!
//! When `tshark` is not installed the tests are skipped with a message, except under CI
//! (environment variable `CI` set), where a missing `tshark` fails them.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::{ErrorFrame, Record, create, error_class};
use std::path::PathBuf;
use std::process::Command;

/// Whether tshark can run here; panics under CI when it cannot.
fn tshark_available() -> bool {
    let found = Command::new("tshark")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "tshark is required under CI: install it with \
             `DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends tshark`"
        );
        println!("tshark not installed: skipped");
    }
    found
}

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// Runs tshark over `file` and returns one line per packet: the requested fields then
/// [`FIELDS`], comma separated. Asserts tshark exits successfully and reports no malformed packet.
fn tshark_fields(file: &PathBuf, fields: &[&str]) -> Vec<String> {
    let mut cmd = Command::new("tshark");
    // AUTOSAR NM claims some frames heuristically (an empty frame on id 0 included) and calls
    // them malformed; that is a guess about the payload, not about the capture.
    cmd.args(["-n", "--disable-protocol", "autosar-nm", "-r"])
        .arg(file)
        .args(["-T", "fields", "-E", "separator=,"]);
    for f in fields
        .iter()
        .chain(&FIELDS)
        .chain(&["_ws.malformed", "_ws.expert.severity"])
    {
        cmd.args(["-e", f]);
    }
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark failed: {stderr}");
    for line in stderr.lines() {
        // tshark warns about running as root; anything else is a complaint about the file.
        assert!(line.starts_with("Running as user"), "tshark: {stderr}");
    }
    stdout
        .lines()
        .map(|l| {
            let l = l
                .strip_suffix(",,")
                .unwrap_or_else(|| panic!("malformed or expert info: {l}"));
            l.to_owned()
        })
        .collect()
}

fn frames(channel: &str, t0: u64) -> Vec<Record> {
    let std = |id| Id::standard(id).unwrap();
    let ext = |id| Id::extended(id).unwrap();
    vec![
        Record::new(
            t0,
            channel,
            Frame::data(std(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap(),
        ),
        Record::new(
            t0 + 1_000,
            channel,
            Frame::data(ext(0x18DA_F110), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap(),
        ),
        Record::new(t0 + 2_000, channel, Frame::remote(std(0x705), 0).unwrap()),
        Record::new(
            t0 + 3_000,
            channel,
            Frame::remote(ext(0x1FFF_FFFF), 2).unwrap(),
        ),
        Record::new(t0 + 4_000, channel, Frame::data(std(0x000), &[]).unwrap()),
        Record::new(
            t0 + 5_001,
            channel,
            ErrorFrame::new(error_class::BUS_OFF, [0; 8]).unwrap(),
        ),
    ]
}

fn write(file: &PathBuf, records: &[Record]) {
    let mut w = create(file).unwrap();
    for r in records {
        w.write_record(r).unwrap();
    }
    w.flush().unwrap();
}

/// Expected per frame: can.id (decimal, without flag bits), can.len, can.flags.xtd,
/// can.flags.rtr, can.flags.err, can.err.busoff (tshark 4.0 field names). For an error frame
/// tshark shows no identifier or format flags, only the error class.
const EXPECTED: [&str; 6] = [
    "291,4,0,0,0,",
    "417001744,8,1,0,0,",
    "1797,0,0,1,0,",
    "536870911,2,1,1,0,",
    "0,0,0,0,0,",
    ",8,,,1,1",
];

const FIELDS: [&str; 6] = [
    "can.id",
    "can.len",
    "can.flags.xtd",
    "can.flags.rtr",
    "can.flags.err",
    "can.err.busoff",
];

#[test]
fn tshark_reads_cantwin_pcap() {
    if !tshark_available() {
        return;
    }
    let file = path("tshark_reads_cantwin_pcap.pcap");
    write(&file, &frames("can0", 1_700_000_000_123_456_789));
    let lines = tshark_fields(&file, &["frame.number", "frame.time_epoch"]);
    let want: Vec<String> = EXPECTED
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let ns = [789, 1_789, 2_789, 3_789, 4_789, 5_790][i];
            format!("{},1700000000.123{:06},{e}", i + 1, 456_000 + ns)
        })
        .collect();
    assert_eq!(lines, want);
}

#[test]
fn tshark_reads_cantwin_pcapng_with_two_interfaces() {
    if !tshark_available() {
        return;
    }
    let file = path("tshark_reads_cantwin_pcapng.pcapng");
    let mut records = Vec::new();
    for (a, b) in frames("can0", 1_000_000_000)
        .into_iter()
        .zip(frames("vcan1", 2_000_000_000))
    {
        records.push(a);
        records.push(b);
    }
    write(&file, &records);
    let lines = tshark_fields(&file, &["frame.number", "frame.interface_name"]);
    let want: Vec<String> = (0..12)
        .map(|i| format!("{},{},{}", i + 1, ["can0", "vcan1"][i % 2], EXPECTED[i / 2]))
        .collect();
    assert_eq!(lines, want);
}

/// Wireshark 4.0 also opens candump logs, as long as the lines carry no direction flag.
#[test]
fn tshark_reads_cantwin_candump_log() {
    if !tshark_available() {
        return;
    }
    let file = path("tshark_reads_cantwin_candump.log");
    write(&file, &frames("can0", 1_700_000_000_000_000_000));
    let lines = tshark_fields(&file, &["frame.number"]);
    let want: Vec<String> = EXPECTED
        .iter()
        .enumerate()
        .map(|(i, e)| format!("{},{e}", i + 1))
        .collect();
    assert_eq!(lines, want);
}
