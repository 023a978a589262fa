//! Every fault-injection scenario in `scenarios/faults/` passes `cantwin sim --check`, and a
//! failed expectation makes the command fail with a report naming the line.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn check(path: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", "--check"])
        .arg(path)
        .output()
        .unwrap()
}

#[test]
fn every_fault_scenario_passes_its_checks() {
    let dir = workspace().join("scenarios/faults");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 20, "fault scenarios: {files:?}");
    for file in &files {
        let out = check(file);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}:\n{stdout}\n{}",
            file.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(!stdout.contains("FAIL"), "{stdout}");
        assert!(
            stdout.lines().filter(|l| l.starts_with("PASS")).count() >= 3,
            "{stdout}"
        );
    }
}

/// The device twins' fault scenarios: each must be there and pass, with the verdicts that
/// say its manual's reaction (they also run in `every_fault_scenario_passes_its_checks`).
#[test]
fn tm3_and_opendrive_fault_scenarios_react_as_their_manuals_say() {
    let dir = workspace().join("scenarios/faults");
    for (file, verdict) in [
        (
            "tm3-master-vanishes.toml",
            "EMCY 0x8130, register 0x11, 1002H = 0, module 0",
        ),
        (
            "tm3-module-pulled.toml",
            "EMCY 0x7003, register 0x81, 1002H = 0x80000008, module 2",
        ),
        ("tm3-guarding-loss.toml", "1029H sub 1 = 2: stopped"),
        ("tm3-bus-off.toml", "EMCY 0x8140 bus-off recovered"),
        (
            "tm3-power-cycle-mid-sdo.toml",
            "10.5 ms refused at the object write",
        ),
        ("tm3-segmented-loss.toml", "completed at its second attempt"),
        (
            "opendrive-master-vanishes.toml",
            "still runs at 50 Hz on the last command",
        ),
        (
            "opendrive-bus-off.toml",
            "an overcurrent after the recovery is notified",
        ),
        (
            "opendrive-overload-trip.toml",
            "A3 after about 33 s: message 1 bit 7",
        ),
        (
            "opendrive-power-cycle.toml",
            "flying restart: no overcurrent trip",
        ),
    ] {
        let out = check(&dir.join(file));
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{file}:\n{stdout}");
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with("PASS") && l.contains(verdict)),
            "{file}: no passed check \"{verdict}\":\n{stdout}"
        );
    }
}

#[test]
fn a_failed_expectation_fails_the_command_and_names_its_line() {
    let dir = std::env::temp_dir().join(format!("cantwin-faults-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("wrong.toml");
    std::fs::write(
        &file,
        "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
         [[device]]\nname = \"node5\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\nheartbeat_ms = 100\n\n\
         [[expect]]\nwithin_ms = [0, 1]\nframe = \"705#00\"\n\n\
         [[expect]]\nlabel = \"an operational heartbeat (but nobody starts the node)\"\nwithin_ms = [50, 250]\nframe = \"705#05\"\n",
    )
    .unwrap();
    let out = check(&file);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stdout.contains("PASS"), "{stdout}");
    assert!(
        stdout.contains("wrong.toml:16: an operational heartbeat (but nobody starts the node): 0 seen, 1 needed; next frame with that identifier: 705#7F at 100.110 ms"),
        "{stdout}"
    );
    assert!(stdout.contains("first failure: "), "{stdout}");
    assert!(stderr.contains("check failed"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_scenario_without_a_script_is_refused_by_check() {
    let out = check(&workspace().join("scenarios/cia301-device.toml"));
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no [[at]] or [[expect]] tables"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs one ADV200 fault scenario: it must pass, with a PASS line for each of `verdicts`
/// (the expectations that carry the manual's behaviour).
fn adv200(name: &str, verdicts: &[&str]) {
    let file = workspace().join("scenarios/faults").join(name);
    let out = check(&file);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{name}:\n{stdout}");
    for v in verdicts {
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with("PASS") && l.contains(v)),
            "{name}: no PASS for {v:?}:\n{stdout}"
        );
    }
}

#[test]
fn adv200_manual_1_5_master_heartbeat_loss_is_opt_bus_fault_8130_per_alarm_mode() {
    adv200(
        "adv200-master-vanishes.toml",
        &[
            "node 12 (enabled): Opt Bus Fault 8130",
            "node 13: no Opt Bus Fault",
            "node 14 (disabled, alarm mode 1): Opt Bus Fault 8130",
            "node 12 tripped",
            "node 12 runs again",
        ],
    );
}

#[test]
fn adv200_manual_1_5_bus_off_is_ffc7_then_8100_and_the_network_recovers() {
    adv200(
        "adv200-bus-off.toml",
        &[
            "Opt Bus Fault FFC7",
            "Opt Bus Fault 8100",
            "node 13 (disabled, alarm mode 0): no Opt Bus Fault",
            "node 12 answers SYNC again",
            "node 12 runs again",
        ],
    );
}

#[test]
fn adv200_manual_3_7_1_polled_io_watchdog_is_bus_loss_and_a_wrong_poll_size_ffc8() {
    adv200(
        "adv200-devicenet-master-silent.toml",
        &[
            "MAC 12 after the watchdog: Opt Bus fault",
            "MAC 12 tripped",
            "MAC 13 does not answer the 2-byte poll",
            "MAC 13: Opt Bus fault (FFC8",
        ],
    );
}

#[test]
fn adv200_power_cycle_mid_transfer_and_internal_error_ffb5_at_power_up() {
    adv200(
        "adv200-power-cycle.toml",
        &[
            "the lost transfer's segment is refused",
            "the drive restarted disabled",
            "and reports Opt Bus Fault FFB5",
            "the alarm reset cannot clear it",
            "the repaired card boots clean",
        ],
    );
}
