//! Twins as SIL Kit participants: every bus of a cantwin simulation becomes a SIL Kit CAN
//! network of the same name. A port on each bus stands for the rest of the SIL Kit
//! simulation: the frames other participants send are transmitted through it (so they
//! arbitrate, take bus time and are acknowledged like any node's), and every frame the twins
//! put on the bus leaves through it to SIL Kit.
//!
//! # Time
//!
//! **Synchronised** ([`run_synchronized`]): a coordinated lifecycle with time
//! synchronisation. cantwin's virtual time is SIL Kit's: in the step that starts at `now`,
//! the bus first takes each frame other participants sent before `now` at the very instant
//! it carries (the sender's virtual time; SIL Kit delivers a message sent at T before any
//! peer starts a step after T, `docs/simulation/simulation.rst`), runs every event up to just
//! before `now`, and sends what the twins completed in that interval, stamped `now` by SIL
//! Kit. Frames at or after `now` wait for the next step. The bus therefore never runs ahead of
//! what it has heard, a frame leaves at most one step after it ended on the bus, and the
//! whole distributed simulation replays identically: which frames a step sees depends only
//! on virtual time, never on wall-clock order.
//!
//! **Unsynchronised** ([`PacedBridge`]): an autonomous lifecycle without time
//! synchronisation, for a simulation paced to the wall clock ([`cantwin_bus::PacedSimulation`]).
//! Frames are exchanged as they come; SIL Kit stamps them with no virtual time (the value
//! with only bit 63 set), and cantwin's bus puts them on the wire when they arrive.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;

use cantwin_bus::{BusId, ExternalConfig, ExternalPort, PortConfig, PortId, SimHandle, Simulation};
use cantwin_can::{Duration, Frame, Instant, Node, Outbox};

use crate::error::Error;
use crate::ffi::{CanController, Lifecycle, Participant, SilKit};
use crate::types::{CanFrame, DirectionMask, OperationMode, ParticipantState};

/// Where and as whom to join.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BridgeConfig {
    /// The registry, e.g. `silkit://127.0.0.1:8500`.
    pub registry_uri: String,
    /// The participant name (a system controller lists it among the required participants
    /// in synchronised mode).
    pub participant: String,
    /// A SIL Kit participant configuration (YAML or JSON; empty for SIL Kit's defaults).
    pub configuration: String,
}

/// A participant configuration that turns SIL Kit's own logging off (its default sink is
/// stdout, which a command line keeps for its results); failures come back as errors.
pub const QUIET_CONFIGURATION: &str = r#"{"Logging":{"Sinks":[{"Type":"Stdout","Level":"Off"}]}}"#;

/// Counters of a bridge.
#[derive(Debug, Default)]
pub struct Counters {
    /// Frames of other participants put on cantwin's buses.
    pub frames_in: AtomicU64,
    /// Frames of cantwin's buses sent to SIL Kit.
    pub frames_out: AtomicU64,
    /// Frames of other participants cantwin's buses cannot carry (CAN FD, CAN XL, bad
    /// identifiers or lengths), or that found the port's transmit queue full.
    pub frames_refused: AtomicU64,
    /// Simulation steps run (synchronised mode).
    pub steps: AtomicU64,
}

/// Counter values at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CountersSnapshot {
    /// See [`Counters::frames_in`].
    pub frames_in: u64,
    /// See [`Counters::frames_out`].
    pub frames_out: u64,
    /// See [`Counters::frames_refused`].
    pub frames_refused: u64,
    /// See [`Counters::steps`].
    pub steps: u64,
}

impl Counters {
    /// The values now.
    pub fn snapshot(&self) -> CountersSnapshot {
        CountersSnapshot {
            frames_in: self.frames_in.load(Ordering::Relaxed),
            frames_out: self.frames_out.load(Ordering::Relaxed),
            frames_refused: self.frames_refused.load(Ordering::Relaxed),
            steps: self.steps.load(Ordering::Relaxed),
        }
    }
}

