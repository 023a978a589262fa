//! `cantwin dnet shell` (one node on line, many commands) and `dnet poll` naming the
//! ADV200's PDC words, against `scenarios/adv200-devicenet.toml` (MAC ID 12) served by
//! `cantwin sim --socketcand 0`.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::io::Write;
use std::process::{Command, Stdio};

#[test]
fn shell_goes_on_line_once_says_why_it_waits_and_runs_many_commands() {
    let (_sim, addr) = sim_with_socketcand(&scenario_file("adv200-devicenet.toml"), "60");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["dnet", "--socketcand", &addr, "shell"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut stdin = child.stdin.take().unwrap();
        let script = "get 12 1 1 7 --type short-string\n\
                      \n\
                      get 12 1 1 1 --type u16\n\
                      jump 12\n\
                      get 12 0x0F 600 1 --type i32\n\
                      help\n\
                      quit\n\
                      get 12 1 1 2\n";
        stdin.write_all(script.as_bytes()).unwrap();
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // One bad line: the shell goes on and reports the failure in its exit status.
    assert!(!out.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("1 command(s) failed"), "{stderr}");
    assert!(
        stderr.contains("unrecognized subcommand 'jump'"),
        "{stderr}"
    );
    // The duplicate MAC ID check is explained once, and done once.
    assert_eq!(
        stderr
            .matches("the duplicate MAC ID check takes 2 s")
            .count(),
        1,
        "{stderr}"
    );
    assert!(stderr.contains("ODVA"), "{stderr}");
    assert!(stderr.contains("on line as MAC ID 0"), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    // Product name, vendor ID 0, PAR 600 (its default), the help; nothing after quit.
    assert_eq!(lines[0], "\"ADV200 EXP-CAN/DN-ADV\"", "{stdout}");
    assert_eq!(lines[1], "0", "{stdout}");
    assert!(lines[2].parse::<i64>().is_ok(), "{stdout}");
    assert!(lines[3].starts_with("commands: browse"), "{stdout}");
    assert_eq!(lines.len(), 4, "{stdout}");
}

#[test]
fn poll_names_the_adv200_pdc_words_of_the_worked_example() {
    let (_sim, addr) = sim_with_socketcand(&scenario_file("adv200-devicenet.toml"), "60");
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
        "--period-ms",
        "25",
    ]);
    assert!(ok, "{err}");
    // Manual §1.6: M2S word decomposition (control word) and Ramp ref 1; S2M the status
    // word, the motor speed and analog input 2 (2.5 V = 4096 counts in the scenario).
    assert!(
        out.contains("output: Word decomp = 3, Ramp ref 1 = 1000"),
        "{out}"
    );
    let decoded: Vec<&str> = out.lines().filter_map(|l| l.strip_prefix("  ")).collect();
    assert_eq!(decoded.len(), 3, "{out}");
    for d in &decoded {
        assert!(d.starts_with("Word comp mon = 0x0"), "{d}");
        assert!(d.contains(", Motor speed = "), "{d}");
        assert!(d.ends_with(" rpm, Analog inp 2 mon = 4096 cnt"), "{d}");
    }
    // JSON Lines carry the words beside the bytes.
    let (ok, out, err) = cantwin(&[
        "--json",
        "dnet",
        "--socketcand",
        &addr,
        "poll",
        "12",
        "--out",
        "0300E803",
    ]);
    assert!(ok, "{err}");
    let head: serde_json::Value = serde_json::from_str(out.lines().next().unwrap()).unwrap();
    assert_eq!(
        head["output_decoded"], "Word decomp = 3, Ramp ref 1 = 1000",
        "{out}"
    );
    let input: serde_json::Value = serde_json::from_str(out.lines().nth(1).unwrap()).unwrap();
    assert_eq!(input["input"], 1, "{out}");
    assert!(
        input["decoded"]
            .as_str()
            .unwrap()
            .starts_with("Word comp mon = 0x0"),
        "{out}"
    );
    // --raw prints the bytes only.
    let (ok, out, err) = cantwin(&[
        "dnet",
        "--socketcand",
        &addr,
        "poll",
        "12",
        "--out",
        "0300E803",
        "--raw",
    ]);
    assert!(ok, "{err}");
    assert!(!out.contains("Word comp"), "{out}");
    assert!(out.contains("input 1: "), "{out}");
}
