//! An open CANopen conformance test: test cases written from CiA 301 and CiA 306, grouped
//! in the areas of CiA 310-1's test plan ([`Area`]), run against one device (a twin in
//! virtual time or a real device behind socketcand, slcan or SocketCAN) through a
//! [`Transport`].
//!
//! * [`run`] takes the transport, the node-ID, the device's EDS (or DCF), its [`Profile`]
//!   and the [`Options`], and returns a [`Report`]: one [`CaseReport`] per case with its
//!   verdict, the clause it checks and the frames it exchanged.
//! * [`catalogue`] lists every case ([`CaseInfo`]).
//! * [`output`] renders a report as a terminal summary, JUnit XML, JSON and HTML.
//!
//! A case fails only for what the clause it cites requires; an optional service the
//! device does not offer is reported as not supported. Deviations the device's manual
//! prescribes are listed in its profile (see [`profile`]): each is reported with the
//! manual's section when observed, and fails when not observed.
//!
//! ```
//! use cantwin_can::{Frame, Instant};
//! use cantwin_conform::{Area, Options, Profile, Transport, TransportError, run};
//!
//! /// A bus with nobody on it.
//! struct Silent(Instant);
//! impl Transport for Silent {
//!     fn send(&mut self, _frame: Frame) -> Result<(), TransportError> { Ok(()) }
//!     fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
//!         self.0 = self.0.max(deadline);
//!         Ok(None)
//!     }
//!     fn now(&self) -> Instant { self.0 }
//!     fn describe(&self) -> String { "silence".into() }
//! }
//!
//! let eds = cantwin_eds::load("[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\n").eds;
//! let options = Options { only: vec![Area::Sdo], ..Options::default() };
//! let report = run(&mut Silent(Instant::ZERO), 5, &eds, &Profile::from_eds(&eds), &options, &mut |_| {});
//! // Nobody answers: the run stops before its first case, and fails.
//! assert!(!report.passed());
//! assert!(report.stopped.as_deref().is_some_and(|s| s.contains("does not answer")));
//! assert_eq!(report.case("sdo.expedited-upload").map(|c| c.verdict), Some(cantwin_conform::Verdict::Skipped));
//! ```
#![forbid(unsafe_code)]

mod cases;
mod ctx;
pub mod output;
pub mod profile;
pub mod report;
pub mod transport;
pub mod transport_slcan;
#[cfg(feature = "socketcan")]
pub mod transport_socketcan;

use cantwin_can::Duration;
use cantwin_eds::Eds;

pub use profile::{Deviation, FailureKind, Profile, ProfileError, ProfileFile};
pub use report::{Area, CaseReport, Direction, LoggedFrame, Progress, Report, Severity, Verdict};
pub use transport::{PortTransport, Transport, TransportError, VirtualBus};

use ctx::{Ctx, Finding};

/// How a run goes.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Run only these areas (empty: all).
    pub only: Vec<Area>,
    /// Skip the cases with these identifiers.
    pub skip: Vec<String>,
    /// How long the device has to answer an SDO request (CiA 301 leaves it to the
    /// application; 1 s by default).
    pub sdo_timeout: Duration,
    /// How long the device has to send its boot-up message after an NMT reset.
    pub boot_timeout: Duration,
    /// Timing cases accept a period within this fraction of the nominal one (0.1: ±10 %)…
    pub tolerance: f64,
    /// …plus this much (the jitter of a transport on the wall clock).
    pub slack: Duration,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            only: Vec::new(),
            skip: Vec::new(),
            sdo_timeout: Duration::from_secs(1),
            boot_timeout: Duration::from_secs(2),
            tolerance: 0.1,
            slack: Duration::from_millis(5),
        }
    }
}

/// A case of the catalogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaseInfo {
    /// Identifier (`area.name`), as `--skip` and profile deviations name it.
    pub id: &'static str,
    /// Area.
    pub area: Area,
    /// The clause of CiA 301 or CiA 306 it checks.
    pub clause: &'static str,
    /// What it checks.
    pub title: &'static str,
    /// Whether its failure fails the run.
    pub severity: Severity,
}

