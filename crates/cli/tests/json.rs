//! `--json`: every command that prints data prints JSON a program can parse — one object per
//! result, one object per line for streams — and the same data as the text output.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use serde_json::Value;

/// `cantwin ARGS --json`, which must succeed, as one JSON object.
fn json(args: &[&str]) -> Value {
    let mut full = args.to_vec();
    full.push("--json");
    let (ok, out, err) = cantwin(&full);
    assert!(ok, "{args:?}: {err}");
    serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{args:?}: {e}: {out}"))
}

/// `cantwin ARGS --json` as JSON Lines.
fn json_lines(args: &[&str]) -> Vec<Value> {
    let mut full = args.to_vec();
    full.push("--json");
    let (ok, out, err) = cantwin(&full);
    assert!(ok, "{args:?}: {err}");
    out.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

#[test]
fn canopen_commands_print_json_against_an_in_process_scenario() {
    let scenario = scenario_file("cia301-device.toml");
    let s = scenario.as_str();

    let v = json(&["scan", "--scenario", s]);
    assert_eq!(v["found"], 1);
    assert_eq!(v["nodes"][0]["node"], 5);
    assert!(v["nodes"][0]["device_type"].is_u64(), "{v}");

    let v = json(&["sdo", "--scenario", s, "read", "5", "0x1017", "0", "u16"]);
    assert_eq!(v["node"], 5);
    assert_eq!(v["index"], 0x1017);
    assert_eq!(v["sub"], 0);
    assert_eq!(v["size"], 2);
    assert_eq!(v["data"], "6400");
    assert_eq!(v["value"], 100);

    let v = json(&["sdo", "--scenario", s, "read", "5", "0x1008", "0", "vs"]);
    assert!(
        v["value"]
            .as_str()
            .unwrap()
            .starts_with("cantwin generic CiA 301 device"),
        "{v}"
    );
    // Without a type, the bytes only.
    let v = json(&["sdo", "--scenario", s, "read", "5", "0x1001", "0"]);
    assert_eq!(v["data"], "00");
    assert!(v.get("value").is_none(), "{v}");

    let v = json(&[
        "sdo",
        "--scenario",
        s,
        "write",
        "5",
        "0x1017",
        "0",
        "u16",
        "500",
    ]);
    assert_eq!(v["written"], 2);

    let v = json(&["nmt", "--scenario", s, "start", "5"]);
    assert_eq!(v["sent"], "000#0105");
    assert_eq!(v["node"], 5);

    // The trace is a stream: one object per frame. The in-process node boots (705#00) as the
    // trace starts, then sends its heartbeat every 100 ms.
    let lines = json_lines(&["trace", "--scenario", s, "--count", "3", "--seconds", "5"]);
    assert_eq!(lines.len(), 3);
    for l in &lines {
        assert_eq!(l["id"], 0x705, "{l}");
        assert!(l["frame"] == "705#7F" || l["frame"] == "705#00", "{l}");
        assert!(l["decoded"].as_str().unwrap().contains("node 5"), "{l}");
        assert!(l["time"].is_string());
    }
    assert!(lines.iter().any(|l| l["frame"] == "705#7F"));

    // Errors stay text on standard error, with a failure status and nothing on stdout.
    let (ok, out, err) = cantwin(&["sdo", "--scenario", s, "read", "5", "0x6000", "0", "--json"]);
    assert!(!ok);
    assert!(out.is_empty(), "{out}");
    assert!(err.starts_with("error: SDO aborted by the server"), "{err}");
}

#[test]
fn dump_prints_one_json_object_per_record() {
    let dir = temp_dir("json-dump");
    let log = dir.join("a.log");
    std::fs::write(
        &log,
        "(1700000000.000100) can0 705#00\n(1700000000.000200) can0 12345678#R4\n",
    )
    .unwrap();
    let lines = json_lines(&["dump", log.to_str().unwrap()]);
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["timestamp_ns"], 1_700_000_000_000_100_000u64);
    assert_eq!(lines[0]["channel"], "can0");
    assert_eq!(lines[0]["id"], 0x705);
    assert_eq!(lines[0]["data"], "00");
    assert_eq!(lines[1]["extended"], true);
    assert_eq!(lines[1]["remote"], true);
    assert_eq!(lines[1]["dlc"], 4);
}

#[test]
fn eds_check_sim_check_fuzz_and_bench_print_json() {
    let eds = format!(
        "{}/../../crates/eds/tests/corpus/io_module.eds",
        env!("CARGO_MANIFEST_DIR")
    );
    let v = json(&["eds", "check", &eds]);
    assert_eq!(v["errors"], 0);
    assert!(v["objects"].as_u64().unwrap() > 10, "{v}");
    assert!(v["issues"].is_array());

    let v = json(&["sim", "--check", &scenario_file("faults/cable-cut.toml")]);
    assert_eq!(v["passed"], true);
    let outcomes = v["outcomes"].as_array().unwrap();
    assert!(!outcomes.is_empty());
    assert!(
        outcomes
            .iter()
            .all(|o| o["passed"] == true && o["line"].is_u64())
    );

    let v = json(&["fuzz", "--cases", "3", "eds"]);
    assert_eq!(v["cases"], 3);
    assert_eq!(v["failures"], 0);
    assert_eq!(v["targets"][0]["target"], "eds");

    // The best trial's figures, and the median beside them.
    let v = json(&["bench", "bus", "--seconds", "0.02", "--trials", "2"]);
    assert_eq!(v["bench"], "bus");
    let figure = |v: &serde_json::Value| v.as_str().unwrap().parse::<f64>().unwrap();
    let rtf = figure(&v["figures"]["real-time factor (bus time / wall time)"]);
    let median = figure(&v["medians"]["real-time factor (bus time / wall time)"]);
    assert!(rtf >= median && median > 0.0, "{v}");
    assert!(
        v["figures"]["delivered frames"]
            .as_str()
            .unwrap()
            .parse::<u64>()
            .unwrap()
            > 0
    );
    // The network's four ways of filtering, each by column.
    let v = json(&["bench", "network", "--seconds", "0.02", "--trials", "1"]);
    let firmware = &v["figures"]["firmware acceptance filters"];
    assert!(
        firmware["wall time"].as_str().unwrap().ends_with(" s"),
        "{v}"
    );
    assert!(
        firmware["real-time factor"]
            .as_str()
            .unwrap()
            .contains("of 200"),
        "{v}"
    );
    assert!(
        v["medians"]["every frame through every device's whole stack"]["wall ns per frame"]
            .is_string(),
        "{v}"
    );
}

