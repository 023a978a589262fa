//! Replay runs: the master's frames injected on freshly built twins, to a fixed point of
//! the master's identifiers.

use std::collections::BTreeSet;

use std::sync::{Arc, Mutex};

use cantwin_bus::{BusEvent, BusInfo, FnTap, PortConfig, PortId};
use cantwin_can::{Frame, Instant, ListenOnly};
use cantwin_scenario::{BuildEnv, Built, Registry, Scenario};

use crate::diff::{Entry, Kind, diff};
use crate::error::ReplayError;
use crate::frames::{Captured, id_key, seconds};

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

/// How far a replay has come, for a progress display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// The run under way, from 1 (learning the master's identifiers takes several).
    pub run: usize,
    /// The capture time reached in this run, in nanoseconds.
    pub at: i64,
    /// The capture's last time, in nanoseconds.
    pub end: i64,
}

struct Replayer<'a> {
    scenario: &'a Scenario,
    registry: &'a Registry,
    captured: &'a [Captured],
    /// Nanoseconds per bit, per bus.
    bit_ns: Vec<u64>,
    end: i64,
}

impl Replayer<'_> {
    fn build(&self) -> Result<Built, ReplayError> {
        Ok(self.scenario.build(self.registry, &BuildEnv::default())?)
    }

    /// One run injecting the captured frames whose identifiers are in `master`.
    fn run(
        &self,
        master: &[BTreeSet<u32>],
        number: usize,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Run, ReplayError> {
        let last = self.captured.last().map(|c| c.t).unwrap_or(0);
        let mut report = |at: i64| {
            progress(Progress {
                run: number,
                at,
                end: last,
            })
        };
        report(0);
        let mut built = self.build()?;
        let sink = Arc::new(Mutex::new(Sink {
            frames: Vec::new(),
            budget: frame_budget(self.captured.len()),
            over: None,
        }));
        let mut ports: Vec<PortId> = Vec::new();
        for (i, (_, id)) in built.buses.clone().into_iter().enumerate() {
            let bus = built.sim.bus_mut(id).ok_or(ReplayError::BusGone)?;
            // The replayed master's port; it also acknowledges frames, as the capture's
            // master did.
            let port = bus.attach(ListenOnly, PortConfig::default().with_queue_depth(4096));
            let sink = Arc::clone(&sink);
            bus.add_tap(FnTap(move |_: &BusInfo<'_>, event: &BusEvent| {
                if let BusEvent::Frame(f) = event
                    && !f.dropped
                    && f.sender != port
                {
                    lock(&sink).keep(i, f.end, f.frame);
                }
            }));
            ports.push(port);
        }
        let is_master = |c: &Captured| master[c.bus].contains(&id_key(c.frame.id()));
        // The capture's time 0 is its first frame's end of frame. When that frame is the
        // master's it is sent at once; otherwise time 0 is when the twins' first frame ends.
        let anchor: i64 = match self.captured.first() {
            Some(first) if is_master(first) => to_eof(&first.frame, self.bit_ns[first.bus]),
            Some(_) => {
                let limit = instant(self.end);
                loop {
                    if let Some(t) = lock(&sink).frames.iter().map(|f| f.1).min() {
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
            let start = anchor
                .saturating_add(c.t)
                .saturating_sub(to_eof(&c.frame, self.bit_ns[c.bus]));
            advance(&mut built, instant(start), &sink, anchor, &mut report)?;
            let port = ports[c.bus];
            built
                .sim
                .transmit(port, c.frame)
                .map_err(|e| ReplayError::Inject {
                    frame: c.frame.to_string(),
                    at: seconds(c.t),
                    reason: e.to_string(),
                })?;
            injected += 1;
            report(c.t);
        }
        advance(
            &mut built,
            instant(anchor.saturating_add(self.end)),
            &sink,
            anchor,
            &mut report,
        )?;
        report(last);
        drop(built);
        let kept = std::mem::take(&mut lock(&sink).frames);
        let mut ids = vec![BTreeSet::new(); ports.len()];
        let frames = kept
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

/// The twins' frames a run keeps, up to a budget.
struct Sink {
    /// Bus, end of frame, frame.
    frames: Vec<(usize, Instant, Frame)>,
    budget: usize,
    /// When the first frame beyond the budget ended.
    over: Option<Instant>,
}

impl Sink {
    fn keep(&mut self, bus: usize, end: Instant, frame: Frame) {
        if self.frames.len() < self.budget {
            self.frames.push((bus, end, frame));
        } else if self.over.is_none() {
            self.over = Some(end);
        }
    }
}

fn lock(sink: &Mutex<Sink>) -> std::sync::MutexGuard<'_, Sink> {
    // The taps only push: a poisoned sink still holds whole entries.
    sink.lock().unwrap_or_else(|e| e.into_inner())
}

/// How many twin frames a run of a capture of `captured` frames may keep: what bounds a
/// replay's memory by its input rather than by the time span the capture claims. A replay
/// that matches has about as many twin frames as the capture; a hundred times more, beyond a
/// floor for short captures, is a capture out of proportion to its size.
pub(crate) fn frame_budget(captured: usize) -> usize {
    captured.saturating_mul(100).saturating_add(100_000)
}

/// How much virtual time a run advances at most between looks at its frame budget, while
/// the twins are busy.
const CHUNK_NS: u64 = 1_000_000_000;

/// Run the simulation up to `to` (never back), in chunks while the twins are busy and in one
/// jump over idle time, stopping when the twins exceed the frame budget; `report` is told the
/// capture time reached after each chunk.
fn advance(
    built: &mut Built,
    to: Instant,
    sink: &Mutex<Sink>,
    anchor: i64,
    report: &mut dyn FnMut(i64),
) -> Result<(), ReplayError> {
    loop {
        let now = built.sim.now();
        if now >= to {
            return Ok(());
        }
        let step = match built.sim.next_event_time() {
            Some(next) if next < to => next
                .max(Instant::from_nanos(now.as_nanos().saturating_add(CHUNK_NS)))
                .min(to),
            _ => to,
        };
        built.sim.run_until(step);
        report(i64::try_from(step.as_nanos()).unwrap_or(i64::MAX) - anchor);
        let s = lock(sink);
        if let Some(at) = s.over {
            let at = i64::try_from(at.as_nanos()).unwrap_or(i64::MAX) - anchor;
            return Err(ReplayError::TooManyFrames {
                budget: s.budget,
                at: seconds(at),
            });
        }
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

/// What a replay found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Report {
    /// The master's identifiers ([`id_key`]s), per bus.
    pub master: Vec<BTreeSet<u32>>,
    /// How many runs it took the master's identifiers to settle.
    pub passes: usize,
    /// Master frames injected in the last run.
    pub injected: usize,
    /// The captured twin frames compared (the capture's frames not on a master identifier).
    pub expected: usize,
    /// The comparison, in time order.
    pub entries: Vec<Entry>,
}

impl Report {
    /// How many entries are of `kind`.
    pub fn count(&self, kind: Kind) -> usize {
        self.entries.iter().filter(|e| e.kind == kind).count()
    }

    /// The master's identifiers on any bus, in order.
    pub fn master_ids(&self) -> Vec<u32> {
        let all: BTreeSet<u32> = self.master.iter().flatten().copied().collect();
        all.into_iter().collect()
    }
}

/// Replays the master's frames of `captured` (see [`crate::CapturedFrames`]) on the twins
/// of `scenario`, built from `registry`, and compares the twins' frames with the captured
/// ones within `tolerance` nanoseconds. `master_ids` fixes the master's identifiers on
/// every bus; without it they are learnt to a fixed point (see the crate documentation).
pub fn replay(
    scenario: &Scenario,
    registry: &Registry,
    captured: &[Captured],
    tolerance: i64,
    master_ids: Option<&BTreeSet<u32>>,
) -> Result<Report, ReplayError> {
    replay_with_progress(
        scenario,
        registry,
        captured,
        tolerance,
        master_ids,
        &mut |_| {},
    )
}

/// [`replay`], telling `progress` how far it has come after each master frame it injects.
pub fn replay_with_progress(
    scenario: &Scenario,
    registry: &Registry,
    captured: &[Captured],
    tolerance: i64,
    master_ids: Option<&BTreeSet<u32>>,
    progress: &mut dyn FnMut(Progress),
) -> Result<Report, ReplayError> {
    let buses = scenario.buses.len();
    // Every run indexes its buses by the frames' positions.
    if let Some(c) = captured.iter().find(|c| c.bus >= buses) {
        return Err(ReplayError::NoSuchBus { bus: c.bus, buses });
    }
    let last = captured.last().map(|c| c.t).unwrap_or(0);
    let replayer = Replayer {
        scenario,
        registry,
        captured,
        bit_ns: scenario
            .buses
            .iter()
            .map(|b| b.bit_rate.bit_time().as_nanos())
            .collect(),
        // Times and the tolerance come from outside (a capture file, a command line): the
        // bounds saturate rather than overflow.
        end: last.saturating_add(tolerance).saturating_add(1_000_000),
    };
    let owned = owned_ids(&replayer.build()?);
    let mut captured_ids = vec![BTreeSet::new(); buses];
    for c in captured {
        captured_ids[c.bus].insert(id_key(c.frame.id()));
    }

    let (master, run, passes) = match master_ids {
        Some(ids) => {
            let master = vec![ids.clone(); buses];
            let run = replayer.run(&master, 1, progress)?;
            (master, run, 1)
        }
        None => {
            let mut master = vec![BTreeSet::new(); buses];
            let mut run = replayer.run(&master, 1, progress)?;
            let mut seen: Vec<BTreeSet<u32>> = run.ids.clone();
            let mut passes = 1;
            loop {
                let next: Vec<BTreeSet<u32>> = (0..buses)
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
                    return Err(ReplayError::Unsettled);
                }
                master = next;
                run = replayer.run(&master, passes + 1, progress)?;
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
        .filter(|r| r.t <= last.saturating_add(tolerance))
        .copied()
        .collect();
    let entries = diff(&expected, &replayed, tolerance);
    Ok(Report {
        master,
        passes,
        injected: run.injected,
        expected: expected.len(),
        entries,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_on_a_bus_the_scenario_lacks_is_refused() {
        let scenario = Scenario::parse(
            "name = \"one bus\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n",
            "one-bus.toml",
        )
        .unwrap();
        let frame = Frame::std(0x705, &[0x00]).unwrap();
        let captured = [Captured {
            bus: 1,
            t: 0,
            frame,
        }];
        let e = replay(&scenario, &Registry::builtin(), &captured, 1_000_000, None).unwrap_err();
        assert!(
            matches!(e, ReplayError::NoSuchBus { bus: 1, buses: 1 }),
            "{e}"
        );
    }
}
