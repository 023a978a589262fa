//! cantwin as SIL Kit's CAN network simulator: every controller on a simulated network —
//! cantwin's or anyone's — sends through cantwin's physical bus model.
//!
//! Each SIL Kit controller is a port on a cantwin [`cantwin_bus::Bus`] of the network's bit
//! rate. Its transmit requests queue on the port and arbitrate bit by bit with the others'
//! (ISO 11898-1 §10.4.4.2); a frame occupies the bus for its exact length including stuff
//! bits; it is acknowledged only if another started controller is there, otherwise its
//! sender sees ACK errors, counts them (TEC) and goes error-passive; repeated errors lead
//! to bus-off and recovery, all reported as SIL Kit error-state events. Fault confinement is
//! the bus's own (ISO 11898-1 §12.1.4.2, as for cantwin's nodes): bus-off, a controller
//! takes no part in the bus and its pending requests are discarded; requests it gets then
//! wait on its port until it recovers, by itself, 128 × 11 recessive bits later, or until a
//! `Reset` and `Start` give it fresh counters. Transmit acknowledgements carry
//! `Transmitted` when the frame is out, `TransmitQueueFull` when the port's queue was full,
//! `Canceled` when a stop, reset or bus-off discarded it.
//!
//! # Time
//!
//! The simulator is a synchronised SIL Kit participant. In its step `[now, now + d)` it puts
//! every request received since its previous step on the bus at `now`, runs the bus to just
//! before `now + d`, and produces every event of that interval with its exact time on the
//! bus. SIL Kit's frame request carries no send time (`capi/NetworkSimulator.h`), so a
//! request sent in a participant's step at exactly the simulator's `now` may arrive just
//! before or just after the simulator's step starts: it reaches the bus at `now` or at the
//! next step. Requests sent strictly between two simulator steps always reach the bus at the
//! next one, so participants whose steps fall between the simulator's (a simulator step
//! of twice theirs, for instance, with frames sent in odd steps) get fully reproducible
//! frame times.
//!
//! # Faults
//!
//! A network may carry timed bus-level faults ([`crate::netsim_faults`]): each applies at
//! its time in the step that contains it, the bus run to exactly that time first, so a
//! fault at the start of a step meets the requests that step puts on the bus.
//!
//! The network simulator API is experimental in SIL Kit 5 (`docs/api/netsim.rst`): it may
//! change or go away in a later SIL Kit.

use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use cantwin_bus::{BusConfig, BusId, PortConfig, PortId, Simulation};
use cantwin_can::{BitRate, ControllerEvent, Duration, Frame, Instant, Node, Outbox};

use crate::bridge::{BridgeConfig, BridgeError, Deadlines, run_coordinated};
use crate::ffi::{CanEventProducer, Participant, SilKit, SimulatedCanNetwork};
use crate::netsim_faults::{BusFault, NetsimFault};
use crate::types::{
    CanFrame, ControllerState, Direction, ErrorState, ErrorStateChangeEvent, FrameEvent,
    OperationMode, ParticipantState, StateChangeEvent, TransmitEvent, TransmitStatus,
};

/// How the simulated networks run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NetsimConfig {
    /// The bus bit rate; a controller set to another rate garbles the bus
    /// ([`cantwin_bus::Bus::set_bit_rate_mismatch`]).
    pub bit_rate: BitRate,
    /// The simulator's step.
    pub step: Duration,
    /// Each controller's transmit queue depth (requests beyond it are answered
    /// `TransmitQueueFull`).
    pub queue_depth: usize,
}

impl Default for NetsimConfig {
    /// 500 kbit/s, 1 ms steps, 16 transmit buffers per controller.
    fn default() -> Self {
        NetsimConfig {
            bit_rate: BitRate::R500K,
            step: Duration::from_millis(1),
            queue_depth: 16,
        }
    }
}

/// What happened on the bus to a controller, recorded by its port's node.
#[derive(Debug, Clone, Copy)]
enum BusEvent {
    Received(u64, Frame, Instant),
    Sent(u64, Frame, Instant),
    Controller(u64, ControllerEvent, Instant),
}

