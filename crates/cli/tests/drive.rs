//! `cantwin drive`: CiA 402 drive commands against the ADV200 card's CiA 402 personality
//! (velocity mode, the power drive state machine) through a socketcand gateway, and the
//! errors a user gets for bad input.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;

#[test]
fn cia402_pds_fsa_drive_state_commands_against_the_adv200() {
    let (_child, addr) = sim_with_socketcand(&scenario_file("adv200-ds402.toml"), "300");
    let run = |args: &[&str]| {
        let mut full = vec!["drive", "--socketcand", addr.as_str()];
        full.extend_from_slice(args);
        cantwin(&full)
    };
    let (ok, out, err) = run(&["state", "2"]);
    assert!(ok, "{err}");
    assert_eq!(
        out.trim(),
        "node 2: switch on disabled (statusword 0x0240), mode vl"
    );
    // The card trips on enable outside NMT OPERATIONAL (Opt Bus Fault, bus loss, EMCY
    // 0xFF11): the walk stops at FAULT and says what the drive reported.
    let (ok, _, err) = run(&["state", "2", "enable"]);
    assert!(!ok);
    assert!(
        err.contains("node 2: enable: the drive is in fault")
            && err.contains("EMCY from the node: 0xFF11"),
        "{err}"
    );
    let (ok, out, err) = run(&["state", "2"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("fault (statusword") && out.contains("fault-reset"),
        "{out}"
    );
    // Transition 15 once the cause is gone (NMT Start first).
    let (ok, out, err) = run(&["--nmt-start", "state", "2", "fault-reset"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "node 2: switch on disabled (statusword 0x0240)");
    // Transitions 2, 3, 4, then 5, 6 and 7 one at a time.
    for (action, shown) in [
        ("enable", "operation enabled (statusword 0x0637)"),
        ("switch-on", "switched on (statusword 0x0233)"),
        ("shutdown", "ready to switch on (statusword 0x0231)"),
        ("disable", "switch on disabled (statusword 0x0240)"),
        ("enable", "operation enabled (statusword 0x0637)"),
    ] {
        let (ok, out, err) = run(&["state", "2", action]);
        assert!(ok, "{action}: {err}");
        assert_eq!(out.trim(), format!("node 2: {shown}"), "{action}");
    }
    let (ok, out, err) = run(&["--json", "state", "2"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["state"], "operation enabled");
    assert_eq!(v["statusword"], 0x0637);
    assert_eq!(v["mode_name"], "vl");
    // Quick stop from OPERATION ENABLED: the card stops and ends in SWITCH ON DISABLED.
    let (ok, out, err) = run(&["state", "2", "quick-stop"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "node 2: switch on disabled (statusword 0x0240)");
    // A profile move needs OPERATION ENABLED.
    let (ok, _, err) = run(&["move", "pv", "2", "100"]);
    assert!(!ok);
    assert!(
        err.contains("node 2: pv move: the drive is in switch on disabled, not operation enabled"),
        "{err}"
    );
}

#[test]
fn cia402_6060h_drive_mode_commands_in_a_scenario() {
    let s = scenario_file("adv200-ds402.toml");
    let (ok, out, err) = cantwin(&["drive", "--scenario", &s, "mode", "2", "vl"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "node 2: mode vl");
    // The card is velocity mode only: it refuses pp with its abort code.
    let (ok, _, err) = cantwin(&["drive", "--scenario", &s, "mode", "2", "1"]);
    assert!(!ok);
    assert!(
        err.contains("node 2: mode pp: SDO access to 0x6060 sub 0 aborted: 0x06090032")
            && err.contains("does not take this mode"),
        "{err}"
    );
    let (ok, _, err) = cantwin(&["drive", "--scenario", &s, "home", "2", "35"]);
    assert!(!ok);
    assert!(err.contains("not operation enabled"), "{err}");
}

#[test]
fn drive_commands_refuse_bad_input_clearly() {
    let s = scenario_file("adv200-ds402.toml");
    for (args, wanted) in [
        (
            vec!["drive", "--scenario", &s, "state", "200"],
            "node-ID 200 is outside 1–127",
        ),
        (
            vec!["drive", "--scenario", &s, "mode", "2", "banana"],
            "unknown mode \"banana\"",
        ),
        (
            vec!["drive", "--scenario", &s, "mode", "2", "5"],
            "unknown mode \"5\"",
        ),
        (
            vec!["drive", "--scenario", &s, "home", "2", "300"],
            "homing method \"300\" is not a number",
        ),
        (
            vec![
                "drive",
                "--scenario",
                &s,
                "--step-timeout",
                "0",
                "state",
                "2",
            ],
            "--step-timeout must be a positive number",
        ),
        (vec!["drive", "state", "2"], "--socketcand HOST:PORT"),
    ] {
        let (ok, _, err) = cantwin(&args);
        assert!(!ok, "{args:?}");
        assert!(err.contains(wanted), "{args:?}: {err}");
    }
}

/// One `cia402` servo at node 3 with its home switch above 20000 increments.
fn servo_scenario() -> String {
    let dir = temp_dir("drive-servo");
    let path = dir.join("servo.toml");
    std::fs::write(
        &path,
        "name = \"servo\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n\n\
         [[device]]\nname = \"servo\"\nkind = \"cia402\"\nbus = \"can0\"\nnode_id = 3\nhome_switch = 20000\n",
    )
    .unwrap();
    path.to_string_lossy().into_owned()
}

#[test]
fn cia402_pp_pv_and_hm_drive_commands_against_the_servo_twin() {
    let s = servo_scenario();
    let run = |args: &[&str]| {
        let mut full = vec!["drive", "--scenario", s.as_str()];
        full.extend_from_slice(args);
        cantwin(&full)
    };
    // pp: the set-point handshake, then target reached within the position window.
    let (ok, out, err) = run(&[
        "--json",
        "move",
        "pp",
        "3",
        "8192",
        "--enable",
        "--velocity",
        "40960",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["mode_name"], "pp");
    assert!(
        (v["position"].as_i64().unwrap() - 8192).abs() <= 10,
        "{out}"
    );
    // Relative moves need a target to add to; without --enable the drive is not enabled.
    let (ok, _, err) = run(&["move", "pp", "3", "100", "--relative"]);
    assert!(!ok);
    assert!(
        err.contains("not operation enabled") && err.contains("--enable"),
        "{err}"
    );
    // pv: target velocity reached (bit 10, within the velocity window).
    let (ok, out, err) = run(&["move", "pv", "3", "4096", "--enable"]);
    assert!(ok, "{err}");
    assert!(
        out.starts_with("node 3: target velocity reached, velocity "),
        "{out}"
    );
    // hm: method 19 on the home switch; the home position is 0.
    let (ok, out, err) = run(&[
        "--json",
        "home",
        "3",
        "19",
        "--enable",
        "--switch-speed",
        "40960",
        "--zero-speed",
        "4096",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["statusword"].as_u64().unwrap() & 0x1400, 0x1400, "{out}");
    assert!(v["position"].as_i64().unwrap().abs() < 50, "{out}");
    // A method the drive does not run (15 is reserved, CiA 402-2 6098h) is refused with
    // its abort code.
    let (ok, _, err) = run(&["home", "3", "15", "--enable"]);
    assert!(!ok);
    assert!(
        err.contains("0x06090030") && err.contains("does not run this homing method"),
        "{err}"
    );
}