#[test]
fn progress_bars_stay_off_stdout_and_off_a_non_terminal_stderr() {
    // A 64 KiB DOMAIN upload draws a progress bar on a terminal; here stderr is a pipe.
    let scenario = scenario_file("cia301-device.toml");
    let dir = temp_dir("json-progress");
    let file = dir.join("domain.bin");
    let (ok, out, err) = cantwin(&[
        "sdo",
        "--scenario",
        &scenario,
        "--mode",
        "block",
        "read",
        "5",
        "0x2000",
        "0",
        "--output",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.is_empty(), "{out}");
    assert_eq!(
        err.trim(),
        format!("65536 bytes written to {}", file.display())
    );
    assert_eq!(std::fs::read(&file).unwrap().len(), 65536);
    // And back by block download: a whole block of 127 segments leaves at once.
    let (ok, out, err) = cantwin(&[
        "sdo",
        "--scenario",
        &scenario,
        "--mode",
        "block",
        "write",
        "5",
        "0x2000",
        "0",
        "d",
        "--input",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "written 65536 bytes to node 5 0x2000sub0");
    assert!(err.is_empty(), "{err}");
}

#[test]
fn dnet_browse_get_and_poll_print_json_against_an_in_process_scenario() {
    let scenario = scenario_file("adv200-devicenet.toml");
    let s = scenario.as_str();
    let v = json(&[
        "dnet",
        "--scenario",
        s,
        "browse",
        "--from",
        "10",
        "--to",
        "13",
    ]);
    assert_eq!(v["found"], 1);
    let d = &v["devices"][0];
    assert_eq!(d["mac"], 12);
    assert_eq!(d["device_type"], 2);
    assert_eq!(d["product_name"], "ADV200 EXP-CAN/DN-ADV");
    assert_eq!(d["revision"], "1.000");

    // Identity object (class 1) attribute 7, the product name.
    let v = json(&[
        "dnet",
        "--scenario",
        s,
        "get",
        "12",
        "1",
        "1",
        "7",
        "--type",
        "short-string",
    ]);
    assert_eq!(v["mac"], 12);
    assert_eq!(v["attribute"], 7);
    assert!(v["data"].as_str().unwrap().starts_with("15414456"), "{v}");
    assert!(v["value"].as_str().unwrap().contains("ADV200"), "{v}");

    // Polled I/O is a stream: the connection, then one line per response.
    let lines = json_lines(&[
        "dnet",
        "--scenario",
        s,
        "poll",
        "12",
        "--out",
        "0300E803",
        "--count",
        "2",
    ]);
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[0]["input_bytes"], 6);
    assert_eq!(lines[0]["output_bytes"], 4);
    for (k, l) in lines[1..].iter().enumerate() {
        assert_eq!(l["input"], k + 1);
        assert_eq!(l["data"].as_str().unwrap().len(), 12, "{l}");
    }
}

#[test]
fn cal_read_and_param_commands_print_json() {
    let scenario = scenario_file("opendrive.toml");
    let s = scenario.as_str();
    let v = json(&["cal", "--scenario", s, "read"]);
    assert_eq!(v["reference_hz"], 0.0);
    assert_eq!(v["start"], false);
    let v = json(&["cal", "--scenario", s, "param", "read", "max-frequency"]);
    assert_eq!(v["name"], "max-frequency");
    // fMAX = P68, default 120 % of 50 Hz, in the manual's unit.
    assert_eq!(v["value"], 60.0);
    assert_eq!(v["unit"], "Hz");
    assert_eq!(v["data"], "7017");
    let v = json(&["cal", "param", "list"]);
    let list = v["multiplexors"].as_array().unwrap();
    assert!(
        list.iter()
            .any(|m| m["name"] == "max-frequency" && m["writable"] == true)
    );
}

#[test]
fn sim_prints_its_gateway_lines_as_json() {
    let lines = json_lines(&[
        "sim",
        &scenario_file("cia301-device.toml"),
        "--socketcand",
        "0",
        "--duration",
        "0.2",
    ]);
    assert_eq!(lines.len(), 1);
    assert_eq!(lines[0]["gateway"], "socketcand");
    assert_eq!(lines[0]["bus"], "can0");
    let addr: std::net::SocketAddr = lines[0]["addr"].as_str().unwrap().parse().unwrap();
    assert!(addr.ip().is_loopback() && addr.port() != 0);
}
