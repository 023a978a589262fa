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
//! reads one (an output, an alarm) at `at_ms`: what a device calls its signals is up to its
//! kind ([`crate::DeviceKind::set_signal`], [`crate::DeviceKind::read_signal`]).
//!
//! Frames a script sends come from a port the runner attaches to every bus (it also
//! acknowledges frames, like a bus analyser would).

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use cantwin_bus::{FaultRule, FrameSelector, PortConfig, PortId, Recorder, Simulation, TapId};
use cantwin_can::{BitRate, ErrorState, Frame, Id, Instant, Node, Outbox};
use serde::Deserialize;
use toml::Spanned;

use crate::build::{BuildEnv, Built, BuiltDevice};
use crate::error::{Located, ScenarioError, line_of};
use crate::model::{BusSpec, DeviceSpec, Scenario};
use crate::registry::{DeviceKind, Registry};

/// How long the runner goes on after the last action or expectation window, so that a
/// frame ending exactly at a window's end is recorded.
pub const END_MARGIN_MS: u64 = 10;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCheck {
    end_ms: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAt {
    time_ms: f64,
    action: String,
    device: Option<String>,
    bus: Option<String>,
    frame: Option<String>,
    fraction: Option<f64>,
    count: Option<u64>,
    bit_rate: Option<String>,
    fault: Option<String>,
    signal: Option<String>,
    value: Option<toml::Value>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawExpect {
    label: Option<String>,
    within_ms: Option<[f64; 2]>,
    at_ms: Option<f64>,
    frame: Option<String>,
    bus: Option<String>,
    from: Option<String>,
    at_least: Option<u64>,
    absent: Option<bool>,
    value: Option<RawValue>,
    controller: Option<RawController>,
    signal: Option<RawSignal>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSignal {
    device: String,
    name: String,
    equals: toml::Value,
    tolerance: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawValue {
    device: String,
    index: u16,
    sub: u8,
    equals: toml::Value,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawController {
    device: String,
    state: String,
}

/// The script of a scenario: what to do when, and what must be seen.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Script {
    /// Stimuli, in file order.
    pub actions: Vec<Action>,
    /// Expectations, in file order.
    pub expectations: Vec<Expectation>,
    /// `[check] end_ms`: run at least until then.
    pub end: Option<Instant>,
}

impl Script {
    /// Whether the scenario has nothing to check.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty() && self.expectations.is_empty()
    }

    /// When a check run stops: the last action, expectation instant or window end, or
    /// `[check] end_ms`, plus [`END_MARGIN_MS`].
    pub fn end_time(&self) -> Instant {
        let last = self
            .actions
            .iter()
            .map(|a| a.at)
            .chain(self.expectations.iter().map(|e| e.what.last_instant()))
            .chain(self.end)
            .max()
            .unwrap_or(Instant::from_nanos(0));
        last.checked_add(cantwin_can::Duration::from_millis(END_MARGIN_MS))
            .unwrap_or(last)
    }
}

/// One timed stimulus.
#[derive(Debug, Clone, PartialEq)]
pub struct Action {
    /// When (virtual time since the start).
    pub at: Instant,
    /// What.
    pub kind: ActionKind,
    /// The line of its `[[at]]` table.
    pub line: usize,
}

/// What an action does.
#[derive(Debug, Clone, PartialEq)]
pub enum ActionKind {
    /// Put a frame on a bus from the script's port.
    Send {
        /// The bus.
        bus: String,
        /// The frame.
        frame: Frame,
    },
    /// Power a device off (`false`) or on (`true`).
    Power {
        /// The device.
        device: String,
        /// On or off.
        on: bool,
    },
    /// Cut (`false`) or restore (`true`) a device's connection to the wires.
    Connect {
        /// The device.
        device: String,
        /// Connected or not.
        connected: bool,
    },
    /// Force a device's controller bus-off.
    BusOff {
        /// The device.
        device: String,
    },
    /// Make a device's controller babble `frame`, or stop it (`None`).
    Babble {
        /// The device.
        device: String,
        /// The frame, or `None` to stop.
        frame: Option<Frame>,
    },
    /// Misconfigure a device's bit rate, or fix it (`None`).
    BitRateMismatch {
        /// The device.
        device: String,
        /// The wrong rate, or `None` to fix it.
        rate: Option<BitRate>,
    },
    /// Drop or corrupt a fraction of the frames on a bus.
    Fault {
        /// The bus.
        bus: String,
        /// The rule (sender resolved at run time).
        corrupt: bool,
        /// Probability per transmission attempt.
        fraction: f64,
        /// Only frames from this device.
        from: Option<String>,
        /// At most this many frames.
        count: Option<u64>,
    },
    /// Remove every fault rule of a bus.
    ClearFaults {
        /// The bus.
        bus: String,
    },
    /// Give a device an internal defect its kind names (`Some`), or repair it (`None`); see
    /// [`crate::registry::DeviceKind::inject`].
    Inject {
        /// The device.
        device: String,
        /// The defect, in the kind's words.
        fault: Option<String>,
    },
    /// Set a physical quantity of a device (see [`crate::DeviceKind::set_signal`]).
    Set {
        /// The device.
        device: String,
        /// The signal's name, as its kind calls it.
        signal: String,
        /// The new value.
        value: toml::Value,
    },
}

/// A frame pattern: identifier, and data bytes where `None` matches any byte.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePattern {
    /// The identifier.
    pub id: Id,
    /// Whether a remote frame is expected.
    pub remote: bool,
    /// The data bytes; `None` matches any byte.
    pub data: Vec<Option<u8>>,
    /// Whether further bytes after `data` are allowed.
    pub any_tail: bool,
}

impl FramePattern {
    /// Whether `frame` matches.
    pub fn matches(&self, frame: &Frame) -> bool {
        if frame.id() != self.id || frame.is_remote() != self.remote {
            return false;
        }
        if self.remote {
            return true;
        }
        let d = frame.data_bytes();
        let len_ok = if self.any_tail {
            d.len() >= self.data.len()
        } else {
            d.len() == self.data.len()
        };
        len_ok
            && self
                .data
                .iter()
                .zip(d)
                .all(|(p, b)| p.is_none_or(|p| p == *b))
    }
}

impl fmt::Display for FramePattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.id {
            Id::Standard(s) => write!(f, "{:03X}#", s.as_raw())?,
            Id::Extended(e) => write!(f, "{:08X}#", e.as_raw())?,
        }
        if self.remote {
            return f.write_str("R");
        }
        for b in &self.data {
            match b {
                Some(b) => write!(f, "{b:02X}")?,
                None => f.write_str("??")?,
            }
        }
        if self.any_tail {
            f.write_str("*")?;
        }
        Ok(())
    }
}

