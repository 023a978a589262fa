//! Fault injection in the network simulator from a scenario's `[[at]]` tables
//! (`cantwin silkit netsim --faults SCENARIO.toml`).
//!
//! Only the bus-level actions apply: `drop` and `corrupt` without `from`, `clear_faults` and
//! `send`, each on the simulated network of the bus it names, at its `time_ms` in SIL Kit's
//! simulated time. They act as in `cantwin sim --check`: the bus's fault rules, drawn from a
//! generator seeded with the scenario's `seed`, and frames sent from a script port of the
//! network's own. As there, that port is on the bus for the whole run once the scenario
//! sends on the network, and acknowledges every frame like a bus analyser: a participant
//! alone on such a network is acknowledged. Every other action needs a device of the
//! scenario, which the network simulator does not run (its controllers are the
//! participants'); those are refused with the action, its line and the reason, before the
//! simulator joins.

use cantwin_bus::{FaultAction, FaultRule, FrameSelector};
use cantwin_can::{Frame, Instant};
use cantwin_scenario::Scenario;
use cantwin_scenario::script::{Action, ActionKind};

/// What a fault does to a simulated network's bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BusFault {
    /// Add a fault rule (`drop` or `corrupt`).
    Inject(FaultRule),
    /// Remove every fault rule (`clear_faults`).
    Clear,
    /// Put a frame on the bus from the network's script port (`send`).
    Send(Frame),
}

impl BusFault {
    /// Whether it sends from the script port.
    pub fn sends(&self) -> bool {
        matches!(self, BusFault::Send(_))
    }
}

impl core::fmt::Display for BusFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let rule = match self {
            BusFault::Clear => return f.write_str("clear_faults"),
            BusFault::Send(frame) => return write!(f, "send {frame}"),
            BusFault::Inject(rule) => rule,
        };
        f.write_str(match rule.action {
            FaultAction::Drop => "drop",
            FaultAction::Corrupt => "corrupt",
        })?;
        match rule.selector {
            FrameSelector::Fraction(x) => write!(f, " {} % of the frames", x * 100.0)?,
            FrameSelector::Attempt(n) => write!(f, " attempt {n}")?,
            FrameSelector::Id(id) => write!(f, " the frames of {id}")?,
            FrameSelector::All => f.write_str(" every frame")?,
        }
        match rule.remaining {
            Some(n) => write!(f, ", at most {n}"),
            None => Ok(()),
        }
    }
}

/// One fault of a scenario, due at a time on one network.
#[derive(Debug, Clone, PartialEq)]
pub struct NetsimFault {
    /// When, in SIL Kit's simulated time (the scenario's `time_ms`).
    pub at: Instant,
    /// The simulated network: the bus the action names.
    pub network: String,
    /// What it does.
    pub fault: BusFault,
    /// The line of its `[[at]]` table.
    pub line: usize,
}

/// The faults of `scenario`'s `[[at]]` tables, for the simulated `networks`, in file order;
/// an error naming the first action the network simulator cannot apply.
pub fn faults_from_scenario(
    scenario: &Scenario,
    networks: &[String],
) -> Result<Vec<NetsimFault>, String> {
    let file = scenario.file.display();
    let mut faults = Vec::new();
    for a in &scenario.script.actions {
        let name = action_name(&a.kind);
        let refuse = |why: String| {
            format!(
                "{file}:{}: [[at]] action {name:?} at {} ms: {why}",
                a.line,
                a.at.as_nanos() as f64 / 1e6
            )
        };
        let (bus, fault) = bus_fault(a).map_err(refuse)?;
        if !networks.iter().any(|n| n == bus) {
            return Err(refuse(format!(
                "bus {bus:?} is not a simulated network (--network {})",
                networks.join(", --network ")
            )));
        }
        faults.push(NetsimFault {
            at: a.at,
            network: bus.to_string(),
            fault,
            line: a.line,
        });
    }
    Ok(faults)
}

/// The bus and fault of a bus-level action, or why it is not one.
fn bus_fault(a: &Action) -> Result<(&str, BusFault), String> {
    let device = |d: &str| {
        format!(
            "it acts on device {d:?} of the scenario, and the network simulator runs no \
             devices: its controllers are the SIL Kit participants'"
        )
    };
    match &a.kind {
        ActionKind::Fault { from: Some(d), .. } => Err(device(d)),
        ActionKind::Fault {
            bus,
            corrupt,
            fraction,
            from: None,
            count,
        } => {
            let sel = FrameSelector::Fraction(*fraction);
            let mut rule = if *corrupt {
                FaultRule::corrupt(sel)
            } else {
                FaultRule::drop(sel)
            };
            if let Some(n) = count {
                rule = rule.times(*n);
            }
            Ok((bus, BusFault::Inject(rule)))
        }
        ActionKind::ClearFaults { bus } => Ok((bus, BusFault::Clear)),
        ActionKind::Send { bus, frame } => Ok((bus, BusFault::Send(*frame))),
        ActionKind::Power { device: d, .. }
        | ActionKind::Connect { device: d, .. }
        | ActionKind::BusOff { device: d }
        | ActionKind::Babble { device: d, .. }
        | ActionKind::BitRateMismatch { device: d, .. }
        | ActionKind::Inject { device: d, .. }
        | ActionKind::Set { device: d, .. } => Err(device(d)),
    }
}

