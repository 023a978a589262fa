//! `cantwin replay CAPTURE --scenario FILE`: put a capture's master frames back on the
//! scenario's twins in virtual time and compare what the twins answer with what the capture
//! holds, frame by frame.
//!
//! Which frames are the master's: those whose identifier no twin transmits. The twins'
//! identifiers are learnt from the replay itself, to a fixed point: a first run injects
//! nothing and records what the twins send on their own (boot-up, heartbeats, DeviceNet
//! duplicate MAC ID checks); every further run injects the capture's frames on the
//! identifiers no twin has sent yet and adds what the twins then answer, until the set of
//! injected identifiers stops changing. The identifiers a CANopen twin with node-ID n owns in
//! the predefined connection set (CiA 301 §7.3.5: EMCY 0x80+n, TPDO1–4 0x180+n … 0x480+n,
//! SDO response 0x580+n, NMT error control 0x700+n) always count as the twin's, so that a
//! twin that stopped answering shows as missing frames instead of being replaced by the
//! capture's. NMT (0x000), SDO requests (0x600+n), RPDOs, SYNC and TIME when no twin
//! produces them, and DeviceNet group-2 master messages thus come out as the master's.
//! `--master-ids` replaces the rule with a fixed list.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use cantwin_bus::{BusId, PortConfig, PortId, Recorder, TapId};
use cantwin_can::{Frame, Id, Instant, Node, Outbox};
use cantwin_scenario::{BuildEnv, Built, Registry, Scenario};
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
    /// Also list the frames that matched.
    #[arg(long)]
    verbose: bool,
}

/// An identifier as one number: the raw value, with bit 31 set for extended identifiers.
fn id_key(id: Id) -> u32 {
    if id.is_extended() {
        id.as_raw() | 1 << 31
    } else {
        id.as_raw()
    }
}

fn key_text(key: u32) -> String {
    if key & 1 << 31 != 0 {
        format!("{:08X}", key & 0x1FFF_FFFF)
    } else {
        format!("{key:03X}")
    }
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

/// A frame of the capture, on a scenario bus, at a time relative to the capture's first frame.
#[derive(Debug, Clone, Copy)]
struct Captured {
    bus: usize,
    t: i64,
    frame: Frame,
}

/// The port the replayed master frames come from; it also acknowledges frames, as the
/// capture's master did.
struct MasterPort;

impl Node for MasterPort {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// What one replay run recorded.
struct Run {
    /// Twins' frames: bus, end of frame relative to the anchor, frame.
    frames: Vec<Captured>,
    /// Identifiers the twins sent, per bus.
    ids: Vec<BTreeSet<u32>>,
    injected: usize,
}

/// Time on the bus from start of frame to the end of EOF (the time captures stamp), without
/// the 3 bits of intermission.
fn to_eof(frame: &Frame, bit_ns: u64) -> i64 {
    i64::from(frame.bit_length().saturating_sub(3)) * bit_ns as i64
}

fn instant(ns: i64) -> Instant {
    Instant::from_nanos(u64::try_from(ns).unwrap_or(0))
}

struct Replayer<'a> {
    scenario: &'a Scenario,
    registry: Registry,
    captured: &'a [Captured],
    /// Nanoseconds per bit, per bus.
    bit_ns: Vec<u64>,
    end: i64,
}

impl Replayer<'_> {
    fn build(&self) -> Result<Built> {
        Ok(self.scenario.build(&self.registry, &BuildEnv::default())?)
    }

    /// One run injecting the captured frames whose identifiers are in `master`.
    fn run(&self, master: &[BTreeSet<u32>]) -> Result<Run> {
        let mut built = self.build()?;
        let mut ports: Vec<(BusId, PortId, TapId)> = Vec::new();
        for (_, id) in built.buses.clone() {
            let bus = built
                .sim
                .bus_mut(id)
                .context("a bus of the scenario is gone")?;
            let port = bus.attach(MasterPort, PortConfig::default().with_queue_depth(4096));
            let tap = bus.add_tap(Recorder::new());
            ports.push((id, port, tap));
        }
        let is_master = |c: &Captured| master[c.bus].contains(&id_key(c.frame.id()));
        let twin_frames = |built: &Built| -> Vec<(usize, Instant, Frame)> {
            let mut v = Vec::new();
            for (i, (id, port, tap)) in ports.iter().enumerate() {
                if let Some(r) = built.sim.bus(*id).and_then(|b| b.tap::<Recorder>(*tap)) {
                    v.extend(
                        r.frames()
                            .filter(|f| !f.dropped && f.sender != *port)
                            .map(|f| (i, f.end, f.frame)),
                    );
                }
            }
            v
        };
        // The capture's time 0 is its first frame's end of frame. When that frame is the
        // master's it is sent at once; otherwise time 0 is when the twins' first frame ends.
        let anchor: i64 = match self.captured.first() {
            Some(first) if is_master(first) => to_eof(&first.frame, self.bit_ns[first.bus]),
            Some(_) => {
                let limit = instant(self.end);
                loop {
                    if let Some(t) = twin_frames(&built).iter().map(|f| f.1).min() {
                        break i64::try_from(t.as_nanos()).unwrap_or(i64::MAX);
                    }
                    match built.sim.step_next() {
                        Some(t) if t <= limit => {}
                        // The twins are silent: keep the capture's clock.
                        _ => break 0,
                    }
                }
            }
            None => 0,
        };
        let mut injected = 0;
        for c in self.captured.iter().filter(|c| is_master(c)) {
            let start = anchor + c.t - to_eof(&c.frame, self.bit_ns[c.bus]);
            let start = instant(start).max(built.sim.now());
            built.sim.run_until(start);
            let port = ports[c.bus].1;
            built
                .sim
                .transmit(port, c.frame)
                .map_err(|e| anyhow::anyhow!("injecting {} at {}: {e}", c.frame, seconds(c.t)))?;
            injected += 1;
        }
        built.sim.run_until(instant(anchor + self.end));
        let mut ids = vec![BTreeSet::new(); ports.len()];
        let frames = twin_frames(&built)
            .into_iter()
            .map(|(bus, end, frame)| {
                ids[bus].insert(id_key(frame.id()));
                Captured {
                    bus,
                    t: i64::try_from(end.as_nanos()).unwrap_or(i64::MAX) - anchor,
                    frame,
                }
            })
            .collect();
        Ok(Run {
            frames,
            ids,
            injected,
        })
    }
}

