//! `cantwin scenario check`: broken scenario files are reported with file, line and key, in
//! text and in JSON, without running anything.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

const BUS: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n";

fn node(name: &str, extra: &str) -> String {
    format!("\n[[device]]\nname = \"{name}\"\nkind = \"cia301\"\nbus = \"can0\"\n{extra}\n")
}

/// Writes `text` as `NAME.toml` into the test's scratch directory.
fn write(dir: &std::path::Path, name: &str, text: &str) -> String {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

#[test]
fn scenario_check_reports_each_broken_file_with_line_and_key() {
    let dir = temp_dir("scenario-check");
    let cases = [
        (
            "unknown-kind",
            format!("{BUS}\n[[device]]\nname = \"x\"\nkind = \"cia999\"\nbus = \"can0\"\n"),
            5,
            "device[0].kind",
            "unknown device kind \"cia999\"",
        ),
        (
            "bad-node-id",
            format!("{BUS}{}", node("a", "node_id = 200")),
            9,
            "device[0].node_id",
            "1–127",
        ),
        (
            "unknown-key",
            format!("{BUS}{}", node("a", "node_id = 5\nheartbeat = 100")),
            10,
            "device[0].heartbeat",
            "unknown key `heartbeat`",
        ),
        (
            "duplicate-node-id",
            format!(
                "{BUS}{}{}",
                node("a", "node_id = 5"),
                node("b", "node_id = 5")
            ),
            15,
            "device[1].node_id",
            "node-ID 5 is already used by device \"a\"",
        ),
        (
            "unknown-device-in-script",
            format!(
                "{BUS}{}\n[[at]]\ntime_ms = 10\naction = \"power_off\"\ndevice = \"node9\"\n",
                node("a", "node_id = 5")
            ),
            11,
            "at[0].device",
            "no device named \"node9\"",
        ),
        (
            "unreadable-object-in-script",
            format!(
                "{BUS}{}\n[[expect]]\nat_ms = 10\nvalue = {{ device = \"a\", index = 0x6000, sub = 1, equals = 1 }}\n",
                node("a", "node_id = 5")
            ),
            11,
            "expect[0].value",
            "has no object 0x6000sub1",
        ),
    ];
    for (name, text, line, key, message) in &cases {
        let file = write(&dir, name, text);
        let (ok, out, err) = cantwin(&["scenario", "check", &file]);
        assert!(!ok, "{name}: accepted\n{out}");
        assert!(out.is_empty(), "{name}: {out}");
        let located = format!("{file}:{line}: key `{key}`: ");
        assert!(
            err.contains(&located) && err.contains(message),
            "{name}: expected {located}…{message}, got {err}"
        );

        let (ok, out, _) = cantwin(&["scenario", "check", "--json", &file]);
        assert!(!ok);
        let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
        assert_eq!(v["file"], file.as_str());
        assert_eq!(v["ok"], false);
        assert_eq!(v["error"]["line"], *line, "{name}: {v}");
        assert_eq!(v["error"]["key"], *key, "{name}: {v}");
        assert!(
            v["error"]["message"].as_str().unwrap().contains(message),
            "{name}: {v}"
        );
    }
}

#[test]
fn scenario_check_accepts_the_shipped_scenarios_and_prints_json_lines() {
    // Every scenario of the repository, fault scripts included, is valid.
    let mut shipped: Vec<String> = Vec::new();
    for dir in ["", "faults/"] {
        for e in std::fs::read_dir(scenario_file(dir)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                shipped.push(p.display().to_string());
            }
        }
    }
    assert!(shipped.len() >= 15, "{shipped:?}");
    let mut args = vec!["scenario", "check"];
    args.extend(shipped.iter().map(String::as_str));
    let (ok, out, err) = cantwin(&args);
    assert!(ok, "{err}");
    assert_eq!(out.lines().count(), shipped.len(), "{out}");
    assert!(out.lines().all(|l| l.starts_with("ok ")), "{out}");
    assert!(
        out.contains(
            "cia301-device.toml: CiA 301 device (1 bus, 2 devices, 0 actions, 0 expectations)"
        ),
        "{out}"
    );

    let good = [
        scenario_file("cia301-device.toml"),
        scenario_file("opendrive.toml"),
    ];

    // One broken file among good ones: every file gets its line, the exit status is 1.
    let dir = temp_dir("scenario-check-json");
    let bad = write(
        &dir,
        "bad",
        "[[bus]]\nname = \"can0\"\nbit_rate = \"fast\"\n",
    );
    let (ok, out, err) = cantwin(&["--json", "scenario", "check", &good[0], &bad, &good[1]]);
    assert!(!ok);
    assert!(err.contains("1 of 3 scenario files are broken"), "{err}");
    let lines: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[0]["ok"], true);
    assert!(lines[0]["devices"].as_u64().unwrap() >= 1);
    assert_eq!(lines[1]["ok"], false);
    assert_eq!(lines[1]["error"]["key"], "bus[0].bit_rate");
    assert_eq!(lines[1]["error"]["line"], 3);
    assert_eq!(lines[2]["ok"], true);
}
