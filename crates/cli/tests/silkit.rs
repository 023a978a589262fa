//! The SIL Kit commands' bounded waits on the command line: `cantwin silkit netsim
//! --join-timeout` and `cantwin sim --silkit --silkit-join-timeout` against a registry on
//! 127.0.0.1 whose system controller waits for a participant that never comes. SIL Kit and
//! the registry come from the SIL Kit crate's test set-up (`scripts/fetch-silkit.sh`); the
//! tests skip, saying so, only when this machine has no network to fetch it.

#[path = "../../silkit/tests/common/mod.rs"]
mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{Proc, Registry, silkit_dir, system_controller};

fn cantwin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cantwin"))
}

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios")
        .join(name)
}

/// Run `cmd`, which was given a join timeout of `timeout`, and check that it gives up: exit
/// status 1 after at least `timeout` and within [`WITHIN`], its stderr saying every one of
/// `wants`.
fn assert_gives_up(cmd: Command, timeout: Duration, wants: &[&str]) {
    let (status, stderr, took) = run_bounded(cmd, WITHIN + Duration::from_secs(10));
    assert_eq!(status.code(), Some(1), "{stderr}");
    for want in wants {
        assert!(stderr.contains(want), "{want:?} missing: {stderr}");
    }
    assert!(took >= timeout && took < WITHIN, "{took:?}: {stderr}");
}

/// Run `cmd` to its end, at most `bound` of wall time (killed and failed beyond it): its
/// exit status, stderr and how long it took.
fn run_bounded(mut cmd: Command, bound: Duration) -> (ExitStatus, String, Duration) {
    let started = Instant::now();
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting cantwin");
    let mut stderr = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let mut proc = Proc(child);
    let status = loop {
        if let Some(s) = proc.0.try_wait().expect("try_wait") {
            break s;
        }
        assert!(
            started.elapsed() < bound,
            "cantwin did not exit within {bound:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let took = started.elapsed();
    (status, reader.join().expect("stderr reader"), took)
}

/// The bound a run given `--join-timeout 1` must end within: the second, plus joining and
/// leaving the registry (generous: a loaded machine).
const WITHIN: Duration = Duration::from_secs(16);

#[test]
fn netsim_join_timeout_fails_naming_the_required_participant_that_never_joined() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    // The system controller starts the simulation only once both have joined; Ghost never
    // does.
    let _sc = system_controller(&dir, &registry.uri, &["cantwin-netsim", "Ghost"]);
    let mut cmd = cantwin();
    cmd.env("CANTWIN_SILKIT_DIR", &dir).args([
        "silkit",
        "netsim",
        "--registry",
        &registry.uri,
        "--network",
        "can0",
        "--join-timeout",
        "1",
        "--expect",
        "Ghost",
    ]);
    assert_gives_up(
        cmd,
        Duration::from_secs(1),
        &[
            "error: simulating can0 at ",
            "the SIL Kit simulation did not start within 1s",
            "participant Ghost never joined",
        ],
    );
}

#[test]
fn sim_silkit_join_timeout_fails_naming_the_required_participant_that_never_joined() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "PLC"]);
    let mut cmd = cantwin();
    cmd.env("CANTWIN_SILKIT_DIR", &dir)
        .arg("sim")
        .arg(scenario("adv200-ds402.toml"))
        .args(["--silkit", &registry.uri, "--silkit-step", "1000"])
        .args(["--silkit-join-timeout", "1.5", "--silkit-expect", "PLC"]);
    assert_gives_up(
        cmd,
        Duration::from_millis(1500),
        &[
            "error: running as SIL Kit participant cantwin at ",
            "the SIL Kit simulation did not start within 1.5s",
            "participant PLC never joined",
        ],
    );
}

/// Refused by the command line, before SIL Kit is loaded: no registry is needed.
#[test]
fn join_timeouts_must_be_positive_finite_seconds() {
    for bad in ["0", "-1", "inf", "NaN", "1e400", "soon"] {
        let out = cantwin()
            .args(["silkit", "netsim", "--registry", "silkit://127.0.0.1:9"])
            .args(["--network", "can0"])
            .arg(format!("--join-timeout={bad}"))
            .output()
            .expect("running cantwin");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {stderr}");
        assert!(
            stderr.contains("--join-timeout <SECONDS>"),
            "{bad}: {stderr}"
        );
        assert!(
            stderr.contains("positive, finite number of seconds")
                || stderr.contains("is not a number of seconds"),
            "{bad}: {stderr}"
        );
    }
    let out = cantwin()
        .arg("sim")
        .arg(scenario("adv200-ds402.toml"))
        .args([
            "--silkit",
            "silkit://127.0.0.1:9",
            "--silkit-join-timeout",
            "0",
        ])
        .args(["--silkit-step", "1000"])
        .output()
        .expect("running cantwin");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("positive, finite number of seconds"),
        "{stderr}"
    );
    // Only a synchronised run waits for the simulation to start.
    let out = cantwin()
        .arg("sim")
        .arg(scenario("adv200-ds402.toml"))
        .args([
            "--silkit",
            "silkit://127.0.0.1:9",
            "--silkit-join-timeout",
            "5",
        ])
        .output()
        .expect("running cantwin");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--silkit-step"), "{stderr}");
}