/// How a synchronised run ended.
#[derive(Debug)]
pub struct SyncedOutcome {
    /// The simulation, with its nodes, at the time the SIL Kit simulation stopped.
    pub sim: Simulation,
    /// The participant's final state (`Shutdown` after a normal stop).
    pub final_state: ParticipantState,
    /// The counters.
    pub counters: CountersSnapshot,
    /// Participants that had been running and left before the end, in the order they left.
    /// The first to leave ends the simulation (cantwin stops it: without the participant,
    /// synchronised time cannot advance).
    pub left: Vec<String>,
}

/// Why a synchronised run failed.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A SIL Kit call failed.
    #[error(transparent)]
    SilKit(#[from] Error),
    /// A bus of the list is not in the simulation.
    #[error("no bus {0:?} in the simulation")]
    NoSuchBus(String),
    /// The step size is zero.
    #[error("the SIL Kit step size must be at least 1 ns")]
    ZeroStep,
    /// Asked to stop before the SIL Kit simulation started (no system controller started
    /// it): the participant leaves without running.
    #[error(
        "stopped before the SIL Kit simulation started (state {0:?}): a system controller must start it, e.g. `sil-kit-system-controller` with this participant's name among the required ones"
    )]
    StoppedBeforeStart(ParticipantState),
    /// The simulation did not start within [`Deadlines::join`]: a required participant did
    /// not join (or died before it did), or no system controller started it.
    #[error(
        "the SIL Kit simulation did not start within {after:?}: {} (this participant is {state:?}; others seen: {seen})",
        missing_text(.never_joined, .never_ran)
    )]
    NotStarted {
        /// The bound.
        after: std::time::Duration,
        /// This participant's state then.
        state: ParticipantState,
        /// The expected participants ([`Deadlines::peers`]) never seen at all.
        never_joined: Vec<String>,
        /// The expected participants seen, but never running.
        never_ran: Vec<String>,
        /// Every other participant seen, with its last state.
        seen: String,
    },
    /// The simulation did not end within [`Deadlines::run`] (cantwin then stops it).
    #[error(
        "the SIL Kit simulation did not end within {after:?} (this participant is {state:?}; others seen: {seen})"
    )]
    NotStopped {
        /// The bound.
        after: std::time::Duration,
        /// This participant's state then.
        state: ParticipantState,
        /// Every other participant seen, with its last state.
        seen: String,
    },
}

fn missing_text(never_joined: &[String], never_ran: &[String]) -> String {
    let mut parts = Vec::new();
    if !never_joined.is_empty() {
        parts.push(format!(
            "participant {} never joined",
            never_joined.join(", ")
        ));
    }
    if !never_ran.is_empty() {
        parts.push(format!(
            "participant {} joined but never ran",
            never_ran.join(", ")
        ));
    }
    if parts.is_empty() {
        // The system controller starts it only once every participant it requires has
        // joined, and no participant is told whom it requires.
        "no system controller started it (none is there, or one waits for a required \
         participant that has not joined)"
            .into()
    } else {
        parts.join("; ")
    }
}

/// The node standing for SIL Kit on a bus in synchronised mode: it hands every frame the
/// twins complete to the step that sends it.
struct Gateway {
    bus: usize,
    out: Arc<Mutex<Vec<(usize, Frame)>>>,
}

impl Node for Gateway {
    fn on_frame(&mut self, frame: &Frame, _now: Instant, _out: &mut Outbox) {
        self.out
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((self.bus, *frame));
    }

    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}

    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A frame from SIL Kit waiting for its step.
struct Inbound {
    timestamp: u64,
    seq: u64,
    bus: usize,
    frame: CanFrame,
}

struct Synced {
    sim: Mutex<Simulation>,
    inbox: Mutex<(u64, Vec<Inbound>)>,
    outbox: Arc<Mutex<Vec<(usize, Frame)>>>,
    ports: Vec<PortId>,
    counters: Counters,
}