/// The identifiers CANopen twins own in the predefined connection set (CiA 301 §7.3.5).
fn owned_ids(built: &Built) -> Vec<BTreeSet<u32>> {
    built
        .buses
        .iter()
        .map(|(_, bus)| {
            built
                .devices
                .iter()
                .filter(|d| d.port.bus() == *bus)
                .filter_map(|d| d.node_id)
                .flat_map(|n| {
                    let n = u32::from(n);
                    [0x080, 0x180, 0x280, 0x380, 0x480, 0x580, 0x700].map(|base| base + n)
                })
                .collect()
        })
        .collect()
}

fn seconds(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let a = ns.unsigned_abs();
    format!(
        "{sign}{}.{:06}",
        a / 1_000_000_000,
        (a % 1_000_000_000) / 1000
    )
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Matching,
    Missing,
    Unexpected,
    Different,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Matching => "matching",
            Kind::Missing => "missing",
            Kind::Unexpected => "unexpected",
            Kind::Different => "different",
        }
    }
}

/// One line of the diff: the captured frame, the replayed one, or both.
struct Entry {
    kind: Kind,
    bus: usize,
    captured: Option<(i64, Frame)>,
    replayed: Option<(i64, Frame)>,
}

impl Entry {
    fn time(&self) -> i64 {
        self.captured.or(self.replayed).map(|(t, _)| t).unwrap_or(0)
    }
}

