//! `cantwin replay CAPTURE --scenario FILE`: put a capture's master frames back on the
//! scenario's twins in virtual time and compare what the twins answer with what the capture
//! holds, frame by frame (the engine is `cantwin-replay`; the rule telling the master's
//! frames from the twins' is in [`LONG_HELP`]).

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use cantwin_can::{Frame, Id};
use cantwin_replay::{
    CapturedFrames, GapBound, Kind, Progress, ReplayError, id_key, key_text, seconds,
};
use cantwin_scenario::{Registry, Scenario};
use serde_json::json;

use crate::output;

/// `--help`: examples, then the rule telling the master's frames from the twins'.
pub const LONG_HELP: &str = "Examples:
  cantwin replay run.pcap --scenario scenarios/cia301-device.toml
  cantwin replay run.log --scenario rig.toml --tolerance-ms 5 --master-ids 000,605

Master frames are those whose identifier no twin of the scenario transmits. \
The twins' identifiers are learnt from the replay itself: a first run injects nothing and \
records what the twins send on their own; each further run injects the capture's frames on \
the identifiers no twin has sent yet and adds what the twins answer, until that set stops \
changing. The identifiers a CANopen twin with node-ID n owns (EMCY 0x80+n, TPDO1-4 0x180+n to \
0x480+n, SDO response 0x580+n, NMT error control 0x700+n; CiA 301 predefined connection set) \
are always the twin's, so a twin that stopped answering shows as missing frames. NMT 0x000, \
SDO requests 0x600+n, RPDOs, SYNC/TIME when no twin produces them and DeviceNet group-2 \
master messages thus count as the master's. --master-ids replaces the rule.";

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture: pcap, pcapng or candump log (format recognised from its content).
    capture: PathBuf,
    /// The scenario whose twins answer the master's frames.
    #[arg(long, value_name = "FILE")]
    scenario: PathBuf,
    /// How far (in milliseconds) a twin's frame may be from the captured one's time and
    /// still match.
    #[arg(long, value_name = "MS", default_value_t = 1.0)]
    tolerance_ms: f64,
    /// The master's identifiers, in hex, comma-separated (e.g. 000,605,080); values above
    /// 7FF are extended identifiers. Replaces the rule of `--help`.
    #[arg(long, value_name = "IDS", value_delimiter = ',')]
    master_ids: Option<Vec<String>>,
    /// The longest gap (in seconds) between two consecutive frames the capture may have. The
    /// twins run through every gap, so a capture with a corrupt timestamp would otherwise cost
    /// time and memory in proportion to the span it claims; a longer gap is refused, naming
    /// its records.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
    max_gap: f64,
    /// Shorten each gap longer than --max-gap to --max-gap (every later frame moves earlier)
    /// instead of refusing the capture.
    #[arg(long)]
    clamp_gaps: bool,
    /// Also list the frames that matched.
    #[arg(long)]
    verbose: bool,
}

fn parse_master_id(text: &str) -> Result<u32> {
    let t = text.trim();
    let t = t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .unwrap_or(t);
    let raw = u32::from_str_radix(t, 16)
        .with_context(|| format!("--master-ids: {text:?} is not a hex identifier"))?;
    let id = if raw <= 0x7FF {
        Id::standard(raw as u16)
    } else {
        Id::extended(raw)
    }
    .map_err(|e| anyhow::anyhow!("--master-ids: {text:?}: {e}"))?;
    Ok(id_key(id))
}