impl Synced {
    /// One SIL Kit step at `now` (see the module documentation).
    fn step(&self, now: u64, controllers: &[CanController]) {
        let mut due: Vec<Inbound> = {
            let mut inbox = self.inbox.lock().unwrap_or_else(PoisonError::into_inner);
            let (due, later) = std::mem::take(&mut inbox.1)
                .into_iter()
                .partition(|f| f.timestamp < now);
            inbox.1 = later;
            due
        };
        due.sort_by_key(|f| (f.timestamp, f.seq));
        {
            let mut sim = self.sim.lock().unwrap_or_else(PoisonError::into_inner);
            for f in due {
                let at = Instant::from_nanos(f.timestamp);
                if at > sim.now() {
                    sim.run_until(at);
                }
                let accepted = match f.frame.to_frame() {
                    Ok(frame) => sim.transmit(self.ports[f.bus], frame).is_ok(),
                    Err(_) => false,
                };
                let counter = if accepted {
                    &self.counters.frames_in
                } else {
                    &self.counters.frames_refused
                };
                counter.fetch_add(1, Ordering::Relaxed);
            }
            if now > 0 {
                sim.run_until(Instant::from_nanos(now - 1));
            }
        }
        let out = std::mem::take(&mut *self.outbox.lock().unwrap_or_else(PoisonError::into_inner));
        for (bus, frame) in out {
            if controllers[bus]
                .send(&CanFrame::from_frame(&frame), 0)
                .is_ok()
            {
                self.counters.frames_out.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.counters.steps.fetch_add(1, Ordering::Relaxed);
    }
}

/// Run `sim` as participant `config.participant` of a coordinated, synchronised SIL Kit
/// simulation with steps of `step`, until the SIL Kit simulation stops (any required
/// participant stops it, or `stop` becomes true, which stops it from here). Each bus of
/// `buses` is the SIL Kit CAN network of its name. Blocks; returns the simulation.
pub fn run_synchronized(
    kit: &SilKit,
    sim: Simulation,
    buses: &[(String, BusId)],
    config: &BridgeConfig,
    step: Duration,
    stop: &AtomicBool,
) -> Result<SyncedOutcome, BridgeError> {
    run_synchronized_within(kit, sim, buses, config, step, stop, &Deadlines::default())
}

/// [`run_synchronized`] within `deadlines`: [`BridgeError::NotStarted`] naming who never
/// joined when the simulation does not start in time, [`BridgeError::NotStopped`] when it
/// does not end in time.
pub fn run_synchronized_within(
    kit: &SilKit,
    mut sim: Simulation,
    buses: &[(String, BusId)],
    config: &BridgeConfig,
    step: Duration,
    stop: &AtomicBool,
    deadlines: &Deadlines,
) -> Result<SyncedOutcome, BridgeError> {
    if step.is_zero() {
        return Err(BridgeError::ZeroStep);
    }
    let outbox = Arc::new(Mutex::new(Vec::new()));
    let mut ports = Vec::new();
    let mut rates = Vec::new();
    for (i, (name, id)) in buses.iter().enumerate() {
        let rate = sim
            .bus(*id)
            .map(|b| b.bit_rate().bits_per_second())
            .ok_or_else(|| BridgeError::NoSuchBus(name.clone()))?;
        let node = Gateway {
            bus: i,
            out: Arc::clone(&outbox),
        };
        // A deep queue: SIL Kit delivers what other participants sent in one step at once.
        let port = sim
            .attach(*id, node, PortConfig::DEFAULT.with_queue_depth(4096))
            .map_err(|_| BridgeError::NoSuchBus(name.clone()))?;
        ports.push(port);
        rates.push(rate);
    }
    let shared = Arc::new(Synced {
        sim: Mutex::new(sim),
        inbox: Mutex::new((0, Vec::new())),
        outbox,
        ports,
        counters: Counters::default(),
    });
    let participant = Participant::create(
        kit,
        &config.participant,
        &config.registry_uri,
        &config.configuration,
    )?;
    let mut controllers = Vec::new();
    for (i, (name, _)) in buses.iter().enumerate() {
        let c = participant.can_controller(&format!("{}/{name}", config.participant), name)?;
        let s = Arc::clone(&shared);
        c.on_frame(DirectionMask::Receive, move |ev| {
            let mut inbox = s.inbox.lock().unwrap_or_else(PoisonError::into_inner);
            inbox.0 += 1;
            let seq = inbox.0;
            inbox.1.push(Inbound {
                timestamp: ev.timestamp,
                seq,
                bus: i,
                frame: ev.frame,
            });
        })?;
        controllers.push(c);
    }
    let lifecycle = participant.lifecycle(OperationMode::Coordinated)?;
    start_controllers_when_ready(&lifecycle, &controllers, &rates)?;
    let time_sync = lifecycle.time_sync()?;
    {
        let (s, controllers) = (Arc::clone(&shared), controllers.clone());
        time_sync.on_step(step.as_nanos(), move |now, _duration| {
            s.step(now, &controllers);
        })?;
    }
    let (participant, final_state, left) = run_coordinated(
        participant,
        &lifecycle,
        &config.participant,
        stop,
        deadlines,
    )?;
    // Destroying the participant frees the handlers, the last holders of `shared` but this.
    drop(time_sync);
    drop(lifecycle);
    drop(controllers);
    drop(participant);
    let shared = Arc::try_unwrap(shared).map_err(|_| {
        BridgeError::SilKit(Error::Call {
            function: "SilKit_Participant_Destroy",
            code: 1,
            message: "a handler outlived its participant".into(),
        })
    })?;
    let counters = shared.counters.snapshot();
    Ok(SyncedOutcome {
        sim: shared
            .sim
            .into_inner()
            .unwrap_or_else(PoisonError::into_inner),
        final_state,
        counters,
        left,
    })
}

/// Bounds on the waits of a coordinated run ([`run_synchronized_within`],
/// [`crate::run_network_simulator_within`]). A coordinated participant otherwise waits for
/// ever: for the system controller to start the simulation (which it does only once every
/// required participant has joined, so one that dies before it joins keeps it from ever
/// starting), and for the simulation to stop. `None` waits without bound.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Deadlines {
    /// From the lifecycle's start until it runs.
    pub join: Option<std::time::Duration>,
    /// From the lifecycle's start until it ends.
    pub run: Option<std::time::Duration>,
    /// The other participants expected, named in [`BridgeError::NotStarted`] when they did
    /// not run (the system controller knows the required ones; a participant does not).
    pub peers: Vec<String>,
}

impl Deadlines {
    /// At most `join` until running, `run` until the end.
    pub fn new(join: std::time::Duration, run: std::time::Duration) -> Deadlines {
        Deadlines {
            join: Some(join),
            run: Some(run),
            peers: Vec::new(),
        }
    }

