//! Scenario scripts: timed stimuli (`[[at]]`) and expectations (`[[expect]]`) in the scenario
//! file, run in virtual time by [`check`] into a [`CheckReport`].
//!
//! The format is described in `docs/scenarios.md`. In short:
//!
//! ```toml
//! [check]
//! end_ms = 3000            # optional: run at least this long
//!
//! [[at]]
//! time_ms = 500
//! action = "power_off"     # power_on, disconnect, connect, bus_off, babble, babble_stop,
//! device = "node5"         # bit_rate_mismatch, bit_rate_fix, send, drop, corrupt, clear_faults,
//!                          # inject (with `fault`), repair, set
//!
//! [[expect]]
//! within_ms = [1000, 1100]
//! frame = "705#00"         # ID#DATA; `??` matches any byte, a trailing `*` any further bytes
//! ```
//!
//! `action = "set"` with `signal` and `value` changes a physical quantity of a device (an
//! input, a load, a module pulled out) and `[[expect]] signal = { device, name, equals }`
//! reads one (an output, an alarm) at `at_ms`: what a device calls its signals is up to the
//! device ([`cantwin_twin::Twin::set_signal`], [`cantwin_twin::Twin::read_signal`]); the
//! script's TOML values become [`cantwin_twin::SignalValue`]s when the file is parsed.
//!
//! Frames a script sends come from a port the runner attaches to every bus (it also
//! acknowledges frames, like a bus analyser would).

pub(crate) mod parse;
mod run;

pub use parse::{
    Action, ActionKind, END_MARGIN_MS, Expect, Expectation, FramePattern, Script, parse_frame,
    parse_pattern,
};
pub use run::{
    CheckReport, Outcome, apply_action, check, check_with_progress, parse_action, validate,
};
