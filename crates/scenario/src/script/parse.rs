//! The script's vocabulary: the raw `[check]`, `[[at]]` and `[[expect]]` tables, what they
//! parse into, and the parser.

use std::fmt;
use std::path::Path;

use cantwin_can::{BitRate, ErrorState, Frame, Id, Instant};
use cantwin_twin::{SignalId, SignalValue};
use serde::Deserialize;
use toml::Spanned;

use crate::error::{Located, ScenarioError, line_of};
use crate::spec::{BusSpec, DeviceSpec};

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
    /// Give a device an internal defect it names (`Some`), or repair its internal defects
    /// (`None`); see [`cantwin_twin::Twin::inject`].
    Inject {
        /// The device.
        device: String,
        /// The defect, in the device's words.
        fault: Option<String>,
    },
    /// Set a physical quantity of a device (see [`cantwin_twin::Twin::set_signal`]).
    Set {
        /// The device.
        device: String,
        /// The signal, as the device calls it.
        signal: SignalId,
        /// The new value.
        value: SignalValue,
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
    /// [`cantwin_twin::Twin::read_signal`]).
    Signal {
        /// When.
        at: Instant,
        /// The device.
        device: String,
        /// The signal.
        name: SignalId,
        /// The value expected.
        equals: SignalValue,
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

    pub(crate) fn instant(&self) -> Option<Instant> {
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

    pub(crate) fn action(&self, i: usize, line: usize, a: &RawAt) -> Result<Action, ScenarioError> {
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
                signal: SignalId::new(a.signal.clone().ok_or_else(|| {
                    self.err(line, key("signal"), "needs `signal`, the quantity to set")
                })?),
                value: a
                    .value
                    .as_ref()
                    .map(|v| {
                        signal_value(v).ok_or_else(|| self.err(line, key("value"), NOT_A_VALUE))
                    })
                    .ok_or_else(|| self.err(line, key("value"), "needs `value`"))??,
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
                name: SignalId::new(g.name.clone()),
                equals: signal_value(&g.equals)
                    .ok_or_else(|| self.err(line, key("signal.equals"), NOT_A_VALUE))?,
                tolerance,
            }
        } else {
            return Err(self.err(line, key("frame"), "nothing to expect"));
        };
        let label = e.label.clone().unwrap_or_else(|| describe(&what));
        Ok(Expectation { label, line, what })
    }
}

pub(crate) fn fmt_ms(t: Instant) -> String {
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

/// What a signal's value may be in a script.
const NOT_A_VALUE: &str = "a signal value is a boolean, a number, a string or an array of them";

/// A signal's value as a script writes it: a boolean, an integer, a float, a string or an
/// array of them. `None` for dates and tables, which no signal takes.
pub(crate) fn signal_value(v: &toml::Value) -> Option<SignalValue> {
    Some(match v {
        toml::Value::Boolean(b) => SignalValue::Bool(*b),
        toml::Value::Integer(i) => SignalValue::Integer(*i),
        toml::Value::Float(f) => SignalValue::Real(*f),
        toml::Value::String(s) => SignalValue::Text(s.clone()),
        toml::Value::Array(a) => {
            SignalValue::List(a.iter().map(signal_value).collect::<Option<_>>()?)
        }
        toml::Value::Datetime(_) | toml::Value::Table(_) => return None,
    })
}

pub(crate) fn state_name(s: ErrorState) -> &'static str {
    match s {
        ErrorState::Active => "error-active",
        ErrorState::Passive => "error-passive",
        ErrorState::BusOff => "bus-off",
    }
}

pub(crate) fn hex(b: &[u8]) -> String {
    b.iter().map(|b| format!("{b:02X}")).collect()
}
