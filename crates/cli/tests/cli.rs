//! The real `cantwin` binary, run as a user would.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn cantwin(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn demo_runs_without_arguments_and_tells_the_story() {
    let (ok, out, err) = cantwin(&["demo"]);
    assert!(ok, "demo failed: {err}");
    // Arbitration at power-up: 0x181 beats 0x182 beats 0x701, at exact bus times (500 kbit/s:
    // 2 µs a bit; 69 stuffed bits to the end of EOF = 138 µs minus the 3 intermission bits).
    let a = out.find("0.000132000  181#0000").expect("0x181 first");
    let b = out.find("0.000268000  182#0000").expect("0x182 second");
    let c = out.find("0.000404000  701#0000").expect("0x701 third");
    assert!(a < b && b < c);
    // Injected corruption: three error frames and the retransmission.
    assert_eq!(out.matches("ERROR FRAME: bit error").count(), 3);
    assert!(out.contains("0.200688000  182#0200"));
    // Remote frames answered.
    assert!(out.contains("285#R4"));
    assert!(out.contains("the responder answered 4 remote frames"));
    // Bus-off and recovery, error-passive of the lonely node.
    assert!(out.contains("controller BUS-OFF"));
    assert!(out.contains("recovered from bus-off"));
    assert!(out.contains("lonely     controller error-passive (TEC 128)"));
}

#[test]
fn demo_is_deterministic() {
    let strip = |s: String| {
        s.lines()
            .filter(|l| !l.contains("of wall time"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let (_, a, _) = cantwin(&["demo", "--verbose"]);
    let (_, b, _) = cantwin(&["demo", "--verbose"]);
    assert_eq!(strip(a), strip(b));
}

#[test]
fn every_command_has_help_with_examples() {
    for cmd in [&["--help"][..], &["demo", "--help"], &["bench", "--help"]] {
        let (ok, out, _) = cantwin(cmd);
        assert!(ok);
        assert!(out.contains("Examples:"), "{cmd:?}: {out}");
    }
}

#[test]
fn bench_rejects_unknown_names_and_bad_durations() {
    let (ok, _, err) = cantwin(&["bench", "nosuch"]);
    assert!(!ok);
    assert!(err.contains("unknown benchmark \"nosuch\""), "{err}");
    let (ok, _, err) = cantwin(&["bench", "bus", "--seconds", "0"]);
    assert!(!ok);
    assert!(err.contains("--seconds must be a positive number"), "{err}");
}

#[test]
fn bench_bus_short_run_prints_figures_and_records_them() {
    let dir = std::env::temp_dir().join(format!("cantwin-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("BENCHMARKS.md");
    let (ok, out, err) = cantwin(&[
        "bench",
        "bus",
        "--seconds",
        "0.05",
        "--write",
        "--file",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("real-time factor"));
    let md = std::fs::read_to_string(&file).unwrap();
    assert!(md.contains("<!-- bench:bus -->") && md.contains("<!-- /bench:bus -->"));
    assert!(md.contains("cantwin -- bench bus --write"));
    std::fs::remove_dir_all(&dir).unwrap();
}
