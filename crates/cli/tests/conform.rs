//! `cantwin conform` against every shipped CANopen twin in virtual time: every area, the
//! EDS and profile `cantwin eds export` writes, JUnit XML, JSON and HTML produced.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-conform-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cantwin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(args)
        .current_dir(root())
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The number of cases of the catalogue (`--list`).
fn catalogue_size() -> usize {
    let o = cantwin(&["conform", "--list"]);
    assert!(o.status.success(), "{}", text(&o));
    String::from_utf8_lossy(&o.stdout).lines().count()
}

/// Runs every area against `device` of `scenario` with `eds` (and `profile`), and checks
/// the exit status and the three reports.
fn conform(dir: &Path, scenario: &str, node: u8, eds: &Path, profile: Option<&Path>) {
    let junit = dir.join("conform.xml");
    let html = dir.join("conform.html");
    let json = dir.join("conform.json");
    let node = node.to_string();
    let mut args = vec![
        "conform",
        "--scenario",
        scenario,
        "--node-id",
        &node,
        "--eds",
        eds.to_str().unwrap(),
        "--junit",
        junit.to_str().unwrap(),
        "--html",
        html.to_str().unwrap(),
        "--json-report",
        json.to_str().unwrap(),
    ];
    if let Some(p) = profile {
        args.extend(["--profile", p.to_str().unwrap()]);
    }
    let o = cantwin(&args);
    assert!(o.status.success(), "{scenario}: {}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("PASSED"),
        "{}",
        text(&o)
    );
    let n = catalogue_size();
    let xml = std::fs::read_to_string(&junit).unwrap();
    assert!(xml.starts_with("<?xml"), "{xml}");
    assert_eq!(xml.matches("<testcase ").count(), n, "{xml}");
    assert_eq!(xml.matches("<testsuite ").count(), 8, "one suite per area");
    assert!(!xml.contains("<failure"), "{xml}");
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    for id in [
        "sdo.expedited-upload",
        "nmt.sdo-stopped",
        "store.wrong-signature",
    ] {
        assert!(page.contains(id), "{id} missing from the HTML");
    }
    // The stimulus and response frames of the cases, with their clauses.
    let sdo_rx = format!("{:03X}#", 0x600 + node.parse::<u16>().unwrap());
    assert!(page.contains(&sdo_rx), "no SDO request frame in the HTML");
    assert!(page.contains("CiA 301 §7.2.4.3.17"));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["cases"].as_array().unwrap().len(), n);
}