/// The node behind a SIL Kit controller's port: it only records.
struct ControllerNode {
    descriptor: u64,
    events: Arc<Mutex<Vec<BusEvent>>>,
}

impl ControllerNode {
    fn push(&self, e: BusEvent) {
        self.events
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(e);
    }
}

impl Node for ControllerNode {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.push(BusEvent::Received(self.descriptor, *frame, now));
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.push(BusEvent::Sent(self.descriptor, *frame, now));
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, _out: &mut Outbox) {
        self.push(BusEvent::Controller(self.descriptor, event, now));
    }

    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}

    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A controller's input, in arrival order.
#[derive(Debug)]
enum Input {
    Added(u64),
    Removed(u64),
    BaudRate(u64, u32),
    Frame(u64, CanFrame, usize),
    Mode(u64, ControllerState),
}

struct Controller {
    port: PortId,
    /// Frames on the port's queue with their SIL Kit tags, oldest first.
    pending: VecDeque<(Frame, usize)>,
    started: bool,
}

/// Counters of a simulated network.
#[derive(Debug, Default)]
struct NetCounters {
    frames: AtomicU64,
    refused: AtomicU64,
    queue_full: AtomicU64,
}

/// Counter values of a simulated network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NetworkCounters {
    /// Frames transmitted on the bus.
    pub frames: u64,
    /// Requests refused: CAN FD or XL, bad identifiers or lengths, controller not started.
    pub refused: u64,
    /// Requests answered `TransmitQueueFull`.
    pub queue_full: u64,
}

struct ModelState {
    sim: Simulation,
    bus: BusId,
    controllers: BTreeMap<u64, Controller>,
    inputs: Vec<Input>,
    producer: Option<CanEventProducer>,
    /// Faults not applied yet, latest first (the next one due is last).
    faults: Vec<(Instant, BusFault)>,
    /// Faults applied, with their times.
    applied: Vec<(Instant, BusFault)>,
    /// The port `send` faults send from, when there are any.
    script: Option<PortId>,
}

/// The port a scenario's `send` actions send from: it acknowledges and receives every frame
/// and sends only what it is given, as the script port of `cantwin sim --check`.
struct ScriptPort;

impl Node for ScriptPort {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}

    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}

    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// Frames a script port holds before it refuses more (a scenario's burst of sends).
const SCRIPT_QUEUE_DEPTH: usize = 64;

/// One simulated CAN network: cantwin's bus model behind SIL Kit's controllers.
pub struct CanNetworkModel {
    name: String,
    config: NetsimConfig,
    state: Mutex<ModelState>,
    events: Arc<Mutex<Vec<BusEvent>>>,
    counters: NetCounters,
}

impl core::fmt::Debug for CanNetworkModel {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("CanNetworkModel")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl CanNetworkModel {
    /// A network named `name`.
    pub fn new(name: &str, config: NetsimConfig) -> Self {
        Self::with_faults(name, config, 0, &[])
    }

    /// A network named `name` applying those of `faults` that are for it, each at its time;
    /// `seed` seeds the bus's fault injection generator (a scenario's `seed`).
    pub fn with_faults(
        name: &str,
        config: NetsimConfig,
        seed: u64,
        faults: &[NetsimFault],
    ) -> Self {
        let mut sim = Simulation::new();
        let bus = sim.add_bus(BusConfig::new(name, config.bit_rate).with_seed(seed));
        let mut due: Vec<(Instant, BusFault)> = faults
            .iter()
            .filter(|f| f.network == name)
            .map(|f| (f.at, f.fault))
            .collect();
        // Stable: faults of one time apply in file order.
        due.sort_by_key(|(at, _)| *at);
        due.reverse();
        let script = due
            .iter()
            .any(|(_, f)| f.sends())
            .then(|| {
                sim.attach(
                    bus,
                    ScriptPort,
                    PortConfig::DEFAULT.with_queue_depth(SCRIPT_QUEUE_DEPTH),
                )
                .ok()
            })
            .flatten();
        CanNetworkModel {
            name: name.to_string(),
            config,
            state: Mutex::new(ModelState {
                sim,
                bus,
                controllers: BTreeMap::new(),
                inputs: Vec::new(),
                producer: None,
                faults: due,
                applied: Vec::new(),
                script,
            }),
            events: Arc::new(Mutex::new(Vec::new())),
            counters: NetCounters::default(),
        }
    }

