//! How commands print: text for a person, or JSON for a program (`--json`), and progress
//! bars on standard error for long operations.
//!
//! In JSON mode a command that prints one result prints one JSON object on one line; a
//! command that prints a stream (trace, dump, cal events) prints one object per line (JSON
//! Lines). Errors still go to standard error as text, with a non-zero exit status.
//!
//! Progress bars are drawn on standard error only when it is a terminal and neither `--json`
//! nor `--quiet` was given, so what goes to standard output is the same with and without them.

use std::io::Write as _;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration as WallDuration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::Value;

static JSON: AtomicBool = AtomicBool::new(false);
static QUIET: AtomicBool = AtomicBool::new(false);

/// Set once by `main` from the global flags.
pub fn configure(json: bool, quiet: bool) {
    JSON.store(json, Ordering::Relaxed);
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether `--json` was given.
pub fn json() -> bool {
    JSON.load(Ordering::Relaxed)
}

/// Whether progress bars are off.
fn silent() -> bool {
    json() || QUIET.load(Ordering::Relaxed)
}

/// Print one JSON value on one line of standard output.
pub fn emit(value: &Value) -> std::io::Result<()> {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    writeln!(out, "{value}")?;
    out.flush()
}

/// Print `text` in text mode, or `value` in JSON mode.
pub fn result(text: impl std::fmt::Display, value: impl FnOnce() -> Value) -> std::io::Result<()> {
    if json() {
        emit(&value())
    } else {
        let stdout = std::io::stdout();
        let mut out = stdout.lock();
        writeln!(out, "{text}")?;
        out.flush()
    }
}

/// Bytes as upper-case hex without separators, the way captures and frames show data.
pub fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

/// A CAN frame as JSON: identifier, whether it is extended or remote, data in hex.
pub fn frame_json(frame: &cantwin_can::Frame) -> Value {
    serde_json::json!({
        "id": frame.id().as_raw(),
        "extended": frame.is_extended(),
        "remote": frame.is_remote(),
        "dlc": frame.dlc(),
        "data": hex(frame.data_bytes()),
    })
}

fn bar(len: Option<u64>, template: &str) -> ProgressBar {
    let target = if silent() {
        ProgressDrawTarget::hidden()
    } else {
        // indicatif draws nothing when standard error is not a terminal.
        ProgressDrawTarget::stderr()
    };
    let pb = match len {
        Some(n) => ProgressBar::with_draw_target(Some(n), target),
        None => ProgressBar::with_draw_target(None, target),
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style.progress_chars("#>-"));
    }
    pb.enable_steady_tick(WallDuration::from_millis(200));
    pb
}

/// A progress bar counting bytes (SDO transfers); `total` unknown gives a spinner.
pub fn bytes(total: Option<u64>, what: &str) -> ProgressBar {
    let pb = match total {
        Some(t) => bar(
            Some(t),
            "{msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta}",
        ),
        None => bar(None, "{spinner} {msg} {bytes} {bytes_per_sec}"),
    };
    pb.set_message(what.to_string());
    pb
}

/// A progress bar counting `total` steps of something named by `unit`.
pub fn steps(total: u64, what: &str) -> ProgressBar {
    let pb = bar(
        Some(total),
        "{msg} [{bar:40}] {human_pos}/{human_len} eta {eta}",
    );
    pb.set_message(what.to_string());
    pb
}

/// A spinner with the elapsed time, for operations whose length is not known in advance.
pub fn spinner(what: &str) -> ProgressBar {
    let pb = bar(None, "{spinner} {msg} {elapsed}");
    pb.set_message(what.to_string());
    pb
}

/// The line `cantwin sim` prints for each bus a gateway serves once it accepts connections:
/// `KIND ADDR BUS`, or `{"gateway", "addr", "bus"}` with `--json`.
pub fn gateway(kind: &str, addr: std::net::SocketAddr, bus: &str) -> std::io::Result<()> {
    result(
        format_args!("{kind} {addr} {bus}"),
        || serde_json::json!({"gateway": kind, "addr": addr.to_string(), "bus": bus}),
    )
}