/// Exports `device`'s EDS and profile, then conforms it.
fn shipped(name: &str, scenario: &str, device: &str, node: u8) {
    let dir = tmp(name);
    let eds = dir.join(format!("{device}.eds"));
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        scenario,
        "--device",
        device,
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let profile = dir.join(format!("{device}.profile.toml"));
    assert!(
        profile.exists(),
        "eds export writes the profile beside the EDS"
    );
    conform(&dir, scenario, node, &eds, Some(&profile));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cia301_twin_conforms() {
    shipped("cia301", "scenarios/cia301-device.toml", "node5", 5);
}

#[test]
fn tm3_island_conforms() {
    shipped("tm3", "scenarios/tm3-island.toml", "island", 3);
}

#[test]
fn adv200_canopen_conforms_with_its_manuals_deviations() {
    shipped("adv200", "scenarios/adv200-example.toml", "drive", 12);
    let dir = tmp("adv200-profile");
    let eds = dir.join("drive.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/adv200-example.toml",
        "--device",
        "drive",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let profile = std::fs::read_to_string(dir.join("drive.profile.toml")).unwrap();
    assert!(profile.contains("§1.1 item 11"), "{profile}");
    assert!(profile.contains("segmented = false"), "{profile}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn adv200_ds402_conforms_with_its_manuals_deviations() {
    shipped("ds402", "scenarios/adv200-ds402.toml", "drive", 2);
}

#[test]
fn cia402_servo_axis_conforms() {
    // The axis of scenarios/servo-axis.toml alone: conform is the master, so the
    // scenario's SYNC generator and scripted frames are left out.
    let dir = tmp("cia402-scenario");
    let scenario = dir.join("axis.toml");
    std::fs::write(
        &scenario,
        "name = \"t\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n\n[[device]]\nname = \"axis\"\nkind = \"cia402\"\nbus = \"can0\"\nnode_id = 5\nload_inertia = 1.0e-4\n",
    )
    .unwrap();
    shipped("cia402", scenario.to_str().unwrap(), "axis", 5);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eds_twin_of_example_io_conforms_to_its_own_file() {
    let dir = tmp("io6");
    conform(
        &dir,
        "scenarios/eds-device.toml",
        6,
        &root().join("scenarios/eds/example-io.eds"),
        None,
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scenario of one `eds` twin of `file` at node-ID 9.
fn eds_scenario(dir: &Path, file: &Path) -> PathBuf {
    let scenario = dir.join("s.toml");
    std::fs::write(
        &scenario,
        format!(
            "name = \"t\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n[[device]]\nname = \"d\"\nkind = \"eds\"\nbus = \"can0\"\nfile = {:?}\nnode_id = 9\n",
            file.to_str().unwrap()
        ),
    )
    .unwrap();
    scenario
}

/// The device description files of the field the eds crate's tests load, each twinned and
/// tested against itself.
#[test]
fn eds_twins_of_real_files_conform_to_their_files() {
    let corpus = root().join("crates/eds/tests/corpus");
    for file in [
        "servo_like.eds",
        "drive.eds",
        "io_module.eds",
        "quirks.eds",
        "sample_like.dcf",
        "configured.dcf",
        "irregular/i04_access_case.eds",
        "irregular/i13_lely_values.eds",
        "irregular/i14_bytes.eds",
    ] {
        let dir = tmp(&file.replace('/', "-"));
        let path = corpus.join(file);
        let scenario = eds_scenario(&dir, &path);
        conform(&dir, scenario.to_str().unwrap(), 9, &path, None);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// Files that are not valid device descriptions fail the case meant for their fault.
#[test]
fn eds_files_with_faults_fail_their_case() {
    let corpus = root().join("crates/eds/tests/corpus");
    // CiA 306 §4.5.2: a file without [DeviceInfo] is no device description.
    let io = std::fs::read_to_string(root().join("scenarios/eds/example-io.eds")).unwrap();
    let start = io.find("[DeviceInfo]").unwrap();
    let end = start + 1 + io[start + 1..].find("\n[").unwrap();
    let no_device_info = tmp("no-device-info").join("no-device-info.eds");
    std::fs::write(&no_device_info, format!("{}{}", &io[..start], &io[end..])).unwrap();
    for (file, case) in [
        (no_device_info.to_str().unwrap(), "eds.file-valid"),
        ("datatypes_like.eds", "eds.mandatory-objects"),
    ] {
        let dir = tmp(&file.replace('/', "-"));
        let path = corpus.join(file);
        let scenario = eds_scenario(&dir, &path);
        let json = dir.join("r.json");
        let o = cantwin(&[
            "conform",
            "--scenario",
            scenario.to_str().unwrap(),
            "--node-id",
            "9",
            "--eds",
            path.to_str().unwrap(),
            "--only",
            "eds",
            "--json-report",
            json.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{file}: {}", text(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let failed: Vec<&str> = v["cases"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["verdict"] == "fail")
            .map(|c| c["id"].as_str().unwrap())
            .collect();
        assert!(failed.contains(&case), "{file}: {failed:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }
    let _ = std::fs::remove_dir_all(no_device_info.parent().unwrap());
}

#[test]
fn a_mandatory_failure_exits_non_zero_and_fails_in_junit() {
    let dir = tmp("claims");
    let eds = dir.join("drive.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/adv200-example.toml",
        "--device",
        "drive",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // A profile that claims segmented transfers the expedited-only card does not offer.
    let profile = dir.join("claims.toml");
    std::fs::write(&profile, "[sdo]\nsegmented = true\n").unwrap();
    let junit = dir.join("j.xml");
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/adv200-example.toml",
        "--node-id",
        "12",
        "--eds",
        eds.to_str().unwrap(),
        "--profile",
        profile.to_str().unwrap(),
        "--only",
        "sdo",
        "--skip",
        "sdo.abort-timeout",
        "--junit",
        junit.to_str().unwrap(),
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    let xml = std::fs::read_to_string(&junit).unwrap();
    assert!(xml.contains("<failure"), "{xml}");
    assert!(xml.contains("name=\"sdo.segmented-download\""), "{xml}");
    assert!(xml.contains("skipped (--skip)"), "{xml}");
    assert_eq!(xml.matches("<testsuite ").count(), 1, "--only sdo");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_arguments_are_refused() {
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "5",
        "--eds",
        "scenarios/eds/example-io.eds",
        "--only",
        "bogus",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("no such area"), "{}", text(&o));
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "5",
        "--eds",
        "scenarios/eds/example-io.eds",
        "--skip",
        "sdo.nope",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("no such case"), "{}", text(&o));
    // A node that is not there: the run stops at once, non-zero.
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "77",
        "--eds",
        "scenarios/eds/example-io.eds",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("does not answer"), "{}", text(&o));
}

/// Over a socketcand connection on the wall clock (here to `cantwin sim`; a socketcand
/// daemon in front of a real device the same way): the NMT area passes, with frames.
#[test]
fn conform_over_socketcand_on_the_wall_clock() {
    let (_sim, addr) =
        common::sim_with_socketcand(&common::scenario_file("cia301-device.toml"), "60");
    let dir = tmp("socketcand");
    let eds = dir.join("node5.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--device",
        "node5",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let json = dir.join("r.json");
    let o = cantwin(&[
        "conform",
        "--socketcand",
        &addr,
        "--node-id",
        "5",
        "--eds",
        eds.to_str().unwrap(),
        "--only",
        "nmt",
        "--json-report",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(
        v["transport"].as_str().unwrap().starts_with("socketcand"),
        "{v}"
    );
    let cases = v["cases"].as_array().unwrap();
    assert!(cases.iter().all(|c| c["verdict"] == "pass"), "{}", text(&o));
    assert!(
        cases.iter().any(|c| c["frames"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f["frame"] == "705#00")),
        "a boot-up logged"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run that is killed leaves its reports with the cases it ran, marked as interrupted.
#[test]
fn a_killed_run_leaves_its_reports_so_far() {
    let (_sim, addr) =
        common::sim_with_socketcand(&common::scenario_file("cia301-device.toml"), "60");
    let dir = tmp("killed");
    let eds = dir.join("node5.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--device",
        "node5",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let json = dir.join("r.json");
    let mut run = common::Killed(
        Command::new(env!("CARGO_BIN_EXE_cantwin"))
            .args([
                "conform",
                "--socketcand",
                &addr,
                "--node-id",
                "5",
                "--eds",
                eds.to_str().unwrap(),
                "--json-report",
                json.to_str().unwrap(),
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    // The reports are rewritten at most once a second of wall time while the run goes.
    let until = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !json.exists() && std::time::Instant::now() < until {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    run.0.kill().unwrap();
    run.0.wait().unwrap();
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(
        v["stopped"]
            .as_str()
            .unwrap()
            .starts_with("interrupted after"),
        "{v}"
    );
    assert!(!v["cases"].as_array().unwrap().is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Over an slcan adapter on TCP (here `cantwin sim --slcan`), remote frames included: the
/// error-control area passes, node guarding polling with remote frames. The wall clock of
/// a loaded machine gets a wide tolerance.
#[test]
fn conform_over_slcan_with_remote_frames() {
    let mut sim = common::Killed(
        Command::new(env!("CARGO_BIN_EXE_cantwin"))
            .args([
                "sim",
                &common::scenario_file("cia301-device.toml"),
                "--slcan",
                "0",
                "--duration",
                "60",
            ])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(sim.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr = line.split_whitespace().nth(1).unwrap().to_string();
    let dir = tmp("slcan");
    let eds = dir.join("node5.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--device",
        "node5",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let json = dir.join("r.json");
    let o = cantwin(&[
        "conform",
        "--slcan",
        &addr,
        "--node-id",
        "5",
        "--eds",
        eds.to_str().unwrap(),
        "--only",
        "error-control",
        "--tolerance-percent",
        "50",
        "--json-report",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let cases = v["cases"].as_array().unwrap();
    let guarding = cases
        .iter()
        .find(|c| c["id"] == "error-control.node-guarding")
        .unwrap();
    assert_eq!(guarding["verdict"], "pass", "{guarding}");
    assert!(
        guarding["frames"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f["frame"] == "705#R1"),
        "{guarding}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The help names the SocketCAN transport: the option in a build with the feature, how to
/// build with it in one without.
#[test]
fn the_help_names_the_socketcan_transport() {
    let o = cantwin(&["conform", "--help"]);
    assert!(o.status.success(), "{}", text(&o));
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(help.contains("--features socketcan"), "{help}");
    assert_eq!(
        help.contains("--socketcan <IFACE>"),
        cfg!(feature = "socketcan"),
        "{help}"
    );
}

/// `--socketcan IFACE` opens the interface, and one that is not CAN is refused by name
/// before any case (every Linux host has `lo`, a loopback interface).
#[cfg(feature = "socketcan")]
#[test]
fn socketcan_on_an_interface_that_is_not_can_is_refused() {
    let o = cantwin(&[
        "conform",
        "--socketcan",
        "lo",
        "--node-id",
        "5",
        "--eds",
        "scenarios/eds/example-io.eds",
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("--socketcan \"lo\""), "{t}");
    assert!(t.contains("not a CAN interface"), "{t}");
    let o = cantwin(&[
        "conform",
        "--socketcan",
        "vcan0",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "5",
        "--eds",
        "scenarios/eds/example-io.eds",
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("cannot be used with"), "{}", text(&o));
}

#[test]
fn boot_timeout_is_taken_and_checked() {
    for bad in ["0", "-1", "601", "NaN"] {
        let o = cantwin(&[
            "conform",
            "--scenario",
            "scenarios/cia301-device.toml",
            "--node-id",
            "5",
            "--eds",
            "scenarios/eds/example-io.eds",
            &format!("--boot-timeout={bad}"),
        ]);
        assert!(!o.status.success(), "{bad}: {}", text(&o));
        assert!(text(&o).contains("--boot-timeout"), "{bad}: {}", text(&o));
    }
    let o = cantwin(&["conform", "--help"]);
    assert!(
        text(&o).contains("--boot-timeout <SECONDS>"),
        "{}",
        text(&o)
    );
    // With 0.5 s the boot-up (within milliseconds on the twin) still counts.
    let dir = tmp("boot-timeout");
    let eds = dir.join("node5.eds");
    let o = cantwin(&[
        "eds",
        "export",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--device",
        "node5",
        "-o",
        eds.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "5",
        "--eds",
        eds.to_str().unwrap(),
        "--only",
        "nmt",
        "--boot-timeout",
        "0.5",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_file_that_describes_no_object_is_refused_before_the_run() {
    let dir = tmp("empty-eds");
    for (name, content) in [("empty.eds", ""), ("notes.txt", "just some notes\n")] {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        let o = cantwin(&[
            "conform",
            "--scenario",
            "scenarios/cia301-device.toml",
            "--node-id",
            "5",
            "--eds",
            path.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{name}: {}", text(&o));
        let t = text(&o);
        assert!(t.contains("no object dictionary"), "{name}: {t}");
        assert!(t.contains(name), "{name}: {t}");
        assert!(
            !t.contains("PASSED") && !t.contains("FAILED"),
            "{name}: not run: {t}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn report_paths_are_checked_before_the_run() {
    for flag in ["--junit", "--json-report", "--html"] {
        let path = "no-such-dir/sub/report.out";
        let o = cantwin(&[
            "conform",
            "--scenario",
            "scenarios/cia301-device.toml",
            "--node-id",
            "5",
            "--eds",
            "scenarios/eds/example-io.eds",
            flag,
            path,
        ]);
        assert!(!o.status.success(), "{flag}: {}", text(&o));
        let t = text(&o);
        assert!(t.contains(&format!("{flag} {path}")), "{flag}: {t}");
        assert!(t.contains("does not exist"), "{flag}: {t}");
        // Refused before the run: no case ran.
        assert!(
            !t.contains("PASSED") && !t.contains("FAILED"),
            "{flag}: {t}"
        );
    }
}

#[test]
fn a_stopped_run_is_an_error_in_junit() {
    let dir = tmp("stopped");
    let junit = dir.join("j.xml");
    let o = cantwin(&[
        "conform",
        "--scenario",
        "scenarios/cia301-device.toml",
        "--node-id",
        "77",
        "--eds",
        "scenarios/eds/example-io.eds",
        "--junit",
        junit.to_str().unwrap(),
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    let xml = std::fs::read_to_string(&junit).unwrap();
    assert!(xml.contains("errors=\"1\""), "{xml}");
    assert!(xml.contains("<error message=\"the run stopped: "), "{xml}");
    assert!(xml.contains("does not answer"), "{xml}");
    let _ = std::fs::remove_dir_all(&dir);
}
