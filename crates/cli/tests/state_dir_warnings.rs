//! `cantwin sim --state-dir`: stored parameters that cannot be used are reported on standard
//! error, naming the device, the file and why (the device starts on its defaults and raises
//! its alarm), both when the scenario runs and under `--check`.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

fn scenario(name: &str) -> String {
    format!("{}/../../scenarios/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn stderr_of(args: &[&str], dir: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(args)
        .arg("--state-dir")
        .arg(dir)
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn sim_warns_of_a_store_that_cannot_be_read() {
    let dir = std::env::temp_dir().join(format!("cantwin-sim-warn-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("node5")).unwrap();
    let file = dir.join("node5").join("parameters.store");
    std::fs::write(&file, b"not a parameter store at all").unwrap();
    let run = stderr_of(
        &["sim", &scenario("cia301-device.toml"), "--duration", "0.2"],
        &dir,
    );
    let check = stderr_of(
        &["sim", &scenario("faults/frame-loss.toml"), "--check"],
        &dir,
    );
    for err in [run, check] {
        assert!(
            err.contains("warning: device \"node5\"")
                && err.contains(&file.display().to_string())
                && err.contains("wrong magic")
                && err.contains("EMCY 0x5000"),
            "{err}"
        );
    }
    // The file is left as it was for the user to look at.
    assert_eq!(
        std::fs::read(&file).unwrap(),
        b"not a parameter store at all"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An LSS slave (`lss = true`) keeps its parameters the same way and warns the same way.
#[test]
fn sim_warns_of_an_lss_slaves_store_that_cannot_be_read() {
    let dir = std::env::temp_dir().join(format!("cantwin-sim-warn-lss-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("fresh")).unwrap();
    let file = dir.join("fresh").join("parameters.store");
    std::fs::write(&file, b"not a parameter store at all").unwrap();
    let err = stderr_of(
        &[
            "sim",
            &scenario("lss-commissioning.toml"),
            "--duration",
            "0.2",
        ],
        &dir,
    );
    assert!(
        err.contains("warning: device \"fresh\"")
            && err.contains(&file.display().to_string())
            && err.contains("wrong magic"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