/// One expectation.
#[derive(Debug, Clone, PartialEq)]
pub struct Expectation {
    /// Its `label`, or a description made from it.
    pub label: String,
    /// The line of its `[[expect]]` table.
    pub line: usize,
    /// What is expected.
    pub what: Expect,
}

/// What an expectation asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Expect {
    /// Frames matching a pattern completed (and were not dropped) on a bus in a window.
    Frame {
        /// The bus.
        bus: String,
        /// The pattern.
        pattern: FramePattern,
        /// Only frames sent by this device.
        from: Option<String>,
        /// The window, inclusive, on the frame's end of frame.
        from_time: Instant,
        /// The window's end.
        to_time: Instant,
        /// How many at least (ignored when `absent`).
        at_least: u64,
        /// Whether no matching frame may appear instead.
        absent: bool,
    },
    /// An object of a device holds bytes at an instant.
    Value {
        /// When.
        at: Instant,
        /// The device.
        device: String,
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The little-endian bytes expected.
        equals: Vec<u8>,
        /// Whether `equals` is only the first bytes (a hex string ending in `*`).
        prefix: bool,
    },
    /// A device's controller is in a fault confinement state at an instant.
    Controller {
        /// When.
        at: Instant,
        /// The device.
        device: String,
        /// The state.
        state: ErrorState,
    },
    /// A physical quantity of a device has a value at an instant (see
    /// [`crate::DeviceKind::read_signal`]).
    Signal {
        /// When.
        at: Instant,
        /// The device.
        device: String,
        /// The signal's name.
        name: String,
        /// The value expected.
        equals: toml::Value,
        /// For numbers: how far the value may be from `equals`.
        tolerance: f64,
    },
}

impl Expect {
    fn last_instant(&self) -> Instant {
        match self {
            Expect::Frame { to_time, .. } => *to_time,
            Expect::Value { at, .. }
            | Expect::Controller { at, .. }
            | Expect::Signal { at, .. } => *at,
        }
    }

    fn instant(&self) -> Option<Instant> {
        match self {
            Expect::Frame { .. } => None,
            Expect::Value { at, .. }
            | Expect::Controller { at, .. }
            | Expect::Signal { at, .. } => Some(*at),
        }
    }
}

fn ms(v: f64) -> Option<Instant> {
    (v.is_finite() && (0.0..=1e10).contains(&v)).then(|| Instant::from_nanos((v * 1e6) as u64))
}

