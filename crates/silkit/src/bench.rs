//! Throughput and latency of CAN frames through SIL Kit, with cantwin as network simulator
//! and without one, in one process on loopback (`cantwin bench silkit`).
//!
//! `n` synchronised participants each send one frame per 1 ms step; the first participant
//! is also the system controller and stops the simulation after the given number of steps.
//! Measured: frames acknowledged `Transmitted` per wall second, and the wall time from a
//! frame's `SendFrame` to its reception by the first participant (mean over every frame it
//! received), the same load with and without cantwin's network simulator.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant as WallInstant;

use cantwin_can::{BitRate, Duration};

use crate::bridge::{BridgeConfig, QUIET_CONFIGURATION};
use crate::error::Error;
use crate::ffi::{Participant, SilKit};
use crate::netsim::{NetsimConfig, run_network_simulator};
use crate::types::{CanFrame, DirectionMask, OperationMode, ParticipantState, TransmitStatus};

/// The participants' step, 1 ms.
const STEP_NS: u64 = 1_000_000;

/// One measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchReport {
    /// Sending participants.
    pub participants: usize,
    /// Whether cantwin was the network simulator.
    pub netsim: bool,
    /// Frames acknowledged `Transmitted`.
    pub frames: u64,
    /// Wall time from the first step to the stop.
    pub wall: std::time::Duration,
    /// Frames per wall second.
    pub frames_per_second: f64,
    /// Mean wall time from `SendFrame` to reception, in microseconds.
    pub latency_us: f64,
    /// Synchronisation steps in [`BenchReport::wall`]: from the first step to the stop.
    pub steps: u64,
}

impl BenchReport {
    /// Mean wall time of one synchronisation step, in microseconds.
    pub fn step_us(&self) -> f64 {
        self.wall.as_secs_f64() * 1e6 / self.steps.max(1) as f64
    }

    /// The latency in synchronisation steps: how many steps' wall time a frame takes from
    /// `SendFrame` to its reception.
    pub fn latency_steps(&self) -> f64 {
        self.latency_us / self.step_us().max(1e-9)
    }
}

/// What a run measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BenchConfig {
    /// Sending participants (at least 2: the first measures the others' frames).
    pub participants: usize,
    /// 1 ms steps to run.
    pub steps: u64,
    /// With cantwin as network simulator.
    pub netsim: bool,
}

/// Shared by the participants of one run.
struct Shared {
    /// Wall time of each frame's send, by sender and sequence number.
    sent: Vec<Mutex<Vec<Option<WallInstant>>>>,
    latency_ns: AtomicU64,
    latency_count: AtomicU64,
    transmitted: AtomicU64,
    started: Mutex<Option<WallInstant>>,
    stopped: Mutex<Option<WallInstant>>,
}

/// Run one measurement against the registry at `registry_uri`.
pub fn run(kit: &SilKit, registry_uri: &str, config: BenchConfig) -> Result<BenchReport, Error> {
    let n = config.participants.max(2);
    let names: Vec<String> = (0..n).map(|i| format!("P{i}")).collect();
    let shared = Arc::new(Shared {
        sent: (0..n)
            .map(|_| Mutex::new(vec![None; config.steps as usize + 2]))
            .collect(),
        latency_ns: AtomicU64::new(0),
        latency_count: AtomicU64::new(0),
        transmitted: AtomicU64::new(0),
        started: Mutex::new(None),
        stopped: Mutex::new(None),
    });
    let step_ns = STEP_NS;
    let failed = Arc::new(AtomicBool::new(false));
    let netsim_stop = Arc::new(AtomicBool::new(false));
    let netsim = if config.netsim {
        let kit = kit.clone();
        let bridge = BridgeConfig {
            registry_uri: registry_uri.to_string(),
            participant: "cantwin-netsim".into(),
            configuration: QUIET_CONFIGURATION.into(),
        };
        let (stop, failed) = (Arc::clone(&netsim_stop), Arc::clone(&failed));
        Some(std::thread::spawn(move || {
            let cfg = NetsimConfig {
                bit_rate: BitRate::R1M,
                step: Duration::from_nanos(step_ns),
                queue_depth: 16,
            };
            let r = run_network_simulator(&kit, &bridge, &["bench".into()], cfg, &stop).map(drop);
            // Its participants cannot start without it: they give up instead of waiting.
            if r.is_err() {
                failed.store(true, Ordering::SeqCst);
            }
            r
        }))
    } else {
        None
    };
    let mut required: Vec<&str> = names.iter().map(String::as_str).collect();
    if config.netsim {
        required.push("cantwin-netsim");
    }
    let mut threads = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let (kit, shared, uri, name) = (
            kit.clone(),
            Arc::clone(&shared),
            registry_uri.to_string(),
            name.clone(),
        );
        let required: Vec<String> = required.iter().map(|s| s.to_string()).collect();
        let steps = config.steps;
        let failed = Arc::clone(&failed);
        threads.push(std::thread::spawn(move || -> Result<(), Error> {
            let r = participant(i, &kit, &name, &uri, &shared, &required, steps, &failed);
            if r.is_err() {
                failed.store(true, Ordering::SeqCst);
            }
            r
        }));
    }

    let mut result = Ok(());
    for t in threads {
        let r = t.join().unwrap_or(Ok(()));
        if result.is_ok() {
            result = r;
        }
    }
    netsim_stop.store(true, Ordering::SeqCst);
    if let Some(t) = netsim {
        let r = t.join().unwrap_or(Ok(()));
        if let (Ok(()), Err(crate::bridge::BridgeError::SilKit(e))) = (&result, r) {
            result = Err(e);
        }
    }
    result?;
    let started = shared
        .started
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .unwrap_or_else(WallInstant::now);
    let stopped = shared
        .stopped
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .unwrap_or_else(WallInstant::now);
    let wall = stopped.saturating_duration_since(started);
    let frames = shared.transmitted.load(Ordering::Relaxed);
    let count = shared.latency_count.load(Ordering::Relaxed).max(1);
    Ok(BenchReport {
        participants: n,
        netsim: config.netsim,
        frames,
        wall,
        frames_per_second: frames as f64 / wall.as_secs_f64().max(1e-9),
        latency_us: shared.latency_ns.load(Ordering::Relaxed) as f64 / count as f64 / 1000.0,
        // Timed from the start of step 1 to the start of step `steps + 2`.
        steps: config.steps + 1,
    })
}