/// The `action` value of a `[[at]]` table (docs/scenarios.md).
fn action_name(kind: &ActionKind) -> &'static str {
    match kind {
        ActionKind::Send { .. } => "send",
        ActionKind::Power { on: true, .. } => "power_on",
        ActionKind::Power { on: false, .. } => "power_off",
        ActionKind::Connect {
            connected: true, ..
        } => "connect",
        ActionKind::Connect {
            connected: false, ..
        } => "disconnect",
        ActionKind::BusOff { .. } => "bus_off",
        ActionKind::Babble { frame: Some(_), .. } => "babble",
        ActionKind::Babble { frame: None, .. } => "babble_stop",
        ActionKind::BitRateMismatch { rate: Some(_), .. } => "bit_rate_mismatch",
        ActionKind::BitRateMismatch { rate: None, .. } => "bit_rate_fix",
        ActionKind::Fault { corrupt: true, .. } => "corrupt",
        ActionKind::Fault { corrupt: false, .. } => "drop",
        ActionKind::ClearFaults { .. } => "clear_faults",
        ActionKind::Inject { fault: Some(_), .. } => "inject",
        ActionKind::Inject { fault: None, .. } => "repair",
        ActionKind::Set { .. } => "set",
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A scenario named `faults.toml` with one `cia301` device on `can0` and `at`.
    pub(crate) fn scenario(at: &str) -> Scenario {
        let text = format!(
            "name = \"faults\"\nseed = 7\n\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
             [[device]]\nname = \"node5\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\n\n{at}"
        );
        Scenario::parse(&text, "faults.toml").expect("scenario")
    }

    /// The simulated networks of the tests.
    pub(crate) fn networks() -> Vec<String> {
        vec!["can0".to_string()]
    }

    #[test]
    fn bus_level_actions_become_faults_at_their_times() {
        let s = scenario(
            "[[at]]\ntime_ms = 6\naction = \"corrupt\"\nbus = \"can0\"\nfraction = 1.0\ncount = 1\n\n\
             [[at]]\ntime_ms = 8.5\naction = \"drop\"\nbus = \"can0\"\nfraction = 0.25\n\n\
             [[at]]\ntime_ms = 12\naction = \"clear_faults\"\nbus = \"can0\"\n",
        );
        let f = faults_from_scenario(&s, &networks()).expect("faults");
        let got: Vec<(u64, &str, BusFault)> = f
            .iter()
            .map(|f| (f.at.as_nanos(), f.network.as_str(), f.fault))
            .collect();
        assert_eq!(
            got,
            [
                (
                    6_000_000,
                    "can0",
                    BusFault::Inject(FaultRule::corrupt(FrameSelector::Fraction(1.0)).times(1))
                ),
                (
                    8_500_000,
                    "can0",
                    BusFault::Inject(FaultRule::drop(FrameSelector::Fraction(0.25)))
                ),
                (12_000_000, "can0", BusFault::Clear),
            ]
        );
        let shown: Vec<String> = f.iter().map(|f| f.fault.to_string()).collect();
        assert_eq!(
            shown,
            [
                "corrupt 100 % of the frames, at most 1",
                "drop 25 % of the frames",
                "clear_faults"
            ]
        );
    }

    #[test]
    fn actions_needing_a_device_or_another_bus_are_refused_by_name() {
        for (at, words) in [
            (
                "action = \"bus_off\"\ndevice = \"node5\"",
                &["action \"bus_off\"", "device \"node5\""][..],
            ),
            (
                "action = \"power_off\"\ndevice = \"node5\"",
                &["action \"power_off\"", "device \"node5\""],
            ),
            (
                "action = \"drop\"\nbus = \"can0\"\nfraction = 1.0\ndevice = \"node5\"",
                &["action \"drop\"", "device \"node5\""],
            ),
            (
                "action = \"disconnect\"\ndevice = \"node5\"",
                &["action \"disconnect\"", "device \"node5\""],
            ),
        ] {
            let s = scenario(&format!("[[at]]\ntime_ms = 3\n{at}\n"));
            let e = faults_from_scenario(&s, &networks()).expect_err(at);
            assert!(e.contains("faults.toml:"), "{e}");
            assert!(e.contains("at 3 ms"), "{e}");
            for w in words {
                assert!(e.contains(w), "{w:?} missing from {e}");
            }
        }
        let s = scenario("[[at]]\ntime_ms = 3\naction = \"clear_faults\"\nbus = \"can0\"\n");
        let e = faults_from_scenario(&s, &["can1".to_string()]).expect_err("other bus");
        assert!(
            e.contains("bus \"can0\" is not a simulated network (--network can1)"),
            "{e}"
        );
    }
}
