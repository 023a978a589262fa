//! Helpers shared by the command-line tests: run the real binary, start `cantwin sim` behind
//! a socketcand gateway, find the repository's scenarios, make scratch directories.
#![allow(dead_code, clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

/// Run `cantwin ARGS`: (success, stdout, stderr).
pub fn cantwin(args: &[&str]) -> (bool, String, String) {
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

/// A child process that is killed when the test ends, passed or failed: a simulation's
/// `--duration` is only a bound for a test that dies before it cleans up.
pub struct Killed(pub Child);

impl std::ops::Deref for Killed {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Killed {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start `cantwin sim SCENARIO --socketcand 0 --duration SECONDS` and return the child and the
/// address from the line it prints once it accepts connections.
pub fn sim_with_socketcand(scenario: &str, seconds: &str) -> (Killed, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", scenario, "--socketcand", "0", "--duration", seconds])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line.split_whitespace().nth(1).unwrap().to_string();
    (Killed(child), addr)
}

/// A scenario of the repository's `scenarios/`.
pub fn scenario_file(name: &str) -> String {
    format!("{}/../../scenarios/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A fresh scratch directory for one test (`tag`) of this process.
pub fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
