//! `cantwin sim` as the user runs it: a child process on a scenario file, timed from spawn
//! until its socketcand gateway is listening, with its resident memory read from
//! `/proc/PID/status` while it runs.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, anyhow, bail};

/// What one `cantwin sim` run measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimProcessReport {
    /// Devices in the scenario.
    pub devices: u8,
    /// From spawning the process until it printed its gateway's address (scenario parsed,
    /// devices built and powered, simulation thread and gateway started).
    pub startup: WallDuration,
    /// Resident set size while running, in KiB (`VmRSS`).
    pub rss_kib: u64,
    /// Peak resident set size, in KiB (`VmHWM`).
    pub peak_kib: u64,
}

/// A child that is killed if the measurement ends early.
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// A `/proc/PID/status` field in KiB (`VmRSS:     1234 kB`).
fn status_kib(status: &str, field: &str) -> Option<u64> {
    status
        .lines()
        .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
}

/// Run `exe sim SCENARIO --socketcand 0` on `scenario_text` (written into `dir`) with
/// `devices` devices for `run_for` of wall time, and measure it. Needs Linux (`/proc`).
pub fn measure_sim(
    exe: &Path,
    dir: &Path,
    scenario_text: &str,
    devices: u8,
    run_for: WallDuration,
) -> Result<SimProcessReport> {
    let file = dir.join(format!("bench-sim-{devices}.toml"));
    std::fs::write(&file, scenario_text).with_context(|| format!("writing {}", file.display()))?;
    // The process is stopped once its memory has been read; it ends by itself a little
    // later should the measurement not get that far.
    let seconds = run_for.as_secs_f64() + 0.5;
    let started = WallInstant::now();
    let child = Command::new(exe)
        .arg("sim")
        .arg(&file)
        .args(["--socketcand", "0", "--duration", &format!("{seconds:.3}")])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting {} sim", exe.display()))?;
    let mut child = Guard(child);
    let stdout = child
        .0
        .stdout
        .take()
        .ok_or_else(|| anyhow!("no standard output from cantwin sim"))?;
    let mut lines = BufReader::new(stdout).lines();
    let startup = loop {
        match lines.next() {
            Some(Ok(line)) if line.starts_with("socketcand ") => break started.elapsed(),
            Some(Ok(_)) => {}
            Some(Err(e)) => return Err(e).context("reading cantwin sim's output"),
            None => bail!("cantwin sim ended before its gateway was listening"),
        }
    };
    std::thread::sleep(run_for);
    // A process that has ended has no memory left to read.
    if let Some(exit) = child.0.try_wait().context("checking on cantwin sim")? {
        bail!("cantwin sim on {devices} devices exited with {exit} before it was measured");
    }
    let status_path = format!("/proc/{}/status", child.0.id());
    let status = std::fs::read_to_string(&status_path)
        .with_context(|| format!("reading {status_path} (the memory figures need Linux)"))?;
    let rss_kib =
        status_kib(&status, "VmRSS").ok_or_else(|| anyhow!("no VmRSS in {status_path}"))?;
    let peak_kib = status_kib(&status, "VmHWM").unwrap_or(rss_kib);
    // Measured: stopped now rather than at the end of its `--duration`, which half a second
    // of every start would wait for.
    drop(child);
    let _ = std::fs::remove_file(&file);
    Ok(SimProcessReport {
        devices,
        startup,
        rss_kib,
        peak_kib,
    })
}

/// [`measure_sim`] `starts` times, each running [`RUN_FOR`]: the fastest start-up (a slower
/// one waited for a core) and the largest resident and peak sets (so that no figure is
/// flattered by a run that had touched fewer pages when it was read).
pub fn best_of(
    exe: &Path,
    dir: &Path,
    scenario_text: &str,
    devices: u8,
    starts: usize,
) -> Result<SimProcessReport> {
    let mut best: Option<SimProcessReport> = None;
    for _ in 0..starts {
        let m = measure_sim(exe, dir, scenario_text, devices, RUN_FOR)?;
        best = Some(match best {
            Some(b) => SimProcessReport {
                startup: b.startup.min(m.startup),
                rss_kib: b.rss_kib.max(m.rss_kib),
                peak_kib: b.peak_kib.max(m.peak_kib),
                ..b
            },
            None => m,
        });
    }
    best.ok_or_else(|| anyhow!("no cantwin sim run"))
}

/// How long each run of [`best_of`] runs paced before its memory is read.
pub const RUN_FOR: WallDuration = WallDuration::from_millis(600);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_fields_are_read_in_kib() {
        let status = "Name:\tcantwin\nVmHWM:\t    9000 kB\nVmRSS:\t    8123 kB\n";
        assert_eq!(status_kib(status, "VmRSS"), Some(8123));
        assert_eq!(status_kib(status, "VmHWM"), Some(9000));
        assert_eq!(status_kib(status, "VmSwap"), None);
    }
}