/// Every case, in run order.
pub fn catalogue() -> Vec<CaseInfo> {
    cases::all().iter().map(|c| c.info).collect()
}

fn verdict_of(
    info: &CaseInfo,
    outcome: Result<String, Finding>,
    profile: &Profile,
) -> (Verdict, String, Option<String>) {
    let dev = profile.deviation(info.id);
    // A deviation with an abort code matches a refusal with that code; one without matches
    // only a failure of the kind it names (timing, value, a missing event), never a
    // device that does not answer (the profile's parser refuses a deviation for silence).
    let matches = |abort: Option<cantwin_canopen::AbortCode>, kind: Option<FailureKind>| {
        dev.is_some_and(|d| match (d.abort, abort) {
            (Some(want), Some(got)) => want == got.to_u32(),
            (Some(_), None) | (None, Some(_)) => false,
            (None, None) => kind.is_some_and(|k| k != FailureKind::Silence && d.kind == Some(k)),
        })
    };
    let section = dev.map(|d| d.section.clone());
    match outcome {
        Ok(note) => match dev {
            Some(d) => (
                Verdict::Fail,
                format!(
                    "the profile lists a deviation ({}) that was not observed: {note}",
                    d.behaviour
                ),
                section,
            ),
            None => (Verdict::Pass, note, None),
        },
        Err(Finding::Fail { why, abort, kind }) if matches(abort, Some(kind)) => {
            let behaviour = dev.map(|d| d.behaviour.as_str()).unwrap_or_default();
            (Verdict::Deviation, format!("{behaviour}: {why}"), section)
        }
        // A feature not offered matches a deviation by its abort code only.
        Err(Finding::NotSupported { why, abort }) if abort.is_some() && matches(abort, None) => {
            let behaviour = dev.map(|d| d.behaviour.as_str()).unwrap_or_default();
            (Verdict::Deviation, format!("{behaviour}: {why}"), section)
        }
        Err(Finding::Fail { why, .. }) => match dev {
            Some(d) => (
                Verdict::Fail,
                format!(
                    "{why} (the profile lists a different deviation: {})",
                    d.behaviour
                ),
                section,
            ),
            None => (Verdict::Fail, why, None),
        },
        Err(Finding::NotSupported { why, .. }) => match dev {
            Some(d) => (
                Verdict::Fail,
                format!(
                    "{why} (the profile lists a different deviation: {})",
                    d.behaviour
                ),
                section,
            ),
            None => (Verdict::NotSupported, why, None),
        },
        Err(Finding::NotApplicable(why)) => match dev {
            Some(d) => (
                Verdict::Fail,
                format!(
                    "the profile lists a deviation ({}) that this device gives no way to observe: {why}",
                    d.behaviour
                ),
                section,
            ),
            None => (Verdict::Skipped, why, None),
        },
        Err(Finding::Transport(e)) => (Verdict::Fail, format!("transport: {e}"), None),
    }
}

/// How long the bus must carry nothing before the first case runs (a device's boot-up
/// and the EMCYs behind it come within a few milliseconds of power-up).
const SETTLE_QUIET: cantwin_can::Duration = cantwin_can::Duration::from_millis(50);

/// How long the device has to act on the NMT command that starts the run (CiA 301 leaves
/// it to the device; the state change stops its PDOs within a few milliseconds).
const ENTER_PRE_OPERATIONAL: cantwin_can::Duration = cantwin_can::Duration::from_millis(50);

/// Whether the selection needs no bus at all (only the file checks of the EDS area).
fn only_offline(options: &Options) -> bool {
    cases::all()
        .iter()
        .filter(|c| options.only.is_empty() || options.only.contains(&c.info.area))
        .filter(|c| !options.skip.iter().any(|s| s == c.info.id))
        .all(|c| c.info.id == "eds.file-valid")
}

