//! What a run produced: one [`CaseReport`] per test case, with its verdict, the clause it
//! checks and the frames it exchanged.

use serde::{Deserialize, Serialize};

/// The test areas, in the order of CiA 310-1's conformance test plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Area {
    /// The EDS and the device agree (CiA 306).
    Eds,
    /// The SDO server (CiA 301 §7.2.4).
    Sdo,
    /// The object dictionary read and written (CiA 301 §7.4).
    Od,
    /// PDO communication and mapping (CiA 301 §7.2.2, §7.5.2.35–38).
    Pdo,
    /// SYNC, EMCY and TIME (CiA 301 §7.2.5, §7.2.6, §7.2.7).
    SyncEmcyTime,
    /// Heartbeat, node guarding and life guarding (CiA 301 §7.2.8.3.2).
    ErrorControl,
    /// NMT states and services (CiA 301 §7.3.2).
    Nmt,
    /// Store and restore parameters (CiA 301 §7.5.2.13–14).
    StoreRestore,
}

impl Area {
    /// Every area, in run order.
    pub const ALL: [Area; 8] = [
        Area::Eds,
        Area::Sdo,
        Area::Od,
        Area::Pdo,
        Area::SyncEmcyTime,
        Area::ErrorControl,
        Area::Nmt,
        Area::StoreRestore,
    ];

    /// The name `--only` takes.
    pub const fn name(self) -> &'static str {
        match self {
            Area::Eds => "eds",
            Area::Sdo => "sdo",
            Area::Od => "od",
            Area::Pdo => "pdo",
            Area::SyncEmcyTime => "sync-emcy-time",
            Area::ErrorControl => "error-control",
            Area::Nmt => "nmt",
            Area::StoreRestore => "store-restore",
        }
    }

    /// A title for reports.
    pub const fn title(self) -> &'static str {
        match self {
            Area::Eds => "EDS",
            Area::Sdo => "SDO",
            Area::Od => "Object dictionary",
            Area::Pdo => "PDO",
            Area::SyncEmcyTime => "SYNC, EMCY, TIME",
            Area::ErrorControl => "Error control",
            Area::Nmt => "NMT",
            Area::StoreRestore => "Store/restore",
        }
    }

    /// The area called `name` (as [`Area::name`]).
    pub fn from_name(name: &str) -> Option<Area> {
        Area::ALL.into_iter().find(|a| a.name() == name)
    }
}

/// Whether a failure of the case fails the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Severity {
    /// CiA 301/306 requires it of the device (given the features it claims).
    Mandatory,
    /// A recommendation, or a check the standard leaves to the device (reported, never
    /// fatal).
    Advisory,
}

/// The outcome of one case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The device behaved as the clause says.
    Pass,
    /// It did not (or a deviation its profile lists was not observed).
    Fail,
    /// It behaved as a deviation listed in its profile says, with the manual's section.
    Deviation,
    /// The device does not offer the optional feature the case checks.
    NotSupported,
    /// Not run: `--skip`, or nothing the case could check on this device.
    Skipped,
}

impl Verdict {
    /// The word reports print.
    pub const fn word(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Fail => "FAIL",
            Verdict::Deviation => "deviation",
            Verdict::NotSupported => "not supported",
            Verdict::Skipped => "skipped",
        }
    }
}

/// Who sent a logged frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Direction {
    /// The runner (stimulus).
    Stimulus,
    /// The bus: the device's answer or anything else it carried.
    Response,
}

/// One frame a case sent or saw.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedFrame {
    /// Microseconds since the start of the run, in the transport's clock.
    pub t_us: u64,
    /// Stimulus or response.
    pub dir: Direction,
    /// The frame in candump notation (`605#4000100000000000`, `705#R`).
    pub frame: String,
}

/// One case's result.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaseReport {
    /// The case's identifier (`sdo.expedited-upload`), as `--skip` takes it.
    pub id: String,
    /// Its area.
    pub area: Area,
    /// What it checks.
    pub title: String,
    /// The clause of CiA 301 or CiA 306 it checks.
    pub clause: String,
    /// Whether a failure fails the run.
    pub severity: Severity,
    /// The outcome.
    pub verdict: Verdict,
    /// What was observed (the reason of a failure, the note of a pass).
    pub detail: String,
    /// For [`Verdict::Deviation`] and a deviation not observed: the manual's section the
    /// profile names.
    pub manual_section: Option<String>,
    /// The frames, in order (at most [`MAX_LOGGED_FRAMES`]).
    pub frames: Vec<LoggedFrame>,
    /// Frames seen but not logged beyond that bound.
    pub frames_omitted: u64,
    /// Time the case took, in microseconds of the transport's clock.
    pub duration_us: u64,
}

/// The most frames one case logs (a case that waits through many heartbeats keeps its
/// first ones and counts the rest).
pub const MAX_LOGGED_FRAMES: usize = 400;

/// A whole run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Report {
    /// The device as its EDS names it.
    pub device: String,
    /// Its node-ID.
    pub node: u8,
    /// How it was reached.
    pub transport: String,
    /// Where the profile came from ("EDS", or a file).
    pub profile: String,
    /// The cases, in run order.
    pub cases: Vec<CaseReport>,
    /// Set when the run stopped early (the transport failed).
    pub stopped: Option<String>,
    /// Length of the run in microseconds of the transport's clock.
    pub duration_us: u64,
}

impl Report {
    /// Mandatory cases that failed.
    pub fn mandatory_failures(&self) -> impl Iterator<Item = &CaseReport> {
        self.cases
            .iter()
            .filter(|c| c.verdict == Verdict::Fail && c.severity == Severity::Mandatory)
    }

    /// Whether every mandatory case passed and the run was complete.
    pub fn passed(&self) -> bool {
        self.stopped.is_none() && self.mandatory_failures().next().is_none()
    }

    /// How many cases have `verdict`.
    pub fn count(&self, verdict: Verdict) -> usize {
        self.cases.iter().filter(|c| c.verdict == verdict).count()
    }

    /// The case called `id`.
    pub fn case(&self, id: &str) -> Option<&CaseReport> {
        self.cases.iter().find(|c| c.id == id)
    }
}

/// Reported after every case: how far the run is.
#[derive(Debug, Clone, Copy)]
pub struct Progress<'a> {
    /// Cases done (including this one).
    pub done: usize,
    /// Cases the run will do.
    pub total: usize,
    /// The case just finished.
    pub case: &'a CaseReport,
    /// The report so far (its last case is [`Progress::case`]).
    pub report: &'a Report,
}
