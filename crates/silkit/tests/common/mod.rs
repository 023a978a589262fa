//! Test set-up shared by the SIL Kit tests: SIL Kit from `scripts/fetch-silkit.sh`, a registry
//! on 127.0.0.1 with a port the system picks, child processes that die with the test.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::{Duration, Instant};

/// The directory holding libSilKit.so, sil-kit-registry and sil-kit-system-controller, or
/// `None` (with the reason printed) when SIL Kit cannot be fetched because this machine has
/// no network. Any other failure fails the test.
pub fn silkit_dir() -> Option<PathBuf> {
    static DIR: OnceLock<Option<PathBuf>> = OnceLock::new();
    DIR.get_or_init(|| {
        if let Some(d) = std::env::var_os("CANTWIN_SILKIT_DIR") {
            return Some(PathBuf::from(d));
        }
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let out = Command::new(root.join("scripts/fetch-silkit.sh"))
            .output()
            .expect("running scripts/fetch-silkit.sh");
        match out.status.code() {
            Some(0) => {
                let rel = String::from_utf8_lossy(&out.stdout).trim().to_string();
                Some(root.join(rel))
            }
            Some(2) => {
                // Straight to the process's stderr, not `eprintln!`: libtest captures the
                // macros' output of a passing test, and a skip nobody sees looks like a pass.
                // The script's own message names what it could not reach.
                let _ = writeln!(
                    std::io::stderr(),
                    "SKIPPED: the SIL Kit tests of {}: SIL Kit cannot be fetched, this machine has no network ({})",
                    env!("CARGO_CRATE_NAME"),
                    String::from_utf8_lossy(&out.stderr).trim()
                );
                None
            }
            _ => panic!(
                "scripts/fetch-silkit.sh failed: {}",
                String::from_utf8_lossy(&out.stderr)
            ),
        }
    })
    .clone()
}

/// How long a participant may take to join and the simulation to start: a few seconds on a
/// loaded machine, so a bound that only a participant that never joins reaches.
pub const JOIN: Duration = Duration::from_secs(20);

/// How long a whole coordinated run may take (the tests' runs take well under a second).
pub const RUN: Duration = Duration::from_secs(40);

/// The tests' bounds for a coordinated run with `peers` (named when they never join): the
/// run fails with an error naming them instead of hanging, and the test's child processes
/// die as it unwinds.
pub fn deadlines(peers: &[&str]) -> cantwin_silkit::Deadlines {
    cantwin_silkit::Deadlines::new(JOIN, RUN).expecting(peers)
}

/// A child process killed when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A SIL Kit registry listening on 127.0.0.1 on a port the system picked.
pub struct Registry {
    pub uri: String,
    _proc: Proc,
    _dir: TempDir,
}

/// A directory removed when dropped.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let base = std::env::temp_dir().join(format!(
            "cantwin-silkit-{tag}-{}-{}",
            std::process::id(),
            Instant::now().elapsed().as_nanos() ^ (rand_u32() as u128)
        ));
        std::fs::create_dir_all(&base).expect("temp dir");
        TempDir(base)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn rand_u32() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u8(0);
    h.finish() as u32
}

impl Registry {
    pub fn start(dir: &Path) -> Registry {
        let tmp = TempDir::new("registry");
        let cfg = tmp.0.join("registry.yaml");
        let child = Command::new(dir.join("sil-kit-registry"))
            .args(["-u", "silkit://127.0.0.1:0", "-g"])
            .arg(&cfg)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("starting sil-kit-registry");
        let proc = Proc(child);
        // The registry writes the file (atomically) once it listens (docs/utilities).
        let until = Instant::now() + Duration::from_secs(20);
        let uri = loop {
            if let Ok(text) = std::fs::read_to_string(&cfg)
                && let Some(line) = text.lines().find(|l| l.contains("RegistryUri"))
            {
                let uri = line
                    .split_once(':')
                    .map(|(_, v)| v.trim().trim_matches('\'').trim_matches('"').to_string())
                    .expect("RegistryUri line");
                break uri;
            }
            assert!(Instant::now() < until, "sil-kit-registry did not start");
            std::thread::sleep(Duration::from_millis(10));
        };
        Registry {
            uri,
            _proc: proc,
            _dir: tmp,
        }
    }
}

/// Start `sil-kit-system-controller` for a coordinated simulation of `names`.
pub fn system_controller(dir: &Path, uri: &str, names: &[&str]) -> Proc {
    let child = Command::new(dir.join("sil-kit-system-controller"))
        .args(["-u", uri, "-l", "off"])
        .args(names)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting sil-kit-system-controller");
    Proc(child)
}

/// A child whose stdout lines arrive on a channel.
pub struct Lines {
    pub proc: Proc,
    rx: Receiver<String>,
    pub seen: Vec<String>,
}

impl Lines {
    pub fn spawn(mut cmd: Command) -> Lines {
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("spawning a participant");
        let out = child.stdout.take().expect("stdout");
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Lines {
            proc: Proc(child),
            rx,
            seen: Vec::new(),
        }
    }

    /// The next line satisfying `pred`, waiting at most `timeout` in all.
    pub fn wait_for(&mut self, timeout: Duration, pred: impl Fn(&str) -> bool) -> Option<String> {
        let until = Instant::now() + timeout;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if pred(&line) {
                        return Some(line);
                    }
                }
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    /// Every line until the process ends (at most `timeout`).
    pub fn finish(&mut self, timeout: Duration) -> Vec<String> {
        let until = Instant::now() + timeout;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => panic!(
                    "participant did not finish in {timeout:?}; output so far: {:#?}",
                    self.seen
                ),
            }
        }
        self.seen.clone()
    }

    /// The exit status, waiting at most `timeout`.
    pub fn status(&mut self, timeout: Duration) -> std::process::ExitStatus {
        let until = Instant::now() + timeout;
        loop {
            if let Some(s) = self.proc.0.try_wait().expect("try_wait") {
                return s;
            }
            assert!(
                Instant::now() < until,
                "process did not exit in {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// The example participant program, built by cargo for the tests.
pub fn example_participant() -> PathBuf {
    // Integration tests live in target/<profile>/deps; examples in target/<profile>/examples.
    let exe = std::env::current_exe().expect("test exe");
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target profile dir");
    let exe = profile_dir.join("examples").join("can_participant");
    assert!(
        exe.exists(),
        "{} is missing: `cargo test -p cantwin-silkit` builds it (a `--test` filter alone does not)",
        exe.display()
    );
    exe
}

/// A participant configuration that logs nothing (stdout carries the participants' reports).
pub const QUIET_CONFIG: &str = r#"{"Logging":{"Sinks":[{"Type":"Stdout","Level":"Off"}]}}"#;
