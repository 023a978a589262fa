//! The device profile: the optional features a device claims and the deviations from
//! CiA 301 its manual prescribes.
//!
//! Most features follow from the EDS ([`Profile::from_eds`]: an object present means the
//! service is offered). What CiA 306 cannot express comes from a profile file
//! ([`ProfileFile`], TOML), which overrides the EDS: whether the SDO server offers the
//! segmented and block protocols (a device that knows expedited transfers only answers a
//! segmented initiate with 0x05040001), whether PDOs answer RTR, and the deviations.
//!
//! ```toml
//! [sdo]
//! segmented = false
//!
//! [[deviation]]
//! case = "sdo.segmented-download"
//! section = "ADV200 CANopen manual §1.1 item 11"
//! behaviour = "expedited transfers only"
//! abort = 0x05040001
//! ```
//!
//! A deviation names the case it excuses: when that case fails the way the deviation says
//! (with its abort code, or, without one, with a failure of the kind it names: `timing`,
//! `value` or `event`; never silence), the case is reported as a deviation with the
//! manual's section; when it passes, the listed deviation was not observed and the case
//! fails; a failure the profile does not list fails.

use serde::{Deserialize, Serialize};

use cantwin_eds::Eds;

/// A profile file that cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProfileError {
    /// Not valid TOML, or keys of the wrong type.
    #[error("{0}")]
    Syntax(String),
    /// A deviation that names no case of the catalogue.
    #[error("deviation names the case {0:?}, which does not exist")]
    UnknownCase(String),
    /// A deviation that does not say what failure it excuses, or says silence.
    #[error("deviation of {0:?}: {1}")]
    Excuse(String, &'static str),
}

/// A deviation the device's manual prescribes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Deviation {
    /// The case it excuses (as [`crate::CaseInfo::id`]).
    pub case: String,
    /// The manual's section that prescribes it.
    pub section: String,
    /// What the device does instead.
    pub behaviour: String,
    /// The abort code the device answers with, where the deviation is an abort.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub abort: Option<u32>,
    /// Without an abort code: the kind of failure the deviation excuses (`timing`,
    /// `value` or `event`). Silence is never excused, and an abort needs its code.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<FailureKind>,
}

/// What kind of failure a case found: a deviation without an abort code excuses only a
/// failure of the kind it names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FailureKind {
    /// The server refused with an SDO abort code.
    Abort,
    /// The device did not answer a request addressed to it (an SDO timeout, an unanswered
    /// guarding request, no boot-up message after a reset). Never excused: a device that
    /// is not there must not pass as one with a deviation.
    Silence,
    /// A frame came at the wrong time.
    Timing,
    /// An answer or a frame came with the wrong content, or a request was taken that
    /// should have been refused.
    Value,
    /// An event the device produces on its own (an EMCY, a TPDO) did not come.
    Event,
}

/// SDO protocols beyond expedited (CiA 306 has no key for them).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SdoFeatures {
    /// Segmented transfer (CiA 301 §7.2.4.3.3–7).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segmented: Option<bool>,
    /// Block transfer (CiA 301 §7.2.4.3.9–16).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub block: Option<bool>,
}

/// Services the device offers. `None`: not known, the case finds out and reports an
/// absent optional service as not supported.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Features {
    /// Heartbeat producer, 0x1017 (CiA 301 §7.2.8.3.2.2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heartbeat_producer: Option<bool>,
    /// Heartbeat consumer, 0x1016.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heartbeat_consumer: Option<bool>,
    /// Node guarding and life guarding, 0x100C/0x100D (§7.2.8.3.2.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_guarding: Option<bool>,
    /// SYNC consumer, 0x1005 (§7.2.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sync: Option<bool>,
    /// EMCY producer, 0x1014 (§7.2.7).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emcy: Option<bool>,
    /// EMCY inhibit time, 0x1015.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emcy_inhibit: Option<bool>,
    /// Pre-defined error field, 0x1003.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_history: Option<bool>,
    /// TIME consumer or producer, 0x1012 (§7.2.6).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<bool>,
    /// Store parameters, 0x1010 (§7.5.2.13).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub store: Option<bool>,
    /// Restore default parameters, 0x1011 (§7.5.2.14).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restore: Option<bool>,
    /// TPDOs answer a remote frame (RTR, §7.2.2.2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pdo_rtr: Option<bool>,
}

