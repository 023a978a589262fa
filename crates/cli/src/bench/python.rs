//! `cantwin bench python`: python-canopen against cantwin's CiA 301 twin and against
//! python-canopen's own `LocalNode`, both through this binary's socketcand gateway.
//!
//! The measurement itself is `tests/interop/bench_sdo_roundtrip.py` (it needs python-can and
//! python-canopen, which the interop suite installs into its virtualenv): this runs it with
//! this binary as the simulator and lets it record its section of `BENCHMARKS.md`.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// The script, relative to the repository root.
const SCRIPT: &str = "tests/interop/bench_sdo_roundtrip.py";

/// Where a Python with python-can and python-canopen is: `CANTWIN_PYTHON`, else the interop
/// suite's virtualenv under `CARGO_TARGET_DIR` or the repository's `target/`.
fn python(root: &Path) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("CANTWIN_PYTHON") {
        return Some(PathBuf::from(p));
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|t| if t.is_absolute() { t } else { root.join(t) })
        .unwrap_or_else(|| root.join("target"));
    let venv = target.join("interop-venv").join("bin").join("python");
    venv.is_file().then_some(venv)
}

/// What stands in the way of running the benchmark from `root`, if anything.
pub fn missing(root: &Path) -> Option<String> {
    interpreter(root).err()
}

/// The Python to run the script with, or why it cannot run from `root`.
fn interpreter(root: &Path) -> Result<PathBuf, String> {
    if !root.join(SCRIPT).is_file() {
        return Err(format!(
            "{SCRIPT} is not under {}: run it from the cantwin repository (or give --file \
             the repository's BENCHMARKS.md)",
            display_root(root)
        ));
    }
    python(root).ok_or_else(|| {
        "no Python with python-can and python-canopen: run `bash tests/interop/run.sh` once \
         to create target/interop-venv, or set CANTWIN_PYTHON to such an interpreter"
            .to_string()
    })
}

fn display_root(root: &Path) -> String {
    if root.as_os_str().is_empty() {
        "the current directory".to_string()
    } else {
        root.display().to_string()
    }
}

/// Run the benchmark: `requests` expedited uploads per server and `transfers` 64 KiB
/// segmented uploads and downloads per server; with `write`, record it in `file`.
pub fn run(root: &Path, file: &Path, requests: usize, transfers: usize, write: bool) -> Result<()> {
    let python = interpreter(root).map_err(|why| anyhow::anyhow!("bench python: {why}"))?;
    let exe = std::env::current_exe().context("locating this cantwin binary")?;
    let mut cmd = Command::new(&python);
    cmd.arg(root.join(SCRIPT))
        .arg(requests.to_string())
        .arg(transfers.to_string())
        .env("CANTWIN_BIN", &exe)
        .env("CANTWIN_BENCHMARKS_MD", absolute(file)?);
    if write {
        cmd.arg("--write");
    }
    if crate::output::json() {
        cmd.arg("--json");
    }
    let status = cmd
        .status()
        .with_context(|| format!("starting {}", python.display()))?;
    if !status.success() {
        bail!("bench python: {SCRIPT} failed ({status})");
    }
    Ok(())
}

fn absolute(p: &Path) -> Result<PathBuf> {
    if p.is_absolute() {
        Ok(p.to_path_buf())
    } else {
        Ok(std::env::current_dir()
            .context("reading the current directory")?
            .join(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_the_repository_the_missing_script_is_named() {
        let dir = std::env::temp_dir().join("cantwin-bench-python-nowhere");
        let why = missing(&dir).expect("no script there");
        assert!(why.contains(SCRIPT), "{why}");
    }
}