fn hex_bytes(s: &str) -> Option<Vec<u8>> {
    let s: String = s
        .chars()
        .filter(|c| !c.is_whitespace() && *c != '.')
        .collect();
    if s.len() % 2 != 0 {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// Splits an optional `BUS ` prefix from a frame text.
fn split_bus(text: &str) -> (Option<&str>, &str) {
    match text.trim().split_once(char::is_whitespace) {
        Some((bus, rest)) => (Some(bus), rest.trim()),
        None => (None, text.trim()),
    }
}

/// Parses `ID#DATA` (candump notation: 3 hex digits standard, 8 extended; `ID#R` remote;
/// in patterns `??` is any byte and a trailing `*` any further bytes).
pub fn parse_pattern(text: &str) -> Result<FramePattern, String> {
    let (id, data) = text
        .split_once('#')
        .ok_or_else(|| format!("{text:?} is not ID#DATA (e.g. 705#05)"))?;
    let raw = u32::from_str_radix(id, 16).map_err(|_| format!("bad identifier {id:?}"))?;
    let id = match id.len() {
        1..=3 => Id::standard(raw as u16).map_err(|e| e.to_string())?,
        8 => Id::extended(raw).map_err(|e| e.to_string())?,
        _ => {
            return Err(format!(
                "identifier {id:?}: 3 hex digits (11 bits) or 8 (29 bits)"
            ));
        }
    };
    if data.eq_ignore_ascii_case("r") {
        return Ok(FramePattern {
            id,
            remote: true,
            data: Vec::new(),
            any_tail: false,
        });
    }
    let (data, any_tail) = match data.strip_suffix('*') {
        Some(d) => (d, true),
        None => (data, false),
    };
    let data: String = data.chars().filter(|c| *c != '.').collect();
    if data.len() % 2 != 0 || data.len() > 16 {
        return Err(format!("data {data:?}: 0–8 bytes as pairs of hex digits"));
    }
    let mut bytes = Vec::new();
    for i in (0..data.len()).step_by(2) {
        let pair = data.get(i..i + 2).unwrap_or("");
        if pair == "??" {
            bytes.push(None);
        } else {
            bytes.push(Some(
                u8::from_str_radix(pair, 16).map_err(|_| format!("bad data byte {pair:?}"))?,
            ));
        }
    }
    Ok(FramePattern {
        id,
        remote: false,
        data: bytes,
        any_tail,
    })
}

/// Parses `ID#DATA` into a frame to send (no wildcards).
pub fn parse_frame(text: &str) -> Result<Frame, String> {
    let p = parse_pattern(text)?;
    if p.any_tail || p.data.iter().any(Option::is_none) {
        return Err(format!("{text:?}: a frame to send has no wildcards"));
    }
    if p.remote {
        return Frame::remote(p.id, 0).map_err(|e| e.to_string());
    }
    let data: Vec<u8> = p.data.iter().flatten().copied().collect();
    Frame::data(p.id, &data).map_err(|e| e.to_string())
}

pub(crate) struct ScriptParser<'a> {
    pub(crate) text: &'a str,
    pub(crate) file: &'a Path,
    pub(crate) buses: &'a [BusSpec],
    pub(crate) devices: &'a [DeviceSpec],
}

impl ScriptParser<'_> {
    fn err(&self, line: usize, key: String, message: impl Into<String>) -> ScenarioError {
        ScenarioError::Invalid {
            at: Located {
                file: self.file.to_path_buf(),
                line: Some(line),
                key: Some(key),
            },
            message: message.into(),
        }
    }

    fn device(&self, d: Option<&String>, line: usize, key: &str) -> Result<String, ScenarioError> {
        let d = d.ok_or_else(|| self.err(line, key.into(), "needs `device`"))?;
        if self.devices.iter().any(|x| &x.name == d) {
            Ok(d.clone())
        } else {
            let known: Vec<&str> = self.devices.iter().map(|x| x.name.as_str()).collect();
            Err(self.err(
                line,
                key.into(),
                format!("no device named {d:?} (devices: {})", known.join(", ")),
            ))
        }
    }

    /// The bus from an explicit key, a frame prefix, or the only bus.
    fn bus(
        &self,
        explicit: Option<&str>,
        prefix: Option<&str>,
        line: usize,
        key: &str,
    ) -> Result<String, ScenarioError> {
        let name = match (explicit, prefix) {
            (Some(a), Some(b)) if a != b => {
                return Err(self.err(
                    line,
                    key.into(),
                    format!("`bus = {a:?}` but the frame names bus {b:?}"),
                ));
            }
            (Some(a), _) | (None, Some(a)) => a.to_string(),
            (None, None) if self.buses.len() == 1 => self.buses[0].name.clone(),
            (None, None) => {
                return Err(self.err(
                    line,
                    key.into(),
                    "the scenario has several buses: name one with `bus`",
                ));
            }
        };
        if self.buses.iter().any(|b| b.name == name) {
            Ok(name)
        } else {
            Err(self.err(line, key.into(), format!("no bus named {name:?}")))
        }
    }

    pub(crate) fn parse(
        &self,
        check: Option<&RawCheck>,
        at: &[Spanned<RawAt>],
        expect: &[Spanned<RawExpect>],
    ) -> Result<Script, ScenarioError> {
        let mut script = Script::default();
        if let Some(c) = check
            && let Some(end) = c.end_ms
        {
            script.end = Some(ms(end).ok_or_else(|| {
                self.err(1, "check.end_ms".into(), "`end_ms` must be a number ≥ 0")
            })?);
        }
        for (i, a) in at.iter().enumerate() {
            let line = line_of(self.text, a.span().start);
            script.actions.push(self.action(i, line, a.get_ref())?);
        }
        for (i, e) in expect.iter().enumerate() {
            let line = line_of(self.text, e.span().start);
            script
                .expectations
                .push(self.expectation(i, line, e.get_ref())?);
        }
        Ok(script)
    }

    fn action(&self, i: usize, line: usize, a: &RawAt) -> Result<Action, ScenarioError> {
        let key = |k: &str| format!("at[{i}].{k}");
        let at = ms(a.time_ms)
            .ok_or_else(|| self.err(line, key("time_ms"), "`time_ms` must be a number ≥ 0"))?;
        let dev = || self.device(a.device.as_ref(), line, &key("device"));
        let frame = |required: bool| -> Result<Option<(Option<&str>, Frame)>, ScenarioError> {
            match &a.frame {
                None if required => Err(self.err(line, key("frame"), "needs `frame`")),
                None => Ok(None),
                Some(f) => {
                    let (bus, f) = split_bus(f);
                    let frame = parse_frame(f).map_err(|m| self.err(line, key("frame"), m))?;
                    Ok(Some((bus, frame)))
                }
            }
        };
        let kind = match a.action.as_str() {
            "send" => {
                let (prefix, frame) =
                    frame(true)?.ok_or_else(|| self.err(line, key("frame"), "needs `frame`"))?;
                let bus = self.bus(a.bus.as_deref(), prefix, line, &key("bus"))?;
                ActionKind::Send { bus, frame }
            }
            "power_off" | "power_on" => ActionKind::Power {
                device: dev()?,
                on: a.action == "power_on",
            },
            "disconnect" | "connect" => ActionKind::Connect {
                device: dev()?,
                connected: a.action == "connect",
            },
            "bus_off" => ActionKind::BusOff { device: dev()? },
            "babble" => ActionKind::Babble {
                device: dev()?,
                frame: frame(true)?.map(|(_, f)| f),
            },
            "babble_stop" => ActionKind::Babble {
                device: dev()?,
                frame: None,
            },
            "bit_rate_mismatch" => {
                let text = a.bit_rate.as_deref().ok_or_else(|| {
                    self.err(line, key("bit_rate"), "needs `bit_rate`, the wrong rate")
                })?;
                let rate = text
                    .parse::<BitRate>()
                    .map_err(|e| self.err(line, key("bit_rate"), e.to_string()))?;
                ActionKind::BitRateMismatch {
                    device: dev()?,
                    rate: Some(rate),
                }
            }
            "bit_rate_fix" => ActionKind::BitRateMismatch {
                device: dev()?,
                rate: None,
            },
            "drop" | "corrupt" => {
                let fraction = a
                    .fraction
                    .ok_or_else(|| self.err(line, key("fraction"), "needs `fraction` (0.0–1.0)"))?;
                if !(0.0..=1.0).contains(&fraction) {
                    return Err(self.err(line, key("fraction"), "`fraction` is 0.0–1.0"));
                }
                let from = match &a.device {
                    Some(_) => Some(dev()?),
                    None => None,
                };
                ActionKind::Fault {
                    bus: self.bus(a.bus.as_deref(), None, line, &key("bus"))?,
                    corrupt: a.action == "corrupt",
                    fraction,
                    from,
                    count: a.count,
                }
            }
            "clear_faults" => ActionKind::ClearFaults {
                bus: self.bus(a.bus.as_deref(), None, line, &key("bus"))?,
            },
            "inject" => ActionKind::Inject {
                device: dev()?,
                fault: Some(a.fault.clone().ok_or_else(|| {
                    self.err(
                        line,
                        key("fault"),
                        "needs `fault`, the defect in the device kind's words",
                    )
                })?),
            },
            "repair" => ActionKind::Inject {
                device: dev()?,
                fault: None,
            },
            "set" => ActionKind::Set {
                device: dev()?,
                signal: a.signal.clone().ok_or_else(|| {
                    self.err(line, key("signal"), "needs `signal`, the quantity to set")
                })?,
                value: a
                    .value
                    .clone()
                    .ok_or_else(|| self.err(line, key("value"), "needs `value`"))?,
            },
            other => {
                return Err(self.err(
                    line,
                    key("action"),
                    format!(
                        "unknown action {other:?} (actions: send, power_off, power_on, disconnect, connect, bus_off, babble, babble_stop, bit_rate_mismatch, bit_rate_fix, drop, corrupt, clear_faults, inject, repair, set)"
                    ),
                ));
            }
        };
        Ok(Action { at, kind, line })
    }

    fn expectation(
        &self,
        i: usize,
        line: usize,
        e: &RawExpect,
    ) -> Result<Expectation, ScenarioError> {
        let key = |k: &str| format!("expect[{i}].{k}");
        let kinds = [
            e.frame.is_some(),
            e.value.is_some(),
            e.controller.is_some(),
            e.signal.is_some(),
        ]
        .iter()
        .filter(|x| **x)
        .count();
        if kinds != 1 {
            return Err(self.err(
                line,
                key("frame"),
                "an [[expect]] has exactly one of `frame`, `value`, `controller`, `signal`",
            ));
        }
        let instant = || -> Result<Instant, ScenarioError> {
            let v = e
                .at_ms
                .ok_or_else(|| self.err(line, key("at_ms"), "needs `at_ms`"))?;
            ms(v).ok_or_else(|| self.err(line, key("at_ms"), "`at_ms` must be a number ≥ 0"))
        };
        let what = if let Some(f) = &e.frame {
            let (prefix, f) = split_bus(f);
            let pattern = parse_pattern(f).map_err(|m| self.err(line, key("frame"), m))?;
            let [a, b] = e.within_ms.ok_or_else(|| {
                self.err(
                    line,
                    key("within_ms"),
                    "a frame expectation needs `within_ms = [FROM, TO]`",
                )
            })?;
            let (from_time, to_time) = match (ms(a), ms(b)) {
                (Some(a), Some(b)) if a <= b => (a, b),
                _ => {
                    return Err(self.err(
                        line,
                        key("within_ms"),
                        "`within_ms` is [FROM, TO] with 0 ≤ FROM ≤ TO",
                    ));
                }
            };
            let from = match &e.from {
                Some(d) => Some(self.device(Some(d), line, &key("from"))?),
                None => None,
            };
            Expect::Frame {
                bus: self.bus(e.bus.as_deref(), prefix, line, &key("bus"))?,
                pattern,
                from,
                from_time,
                to_time,
                at_least: e.at_least.unwrap_or(1),
                absent: e.absent.unwrap_or(false),
            }
        } else if let Some(v) = &e.value {
            let mut prefix = false;
            let equals = match &v.equals {
                toml::Value::Integer(n) => {
                    // Little-endian, as many bytes as the value needs (at least one); the
                    // comparison extends the shorter side with zeros.
                    let mut b = n.to_le_bytes().to_vec();
                    while b.len() > 1 && b.last() == Some(&0) {
                        b.pop();
                    }
                    b
                }
                toml::Value::String(s) => match hex_bytes(match s.strip_suffix('*') {
                    Some(head) => {
                        prefix = true;
                        head
                    }
                    None => s,
                }) {
                    Some(b) => b,
                    None => {
                        return Err(self.err(
                            line,
                            key("value.equals"),
                            "`equals` is an integer or a string of hex bytes",
                        ));
                    }
                },
                _ => {
                    return Err(self.err(
                        line,
                        key("value.equals"),
                        "`equals` is an integer or a string of hex bytes",
                    ));
                }
            };
            Expect::Value {
                at: instant()?,
                device: self.device(Some(&v.device), line, &key("value.device"))?,
                index: v.index,
                sub: v.sub,
                equals,
                prefix,
            }
        } else if let Some(c) = &e.controller {
            let state = match c.state.as_str() {
                "error-active" => ErrorState::Active,
                "error-passive" => ErrorState::Passive,
                "bus-off" => ErrorState::BusOff,
                s => {
                    return Err(self.err(
                        line,
                        key("controller.state"),
                        format!("state {s:?} is error-active, error-passive or bus-off"),
                    ));
                }
            };
            Expect::Controller {
                at: instant()?,
                device: self.device(Some(&c.device), line, &key("controller.device"))?,
                state,
            }
        } else if let Some(g) = &e.signal {
            let tolerance = g.tolerance.unwrap_or(0.0);
            if !(tolerance.is_finite() && tolerance >= 0.0) {
                return Err(self.err(line, key("signal.tolerance"), "`tolerance` is a number ≥ 0"));
            }
            Expect::Signal {
                at: instant()?,
                device: self.device(Some(&g.device), line, &key("signal.device"))?,
                name: g.name.clone(),
                equals: g.equals.clone(),
                tolerance,
            }
        } else {
            return Err(self.err(line, key("frame"), "nothing to expect"));
        };
        let label = e.label.clone().unwrap_or_else(|| describe(&what));
        Ok(Expectation { label, line, what })
    }
}