/// A profile as written in a file: every key optional, each overrides what the EDS says.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileFile {
    /// The device the profile describes (for the reader).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// SDO protocols.
    #[serde(default)]
    pub sdo: SdoFeatures,
    /// Services.
    #[serde(default)]
    pub features: Features,
    /// The manual's deviations.
    #[serde(default, rename = "deviation", skip_serializing_if = "Vec::is_empty")]
    pub deviations: Vec<Deviation>,
}

impl ProfileFile {
    /// Reads a profile file; deviations must name cases of the catalogue.
    pub fn parse(text: &str) -> Result<ProfileFile, ProfileError> {
        let file: ProfileFile =
            toml::from_str(text).map_err(|e| ProfileError::Syntax(e.to_string()))?;
        for d in &file.deviations {
            if !crate::catalogue().iter().any(|c| c.id == d.case) {
                return Err(ProfileError::UnknownCase(d.case.clone()));
            }
            let excuse = match (d.abort, d.kind) {
                (Some(_), None | Some(FailureKind::Abort)) => None,
                (Some(_), Some(_)) => Some("an abort code excuses an abort only"),
                (None, None) => Some(
                    "give its abort code, or the kind of failure it excuses (kind = \"timing\", \"value\" or \"event\")",
                ),
                (None, Some(FailureKind::Abort)) => Some("an abort needs its abort code"),
                (None, Some(FailureKind::Silence)) => {
                    Some("silence is never a deviation: a device must answer")
                }
                (None, Some(_)) => None,
            };
            if let Some(why) = excuse {
                return Err(ProfileError::Excuse(d.case.clone(), why));
            }
        }
        Ok(file)
    }

    /// The file's text (what `cantwin eds export` writes beside an EDS).
    pub fn to_toml(&self) -> String {
        let body = toml::to_string(self).unwrap_or_default();
        let mut out = String::from(
            "# cantwin conform device profile: optional features the device claims beyond\n\
             # its EDS, and the deviations from CiA 301 its manual prescribes.\n\n",
        );
        // Abort codes read as CiA 301 writes them.
        for line in body.lines() {
            match line
                .strip_prefix("abort = ")
                .and_then(|v| v.parse::<u32>().ok())
            {
                Some(code) => out.push_str(&format!("abort = 0x{code:08X}\n")),
                None => {
                    out.push_str(line);
                    out.push('\n');
                }
            }
        }
        out
    }
}

/// The features a run assumes and the deviations it accepts.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Profile {
    /// Where it came from ("EDS", or "EDS + FILE").
    pub source: String,
    /// SDO protocols.
    pub sdo: SdoFeatures,
    /// Services.
    pub features: Features,
    /// Deviations.
    pub deviations: Vec<Deviation>,
}

fn has(eds: &Eds, index: u16) -> Option<bool> {
    Some(eds.objects.contains_key(&index))
}

impl Profile {
    /// What the EDS says: each service whose object the file lists is claimed, each other
    /// one is not. Segmented and block SDO stay unknown (CiA 306 has no key for them).
    pub fn from_eds(eds: &Eds) -> Profile {
        Profile {
            source: "EDS".into(),
            sdo: SdoFeatures::default(),
            features: Features {
                heartbeat_producer: has(eds, 0x1017),
                heartbeat_consumer: has(eds, 0x1016),
                node_guarding: Some(
                    eds.objects.contains_key(&0x100C) && eds.objects.contains_key(&0x100D),
                ),
                sync: has(eds, 0x1005),
                emcy: has(eds, 0x1014),
                emcy_inhibit: has(eds, 0x1015),
                error_history: has(eds, 0x1003),
                time: has(eds, 0x1012),
                store: has(eds, 0x1010),
                restore: has(eds, 0x1011),
                pdo_rtr: None,
            },
            deviations: Vec::new(),
        }
    }