    /// The same bounds, with `peers` named when they did not run.
    pub fn expecting(mut self, peers: &[&str]) -> Deadlines {
        self.peers = peers.iter().map(|p| p.to_string()).collect();
        self
    }
}

/// How long a stopped lifecycle may take to shut down before its participant leaves anyway
/// (a run stopped at its bound: the stop goes round through the system controller; a paced
/// bridge leaving: its autonomous lifecycle shuts down by itself in milliseconds).
const STOP_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// What the system monitor saw of the others.
#[derive(Default)]
struct Peers {
    /// Each participant's last state, in the order first seen.
    last: Vec<(String, ParticipantState)>,
    /// Those that ran.
    ran: Vec<String>,
    /// Those that disconnected.
    gone: Vec<String>,
}

impl Peers {
    /// "PLC ServicesCreated, A disconnected", or "none".
    fn describe(&self) -> String {
        if self.last.is_empty() {
            return "none".into();
        }
        self.last
            .iter()
            .map(|(name, state)| {
                if self.gone.contains(name) {
                    format!("{name} disconnected after {state:?}")
                } else {
                    format!("{name} {state:?}")
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Start a coordinated lifecycle and block until it ends (or a bound of `deadlines` runs
/// out): stop it when `stop` is set, and when a participant that ran with us leaves mid-run
/// (a synchronised participant that disconnects while running stalls everyone's time, since
/// SIL Kit waits for its next step for ever). Returns the participant (for the caller to
/// destroy), the final state and who left. On an error the participant is destroyed here.
pub(crate) fn run_coordinated(
    participant: Participant,
    lifecycle: &Lifecycle,
    me: &str,
    stop: &AtomicBool,
    deadlines: &Deadlines,
) -> Result<(Participant, ParticipantState, Vec<String>), BridgeError> {
    let stop_requested = AtomicBool::new(false);
    let peers = Arc::new(Mutex::new(Peers::default()));
    let left = Arc::new(Mutex::new(Vec::<String>::new()));
    let monitor = participant.system_monitor()?;
    {
        let (seen, me) = (Arc::clone(&peers), me.to_string());
        monitor.on_participant_status(move |name, state| {
            if name == me {
                return;
            }
            let mut peers = seen.lock().unwrap_or_else(PoisonError::into_inner);
            match peers.last.iter_mut().find(|(n, _)| n == name) {
                Some(entry) => entry.1 = state,
                None => peers.last.push((name.to_string(), state)),
            }
            if state == ParticipantState::Running && !peers.ran.iter().any(|p| p == name) {
                peers.ran.push(name.to_string());
            }
        })?;
        let (seen, left, lc) = (Arc::clone(&peers), Arc::clone(&left), lifecycle.clone());
        monitor.on_participant_disconnected(move |name| {
            let mut peers = seen.lock().unwrap_or_else(PoisonError::into_inner);
            if !peers.gone.iter().any(|p| p == name) {
                peers.gone.push(name.to_string());
            }
            // Only a departure while we run is one mid-run: at the end, participants leave
            // once their own lifecycle is over (ours is stopping by then).
            let running = matches!(
                lc.state(),
                Ok(ParticipantState::Running | ParticipantState::Paused)
            );
            if running && peers.ran.iter().any(|p| p == name) {
                left.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(name.to_string());
            }
        })?;
    }
    lifecycle.start()?;
    let started = std::time::Instant::now();
    let mut ran = false;
    // Polled rather than blocking in SIL Kit's wait, which has no bound: the lifecycle ends
    // in Shutdown, and the wait then returns at once with the final state.
    loop {
        let state = lifecycle.state()?;
        if state == ParticipantState::Shutdown {
            break;
        }
        ran |= matches!(
            state,
            ParticipantState::Running
                | ParticipantState::Paused
                | ParticipantState::Stopping
                | ParticipantState::Stopped
                | ParticipantState::ShuttingDown
        );
        let waited = started.elapsed();
        if !ran && let Some(bound) = deadlines.join.filter(|b| waited >= *b) {
            let peers = peers.lock().unwrap_or_else(PoisonError::into_inner);
            let (never_ran, never_joined): (Vec<String>, Vec<String>) = deadlines
                .peers
                .iter()
                .filter(|p| !peers.ran.contains(p))
                .cloned()
                .partition(|p| peers.last.iter().any(|(n, _)| n == p));
            return Err(BridgeError::NotStarted {
                after: bound,
                state,
                never_joined,
                never_ran,
                seen: peers.describe(),
            });
        }
        if let Some(bound) = deadlines.run.filter(|b| waited >= *b) {
            if matches!(state, ParticipantState::Running | ParticipantState::Paused) {
                // Stopped, not just left: the others would wait for our next step for ever.
                // Their stop takes a round trip through the system controller, so the
                // participant stays (a bounded while) until its lifecycle is over.
                if lifecycle.stop("cantwin's run bound ran out").is_ok() {
                    let _ = participant.wait_for_lifecycle_timeout(lifecycle, STOP_GRACE);
                }
            }
            return Err(BridgeError::NotStopped {
                after: bound,
                state,
                seen: peers
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .describe(),
            });
        }
        let gone = left.lock().unwrap_or_else(PoisonError::into_inner).clone();
        if let Some(name) = gone.first()
            && !stop_requested.load(Ordering::SeqCst)
            && matches!(state, ParticipantState::Running | ParticipantState::Paused)
        {
            // The synchronised simulation cannot go on without it (its time never advances
            // again): end it for everyone, saying why.
            stop_requested.store(true, Ordering::SeqCst);
            let _ = lifecycle.stop(&format!("participant {name} left mid-run"));
        }
        if stop.load(Ordering::SeqCst) && !stop_requested.load(Ordering::SeqCst) {
            match state {
                ParticipantState::Running | ParticipantState::Paused => {
                    stop_requested.store(true, Ordering::SeqCst);
                    let _ = lifecycle.stop("cantwin was asked to stop");
                }
                s @ (ParticipantState::Invalid
                | ParticipantState::ServicesCreated
                | ParticipantState::CommunicationInitializing
                | ParticipantState::CommunicationInitialized
                | ParticipantState::ReadyToRun) => return Err(BridgeError::StoppedBeforeStart(s)),
                // Stopping, shutting down, error, aborting: the lifecycle ends by itself.
                _ => stop_requested.store(true, Ordering::SeqCst),
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let final_state = participant.wait_for_lifecycle(lifecycle)?;
    drop(monitor);
    let left = std::mem::take(&mut *left.lock().unwrap_or_else(PoisonError::into_inner));
    Ok((participant, final_state, left))
}

/// Set the bit rates and start the controllers once communication is ready (SIL Kit's rule:
/// no bus messages before CommunicationReady, `docs/api/netsim.rst`).
fn start_controllers_when_ready(
    lifecycle: &Lifecycle,
    controllers: &[CanController],
    rates: &[u32],
) -> Result<(), Error> {
    let controllers: Vec<(CanController, u32)> = controllers
        .iter()
        .cloned()
        .zip(rates.iter().copied())
        .collect();
    lifecycle.on_communication_ready(move || {
        for (c, rate) in &controllers {
            let _ = c.set_baud_rate(*rate, 0, 0).and_then(|()| c.start());
        }
    })
}

/// Twins on a simulation paced to the wall clock, joined to SIL Kit unsynchronised (an
/// autonomous lifecycle without time synchronisation). Dropping it, or [`PacedBridge::stop`],
/// leaves the SIL Kit simulation.
pub struct PacedBridge {
    participant: Option<Participant>,
    lifecycle: Lifecycle,
    forwarders: Vec<JoinHandle<()>>,
    quit: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

impl core::fmt::Debug for PacedBridge {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PacedBridge")
            .field("counters", &self.counters.snapshot())
            .finish_non_exhaustive()
    }
}

impl PacedBridge {
    /// Join SIL Kit with one external port per bus of the paced simulation behind `handle`.
    pub fn start(
        kit: &SilKit,
        handle: &SimHandle,
        buses: &[(String, BusId)],
        config: &BridgeConfig,
    ) -> Result<PacedBridge, BridgeError> {
        let mut ports = Vec::new();
        let mut rates = Vec::new();
        for (name, id) in buses {
            let rate = handle
                .with(|sim| sim.bus(*id).map(|b| b.bit_rate().bits_per_second()))
                .ok()
                .flatten()
                .ok_or_else(|| BridgeError::NoSuchBus(name.clone()))?;
            let config = ExternalConfig {
                port: PortConfig::DEFAULT.with_queue_depth(4096),
                rx_capacity: 65_536,
            };
            let port = handle
                .attach_external(*id, config)
                .map_err(|_| BridgeError::NoSuchBus(name.clone()))?;
            ports.push(Arc::new(port));
            rates.push(rate);
        }
        let participant = Participant::create(
            kit,
            &config.participant,
            &config.registry_uri,
            &config.configuration,
        )?;
        let counters = Arc::new(Counters::default());
        let mut controllers = Vec::new();
        for ((name, _), port) in buses.iter().zip(&ports) {
            let c = participant.can_controller(&format!("{}/{name}", config.participant), name)?;
            let (port, counters) = (Arc::clone(port), Arc::clone(&counters));
            c.on_frame(DirectionMask::Receive, move |ev| {
                let accepted = ev
                    .frame
                    .to_frame()
                    .ok()
                    .is_some_and(|f| port.send(f).is_ok());
                let counter = if accepted {
                    &counters.frames_in
                } else {
                    &counters.frames_refused
                };
                counter.fetch_add(1, Ordering::Relaxed);
            })?;
            controllers.push(c);
        }
        let lifecycle = participant.lifecycle(OperationMode::Autonomous)?;
        start_controllers_when_ready(&lifecycle, &controllers, &rates)?;
        lifecycle.start()?;
        let quit = Arc::new(AtomicBool::new(false));
        let mut forwarders = Vec::new();
        for (port, c) in ports.into_iter().zip(controllers) {
            let (quit, counters) = (Arc::clone(&quit), Arc::clone(&counters));
            let t = std::thread::Builder::new()
                .name("cantwin-silkit-tx".into())
                .spawn(move || forward(&port, &c, &quit, &counters))
                .map_err(|e| {
                    BridgeError::SilKit(Error::Call {
                        function: "std::thread::spawn",
                        code: 1,
                        message: e.to_string(),
                    })
                })?;
            forwarders.push(t);
        }
        Ok(PacedBridge {
            participant: Some(participant),
            lifecycle,
            forwarders,
            quit,
            counters,
        })
    }

    /// The counters now.
    pub fn counters(&self) -> CountersSnapshot {
        self.counters.snapshot()
    }

    /// The participant's lifecycle state.
    pub fn state(&self) -> Result<ParticipantState, Error> {
        self.lifecycle.state()
    }

    /// Leave the SIL Kit simulation: stop the lifecycle, wait (at most 5 s) for it to end,
    /// destroy the participant. Returns the final counters.
    pub fn stop(mut self) -> Result<CountersSnapshot, Error> {
        self.shut_down()?;
        Ok(self.counters.snapshot())
    }

    fn shut_down(&mut self) -> Result<(), Error> {
        self.quit.store(true, Ordering::SeqCst);
        for t in self.forwarders.drain(..) {
            let _ = t.join();
        }
        let Some(participant) = self.participant.take() else {
            return Ok(());
        };
        let r = match self.lifecycle.state() {
            Ok(ParticipantState::Running | ParticipantState::Paused) => self
                .lifecycle
                .stop("cantwin leaves")
                .and_then(|()| participant.wait_for_lifecycle_timeout(&self.lifecycle, STOP_GRACE))
                .map(drop),
            _ => Ok(()),
        };
        drop(participant);
        r
    }
}

impl Drop for PacedBridge {
    fn drop(&mut self) {
        let _ = self.shut_down();
    }
}

/// Send every frame the port receives (the twins' frames) to SIL Kit until told to quit or
/// the simulation stops.
fn forward(port: &ExternalPort, c: &CanController, quit: &AtomicBool, counters: &Counters) {
    while !quit.load(Ordering::SeqCst) {
        match port.recv_timeout(std::time::Duration::from_millis(20)) {
            Ok(Some(rx)) => {
                if c.send(&CanFrame::from_frame(&rx.frame), 0).is_ok() {
                    counters.frames_out.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(None) => {}
            Err(_) => break,
        }
    }
}
