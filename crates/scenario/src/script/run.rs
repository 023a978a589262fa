//! Running a script: its actions applied and its expectations judged in virtual time.

use std::collections::BTreeMap;
use std::fmt;

use cantwin_bus::{FaultRule, FrameSelector, PortConfig, PortId, Recorder, Simulation, TapId};
use cantwin_can::{Instant, ListenOnly};
use cantwin_twin::{
    Direction, Fault, FaultError, FaultKind, ObjectError, SignalError, SignalId, Twin,
};

use super::parse::{
    Action, ActionKind, Expect, Expectation, RawAt, ScriptParser, fmt_ms, hex, state_name,
};
use crate::build::{Built, BuiltDevice};
use crate::error::{Located, ScenarioError};
use crate::model::Scenario;
use crate::registry::{BuildEnv, Registry};

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
                Expect::Signal { name, .. } => read_signal(built.sim.twin(d.port), d, name).err(),
                Expect::Value { index, sub, .. } => {
                    let readable = built
                        .sim
                        .twin(d.port)
                        .is_some_and(|t| t.read_object(*index, *sub).is_ok());
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
            // The port a script sends from: receives everything, sends only what it is given.
            let port = bus.attach(ListenOnly, PortConfig::default().with_queue_depth(64));
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
                let (passed, detail) = probe(&built, &e.what, port_of);
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
/// built scenario), devices are reached as twins through `sim`; frames to send go out from
/// `script_ports`, a port per bus name.
pub fn apply_action(
    sim: &mut Simulation,
    buses: &[(String, cantwin_bus::BusId)],
    devices: &[BuiltDevice],
    script_ports: &BTreeMap<String, PortId>,
    kind: &ActionKind,
) -> Result<(), String> {
    let port = |d: &str| device_named(devices, d).map(|d| d.port);
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
            let d = device_named(devices, device)?;
            let r = sim.with_twin(d.port, |t, cx| match fault {
                Some(f) => t.inject(&Fault::internal(f.as_str()), cx),
                None => t.repair(FaultKind::Internal, cx),
            });
            return r
                .unwrap_or(Err(FaultError::None {
                    kind: FaultKind::Internal,
                }))
                .map_err(|e| d.fault_message(&e));
        }
        ActionKind::Set {
            device,
            signal,
            value,
        } => {
            let d = device_named(devices, device)?;
            let r = sim.with_twin(d.port, |t, cx| t.set_signal(signal, value, cx));
            return r
                .unwrap_or_else(|| Err(SignalError::unknown(signal, Direction::Set, "")))
                .map_err(|e| d.signal_message(&e));
        }
    };
    r.map_err(|e| e.to_string())
}

/// The device named `name`.
fn device_named<'a>(devices: &'a [BuiltDevice], name: &str) -> Result<&'a BuiltDevice, String> {
    devices
        .iter()
        .find(|x| x.name == name)
        .ok_or_else(|| format!("no device {name:?}"))
}

/// Reads signal `name` of device `d` through its twin (`None` when it is not one).
fn read_signal(
    twin: Option<&dyn Twin>,
    d: &BuiltDevice,
    name: &SignalId,
) -> Result<cantwin_twin::SignalValue, String> {
    twin.map_or_else(
        || Err(SignalError::unknown(name, Direction::Read, "")),
        |t| t.read_signal(name),
    )
    .map_err(|e| d.signal_message(&e))
}

fn probe(
    built: &Built,
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
            let Some(d) = built.device(device) else {
                return (false, format!("no device {device:?}"));
            };
            let read = built
                .sim
                .twin(d.port)
                .map_or(Err(ObjectError::NoDictionary), |t| {
                    t.read_object(*index, *sub)
                });
            match read {
                Err(_) => (
                    false,
                    format!(
                        "a {} device does not expose object {index:04X}sub{sub}",
                        d.kind
                    ),
                ),
                Ok(bytes) => {
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
            let Some(d) = built.device(device) else {
                return (false, format!("no device {device:?}"));
            };
            match read_signal(built.sim.twin(d.port), d, name) {
                Ok(seen) => (seen.matches(equals, *tolerance), format!("{name} = {seen}")),
                Err(e) => (false, e),
            }
        }
        Expect::Frame { .. } => (false, "not a probe".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::script::parse::parse_pattern;
    use cantwin_can::Frame;

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
    fn signal_values_that_no_signal_takes_are_refused_with_their_line() {
        let e = error_of(
            "\n[[at]]\ntime_ms = 5\naction = \"set\"\ndevice = \"node5\"\nsignal = \"x\"\nvalue = { a = 1 }\n",
        );
        assert!(
            e.contains("s.toml:12: key `at[0].value`: a signal value is a boolean"),
            "{e}"
        );
        let e = error_of(
            "\n[[expect]]\nat_ms = 1\nsignal = { device = \"node5\", name = \"x\", equals = 1979-05-27 }\n",
        );
        assert!(e.contains("key `expect[0].signal.equals`"), "{e}");
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
        use cantwin_twin::SignalValue::{Bool, Integer, Real, Text};
        assert!(Real(50.0).matches(&Integer(50), 0.0));
        assert!(Real(49.96).matches(&Real(50.0), 0.05));
        assert!(!Real(49.9).matches(&Real(50.0), 0.05));
        assert!(Bool(true).matches(&Bool(true), 0.0));
        assert!(!Bool(true).matches(&Integer(1), 1.0));
        assert!(!Text("on".into()).matches(&Text("off".into()), 0.0));
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