fn fmt_ms(t: Instant) -> String {
    format!("{:.3} ms", t.as_nanos() as f64 / 1e6)
}

fn describe(what: &Expect) -> String {
    match what {
        Expect::Frame {
            bus,
            pattern,
            from,
            from_time,
            to_time,
            at_least,
            absent,
        } => {
            let who = from
                .as_ref()
                .map(|f| format!(" from {f}"))
                .unwrap_or_default();
            let how = if *absent {
                "no".to_string()
            } else if *at_least == 1 {
                "a".to_string()
            } else {
                format!("at least {at_least}")
            };
            format!(
                "{how} frame {bus} {pattern}{who} in [{}, {}]",
                fmt_ms(*from_time),
                fmt_ms(*to_time)
            )
        }
        Expect::Value {
            at,
            device,
            index,
            sub,
            equals,
            prefix,
        } => format!(
            "{device} {index:04X}sub{sub} = {}{} at {}",
            hex(equals),
            if *prefix { "…" } else { "" },
            fmt_ms(*at)
        ),
        Expect::Controller { at, device, state } => {
            format!(
                "{device} controller {} at {}",
                state_name(*state),
                fmt_ms(*at)
            )
        }
        Expect::Signal {
            at,
            device,
            name,
            equals,
            ..
        } => format!("{device} {name} = {equals} at {}", fmt_ms(*at)),
    }
}

/// Whether a signal's value matches: numbers within `tolerance`, anything else equal.
fn signal_matches(seen: &toml::Value, want: &toml::Value, tolerance: f64) -> bool {
    let num = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        _ => None,
    };
    match (num(seen), num(want)) {
        (Some(a), Some(b)) => (a - b).abs() <= tolerance,
        _ => seen == want,
    }
}

fn state_name(s: ErrorState) -> &'static str {
    match s {
        ErrorState::Active => "error-active",
        ErrorState::Passive => "error-passive",
        ErrorState::BusOff => "bus-off",
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|b| format!("{b:02X}")).collect()
}

/// The verdict on one expectation or action.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// The line of its table.
    pub line: usize,
    /// What it checked or did.
    pub label: String,
    /// Whether it held.
    pub passed: bool,
    /// What was seen.
    pub detail: String,
}

/// What a [`check`] run found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckReport {
    /// The scenario's file.
    pub file: std::path::PathBuf,
    /// Where the run stopped.
    pub end: Instant,
    /// Actions that could not be applied (a powered-off port cannot send), then every
    /// expectation, in file order.
    pub outcomes: Vec<Outcome>,
    /// Frames completed on every bus.
    pub frames: u64,
    /// Error frames on every bus.
    pub error_frames: u64,
    /// Actions applied.
    pub actions: usize,
    /// Every bus's events in bus order, by bus name: the run's capture.
    pub events: Vec<(String, Vec<cantwin_bus::BusEvent>)>,
}

impl CheckReport {
    /// Whether every expectation held and every action applied.
    pub fn passed(&self) -> bool {
        self.outcomes.iter().all(|o| o.passed)
    }

    /// The first failure, by line.
    pub fn first_failure(&self) -> Option<&Outcome> {
        self.outcomes
            .iter()
            .filter(|o| !o.passed)
            .min_by_key(|o| o.line)
    }
}