/// Pairs the captured twin frames with the replayed ones, per bus and identifier in time
/// order: first the same data within the tolerance, then the same data at any time (a
/// timing difference), then other data within the tolerance (a data difference). What is
/// left is missing (captured only) or unexpected (replayed only).
fn diff(captured: &[Captured], replayed: &[Captured], tolerance: i64) -> Vec<Entry> {
    type Group = (Vec<(i64, Frame)>, Vec<(i64, Frame)>);
    let mut groups: BTreeMap<(usize, u32), Group> = BTreeMap::new();
    for c in captured {
        groups
            .entry((c.bus, id_key(c.frame.id())))
            .or_default()
            .0
            .push((c.t, c.frame));
    }
    for r in replayed {
        groups
            .entry((r.bus, id_key(r.frame.id())))
            .or_default()
            .1
            .push((r.t, r.frame));
    }
    let mut entries = Vec::new();
    for ((bus, _), (mut cap, mut rep)) in groups {
        cap.sort_by_key(|(t, _)| *t);
        rep.sort_by_key(|(t, _)| *t);
        let mut used = vec![false; rep.len()];
        let mut done = vec![false; cap.len()];
        let passes: [(Kind, bool, bool); 3] = [
            (Kind::Matching, true, true),
            (Kind::Different, true, false),
            (Kind::Different, false, true),
        ];
        for (kind, same_data, within) in passes {
            for (ci, (ct, cf)) in cap.iter().enumerate() {
                if done[ci] {
                    continue;
                }
                // Both lists are in time order: within the tolerance only a window of the
                // replayed frames can pair.
                let range = if within {
                    rep.partition_point(|(rt, _)| *rt < ct - tolerance)
                        ..rep.partition_point(|(rt, _)| *rt <= ct + tolerance)
                } else {
                    0..rep.len()
                };
                let best = range
                    .filter(|ri| !used[*ri] && ((rep[*ri].1 == *cf) == same_data))
                    .min_by_key(|ri| (rep[*ri].0 - ct).abs());
                if let Some(ri) = best {
                    used[ri] = true;
                    done[ci] = true;
                    entries.push(Entry {
                        kind,
                        bus,
                        captured: Some((*ct, *cf)),
                        replayed: Some(rep[ri]),
                    });
                }
            }
        }
        for (ci, c) in cap.iter().enumerate() {
            if !done[ci] {
                entries.push(Entry {
                    kind: Kind::Missing,
                    bus,
                    captured: Some(*c),
                    replayed: None,
                });
            }
        }
        for (ri, r) in rep.iter().enumerate() {
            if !used[ri] {
                entries.push(Entry {
                    kind: Kind::Unexpected,
                    bus,
                    captured: None,
                    replayed: Some(*r),
                });
            }
        }
    }
    entries.sort_by_key(|e| (e.time(), e.bus));
    entries
}