/// How long the bench's participants, all in this process, may take to be running.
const JOIN: std::time::Duration = std::time::Duration::from_secs(30);

/// Participant `i` of a run, until its lifecycle ends. A coordinated participant waits for
/// every required one, so once another has `failed` (it never joins) this one gives up
/// rather than wait for ever; it also gives up after [`JOIN`] without running.
#[allow(clippy::too_many_arguments)]
fn participant(
    i: usize,
    kit: &SilKit,
    name: &str,
    uri: &str,
    shared: &Arc<Shared>,
    required: &[String],
    steps: u64,
    failed: &AtomicBool,
) -> Result<(), Error> {
    let step_ns = STEP_NS;
    let p = Participant::create(kit, name, uri, QUIET_CONFIGURATION)?;
    let can = p.can_controller(&format!("{name}-CAN"), "bench")?;
    if i == 0 {
        let s = Arc::clone(shared);
        can.on_frame(DirectionMask::Receive, move |ev| {
            let (Some(&sender), Some(seq)) = (
                ev.frame.data.first(),
                ev.frame
                    .data
                    .get(1..5)
                    .and_then(|b| <[u8; 4]>::try_from(b).ok())
                    .map(u32::from_be_bytes),
            ) else {
                return;
            };
            let at = s
                .sent
                .get(sender as usize)
                .and_then(|v| {
                    v.lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .get(seq as usize)
                        .copied()
                })
                .flatten();
            if let Some(at) = at {
                s.latency_ns
                    .fetch_add(at.elapsed().as_nanos() as u64, Ordering::Relaxed);
                s.latency_count.fetch_add(1, Ordering::Relaxed);
            }
        })?;
    }
    {
        let s = Arc::clone(shared);
        can.on_transmit(move |ev| {
            if ev.status == TransmitStatus::Transmitted {
                s.transmitted.fetch_add(1, Ordering::Relaxed);
            }
        })?;
    }
    let lifecycle = p.lifecycle(OperationMode::Coordinated)?;
    {
        let can = can.clone();
        lifecycle.on_communication_ready(move || {
            let _ = can
                .set_baud_rate(1_000_000, 0, 0)
                .and_then(|()| can.start());
        })?;
    }
    let ts = lifecycle.time_sync()?;
    {
        let (s, can, lc) = (Arc::clone(shared), can.clone(), lifecycle.clone());
        ts.on_step(step_ns, move |now, _| {
            let k = now / step_ns;
            if i == 0 && k == 1 {
                *s.started.lock().unwrap_or_else(PoisonError::into_inner) =
                    Some(WallInstant::now());
            }
            if k >= 1 && k <= steps {
                let seq = k as u32;
                let mut data = vec![i as u8];
                data.extend_from_slice(&seq.to_be_bytes());
                let frame = CanFrame {
                    id: 0x100 + i as u32,
                    flags: 0,
                    dlc: 5,
                    data,
                };
                if let Some(slot) = s.sent[i]
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .get_mut(k as usize)
                {
                    *slot = Some(WallInstant::now());
                }
                let _ = can.send(&frame, k as usize);
            }
            // Two steps more than the frames, for the last ones to arrive.
            if i == 0 && k == steps + 2 {
                *s.stopped.lock().unwrap_or_else(PoisonError::into_inner) =
                    Some(WallInstant::now());
                let _ = lc.stop("bench done");
            }
        })?;
    }
    if i == 0 {
        let names: Vec<&str> = required.iter().map(String::as_str).collect();
        p.set_required_participants(&names)?;
    }
    lifecycle.start()?;
    let started = WallInstant::now();
    let mut ran = false;
    loop {
        match p.wait_for_lifecycle_timeout(&lifecycle, std::time::Duration::from_millis(20)) {
            Ok(_) => return Ok(()),
            Err(Error::Timeout { state, .. }) => {
                ran |= !matches!(
                    state,
                    ParticipantState::Invalid
                        | ParticipantState::ServicesCreated
                        | ParticipantState::CommunicationInitializing
                        | ParticipantState::CommunicationInitialized
                        | ParticipantState::ReadyToRun
                );
                if !ran && failed.load(Ordering::SeqCst) {
                    // The participant that failed reports the run's error.
                    return Ok(());
                }
                if !ran && started.elapsed() >= JOIN {
                    return Err(Error::Timeout {
                        waited_for: "every bench participant running",
                        after: JOIN,
                        state,
                    });
                }
            }
            Err(e) => return Err(e),
        }
    }
}