    /// The network's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The counters now.
    pub fn counters(&self) -> NetworkCounters {
        NetworkCounters {
            frames: self.counters.frames.load(Ordering::Relaxed),
            refused: self.counters.refused.load(Ordering::Relaxed),
            queue_full: self.counters.queue_full.load(Ordering::Relaxed),
        }
    }

    /// The faults applied so far, with their times.
    pub fn applied_faults(&self) -> Vec<(Instant, BusFault)> {
        self.lock().applied.clone()
    }

    /// Run `f` on the bus simulation (statistics, fault injection).
    pub fn with_simulation<R>(&self, f: impl FnOnce(&mut Simulation, BusId) -> R) -> R {
        let mut st = self.lock();
        let bus = st.bus;
        f(&mut st.sim, bus)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, ModelState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn input(&self, i: Input) {
        self.lock().inputs.push(i);
    }

    /// One simulator step `[now, now + duration)` (see the module documentation).
    pub fn step(&self, now: u64, duration: u64) {
        let mut st = self.lock();
        let t = Instant::from_nanos(now);
        st.sim.run_until(t);
        // Faults due by the step's start first, so that they meet its requests.
        Self::apply_faults(&mut st, t);
        let inputs = std::mem::take(&mut st.inputs);
        for i in inputs {
            self.apply(&mut st, i, now);
        }
        let end = Instant::from_nanos(now.saturating_add(duration.max(1)) - 1);
        while let Some(&(at, _)) = st.faults.last()
            && at <= end
        {
            st.sim.run_until(at);
            Self::apply_faults(&mut st, at);
        }
        st.sim.run_until(end);
        let events =
            std::mem::take(&mut *self.events.lock().unwrap_or_else(PoisonError::into_inner));
        self.produce(&mut st, &events);
    }

    /// Apply every fault due at or before `now`.
    fn apply_faults(st: &mut ModelState, now: Instant) {
        while let Some(&(at, fault)) = st.faults.last()
            && at <= now
        {
            st.faults.pop();
            if let Some(b) = st.sim.bus_mut(st.bus) {
                match fault {
                    BusFault::Inject(rule) => b.inject(rule),
                    BusFault::Clear => b.clear_faults(),
                    BusFault::Send(frame) => {
                        // A full script queue drops the frame, counted in the bus's
                        // statistics, as in `cantwin sim --check`.
                        if let Some(p) = st.script {
                            let _ = b.transmit(p, frame);
                        }
                    }
                }
            }
            st.applied.push((now, fault));
        }
    }

    fn apply(&self, st: &mut ModelState, input: Input, now: u64) {
        let bus = st.bus;
        match input {
            Input::Added(d) => {
                let node = ControllerNode {
                    descriptor: d,
                    events: Arc::clone(&self.events),
                };
                let config = PortConfig {
                    powered: false,
                    ..PortConfig::DEFAULT.with_queue_depth(self.config.queue_depth)
                };
                if let Ok(port) = st.sim.attach(bus, node, config) {
                    st.controllers.insert(
                        d,
                        Controller {
                            port,
                            pending: VecDeque::new(),
                            started: false,
                        },
                    );
                }
            }
            Input::Removed(d) => {
                if let Some(c) = st.controllers.remove(&d)
                    && let Some(b) = st.sim.bus_mut(bus)
                {
                    let _ = b.detach(c.port);
                }
            }
            Input::BaudRate(d, rate) => {
                let mismatch = (rate != 0 && rate != self.config.bit_rate.bits_per_second())
                    .then(|| BitRate::from_bits_per_second(rate))
                    .flatten();
                if let (Some(c), Some(b)) = (st.controllers.get(&d), st.sim.bus_mut(bus)) {
                    let _ = b.set_bit_rate_mismatch(c.port, mismatch);
                }
            }
            Input::Frame(d, frame, tag) => self.request(st, d, &frame, tag, now),
            Input::Mode(d, state) => self.mode(st, d, state, now),
        }
    }

    fn request(&self, st: &mut ModelState, d: u64, frame: &CanFrame, tag: usize, now: u64) {
        let bus = st.bus;
        let Some(c) = st.controllers.get_mut(&d) else {
            return;
        };
        let converted = frame.to_frame();
        let Ok(f) = converted.as_ref().map(|f| *f) else {
            self.counters.refused.fetch_add(1, Ordering::Relaxed);
            return;
        };
        if !c.started {
            self.counters.refused.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let Some(b) = st.sim.bus_mut(bus) else {
            return;
        };
        let queued = b.port_status(c.port).map(|s| s.queued).unwrap_or(0);
        if queued >= self.config.queue_depth {
            self.counters.queue_full.fetch_add(1, Ordering::Relaxed);
            if let Some(p) = &st.producer {
                let _ = p.transmit(
                    &TransmitEvent {
                        timestamp: now,
                        status: TransmitStatus::TransmitQueueFull,
                        can_id: frame.id,
                        user_context: tag,
                    },
                    &[d],
                );
            }
            return;
        }
        if b.transmit(c.port, f).is_ok() {
            c.pending.push_back((f, tag));
        }
    }

    fn mode(&self, st: &mut ModelState, d: u64, state: ControllerState, now: u64) {
        let bus = st.bus;
        let Some(c) = st.controllers.get_mut(&d) else {
            return;
        };
        let Some(b) = st.sim.bus_mut(bus) else {
            return;
        };
        let start = state == ControllerState::Started;
        // Off the bus, a controller's queue is gone: its requests are cancelled whether or not
        // the mode change asked for it (a stopped controller sends nothing, AUTOSAR CAN driver).
        let cancelled: Vec<(Frame, usize)> = if start {
            Vec::new()
        } else {
            c.pending.drain(..).collect()
        };
        if start != c.started {
            // Power on: fresh error counters, error-active (ISO 11898-1 §12.1.4.1).
            let _ = b.set_powered(c.port, start);
            c.started = start;
        }
        let Some(p) = &st.producer else {
            return;
        };
        for (f, tag) in cancelled {
            let _ = p.transmit(
                &TransmitEvent {
                    timestamp: now,
                    status: TransmitStatus::Canceled,
                    can_id: f.id().as_raw(),
                    user_context: tag,
                },
                &[d],
            );
        }
        let _ = p.state(
            &StateChangeEvent {
                timestamp: now,
                state,
            },
            &[d],
        );
        let error_state = match state {
            ControllerState::Started => ErrorState::ErrorActive,
            ControllerState::Uninit => ErrorState::NotAvailable,
            _ => return,
        };
        let _ = p.error_state(
            &ErrorStateChangeEvent {
                timestamp: now,
                error_state,
            },
            &[d],
        );
    }

    fn produce(&self, st: &mut ModelState, events: &[BusEvent]) {
        let Some(p) = st.producer.clone() else {
            return;
        };
        let mut i = 0;
        while i < events.len() {
            match events[i] {
                BusEvent::Received(_, frame, at) => {
                    // Every receiver of one frame in one call.
                    let mut receivers = Vec::new();
                    while let Some(BusEvent::Received(d, f, t)) = events.get(i).copied() {
                        if f != frame || t != at {
                            break;
                        }
                        receivers.push(d);
                        i += 1;
                    }
                    let _ = p.frame(
                        &FrameEvent {
                            timestamp: at.as_nanos(),
                            frame: CanFrame::from_frame(&frame),
                            direction: Direction::Receive,
                            user_context: 0,
                        },
                        &receivers,
                    );
                    continue;
                }
                BusEvent::Sent(d, frame, at) => {
                    self.counters.frames.fetch_add(1, Ordering::Relaxed);
                    let tag = st
                        .controllers
                        .get_mut(&d)
                        .and_then(|c| {
                            let k = c.pending.iter().position(|(f, _)| *f == frame)?;
                            c.pending.remove(k)
                        })
                        .map_or(0, |(_, tag)| tag);
                    // The sender sees its own frame (SIL Kit's TX direction) and the
                    // acknowledgement, as a controller in SIL Kit's trivial mode does.
                    let _ = p.frame(
                        &FrameEvent {
                            timestamp: at.as_nanos(),
                            frame: CanFrame::from_frame(&frame),
                            direction: Direction::Send,
                            user_context: tag,
                        },
                        &[d],
                    );
                    let _ = p.transmit(
                        &TransmitEvent {
                            timestamp: at.as_nanos(),
                            status: TransmitStatus::Transmitted,
                            can_id: frame.id().as_raw(),
                            user_context: tag,
                        },
                        &[d],
                    );
                }
                BusEvent::Controller(d, e, at) => {
                    let ts = at.as_nanos();
                    let error_state = match e {
                        ControllerEvent::ErrorPassive => Some(ErrorState::ErrorPassive),
                        ControllerEvent::ErrorActive | ControllerEvent::BusOffRecovered => {
                            Some(ErrorState::ErrorActive)
                        }
                        ControllerEvent::BusOff => Some(ErrorState::BusOff),
                        ControllerEvent::TxDropped => {
                            // Discarded before it was sent: bus-off cleared the queue.
                            if let Some((f, tag)) = st
                                .controllers
                                .get_mut(&d)
                                .and_then(|c| c.pending.pop_front())
                            {
                                let _ = p.transmit(
                                    &TransmitEvent {
                                        timestamp: ts,
                                        status: TransmitStatus::Canceled,
                                        can_id: f.id().as_raw(),
                                        user_context: tag,
                                    },
                                    &[d],
                                );
                            }
                            None
                        }
                        _ => None,
                    };
                    if let Some(error_state) = error_state {
                        let _ = p.error_state(
                            &ErrorStateChangeEvent {
                                timestamp: ts,
                                error_state,
                            },
                            &[d],
                        );
                    }
                }
            }
            i += 1;
        }
    }
}

impl SimulatedCanNetwork for CanNetworkModel {
    fn controller_added(&self, descriptor: u64) {
        self.input(Input::Added(descriptor));
    }

    fn controller_removed(&self, descriptor: u64) {
        self.input(Input::Removed(descriptor));
    }

    fn event_producer(&self, producer: CanEventProducer) {
        self.lock().producer = Some(producer);
    }

    fn baud_rate(&self, descriptor: u64, rate: u32, _fd_rate: u32, _xl_rate: u32) {
        self.input(Input::BaudRate(descriptor, rate));
    }

    fn frame_request(&self, descriptor: u64, frame: CanFrame, user_context: usize) {
        self.input(Input::Frame(descriptor, frame, user_context));
    }

    fn controller_mode(
        &self,
        descriptor: u64,
        state: ControllerState,
        _reset_error_handling: bool,
        _cancel_transmit_requests: bool,
    ) {
        // Leaving Started powers the port off and on again later, which resets the error
        // counters and cancels the queue in every case, as Reset's flags ask.
        self.input(Input::Mode(descriptor, state));
    }
}

/// How a network simulator run ended.
#[derive(Debug)]
pub struct NetsimOutcome {
    /// The simulated networks, with their buses.
    pub networks: Vec<Arc<CanNetworkModel>>,
    /// The participant's final state.
    pub final_state: ParticipantState,
    /// Participants that ran and left before the end (the first ends the simulation).
    pub left: Vec<String>,
}

/// Run as the network simulator of `networks` until the SIL Kit simulation stops (or `stop`
/// is set, which stops it). The participant is coordinated and synchronised: a system
/// controller must list it with the others (`docs/api/netsim.rst`).
pub fn run_network_simulator(
    kit: &SilKit,
    bridge: &BridgeConfig,
    networks: &[String],
    config: NetsimConfig,
    stop: &AtomicBool,
) -> Result<NetsimOutcome, BridgeError> {
    run_network_simulator_within(kit, bridge, networks, config, stop, &Deadlines::default())
}

/// [`run_network_simulator`] within `deadlines` (see [`crate::run_synchronized_within`]).
pub fn run_network_simulator_within(
    kit: &SilKit,
    bridge: &BridgeConfig,
    networks: &[String],
    config: NetsimConfig,
    stop: &AtomicBool,
    deadlines: &Deadlines,
) -> Result<NetsimOutcome, BridgeError> {
    let faults = NetsimFaults::default();
    run_network_simulator_with_faults(kit, bridge, networks, config, &faults, stop, deadlines)
}

/// Timed faults for the simulated networks, with the seed of their buses' fault injection
/// generators ([`crate::netsim_faults::faults_from_scenario`] makes them from a scenario).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetsimFaults {
    /// The seed (a scenario's `seed`).
    pub seed: u64,
    /// The faults, each for one network.
    pub faults: Vec<NetsimFault>,
}

/// [`run_network_simulator_within`], applying `faults` at their times.
pub fn run_network_simulator_with_faults(
    kit: &SilKit,
    bridge: &BridgeConfig,
    networks: &[String],
    config: NetsimConfig,
    faults: &NetsimFaults,
    stop: &AtomicBool,
    deadlines: &Deadlines,
) -> Result<NetsimOutcome, BridgeError> {
    if config.step.is_zero() {
        return Err(BridgeError::ZeroStep);
    }
    let models: Vec<Arc<CanNetworkModel>> = networks
        .iter()
        .map(|n| {
            Arc::new(CanNetworkModel::with_faults(
                n,
                config,
                faults.seed,
                &faults.faults,
            ))
        })
        .collect();
    let participant = Participant::create(
        kit,
        &bridge.participant,
        &bridge.registry_uri,
        &bridge.configuration,
    )?;
    // The order SIL Kit's netsim documentation gives: lifecycle and time sync, then the
    // simulator and its networks, Start, the step handler, and the lifecycle last.
    let lifecycle = participant.lifecycle(OperationMode::Coordinated)?;
    let time_sync = lifecycle.time_sync()?;
    let simulated: Vec<(&str, Arc<dyn SimulatedCanNetwork>)> = models
        .iter()
        .map(|m| (m.name(), Arc::clone(m) as Arc<dyn SimulatedCanNetwork>))
        .collect();
    participant.simulate_can_networks(&simulated)?;
    {
        let models = models.clone();
        time_sync.on_step(config.step.as_nanos(), move |now, duration| {
            for m in &models {
                m.step(now, duration);
            }
        })?;
    }
    let (participant, final_state, left) = run_coordinated(
        participant,
        &lifecycle,
        &bridge.participant,
        stop,
        deadlines,
    )?;
    drop(time_sync);
    drop(lifecycle);
    drop(participant);
    Ok(NetsimOutcome {
        networks: models,
        final_state,
        left,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::netsim_faults::faults_from_scenario;
    use crate::netsim_faults::tests::{networks, scenario};
    use crate::{CanFrame, ControllerState};
    use cantwin_bus::{FaultRule, FrameSelector};

    #[test]
    fn a_fault_applies_at_its_time_in_the_step_that_holds_it() {
        let s = scenario(
            "[[at]]\ntime_ms = 6\naction = \"corrupt\"\nbus = \"can0\"\nfraction = 1.0\ncount = 1\n\n\
             [[at]]\ntime_ms = 7\naction = \"clear_faults\"\nbus = \"can0\"\n\n\
             [[at]]\ntime_ms = 7.5\naction = \"send\"\nbus = \"can0\"\nframe = \"7FF#01\"\n",
        );
        let faults = faults_from_scenario(&s, &networks()).expect("faults");
        let model = CanNetworkModel::with_faults("can0", NetsimConfig::default(), s.seed, &faults);
        for d in [1, 2] {
            model.controller_added(d);
            model.controller_mode(d, ControllerState::Started, false, false);
        }
        let ms = 1_000_000;
        let frame = CanFrame {
            id: 0x200,
            flags: 0,
            dlc: 1,
            data: vec![0x11],
        };
        let frames_and_errors = || {
            model.with_simulation(|sim, bus| {
                sim.bus(bus)
                    .map(|b| (b.stats().frames(), b.stats().error_frames()))
            })
        };
        let tecs = || {
            model.with_simulation(|sim, bus| {
                let b = sim.bus(bus).expect("bus");
                let mut t: Vec<u16> = b
                    .ports()
                    .map(|p| b.port_status(p).expect("port").counters.tec())
                    .collect();
                t.sort_unstable();
                t
            })
        };
        model.step(0, 2 * ms);
        // Before the fault's step: sent as it is.
        model.frame_request(1, frame.clone(), 1);
        model.step(2 * ms, 2 * ms);
        model.step(4 * ms, 2 * ms);
        assert_eq!((frames_and_errors(), tecs()), (Some((1, 0)), vec![0, 0, 0]));
        // The step at 6 ms: corrupted once (an error frame, TEC + 8, ISO 11898-1 §12.1.4.2
        // rule 3), then sent again and acknowledged (TEC − 1, rule 7).
        model.frame_request(1, frame, 2);
        model.step(6 * ms, 2 * ms);
        assert_eq!((frames_and_errors(), tecs()), (Some((3, 1)), vec![0, 0, 7]));
        assert_eq!(
            model.applied_faults(),
            [
                (
                    Instant::from_nanos(6 * ms),
                    BusFault::Inject(FaultRule::corrupt(FrameSelector::Fraction(1.0)).times(1))
                ),
                (Instant::from_nanos(7 * ms), BusFault::Clear),
                (
                    Instant::from_nanos(7 * ms + ms / 2),
                    BusFault::Send(Frame::std(0x7FF, &[0x01]).expect("frame"))
                ),
            ]
        );
    }

    #[test]
    fn a_reset_ends_bus_off_at_once_and_a_start_sends_with_fresh_counters() {
        let model = CanNetworkModel::new("can0", NetsimConfig::default());
        for d in [1, 2] {
            model.controller_added(d);
            model.controller_mode(d, ControllerState::Started, false, false);
        }
        let ms = 1_000_000;
        let frame = |id| CanFrame {
            id,
            flags: 0,
            dlc: 1,
            data: vec![0x11],
        };
        let a = |model: &CanNetworkModel| {
            let st = model.lock();
            let port = st.controllers[&1].port;
            let b = st.sim.bus(st.bus).expect("bus");
            let s = b.port_status(port).expect("port");
            (s.counters.state(), s.counters.tec(), b.stats().frames())
        };
        model.step(0, 2 * ms);
        model.with_simulation(|sim, bus| {
            sim.bus_mut(bus)
                .expect("bus")
                .inject(FaultRule::corrupt(FrameSelector::All));
        });
        model.frame_request(1, frame(0x200), 1);
        // 32 corrupted attempts in a row: bus-off above TEC 255 (ISO 11898-1 §12.1.4.2).
        for t in [2, 4, 6] {
            model.step(t * ms, 2 * ms);
        }
        let (state, tec, frames) = a(&model);
        assert_eq!((state, frames), (cantwin_can::ErrorState::BusOff, 0));
        assert!(tec > 255, "{tec}");
        model.with_simulation(|sim, bus| sim.bus_mut(bus).expect("bus").clear_faults());
        // SIL Kit's Reset (Uninit, clearing error handling), Start again and a request, all
        // taken at 8 ms, well before bus-off would end by itself (1408 bit times after it
        // began, past 9 ms): the frame goes out at once, error-active with TEC 0.
        model.controller_mode(1, ControllerState::Uninit, true, true);
        model.controller_mode(1, ControllerState::Started, false, false);
        model.frame_request(1, frame(0x201), 2);
        model.step(8 * ms, ms / 2);
        assert_eq!(a(&model), (cantwin_can::ErrorState::Active, 0, 1));
    }
}