    /// This profile with every key `file` sets taken from it; `name` describes the file.
    pub fn with_file(mut self, file: &ProfileFile, name: &str) -> Profile {
        fn take(a: &mut Option<bool>, b: Option<bool>) {
            if b.is_some() {
                *a = b;
            }
        }
        take(&mut self.sdo.segmented, file.sdo.segmented);
        take(&mut self.sdo.block, file.sdo.block);
        let (f, o) = (&mut self.features, &file.features);
        take(&mut f.heartbeat_producer, o.heartbeat_producer);
        take(&mut f.heartbeat_consumer, o.heartbeat_consumer);
        take(&mut f.node_guarding, o.node_guarding);
        take(&mut f.sync, o.sync);
        take(&mut f.emcy, o.emcy);
        take(&mut f.emcy_inhibit, o.emcy_inhibit);
        take(&mut f.error_history, o.error_history);
        take(&mut f.time, o.time);
        take(&mut f.store, o.store);
        take(&mut f.restore, o.restore);
        take(&mut f.pdo_rtr, o.pdo_rtr);
        self.deviations.extend(file.deviations.iter().cloned());
        self.source = format!("{} + {name}", self.source);
        self
    }

    /// The deviation listed for case `id`.
    pub fn deviation(&self, id: &str) -> Option<&Deviation> {
        self.deviations.iter().find(|d| d.case == id)
    }
}

/// The profile of the ADV200 card (CANopen and DS402 personality): expedited-only SDO,
/// the Opt Bus Fault alarm only while the drive is enabled, each deviation with the
/// manual's section.
pub const ADV200: &str = include_str!("../profiles/adv200.toml");

/// The profile of the twins built on the cantwin CANopen stack (`cia301`, `eds`):
/// every SDO protocol, no deviation.
pub const STACK: &str = include_str!("../profiles/stack.toml");

/// The profile of the TM3BCCO coupler: every SDO protocol, RTR on its TPDOs as its
/// manual's table of objects 1800H–1837H says, no deviation.
pub const TM3: &str = include_str!("../profiles/tm3.toml");

/// The profile of a shipped twin of scenario kind `kind`, as `cantwin eds export` writes
/// it beside the twin's EDS.
pub fn shipped(kind: &str) -> ProfileFile {
    let text = match kind {
        "adv200" => ADV200,
        "tm3" => TM3,
        _ => STACK,
    };
    // The shipped files are checked by this crate's tests.
    ProfileFile::parse(text).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_profile_file_survives_its_own_text() {
        let file = ProfileFile::parse(ADV200).unwrap();
        let text = file.to_toml();
        assert_eq!(ProfileFile::parse(&text).unwrap(), file);
        assert!(text.contains("abort = 0x05040001"), "{text}");
        assert_eq!(file.sdo.segmented, Some(false));
        assert!(file.deviations.iter().all(|d| !d.section.is_empty()));
    }

    #[test]
    fn a_file_overrides_only_the_keys_it_sets() {
        let eds =
            cantwin_eds::load("[1017]\nParameterName=hb\nDataType=0x0006\nAccessType=rw\n").eds;
        let p = Profile::from_eds(&eds);
        assert_eq!(p.features.heartbeat_producer, Some(true));
        assert_eq!(p.features.store, Some(false));
        assert_eq!(p.sdo.segmented, None, "CiA 306 cannot say");
        let f = ProfileFile::parse("[features]\nstore = true\n[sdo]\nblock = false\n").unwrap();
        let p = p.with_file(&f, "f.toml");
        assert_eq!(p.features.store, Some(true));
        assert_eq!(p.features.heartbeat_producer, Some(true));
        assert_eq!(p.sdo.block, Some(false));
        assert_eq!(p.source, "EDS + f.toml");
    }

    #[test]
    fn bad_profiles_are_refused_with_a_reason() {
        assert!(matches!(
            ProfileFile::parse("[sdo]\nsegmented = 3\n"),
            Err(ProfileError::Syntax(_))
        ));
        assert!(matches!(
            ProfileFile::parse("[sdo]\nexpedited = true\n"),
            Err(ProfileError::Syntax(_))
        ));
        assert!(matches!(
            ProfileFile::parse(
                "[[deviation]]\ncase = \"x.y\"\nsection = \"1\"\nbehaviour = \"b\"\n"
            ),
            Err(ProfileError::UnknownCase(_))
        ));
    }
}