impl fmt::Display for CheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for o in &self.outcomes {
            writeln!(
                f,
                "{} {}:{}: {}: {}",
                if o.passed { "PASS" } else { "FAIL" },
                self.file.display(),
                o.line,
                o.label,
                o.detail
            )?;
        }
        let failed = self.outcomes.iter().filter(|o| !o.passed).count();
        write!(
            f,
            "{}: {} of {} checks passed, {} actions, {} frames, {} error frames, {} of virtual time",
            if failed == 0 { "ok" } else { "FAILED" },
            self.outcomes.len() - failed,
            self.outcomes.len(),
            self.actions,
            self.frames,
            self.error_frames,
            fmt_ms(self.end)
        )?;
        if let Some(o) = self.first_failure() {
            write!(
                f,
                "\nfirst failure: {}:{}: {}: {}",
                self.file.display(),
                o.line,
                o.label,
                o.detail
            )?;
        }
        Ok(())
    }
}

/// The port a script sends from: receives everything, sends only what it is given.
#[derive(Debug, Default)]
struct ScriptPort;

impl Node for ScriptPort {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

enum Step<'a> {
    Act(&'a Action),
    Probe(&'a Expectation, usize),
}

/// Build `scenario` without running it and check what its script refers to against the
/// built devices: a `value` expectation must name an object the device's kind can read
/// (it has an object dictionary holding that index and sub-index), a `signal` expectation
/// a signal its kind reads. Returns the built scenario, at time zero.
pub fn validate(
    scenario: &Scenario,
    registry: &Registry,
    env: &BuildEnv,
) -> Result<Built, ScenarioError> {
    let built = scenario.build(registry, env)?;
    for (i, e) in scenario.script.expectations.iter().enumerate() {
        let (device, key) = match &e.what {
            Expect::Signal { device, .. } => (device, "signal"),
            Expect::Value { device, .. } => (device, "value"),
            _ => continue,
        };
        let problem = match built.device(device) {
            None => Some(format!("no device named {device:?}")),
            Some(d) => match &e.what {
                Expect::Signal { name, .. } => registry
                    .get(&d.kind)
                    .map(|k| k.read_signal(&built.sim, d.port, name))
                    .and_then(Result::err),
                Expect::Value { index, sub, .. } => {
                    let readable = registry
                        .get(&d.kind)
                        .and_then(|k| k.read_object(&built.sim, d.port, *index, *sub))
                        .is_some();
                    (!readable).then(|| {
                        format!(
                            "device {device:?} (kind {}) has no object {index:#06X}sub{sub} to read",
                            d.kind
                        )
                    })
                }
                _ => None,
            },
        };
        if let Some(message) = problem {
            return Err(ScenarioError::Invalid {
                at: Located {
                    file: scenario.file.clone(),
                    line: Some(e.line),
                    key: Some(format!("expect[{i}].{key}")),
                },
                message,
            });
        }
    }
    Ok(built)
}

/// Build `scenario`, run its script in virtual time and judge every expectation.
pub fn check(
    scenario: &Scenario,
    registry: &Registry,
    env: &BuildEnv,
) -> Result<CheckReport, ScenarioError> {
    check_with_progress(scenario, registry, env, &mut |_, _| {})
}

/// How much virtual time a check run covers between two calls of its progress callback.
const PROGRESS_STEP_MS: u64 = 100;

/// Run `sim` to `t` in steps of [`PROGRESS_STEP_MS`], telling `progress` the virtual time
/// reached and the run's end after each step. Running to `t` in steps processes the same
/// events as running to it at once.
fn advance(
    sim: &mut Simulation,
    t: Instant,
    end: Instant,
    progress: &mut dyn FnMut(Instant, Instant),
) {
    let step = cantwin_can::Duration::from_millis(PROGRESS_STEP_MS);
    while sim.now() < t {
        let next = sim.now().checked_add(step).map_or(t, |n| n.min(t));
        sim.run_until(next);
        progress(next, end);
    }
    sim.run_until(t);
}

/// [`check`], calling `progress(now, end)` as the virtual time advances to the run's end.
pub fn check_with_progress(
    scenario: &Scenario,
    registry: &Registry,
    env: &BuildEnv,
    progress: &mut dyn FnMut(Instant, Instant),
) -> Result<CheckReport, ScenarioError> {
    let mut built = scenario.build(registry, env)?;
    let script = &scenario.script;
    let run_end = script.end_time();
    let mut script_ports: BTreeMap<String, PortId> = BTreeMap::new();
    let mut taps: Vec<(String, cantwin_bus::BusId, TapId)> = Vec::new();
    for (name, id) in built.buses.clone() {
        if let Some(bus) = built.sim.bus_mut(id) {
            let port = bus.attach(ScriptPort, PortConfig::default().with_queue_depth(64));
            let tap = bus.add_tap(Recorder::new());
            script_ports.insert(name.clone(), port);
            taps.push((name, id, tap));
        }
    }
    let mut steps: Vec<(Instant, Step<'_>)> = script
        .actions
        .iter()
        .map(|a| (a.at, Step::Act(a)))
        .chain(
            script
                .expectations
                .iter()
                .enumerate()
                .filter_map(|(i, e)| e.what.instant().map(|t| (t, Step::Probe(e, i)))),
        )
        .collect();
    // Stable: at the same instant, actions and probes keep file order (actions first).
    steps.sort_by_key(|(t, _)| *t);
    let mut outcomes: Vec<Outcome> = Vec::new();
    let mut probes: BTreeMap<usize, Outcome> = BTreeMap::new();
    let port_of = |built: &Built, d: &str| built.device(d).map(|d| d.port);
    for (t, step) in steps {
        advance(&mut built.sim, t, run_end, progress);
        match step {
            Step::Act(a) => {
                if let Err(e) = apply_action(
                    &mut built.sim,
                    &built.buses,
                    &built.devices,
                    registry,
                    &script_ports,
                    &a.kind,
                ) {
                    outcomes.push(Outcome {
                        line: a.line,
                        label: format!("action at {}", fmt_ms(a.at)),
                        passed: false,
                        detail: e,
                    });
                }
            }
            Step::Probe(e, i) => {
                let (passed, detail) = probe(&built, registry, &e.what, port_of);
                probes.insert(
                    i,
                    Outcome {
                        line: e.line,
                        label: e.label.clone(),
                        passed,
                        detail,
                    },
                );
            }
        }
    }
    let end = run_end;
    advance(&mut built.sim, end, end, progress);
    let mut frames = 0;
    let mut error_frames = 0;
    for bus in built.sim.buses() {
        frames += bus.stats().frames();
        error_frames += bus.stats().error_frames();
    }
    for (i, e) in script.expectations.iter().enumerate() {
        if let Some(o) = probes.remove(&i) {
            outcomes.push(o);
            continue;
        }
        if let Expect::Frame {
            bus,
            pattern,
            from,
            from_time,
            to_time,
            at_least,
            absent,
        } = &e.what
        {
            let sender = from.as_deref().and_then(|d| port_of(&built, d));
            let recorder = taps
                .iter()
                .find(|(n, _, _)| n == bus)
                .and_then(|(_, id, tap)| built.sim.bus(*id)?.tap::<Recorder>(*tap));
            let seen: Vec<Instant> = recorder
                .map(|r| {
                    r.frames()
                        .filter(|f| {
                            !f.dropped
                                && f.end >= *from_time
                                && f.end <= *to_time
                                && sender.is_none_or(|s| f.sender == s)
                                && pattern.matches(&f.frame)
                        })
                        .map(|f| f.end)
                        .collect()
                })
                .unwrap_or_default();
            let (passed, detail) = if *absent {
                match seen.first() {
                    None => (true, "none seen".to_string()),
                    Some(t) => (
                        false,
                        format!("{} seen, the first at {}", seen.len(), fmt_ms(*t)),
                    ),
                }
            } else if seen.len() as u64 >= *at_least {
                let first = seen.first().map(|t| fmt_ms(*t)).unwrap_or_default();
                (true, format!("{} seen, the first at {first}", seen.len()))
            } else {
                let nearest = recorder
                    .and_then(|r| {
                        r.frames()
                            .filter(|f| f.frame.id() == pattern.id)
                            .map(|f| (f.end, f.frame))
                            .find(|(t, _)| *t >= *from_time)
                    })
                    .map(|(t, f)| {
                        format!("; next frame with that identifier: {f} at {}", fmt_ms(t))
                    })
                    .unwrap_or_default();
                (
                    false,
                    format!("{} seen, {at_least} needed{nearest}", seen.len()),
                )
            };
            outcomes.push(Outcome {
                line: e.line,
                label: e.label.clone(),
                passed,
                detail,
            });
        }
    }
    let events = taps
        .iter()
        .map(|(name, id, tap)| {
            let events = built
                .sim
                .bus_mut(*id)
                .and_then(|b| b.tap_mut::<Recorder>(*tap))
                .map(|r| core::mem::take(&mut r.events))
                .unwrap_or_default();
            (name.clone(), events)
        })
        .collect();
    Ok(CheckReport {
        file: scenario.file.clone(),
        end,
        outcomes,
        frames,
        error_frames,
        actions: script.actions.len(),
        events,
    })
}

/// Parses one `[[at]]` table of `scenario`'s vocabulary (`action`, `device`, `bus`,
/// `frame`, `fraction`, `count`, `bit_rate`, `fault`; `time_ms` is ignored and may be left
/// out), so that a host can apply, now, the faults the scenario files express: the same
/// names and checks as in a script.
pub fn parse_action(scenario: &Scenario, mut table: toml::Table) -> Result<ActionKind, String> {
    table.entry("time_ms").or_insert(toml::Value::Float(0.0));
    let raw: RawAt = toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| e.message().trim_end().to_string())?;
    let parser = ScriptParser {
        text: "",
        file: &scenario.file,
        buses: &scenario.buses,
        devices: &scenario.devices,
    };
    parser
        .action(0, 0, &raw)
        .map(|a| a.kind)
        .map_err(|e| match e {
            ScenarioError::Invalid { at, message } => match at.key {
                Some(k) => format!("{}: {message}", k.trim_start_matches("at[0].")),
                None => message,
            },
            other => other.to_string(),
        })
}

/// Applies `kind` to `sim` now. Names resolve through `buses` and `devices` (those of the
/// built scenario) and kinds through `registry`; frames to send go out from
/// `script_ports`, a port per bus name.
pub fn apply_action(
    sim: &mut Simulation,
    buses: &[(String, cantwin_bus::BusId)],
    devices: &[crate::BuiltDevice],
    registry: &Registry,
    script_ports: &BTreeMap<String, PortId>,
    kind: &ActionKind,
) -> Result<(), String> {
    let port = |d: &str| {
        devices
            .iter()
            .find(|x| x.name == d)
            .map(|d| d.port)
            .ok_or_else(|| format!("no device {d:?}"))
    };
    let bus_id = |b: &str| {
        buses
            .iter()
            .find(|(n, _)| n == b)
            .map(|(_, id)| *id)
            .ok_or_else(|| format!("no bus {b:?}"))
    };
    fn bus_of(sim: &mut Simulation, p: PortId) -> Result<&mut cantwin_bus::Bus, String> {
        sim.bus_mut(p.bus())
            .ok_or_else(|| "the device's bus is gone".to_string())
    }
    let r = match kind {
        ActionKind::Send { bus, frame } => {
            let p = *script_ports
                .get(bus)
                .ok_or_else(|| format!("no bus {bus:?}"))?;
            sim.transmit(p, *frame)
        }
        ActionKind::Power { device, on } => {
            let p = port(device)?;
            bus_of(sim, p)?.set_powered(p, *on)
        }
        ActionKind::Connect { device, connected } => {
            let p = port(device)?;
            bus_of(sim, p)?.set_connected(p, *connected)
        }
        ActionKind::BusOff { device } => {
            let p = port(device)?;
            bus_of(sim, p)?.force_bus_off(p)
        }
        ActionKind::Babble { device, frame } => {
            let p = port(device)?;
            bus_of(sim, p)?.set_babble(p, *frame)
        }
        ActionKind::BitRateMismatch { device, rate } => {
            let p = port(device)?;
            bus_of(sim, p)?.set_bit_rate_mismatch(p, *rate)
        }
        ActionKind::Fault {
            bus,
            corrupt,
            fraction,
            from,
            count,
        } => {
            let id = bus_id(bus)?;
            let sel = FrameSelector::Fraction(*fraction);
            let mut rule = if *corrupt {
                FaultRule::corrupt(sel)
            } else {
                FaultRule::drop(sel)
            };
            if let Some(d) = from {
                rule = rule.from_port(port(d)?);
            }
            if let Some(n) = count {
                rule = rule.times(*n);
            }
            sim.bus_mut(id)
                .ok_or_else(|| format!("no bus {bus:?}"))?
                .inject(rule);
            Ok(())
        }
        ActionKind::ClearFaults { bus } => {
            let id = bus_id(bus)?;
            sim.bus_mut(id)
                .ok_or_else(|| format!("no bus {bus:?}"))?
                .clear_faults();
            Ok(())
        }
        ActionKind::Inject { device, fault } => {
            let d = devices
                .iter()
                .find(|x| &x.name == device)
                .ok_or_else(|| format!("no device {device:?}"))?;
            let (port, kind) = (d.port, d.kind.clone());
            let k = registry
                .get(&kind)
                .ok_or_else(|| format!("no kind {kind:?}"))?;
            return k.inject(sim, port, fault.as_deref());
        }
        ActionKind::Set {
            device,
            signal,
            value,
        } => {
            let d = devices
                .iter()
                .find(|x| &x.name == device)
                .ok_or_else(|| format!("no device {device:?}"))?;
            let (port, kind) = (d.port, d.kind.clone());
            let k = registry
                .get(&kind)
                .ok_or_else(|| format!("no kind {kind:?}"))?;
            return k.set_signal(sim, port, signal, value);
        }
    };
    r.map_err(|e| e.to_string())
}

fn probe(
    built: &Built,
    registry: &Registry,
    what: &Expect,
    port_of: impl Fn(&Built, &str) -> Option<PortId>,
) -> (bool, String) {
    match what {
        Expect::Value {
            device,
            index,
            sub,
            equals,
            prefix,
            ..
        } => {
            let (d, kind) = match device_and_kind(built, registry, device) {
                Ok(found) => found,
                Err(e) => return (false, e),
            };
            match kind.read_object(&built.sim, d.port, *index, *sub) {
                None => (
                    false,
                    format!(
                        "a {} device does not expose object {index:04X}sub{sub}",
                        d.kind
                    ),
                ),
                Some(bytes) => {
                    let n = bytes.len().max(equals.len());
                    let pad = |b: &[u8]| {
                        let mut v = b.to_vec();
                        v.resize(n, 0);
                        v
                    };
                    let ok = if *prefix {
                        bytes.starts_with(equals)
                    } else {
                        pad(&bytes) == pad(equals)
                    };
                    // A DOMAIN can be megabytes: show its size and first bytes only.
                    let shown = if bytes.len() > 32 {
                        format!("{}… ({} bytes)", hex(&bytes[..32]), bytes.len())
                    } else {
                        hex(&bytes)
                    };
                    (ok, format!("holds {shown}"))
                }
            }
        }
        Expect::Controller { device, state, .. } => {
            let Some(p) = port_of(built, device) else {
                return (false, format!("no device {device:?}"));
            };
            match built.sim.bus(p.bus()).map(|b| b.port_status(p)) {
                Some(Ok(s)) => {
                    let st = s.counters.state();
                    (
                        st == *state,
                        format!(
                            "{} (TEC {}, REC {})",
                            state_name(st),
                            s.counters.tec(),
                            s.counters.rec()
                        ),
                    )
                }
                _ => (false, "the device's port is gone".into()),
            }
        }
        Expect::Signal {
            device,
            name,
            equals,
            tolerance,
            ..
        } => {
            let (d, kind) = match device_and_kind(built, registry, device) {
                Ok(found) => found,
                Err(e) => return (false, e),
            };
            match kind.read_signal(&built.sim, d.port, name) {
                Ok(seen) => (
                    signal_matches(&seen, equals, *tolerance),
                    format!("{name} = {seen}"),
                ),
                Err(e) => (false, e),
            }
        }
        Expect::Frame { .. } => (false, "not a probe".into()),
    }
}

/// The device a probe names and its kind; the error says which of the two is missing.
fn device_and_kind<'a>(
    built: &'a Built,
    registry: &'a Registry,
    device: &str,
) -> Result<(&'a BuiltDevice, &'a dyn DeviceKind), String> {
    let d = built
        .device(device)
        .ok_or_else(|| format!("no device {device:?}"))?;
    let kind = registry
        .get(&d.kind)
        .ok_or_else(|| format!("no kind {:?}", d.kind))?;
    Ok((d, kind))
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
        [[device]]\nname = \"node5\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\nheartbeat_ms = 100\n";

    fn error_of(script: &str) -> String {
        match Scenario::parse(&format!("{HEAD}{script}"), "s.toml") {
            Ok(_) => panic!("accepted: {script}"),
            Err(e) => e.to_string(),
        }
    }

    fn report(script: &str) -> CheckReport {
        let s = Scenario::parse(&format!("{HEAD}{script}"), "s.toml").unwrap();
        check(&s, &Registry::builtin(), &BuildEnv::default()).unwrap()
    }

    #[test]
    fn script_errors_name_file_line_and_key() {
        let e = error_of("\n[[at]]\ntime_ms = 5\naction = \"explode\"\ndevice = \"node5\"\n");
        assert!(
            e.starts_with("s.toml:12: key `at[0].action`: unknown action \"explode\""),
            "{e}"
        );
        let e = error_of("\n[[at]]\ntime_ms = 5\naction = \"power_off\"\ndevice = \"node9\"\n");
        assert!(
            e.contains("key `at[0].device`: no device named \"node9\""),
            "{e}"
        );
        let e = error_of("\n[[expect]]\nwithin_ms = [5, 1]\nframe = \"705#00\"\n");
        assert!(e.contains("s.toml:12: key `expect[0].within_ms`"), "{e}");
        let e = error_of("\n[[expect]]\nwithin_ms = [0, 1]\nframe = \"7055#00\"\n");
        assert!(
            e.contains("key `expect[0].frame`: identifier \"7055\""),
            "{e}"
        );
        let e = error_of("\n[[expect]]\nat_ms = 1\n");
        assert!(
            e.contains("exactly one of `frame`, `value`, `controller`"),
            "{e}"
        );
        let e = error_of("\n[[at]]\ntime_ms = 5\naction = \"send\"\nframe = \"605#4008??\"\n");
        assert!(
            e.contains("no wildcards") || e.contains("bad data byte"),
            "{e}"
        );
    }

    #[test]
    fn frame_patterns_match_wildcards_and_tails() {
        let p = parse_pattern("085#3081??*").unwrap();
        assert!(p.matches(&Frame::std(0x085, &[0x30, 0x81, 0x11, 0, 0, 0, 0, 0]).unwrap()));
        assert!(!p.matches(&Frame::std(0x085, &[0x30, 0x81]).unwrap()));
        assert!(!p.matches(&Frame::std(0x086, &[0x30, 0x81, 0x11]).unwrap()));
        let exact = parse_pattern("705#05").unwrap();
        assert!(exact.matches(&Frame::std(0x705, &[5]).unwrap()));
        assert!(!exact.matches(&Frame::std(0x705, &[5, 0]).unwrap()));
        assert_eq!(
            parse_pattern("12345678#R").unwrap().to_string(),
            "12345678#R"
        );
        assert_eq!(p.to_string(), "085#3081??*");
    }

    #[test]
    fn cia301_7_2_8_3_2_boot_up_then_heartbeat_pass_and_a_wrong_state_fails() {
        let r = report(
            "\n[[expect]]\nwithin_ms = [0, 1]\nframe = \"705#00\"\n\n\
             [[expect]]\nwithin_ms = [99, 101]\nframe = \"705#05\"\n",
        );
        assert!(!r.passed());
        assert!(r.outcomes[0].passed, "{r}");
        assert_eq!(r.outcomes[0].detail, "1 seen, the first at 0.110 ms");
        assert!(!r.outcomes[1].passed);
        assert_eq!(r.first_failure().map(|o| o.line), Some(16));
    }

    #[test]
    fn actions_apply_at_their_time_and_values_are_read_from_the_dictionary() {
        // 0x1017 written to 50 ms at 10 ms: heartbeats at 60 ms and 110 ms, none at 100 ms.
        let r = report(
            "\n[[at]]\ntime_ms = 10\naction = \"send\"\nframe = \"605#2B17100032000000\"\n\n\
             [[expect]]\nat_ms = 11\nvalue = { device = \"node5\", index = 0x1017, sub = 0, equals = 50 }\n\n\
             [[expect]]\nwithin_ms = [59, 61]\nframe = \"705#7F\"\n\n\
             [[expect]]\nwithin_ms = [99, 101]\nframe = \"705#*\"\nabsent = true\n\n\
             [[at]]\ntime_ms = 200\naction = \"bus_off\"\ndevice = \"node5\"\n\n\
             [[expect]]\nat_ms = 200\ncontroller = { device = \"node5\", state = \"bus-off\" }\n",
        );
        assert!(r.passed(), "{r}");
        assert_eq!(r.actions, 2);
        assert_eq!(r.outcomes.len(), 4);
    }

    #[test]
    fn set_actions_and_signal_expectations_go_to_the_device_kind() {
        // A cia301 device has no signals: the kind's answer is the failure's detail.
        let r = report(
            "\n[[at]]\ntime_ms = 1\naction = \"set\"\ndevice = \"node5\"\nsignal = \"load\"\nvalue = 1\n\n\
             [[expect]]\nat_ms = 2\nsignal = { device = \"node5\", name = \"load\", equals = 1 }\n",
        );
        assert!(!r.passed());
        assert_eq!(r.outcomes.len(), 2);
        assert!(
            r.outcomes[0].detail.contains("no signal \"load\" to set"),
            "{r}"
        );
        assert!(
            r.outcomes[1].detail.contains("no signal \"load\" to read"),
            "{r}"
        );
        let e =
            error_of("\n[[at]]\ntime_ms = 5\naction = \"set\"\ndevice = \"node5\"\nvalue = 1\n");
        assert!(e.contains("key `at[0].signal`: needs `signal`"), "{e}");
        let e = error_of(
            "\n[[expect]]\nat_ms = 1\nsignal = { device = \"node5\", name = \"x\", equals = 1, tolerance = -1 }\n",
        );
        assert!(e.contains("`tolerance` is a number"), "{e}");
    }

    #[test]
    fn validate_refuses_a_signal_the_kind_cannot_read() {
        let s = Scenario::parse(
            &format!(
                "{HEAD}\n[[expect]]\nat_ms = 1\nsignal = {{ device = \"node5\", name = \"speed\", equals = 1 }}\n"
            ),
            "s.toml",
        )
        .unwrap();
        let e = validate(&s, &Registry::builtin(), &BuildEnv::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains(
                "s.toml:12: key `expect[0].signal`: a cia301 device has no signal \"speed\" to read"
            ),
            "{e}"
        );
    }

    #[test]
    fn signal_values_match_numbers_within_the_tolerance_and_others_exactly() {
        use toml::Value::{Boolean, Float, Integer, String as Text};
        assert!(signal_matches(&Float(50.0), &Integer(50), 0.0));
        assert!(signal_matches(&Float(49.96), &Float(50.0), 0.05));
        assert!(!signal_matches(&Float(49.9), &Float(50.0), 0.05));
        assert!(signal_matches(&Boolean(true), &Boolean(true), 0.0));
        assert!(!signal_matches(&Boolean(true), &Integer(1), 1.0));
        assert!(!signal_matches(
            &Text("on".into()),
            &Text("off".into()),
            0.0
        ));
    }

    #[test]
    fn an_action_that_cannot_apply_is_a_failure() {
        let r = report(
            "\n[[at]]\ntime_ms = 1\naction = \"power_off\"\ndevice = \"node5\"\n\n\
             [[at]]\ntime_ms = 2\naction = \"bus_off\"\ndevice = \"node5\"\n",
        );
        assert!(!r.passed());
        assert_eq!(r.outcomes.len(), 1);
        assert_eq!(r.outcomes[0].line, 17);
        assert!(r.outcomes[0].detail.contains("powered off"), "{r}");
    }

    #[test]
    fn inject_needs_a_fault_and_a_kind_without_internal_faults_refuses_it() {
        let e = error_of("\n[[at]]\ntime_ms = 1\naction = \"inject\"\ndevice = \"node5\"\n");
        assert!(
            e.contains("at[0].fault") && e.contains("needs `fault`"),
            "{e}"
        );
        let r = report(
            "\n[[at]]\ntime_ms = 1\naction = \"inject\"\ndevice = \"node5\"\nfault = \"FF04\"\n",
        );
        assert!(!r.passed());
        assert!(
            r.outcomes[0]
                .detail
                .contains("a cia301 device has no internal faults to inject"),
            "{r}"
        );
    }

    #[test]
    fn inject_gives_an_adv200_card_its_internal_error_at_the_next_reset() {
        let text = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
            [[device]]\nname = \"drive\"\nkind = \"adv200\"\nbus = \"can0\"\n\
            params = { 4000 = \"CANopen\", 4004 = \"500k\", 4006 = 12 }\n\n\
            [[at]]\ntime_ms = 10\naction = \"inject\"\ndevice = \"drive\"\nfault = \"FFB6\"\n\n\
            [[at]]\ntime_ms = 20\naction = \"power_off\"\ndevice = \"drive\"\n\n\
            [[at]]\ntime_ms = 30\naction = \"power_on\"\ndevice = \"drive\"\n\n\
            [[at]]\ntime_ms = 40\naction = \"inject\"\ndevice = \"drive\"\nfault = \"FF01\"\n\n\
            [[expect]]\nwithin_ms = [0, 19]\nframe = \"08C#*\"\nabsent = true\n\n\
            [[expect]]\nwithin_ms = [30, 31]\nframe = \"08C#11FF81B6FF000000\"\n\n\
            [[expect]]\nat_ms = 35\nvalue = { device = \"drive\", index = 0x2430, sub = 1, equals = 0xFF11 }\n";
        let s = Scenario::parse(text, "s.toml").unwrap();
        let r = check(&s, &Registry::builtin(), &BuildEnv::default()).unwrap();
        // Three expectations pass; the FF01 injection is refused with the list of faults.
        let failed: Vec<_> = r.outcomes.iter().filter(|o| !o.passed).collect();
        assert_eq!(failed.len(), 1, "{r}");
        assert!(failed[0].detail.contains("FFB4..FFC3"), "{r}");
        assert_eq!(r.outcomes.iter().filter(|o| o.passed).count(), 3, "{r}");
    }
}
