//! `cantwin dnet` against the ADV200 DeviceNet twin (`scenarios/adv200-devicenet.toml`: MAC
//! ID 12, 500 kbit/s) served by `cantwin sim --socketcand 0`, run as a user would.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::process::{Child, Command, Stdio};

fn scenario() -> String {
    format!(
        "{}/../../scenarios/adv200-devicenet.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The simulation, killed when the test ends (also on a failed assert).
struct Sim {
    child: Child,
    addr: String,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `cantwin sim SCENARIO --socketcand 0`; its first line names the address.
fn sim() -> Sim {
    use std::io::BufRead;
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", &scenario(), "--socketcand", "0", "--duration", "60"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line.split_whitespace().nth(1).unwrap().to_string();
    Sim { child, addr }
}

fn dnet(sim: &Sim, args: &[&str]) -> (bool, String, String) {
    let mut full = vec!["dnet", "--socketcand", sim.addr.as_str()];
    full.extend_from_slice(args);
    cantwin(&full)
}

#[test]
fn browse_finds_the_drive_at_mac_12_with_its_identity() {
    let sim = sim();
    let (ok, out, err) = dnet(&sim, &["browse", "--from", "1", "--to", "20"]);
    assert!(ok, "{err}");
    let row = out.lines().find(|l| l.starts_with("12 ")).expect(&out);
    let cols: Vec<&str> = row.split_whitespace().collect();
    // Vendor 0, device type 0x02 (AC drive), product code 4, revision 1.000, serial 1.
    assert_eq!(cols[..6], ["12", "0", "0x0002", "4", "1.000", "0x00000001"]);
    assert!(row.ends_with("ADV200 EXP-CAN/DN-ADV"), "{row}");
    assert!(out.contains("1 device(s) found"), "{out}");
}

#[test]
fn get_identity_vendor_id_and_product_name() {
    let sim = sim();
    let (ok, out, err) = dnet(&sim, &["get", "12", "1", "1", "1", "--type", "u16"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "0");
    let (ok, out, err) = dnet(&sim, &["get", "12", "1", "1", "2", "--type", "bytes"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "0200");
    let (ok, out, err) = dnet(
        &sim,
        &["get", "12", "1", "1", "7", "--type", "short-string"],
    );
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "\"ADV200 EXP-CAN/DN-ADV\"");
}

/// Manual §3.4.1: the Parameter object's instance is the PAR (600 needs a 16-bit instance:
/// a UCMM connection with body format 8/16, §3.4.2 note 1); Get answers a DWORD.
#[test]
fn parameter_object_instance_is_a_par_set_then_get_back_3_4_1() {
    let sim = sim();
    let (ok, out, err) = dnet(
        &sim,
        &["set", "12", "0x0F", "600", "1", "1000", "--type", "i16"],
    );
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "ok");
    let (ok, out, err) = dnet(&sim, &["get", "12", "0x0F", "600", "1", "--type", "i32"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "1000");
    // A PAR at or below 255 goes over the predefined explicit connection (8/8).
    let (ok, out, err) = dnet(&sim, &["get", "12", "0x0F", "0", "1", "--type", "u16"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "1");
}

/// Manual §3.4.1: "nel caso di errore il drive non risponde" — a refused Set (above PAR
/// 600's maximum) is not answered, and the value stays.
#[test]
fn refused_parameter_set_is_silent_and_reported_as_no_answer_3_4_1() {
    let sim = sim();
    let (ok, _, err) = dnet(
        &sim,
        &["set", "12", "0x0F", "600", "1", "0x2341", "--type", "u16"],
    );
    assert!(!ok);
    assert!(err.contains("no answer from MAC ID 12 within 1 s"), "{err}");
    let (ok, out, err) = dnet(&sim, &["get", "12", "0x0F", "600", "1", "--type", "i32"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "0");
}

#[test]
fn error_response_is_printed_with_its_general_status_meaning() {
    let sim = sim();
    let (ok, _, err) = dnet(&sim, &["get", "12", "1", "1", "99"]);
    assert!(!ok);
    assert!(
        err.contains("general status 0x14 (attribute not supported), additional code 0xFF"),
        "{err}"
    );
    // A PAR that does not exist: object does not exist.
    let (ok, _, err) = dnet(&sim, &["get", "12", "0x0F", "1", "1"]);
    assert!(!ok);
    assert!(
        err.contains("general status 0x16 (object does not exist)"),
        "{err}"
    );
}

/// Manual §1.6 worked example over polled I/O (§3.5): 4 bytes out (control word 0x0003,
/// Ramp ref 1 = 1000 rpm), 6 bytes in (status word, motor speed, analog input 2 at 2.5 V =
/// 4096 counts). The expected packet rate is rounded up to the card's 10 ms timer.
#[test]
fn poll_exchanges_the_worked_example_4_bytes_out_6_bytes_in() {
    let sim = sim();
    let (ok, out, err) = dnet(
        &sim,
        &[
            "poll",
            "12",
            "--out",
            "0300E803",
            "--count",
            "5",
            "--period-ms",
            "25",
        ],
    );
    assert!(ok, "{err}");
    assert!(
        out.contains(
            "polled I/O allocated: 4 bytes out, 6 bytes in, every 25 ms (expected packet rate 30 ms)"
        ),
        "{out}"
    );
    let inputs: Vec<&str> = out
        .lines()
        .filter_map(|l| l.strip_prefix("input "))
        .map(|l| l.split_once(": ").unwrap().1)
        .collect();
    assert_eq!(inputs.len(), 5, "{out}");
    for i in &inputs {
        assert_eq!(i.len(), 12, "{i}");
        // Analog input 2 and digital input 4 (status bit 8) as in the scenario.
        assert!(i.ends_with("0010"), "{i}");
    }
    // The drive is enabled by the control word: enable state and drive OK set (bits 0, 1).
    assert!(inputs.last().unwrap().starts_with("0301"), "{out}");
}

#[test]
fn dnet_rejects_a_bad_mac_and_bad_hex() {
    let sim = sim();
    let (ok, _, err) = dnet(&sim, &["get", "12", "1", "1", "1", "--mac", "64"]);
    assert!(!ok);
    assert!(err.contains("--mac 64"), "{err}");
    let (ok, _, err) = dnet(&sim, &["poll", "12", "--out", "0G"]);
    assert!(!ok);
    assert!(err.contains("not hex data"), "{err}");
}

/// Sections and `key = value;` entries of EDS text (`$` comments, entries over several
/// lines).
fn ini(
    text: &str,
) -> std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>> {
    let mut out = std::collections::BTreeMap::new();
    let mut section = String::new();
    let mut entry = String::new();
    for raw in text.lines() {
        let mut line = String::new();
        let mut quote = false;
        for c in raw.chars() {
            if c == '"' {
                quote = !quote;
            }
            if c == '$' && !quote {
                break;
            }
            line.push(c);
        }
        let t = line.trim();
        if entry.is_empty() && t.starts_with('[') && t.ends_with(']') {
            section = t[1..t.len() - 1].to_string();
            out.insert(section.clone(), std::collections::BTreeMap::new());
            continue;
        }
        entry.push_str(t);
        if t.ends_with(';') {
            let (k, v) = entry.split_once('=').unwrap();
            out.get_mut(&section).unwrap().insert(
                k.trim().to_string(),
                v.trim().trim_end_matches(';').to_string(),
            );
            entry.clear();
        }
    }
    assert!(entry.is_empty(), "{entry}");
    out
}

#[test]
fn eds_of_the_adv200_devicenet_twin_parses_as_ini_with_its_identity_io_and_params() {
    let (ok, out, err) = cantwin(&[
        "dnet",
        "eds",
        "--scenario",
        &scenario(),
        "--device",
        "drive",
    ]);
    assert!(ok, "{err}");
    let eds = ini(&out);
    assert_eq!(eds["Device"]["VendCode"], "0");
    assert_eq!(eds["Device"]["ProdType"], "2");
    assert_eq!(eds["Device"]["ProdCode"], "4");
    assert_eq!(eds["Device"]["MajRev"], "1");
    assert_eq!(eds["Device"]["ProdName"], "\"ADV200 EXP-CAN/DN-ADV\"");
    assert_eq!(eds["Device Classification"]["Class1"], "DeviceNet");
    // The worked example's PDC: 6 bytes to the master, 4 from it.
    assert!(eds["IO_Info"]["Input1"].starts_with("6, 0, 0x0001"));
    assert!(eds["IO_Info"]["Output1"].starts_with("4, 0, 0x0001"));
    assert!(eds.contains_key("File") && eds.contains_key("ParamClass"));
    // PAR 260 Motor speed: read-only monitor, a 16-bit instance in its path.
    let p260: Vec<&str> = eds["Params"]["Param260"]
        .split(',')
        .map(str::trim)
        .collect();
    assert_eq!(
        p260[1..6],
        ["8", "\"20 0F 25 00 04 01 30 01\"", "0x0030", "0xC4", "4"]
    );
    assert_eq!(p260[6], "\"Motor speed\"");
    // PAR 4000 Fieldbus type: an enumeration.
    assert!(eds["Params"]["Enum4000"].contains("2, \"DeviceNet\""));
    // A device without the DeviceNet personality is refused.
    let (ok, _, err) = cantwin(&[
        "dnet",
        "eds",
        "--scenario",
        &scenario(),
        "--device",
        "master",
    ]);
    assert!(!ok);
    assert!(err.contains("not an ADV200"), "{err}");
}