/// Runs the cases `options` selects against the device `node` described by `eds`, with
/// the features and deviations of `profile`, reporting each case to `progress` as it ends.
pub fn run(
    transport: &mut dyn Transport,
    node: u8,
    eds: &Eds,
    profile: &Profile,
    options: &Options,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Report {
    let device = eds
        .device_info
        .product_name
        .clone()
        .or_else(|| eds.device_info.vendor_name.clone())
        .unwrap_or_else(|| eds.file_info.file_name.clone().unwrap_or_default());
    let mut ctx = Ctx::new(transport, node, eds, profile, options);
    let selected: Vec<&cases::Case> = cases::all()
        .iter()
        .filter(|c| options.only.is_empty() || options.only.contains(&c.info.area))
        .collect();
    let total = selected.len();
    let mut report = Report {
        device,
        node,
        transport: ctx.describe(),
        profile: profile.source.clone(),
        cases: Vec::with_capacity(total),
        stopped: None,
        duration_us: 0,
    };
    let start = ctx.now();
    let bad_node = !(1..=127).contains(&node);
    if !bad_node && !only_offline(options) {
        // Start from a settled bus: a device powered just before the run sends its boot-up
        // (CiA 301 §7.3.2.2.1) now, and no case may take it for the answer to a reset.
        // The frames are before any case: they are in no case's log.
        let settled = ctx.settle(SETTLE_QUIET, options.boot_timeout);
        // The cases start in PRE-OPERATIONAL, where a device is after its boot-up; one a
        // master has started already is put back there (CiA 301 §7.3.2.2.1, figure 48).
        let entered = settled.and_then(|_| {
            ctx.nmt(cantwin_canopen::wire::NmtCs::EnterPreOperational)?;
            ctx.idle(ENTER_PRE_OPERATIONAL)
        });
        let _ = ctx.take_log();
        if let Err(Finding::Transport(e)) = entered {
            report.stopped = Some(e.to_string());
        }
    }
    if !bad_node && !only_offline(options) && report.stopped.is_none() {
        // A device that does not answer at all would take every case to its timeouts.
        match ctx.upload(0x1000, 0) {
            Ok(Err(a)) if !a.by_server => {
                report.stopped = Some(format!(
                    "node {node} does not answer an SDO upload of 0x1000 ({a}): wrong node-ID, bit rate or bus?"
                ));
            }
            Err(Finding::Transport(e)) => report.stopped = Some(e.to_string()),
            _ => {}
        }
        if report.stopped.is_none()
            && let Err(Finding::Transport(e)) = ctx.begin_cases()
        {
            report.stopped = Some(e.to_string());
        }
    }
    for (i, case) in selected.into_iter().enumerate() {
        let info = case.info;
        let t0 = ctx.now();
        let (verdict, detail, section) = if options.skip.iter().any(|s| s == info.id) {
            (Verdict::Skipped, "skipped (--skip)".to_string(), None)
        } else if let Some(why) = &report.stopped {
            (Verdict::Skipped, format!("not run: {why}"), None)
        } else if bad_node {
            (
                Verdict::Fail,
                format!("node-ID {node} is outside 1..=127 (CiA 301 §7.3.4)"),
                None,
            )
        } else {
            let outcome = (case.run)(&mut ctx);
            if let Err(Finding::Transport(e)) = &outcome {
                report.stopped = Some(e.to_string());
            }
            let failed = matches!(outcome, Err(Finding::Fail { .. }));
            let v = verdict_of(&info, outcome, profile);
            if failed && report.stopped.is_none() {
                // Leave the server idle for the next case whatever this one left behind.
                cases::recover(&mut ctx);
            }
            v
        };
        let (frames, frames_omitted) = ctx.take_log();
        let t1 = ctx.now();
        report.cases.push(CaseReport {
            id: info.id.to_string(),
            area: info.area,
            title: info.title.to_string(),
            clause: info.clause.to_string(),
            severity: info.severity,
            verdict,
            detail,
            manual_section: section,
            frames,
            frames_omitted,
            duration_us: t1.saturating_duration_since(t0).as_micros(),
        });
        report.duration_us = ctx.now().saturating_duration_since(start).as_micros();
        if let Some(case) = report.cases.last() {
            progress(Progress {
                done: i + 1,
                total,
                case,
                report: &report,
            });
        }
    }
    report.duration_us = ctx.now().saturating_duration_since(start).as_micros();
    report
}
