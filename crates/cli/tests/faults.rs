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
    assert!(files.len() >= 7, "fault scenarios: {files:?}");
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