pub fn run(args: &Args) -> Result<()> {
    if !(args.tolerance_ms.is_finite() && args.tolerance_ms >= 0.0) {
        bail!(
            "--tolerance-ms must be a non-negative number of milliseconds, not {}",
            args.tolerance_ms
        );
    }
    let tolerance = (args.tolerance_ms * 1e6) as i64;
    let scenario = Scenario::load(&args.scenario)?;
    let records = cantwin_capture::read_all(&args.capture)
        .with_context(|| format!("reading {}", args.capture.display()))?;
    let bus_names: Vec<&str> = scenario.buses.iter().map(|b| b.name.as_str()).collect();
    let mut channels: BTreeSet<&str> = BTreeSet::new();
    let mut frames: Vec<(u64, usize, Frame)> = Vec::new();
    let mut error_frames = 0u64;
    for r in &records {
        let Some(frame) = r.frame() else {
            error_frames += 1;
            continue;
        };
        channels.insert(r.channel.as_str());
        let bus = match bus_names.iter().position(|b| *b == r.channel) {
            Some(i) => i,
            // A capture of one bus may name it otherwise (pcap has no channel names).
            None if bus_names.len() == 1 => 0,
            None => bail!(
                "{}: channel {:?} is none of the scenario's buses ({})",
                args.capture.display(),
                r.channel,
                bus_names.join(", ")
            ),
        };
        frames.push((r.timestamp_ns, bus, *frame));
    }
    if bus_names.len() == 1 && channels.len() > 1 {
        bail!(
            "{} holds {} channels ({}) but the scenario has one bus",
            args.capture.display(),
            channels.len(),
            channels.into_iter().collect::<Vec<_>>().join(", ")
        );
    }
    frames.sort_by_key(|f| f.0);
    let Some(t0) = frames.first().map(|f| f.0) else {
        bail!("{} holds no frames to replay", args.capture.display());
    };
    let captured: Vec<Captured> = frames
        .iter()
        .map(|&(ts, bus, frame)| Captured {
            bus,
            t: i64::try_from(ts - t0).unwrap_or(i64::MAX),
            frame,
        })
        .collect();
    let last = captured.last().map(|c| c.t).unwrap_or(0);
    let replayer = Replayer {
        scenario: &scenario,
        registry: Registry::builtin(),
        captured: &captured,
        bit_ns: scenario
            .buses
            .iter()
            .map(|b| b.bit_rate.bit_time().as_nanos())
            .collect(),
        end: last + tolerance + 1_000_000,
    };
    let owned = owned_ids(&replayer.build()?);
    let mut captured_ids = vec![BTreeSet::new(); bus_names.len()];
    for c in &captured {
        captured_ids[c.bus].insert(id_key(c.frame.id()));
    }

    let (master, run, passes) = match &args.master_ids {
        Some(list) => {
            let ids: BTreeSet<u32> = list
                .iter()
                .map(|t| parse_master_id(t))
                .collect::<Result<_>>()?;
            let master = vec![ids; bus_names.len()];
            let run = replayer.run(&master)?;
            (master, run, 1)
        }
        None => {
            let mut master = vec![BTreeSet::new(); bus_names.len()];
            let mut run = replayer.run(&master)?;
            let mut seen: Vec<BTreeSet<u32>> = run.ids.clone();
            let mut passes = 1;
            loop {
                let next: Vec<BTreeSet<u32>> = (0..bus_names.len())
                    .map(|b| {
                        captured_ids[b]
                            .iter()
                            .filter(|id| !seen[b].contains(id) && !owned[b].contains(id))
                            .copied()
                            .collect()
                    })
                    .collect();
                if next == master {
                    break;
                }
                // Each pass only removes identifiers, so this ends; the bound is a guard.
                if passes > 2 * captured_ids.iter().map(BTreeSet::len).sum::<usize>() + 2 {
                    bail!("the master's identifiers did not settle; give them with --master-ids");
                }
                master = next;
                run = replayer.run(&master)?;
                for (s, ids) in seen.iter_mut().zip(&run.ids) {
                    s.extend(ids.iter().copied());
                }
                passes += 1;
            }
            (master, run, passes)
        }
    };

    let expected: Vec<Captured> = captured
        .iter()
        .filter(|c| !master[c.bus].contains(&id_key(c.frame.id())))
        .copied()
        .collect();
    // Twins' frames after the capture ended have nothing to be compared with.
    let replayed: Vec<Captured> = run
        .frames
        .iter()
        .filter(|r| r.t <= last + tolerance)
        .copied()
        .collect();
    let entries = diff(&expected, &replayed, tolerance);
    let count = |k: Kind| entries.iter().filter(|e| e.kind == k).count();
    let (matching, missing, unexpected, different) = (
        count(Kind::Matching),
        count(Kind::Missing),
        count(Kind::Unexpected),
        count(Kind::Different),
    );
    let master_list: Vec<String> = {
        let all: BTreeSet<u32> = master.iter().flatten().copied().collect();
        all.into_iter().map(key_text).collect()
    };

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
            "master_frames": run.injected,
            "error_frames_skipped": error_frames,
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
            run.injected,
            if master_list.is_empty() {
                "none".to_string()
            } else {
                master_list.join(" ")
            },
            expected.len(),
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

#[cfg(test)]
mod tests {
    use super::*;

    fn c(t_ms: i64, text: &str) -> Captured {
        Captured {
            bus: 0,
            t: t_ms * 1_000_000,
            frame: cantwin_scenario::script::parse_frame(text).expect("frame"),
        }
    }

    #[test]
    fn diff_pairs_by_identifier_data_and_time() {
        let captured = [
            c(10, "585#4B17100064000000"),
            c(20, "701#05"),
            c(30, "181#01"),
            c(40, "181#02"),
        ];
        let replayed = [
            c(10, "585#4B17100065000000"),
            c(25, "701#05"),
            c(40, "181#02"),
            c(50, "182#00"),
        ];
        let e = diff(&captured, &replayed, 1_000_000);
        let kinds: Vec<(&str, i64)> = e.iter().map(|e| (e.kind.name(), e.time())).collect();
        assert_eq!(
            kinds,
            [
                ("different", 10_000_000),
                ("different", 20_000_000),
                ("missing", 30_000_000),
                ("matching", 40_000_000),
                ("unexpected", 50_000_000),
            ]
        );
    }

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