pub fn run(args: &Args) -> Result<()> {
    if !(args.tolerance_ms.is_finite() && args.tolerance_ms >= 0.0) {
        bail!(
            "--tolerance-ms must be a non-negative number of milliseconds, not {}",
            args.tolerance_ms
        );
    }
    // Up to a year: beyond, the bound bounds nothing a run could afford.
    if !(args.max_gap.is_finite() && args.max_gap > 0.0 && args.max_gap <= 31_536_000.0) {
        bail!(
            "--max-gap must be a positive number of seconds up to 31536000, not {}",
            args.max_gap
        );
    }
    let max_gap = (args.max_gap * 1e9) as i64;
    let tolerance = (args.tolerance_ms * 1e6) as i64;
    // The twins run on for the tolerance after the capture's last frame.
    if tolerance > max_gap {
        bail!(
            "--tolerance-ms {} is longer than --max-gap {} s",
            args.tolerance_ms,
            args.max_gap
        );
    }
    let scenario = Scenario::load(&args.scenario)?;
    let bus_names: Vec<&str> = scenario.buses.iter().map(|b| b.name.as_str()).collect();
    let capture = args.capture.display();
    // Records are read one at a time and only their frames kept.
    let reader =
        cantwin_capture::open(&args.capture).with_context(|| format!("reading {capture}"))?;
    let gaps = GapBound {
        max_ns: max_gap,
        clamp: args.clamp_gaps,
    };
    let CapturedFrames {
        frames: captured,
        error_frames,
        clamped,
    } = CapturedFrames::read(reader, &bus_names, gaps).map_err(|e| match e {
        ReplayError::UnknownChannel { .. } | ReplayError::Read { .. } => {
            anyhow::anyhow!("{capture}: {e}")
        }
        ReplayError::Gap { .. } => anyhow::anyhow!(
            "{capture} {e}; a corrupt timestamp? Raise the bound with --max-gap SECONDS, or \
             shorten such gaps with --clamp-gaps"
        ),
        e => anyhow::anyhow!("{capture} {e}"),
    })?;
    for g in &clamped {
        eprintln!(
            "warning: {capture}: the gap of {} s between record {} and record {} is \
             shortened to {} s (--clamp-gaps)",
            seconds(g.gap_ns),
            g.before,
            g.after,
            seconds(max_gap)
        );
    }
    let master_ids = match &args.master_ids {
        Some(list) => Some(
            list.iter()
                .map(|t| parse_master_id(t))
                .collect::<Result<BTreeSet<u32>>>()?,
        ),
        None => None,
    };
    let report = replay_showing_progress(&scenario, &captured, tolerance, master_ids.as_ref())
        .map_err(|e| match e {
            ReplayError::Unsettled => {
                anyhow::anyhow!("{e}; give them with --master-ids")
            }
            ReplayError::TooManyFrames { .. } => {
                anyhow::anyhow!("{capture} {e}; lower --max-gap, or replay a part of the capture")
            }
            e => anyhow::Error::new(e),
        })?;
    let entries = &report.entries;
    let (matching, missing, unexpected, different) = (
        report.count(Kind::Matching),
        report.count(Kind::Missing),
        report.count(Kind::Unexpected),
        report.count(Kind::Different),
    );
    let passes = report.passes;
    let master_list: Vec<String> = report.master_ids().into_iter().map(key_text).collect();

    if output::json() {
        let list: Vec<serde_json::Value> = entries
            .iter()
            .filter(|e| args.verbose || e.kind != Kind::Matching)
            .map(|e| {
                let side = |s: Option<(i64, Frame)>| {
                    s.map(|(t, f)| json!({"time_s": t as f64 / 1e9, "frame": f.to_string()}))
                };
                json!({
                    "kind": e.kind.name(),
                    "bus": bus_names[e.bus],
                    "captured": side(e.captured),
                    "replayed": side(e.replayed),
                })
            })
            .collect();
        output::emit(&json!({
            "capture": args.capture.display().to_string(),
            "scenario": args.scenario.display().to_string(),
            "tolerance_ms": args.tolerance_ms,
            "master_ids": master_list,
            "passes": passes,
            "master_frames": report.injected,
            "error_frames_skipped": error_frames,
            "gaps_clamped": clamped.len(),
            "matching": matching,
            "missing": missing,
            "unexpected": unexpected,
            "different": different,
            "entries": list,
        }))?;
    } else {
        let mut text = String::new();
        for e in entries
            .iter()
            .filter(|e| args.verbose || e.kind != Kind::Matching)
        {
            let bus = bus_names[e.bus];
            let _ = match (e.captured, e.replayed) {
                (Some((ct, cf)), Some((rt, rf))) => writeln!(
                    text,
                    "{:<10} {} {bus} {cf:<24} replayed {} {rf}{}",
                    e.kind.name(),
                    seconds(ct),
                    seconds(rt),
                    if cf != rf {
                        " (data)".to_string()
                    } else if ct != rt {
                        format!(" ({:+.3} ms)", (rt - ct) as f64 / 1e6)
                    } else {
                        String::new()
                    }
                ),
                (Some((ct, cf)), None) => {
                    writeln!(text, "{:<10} {} {bus} {cf}", e.kind.name(), seconds(ct))
                }
                (None, Some((rt, rf))) => {
                    writeln!(text, "{:<10} {} {bus} {rf}", e.kind.name(), seconds(rt))
                }
                (None, None) => Ok(()),
            };
        }
        print!("{text}");
        println!(
            "replay: {} master frames injected (identifiers {}), {} twin frames captured: \
             {matching} matching, {missing} missing, {unexpected} unexpected, {different} different \
             (tolerance {} ms, {passes} runs)",
            report.injected,
            if master_list.is_empty() {
                "none".to_string()
            } else {
                master_list.join(" ")
            },
            report.expected,
            args.tolerance_ms
        );
    }
    if missing + unexpected + different > 0 {
        bail!(
            "the twins' answers differ from {}: {missing} missing, {unexpected} unexpected, {different} different",
            args.capture.display()
        );
    }
    Ok(())
}

/// The replay, with a progress bar of capture time on standard error when both standard
/// output and standard error are terminals (and neither `--json` nor `--quiet` was given).
fn replay_showing_progress(
    scenario: &Scenario,
    captured: &[cantwin_replay::Captured],
    tolerance: i64,
    master_ids: Option<&BTreeSet<u32>>,
) -> Result<cantwin_replay::Report, ReplayError> {
    use std::io::IsTerminal as _;
    let end_ms = captured.last().map(|c| c.t / 1_000_000).unwrap_or(0);
    let bar = if std::io::stdout().is_terminal() {
        output::steps(
            u64::try_from(end_ms).unwrap_or(0),
            "replay: run 1, capture ms",
        )
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut run = 0;
    let result = cantwin_replay::replay_with_progress(
        scenario,
        &Registry::builtin(),
        captured,
        tolerance,
        master_ids,
        &mut |p: Progress| {
            if p.run != run {
                run = p.run;
                bar.set_message(format!("replay: run {run}, capture ms"));
            }
            bar.set_position(u64::try_from(p.at / 1_000_000).unwrap_or(0));
        },
    );
    bar.finish_and_clear();
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn master_ids_parse_as_hex_standard_or_extended() {
        assert_eq!(parse_master_id("605").ok(), Some(0x605));
        assert_eq!(parse_master_id("0x000").ok(), Some(0));
        assert_eq!(
            parse_master_id("18FF0001").ok(),
            Some(0x18FF_0001 | 1 << 31)
        );
        assert!(parse_master_id("xyz").is_err());
        assert!(parse_master_id("3FFFFFFF").is_err());
    }
}
