//! `cantwin dump --decode`: each frame of a capture decoded after it, by the protocol of its
//! channel (CANopen by default, `--protocol`, or the scenario the capture recorded).
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

fn log(tag: &str, lines: &[&str]) -> String {
    let dir = temp_dir(tag);
    let path = dir.join("run.log");
    let text: String = lines.iter().map(|l| format!("{l}\n")).collect();
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn dump_decode_names_canopen_services_lss_and_guarding() {
    let file = log(
        "dump-canopen",
        &[
            "(1700000000.000000) can0 705#00",
            "(1700000000.001000) can0 000#0105",
            "(1700000000.002000) can0 085#1042090000000000",
            "(1700000000.003000) can0 7E5#5E00000000000000",
            "(1700000000.004000) can0 7E4#5E05000000000000",
            "(1700000000.005000) can0 70A#R1",
            "(1700000000.006000) can0 70A#05",
            "(1700000000.100000) can0 705#05",
        ],
    );
    let (ok, out, err) = cantwin(&["dump", &file, "--decode"]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 8, "{out}");
    let ends = [
        "BOOT-UP node 5",
        "NMT Start node 5",
        "EMCY node 5 code 0x4210 (temperature) register 0x09 data 00 00 00 00 00",
        "LSS master: inquire node-ID",
        "LSS slave: node-ID 5",
        "NODE GUARD request node 10",
        "NODE GUARD response node 10 operational (toggle 0)",
        "HEARTBEAT node 5 operational",
    ];
    for (line, end) in lines.iter().zip(ends) {
        assert!(line.ends_with(end), "{line:?} should end with {end:?}");
        assert!(line.starts_with("1700000000."), "{line}");
    }
    assert!(err.contains("8 records"), "{err}");
    // Without --decode the listing is the raw one.
    let (_, raw, _) = cantwin(&["dump", &file]);
    assert!(!raw.contains("BOOT-UP"), "{raw}");
    assert_eq!(raw.lines().count(), 8);
    // JSON Lines carry the decoded text.
    let (ok, json, _) = cantwin(&["--json", "dump", &file, "--decode"]);
    assert!(ok);
    let first: serde_json::Value = serde_json::from_str(json.lines().next().unwrap()).unwrap();
    assert_eq!(first["decoded"], "BOOT-UP node 5");
}

#[test]
fn dump_decode_by_protocol_option_and_by_scenario() {
    let file = log(
        "dump-protocols",
        &[
            "(1700000000.000000) can0 3C5#1020",
            "(1700000000.001000) can0 181#851027",
        ],
    );
    let (ok, out, err) = cantwin(&["dump", &file, "--decode", "--protocol", "devicenet"]);
    assert!(ok, "{err}");
    assert!(
        out.lines()
            .next()
            .unwrap()
            .ends_with("G1 msg 15 from MAC 5: slave poll response / COS-cyclic acknowledge: 10 20"),
        "{out}"
    );
    let (ok, out, err) = cantwin(&["dump", &file, "--decode", "--protocol", "can0=cal"]);
    assert!(ok, "{err}");
    assert!(
        out.lines()
            .nth(1)
            .unwrap()
            .ends_with("COB 0x181 control 0x85 (bit 7 1, multiplexor 5) data 10 27"),
        "{out}"
    );
    // The OPEN DRIVE scenario's bus carries CAL; the ADV200 DeviceNet one DeviceNet.
    let (ok, out, err) = cantwin(&[
        "dump",
        &file,
        "--decode",
        "--scenario",
        &scenario_file("opendrive.toml"),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("COB 0x181 control 0x85"), "{out}");
    let (ok, out, err) = cantwin(&[
        "dump",
        &file,
        "--decode",
        "--scenario",
        &scenario_file("adv200-devicenet.toml"),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("G1 msg 15 from MAC 5"), "{out}");
    let (ok, _, err) = cantwin(&["dump", &file, "--decode", "--protocol", "can0=profibus"]);
    assert!(!ok);
    assert!(err.contains("unknown protocol"), "{err}");
}
