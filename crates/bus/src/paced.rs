//! Running a simulation paced to the wall clock, on its own thread, for external tools.
//!
//! [`PacedSimulation::start`] moves a [`Simulation`] onto a thread that keeps bus time in step
//! with the wall clock: it processes every event due, then sleeps on a condition variable
//! until the next event is due or another thread changes something (no busy waiting). Other
//! threads reach the simulation through a [`SimHandle`] (`Clone + Send + Sync`): run closures
//! against it, attach [`ExternalPort`]s that send and receive frames like any node, read the
//! time mapping, stop it.
//!
//! # Catch-up policy
//!
//! If the host cannot keep up (an event due more than [`PacedConfig::max_lag`] ago has not
//! run yet), the backlog beyond `max_lag` is given up: bus time does not jump, the mapping to
//! wall time slips by the excess instead (counted in [`SimHandle::slips`]) and pacing goes on
//! from there. Bus time therefore never runs ahead of
//! the wall clock, never skips events, and at worst runs slower than it. [`TimeMap`] always
//! gives the current mapping, which captures use to stamp frames.
//!
//! ```
//! use std::time::Duration;
//! use cantwin_bus::{BusConfig, ExternalConfig, PacedConfig, PacedSimulation, Simulation};
//! use cantwin_can::{BitRate, Frame};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut sim = Simulation::new();
//! let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
//! let paced = PacedSimulation::start(sim, PacedConfig::default());
//! let handle = paced.handle(); // Clone + Send: hand it to server threads
//! let tool = handle.attach_external(bus, ExternalConfig::default())?;
//! let other = handle.attach_external(bus, ExternalConfig::default())?;
//! tool.send(Frame::std(0x000, &[0x01, 0x00])?)?; // NMT start all
//! let got = other.recv_timeout(Duration::from_secs(5))?.ok_or("nothing received")?;
//! assert_eq!(got.frame.data_bytes(), [0x01, 0x00]);
//! let wall = handle.time_map().wall_time(got.at); // for a capture's timestamp
//! # let _ = wall;
//! handle.with(|sim| sim.bus(bus).map(|b| b.stats().frames()))?;
//! let sim = paced.stop(); // the simulation comes back, nodes and all
//! # assert!(sim.is_some());
//! # Ok(())
//! # }
//! ```

use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::SystemTime;

use cantwin_can::{Duration, Frame, Instant, Node, Outbox};

use crate::error::BusError;
use crate::ids::{BusId, PortId};
use crate::port::PortConfig;
use crate::rx_queue::{RxClosed, RxQueue};
use crate::sim::Simulation;

pub use crate::rx_queue::Received;
pub use crate::time_map::TimeMap;

/// How a paced simulation runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacedConfig {
    /// The most bus time the simulation may lag behind the wall clock before the backlog is
    /// given up (see the module documentation).
    pub max_lag: Duration,
    /// The longest the thread sleeps when nothing is scheduled.
    pub idle_wait: std::time::Duration,
}

impl Default for PacedConfig {
    /// 50 ms of lag, wake at least every second.
    fn default() -> Self {
        PacedConfig {
            max_lag: Duration::from_millis(50),
            idle_wait: std::time::Duration::from_secs(1),
        }
    }
}

struct State {
    sim: Option<Simulation>,
    stop: bool,
    config: PacedConfig,
    mono_origin: std::time::Instant,
    wall_origin: SystemTime,
    bus_origin: Instant,
    slipped: Duration,
    slips: u64,
    externals: Vec<Arc<RxQueue>>,
}

impl State {
    /// Bus time now by the wall clock, with the slip applied.
    fn target(&self) -> Instant {
        self.bus_origin + Duration::from(self.mono_origin.elapsed()) - self.slipped
    }

    fn time_map(&self) -> TimeMap {
        TimeMap {
            bus_origin: self.bus_origin,
            wall_origin: self.wall_origin + std::time::Duration::from(self.slipped),
        }
    }

    /// Run the simulation up to the wall clock, applying the catch-up policy. The time map
    /// in force is handed to `publish` before any event runs, so that whoever reads it while
    /// the simulation runs (a sink stamping a frame) reads the map the frame is stamped with.
    fn advance(&mut self, publish: impl FnOnce(TimeMap)) {
        let mut target = self.target();
        let Some(sim) = self.sim.as_mut() else {
            return;
        };
        // Late is an event that was due more than `max_lag` ago and has not run yet.
        if let Some(next) = sim.next_event_time()
            && target > next + self.config.max_lag
        {
            let give_up = target - (next + self.config.max_lag);
            self.slipped += give_up;
            self.slips += 1;
            target -= give_up;
        }
        let map = self.time_map();
        publish(map);
        if let Some(sim) = self.sim.as_mut() {
            if sim.time_map() != Some(map) {
                sim.set_time_map(Some(map));
            }
            sim.run_until(target);
        }
    }

    /// How long to sleep until the next event is due.
    fn wait(&mut self) -> std::time::Duration {
        let next = self.sim.as_mut().and_then(Simulation::next_event_time);
        match next {
            None => self.config.idle_wait,
            Some(t) => {
                let due = self.mono_origin
                    + std::time::Duration::from((t - self.bus_origin) + self.slipped);
                due.saturating_duration_since(std::time::Instant::now())
                    .min(self.config.idle_wait)
            }
        }
    }
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    /// The current time map, published apart from `state` so that reading it never waits for
    /// the simulation (and can be done while the simulation is running, from a node).
    map: Arc<Mutex<TimeMap>>,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn map(&self) -> TimeMap {
        *self.map.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Run the simulation up to the wall clock (see [`State::advance`]), publishing the time
    /// map it runs with.
    fn advance(&self, g: &mut State) {
        g.advance(|map| {
            let mut published = self.map.lock().unwrap_or_else(PoisonError::into_inner);
            if *published != map {
                *published = map;
            }
        });
    }
}

/// A simulation running paced to the wall clock on its own thread. Dropping it stops the
/// thread.
pub struct PacedSimulation {
    handle: SimHandle,
    thread: Option<JoinHandle<()>>,
}

impl core::fmt::Debug for PacedSimulation {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PacedSimulation").finish_non_exhaustive()
    }
}

impl PacedSimulation {
    /// Start pacing `sim` from its current time, which is mapped to the wall clock now.
    pub fn start(sim: Simulation, config: PacedConfig) -> Self {
        let state = State {
            bus_origin: sim.now(),
            sim: Some(sim),
            stop: false,
            config,
            mono_origin: std::time::Instant::now(),
            wall_origin: SystemTime::now(),
            slipped: Duration::ZERO,
            slips: 0,
            externals: Vec::new(),
        };
        let map = state.time_map();
        let shared = Arc::new(Shared {
            state: Mutex::new(state),
            wake: Condvar::new(),
            map: Arc::new(Mutex::new(map)),
        });
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("cantwin-bus".into())
            .spawn(move || run(&thread_shared))
            .ok();
        let handle = SimHandle { shared };
        if thread.is_none() {
            // No thread could be started: behave as a stopped simulation.
            handle.stop();
        }
        PacedSimulation { handle, thread }
    }

    /// A handle for other threads.
    pub fn handle(&self) -> SimHandle {
        self.handle.clone()
    }

    /// Stop the thread and take the simulation back (with its nodes, for inspection).
    pub fn stop(mut self) -> Option<Simulation> {
        self.join();
        self.handle.shared.lock().sim.take()
    }

    fn join(&mut self) {
        self.handle.stop();
        if let Some(t) = self.thread.take() {
            // A panic on the simulation thread has already been reported by the runtime.
            let _ = t.join();
        }
    }
}

impl Drop for PacedSimulation {
    fn drop(&mut self) {
        self.join();
    }
}

/// How early the thread wakes before an event while external ports are attached, to meet the
/// event on the wall clock by polling: a sleeping thread wakes tens of microseconds late
/// (Linux timer slack is 50 µs), which a tool waiting on a gateway sees in every round trip.
const PRECISE_WAKE: std::time::Duration = std::time::Duration::from_micros(60);

fn run(shared: &Shared) {
    let mut g = shared.lock();
    while !g.stop {
        shared.advance(&mut g);
        let wait = g.wait();
        if !g.externals.is_empty() && wait <= PRECISE_WAKE {
            // Close to an event that someone outside is waiting for: give the lock up (so
            // gateways can queue frames) and poll the clock until it is due.
            drop(g);
            let due = std::time::Instant::now() + wait;
            while std::time::Instant::now() < due {
                std::thread::yield_now();
            }
            g = shared.lock();
            continue;
        }
        let sleep = if g.externals.is_empty() {
            wait
        } else {
            wait - PRECISE_WAKE
        };
        g = shared
            .wake
            .wait_timeout(g, sleep)
            .unwrap_or_else(PoisonError::into_inner)
            .0;
    }
    for rx in g.externals.drain(..) {
        rx.close();
    }
}

/// A thread-safe handle to a [`PacedSimulation`].
#[derive(Clone)]
pub struct SimHandle {
    shared: Arc<Shared>,
}

impl core::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SimHandle").finish_non_exhaustive()
    }
}

impl SimHandle {
    /// Run `f` against the simulation, brought up to the wall clock first, so what `f` does
    /// happens now. The simulation thread then re-plans its sleep. `f` runs with the
    /// simulation locked: it must not call back into a [`SimHandle`] or [`ExternalPort`].
    pub fn with<R>(&self, f: impl FnOnce(&mut Simulation) -> R) -> Result<R, BusError> {
        let mut g = self.shared.lock();
        if g.stop {
            return Err(BusError::Stopped);
        }
        self.shared.advance(&mut g);
        let sim = g.sim.as_mut().ok_or(BusError::Stopped)?;
        let r = f(sim);
        drop(g);
        self.shared.wake.notify_all();
        Ok(r)
    }

    /// Bus time now.
    pub fn now(&self) -> Result<Instant, BusError> {
        self.with(|sim| sim.now())
    }

    /// The current mapping of bus time to wall time. It never waits for the simulation, so
    /// a node or a [`ExternalPort::deliver_to`] sink may call it while the simulation runs.
    pub fn time_map(&self) -> TimeMap {
        self.shared.map()
    }

    /// How many times the simulation fell more than `max_lag` behind and gave up the backlog.
    pub fn slips(&self) -> u64 {
        self.shared.lock().slips
    }

    /// Stop the simulation thread; external ports then return [`BusError::Stopped`].
    pub fn stop(&self) {
        let mut g = self.shared.lock();
        g.stop = true;
        for rx in g.externals.drain(..) {
            rx.close();
        }
        drop(g);
        self.shared.wake.notify_all();
    }

    /// Whether the simulation was stopped.
    pub fn is_stopped(&self) -> bool {
        self.shared.lock().stop
    }

    /// Attach an external port to a bus: a node driven from another thread.
    pub fn attach_external(
        &self,
        bus: BusId,
        config: ExternalConfig,
    ) -> Result<ExternalPort, BusError> {
        let rx = Arc::new(RxQueue::new(config.rx_capacity));
        let sink = Arc::new(Mutex::new(None));
        let node = ExternalNode {
            rx: Arc::clone(&rx),
            sink: Arc::clone(&sink),
            map: Arc::clone(&self.shared.map),
        };
        let port = self.with(|sim| sim.attach(bus, node, config.port))??;
        {
            let mut g = self.shared.lock();
            if g.stop {
                rx.close();
            } else {
                g.externals.push(Arc::clone(&rx));
            }
        }
        Ok(ExternalPort {
            port,
            rx,
            sink,
            handle: self.clone(),
        })
    }
}

/// How an external port is attached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExternalConfig {
    /// The port (transmit queue depth and order, echo). Default: [`PortConfig::DEFAULT`],
    /// no echo, so the port receives every frame on the bus except its own.
    pub port: PortConfig,
    /// Frames the receive buffer holds; when it is full, further frames are lost and counted
    /// ([`ExternalPort::overruns`]) — the bus never waits for a slow reader.
    pub rx_capacity: usize,
}

impl Default for ExternalConfig {
    /// A 32-frame transmit queue, a 1024-frame receive buffer.
    fn default() -> Self {
        ExternalConfig {
            port: PortConfig::DEFAULT,
            rx_capacity: 1024,
        }
    }
}

/// Where an external port's frames go instead of its receive buffer, each with the time map in
/// force: see [`ExternalPort::deliver_to`].
pub type Sink = Box<dyn FnMut(Received, TimeMap) + Send>;

/// The node behind an external port: it hands every frame to its sink if it has one, else to
/// the receive buffer.
struct ExternalNode {
    rx: Arc<RxQueue>,
    sink: Arc<Mutex<Option<Sink>>>,
    /// The simulation's published time map (not its handle: a sink held by the simulation
    /// must not keep the simulation alive).
    map: Arc<Mutex<TimeMap>>,
}

impl Node for ExternalNode {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        let rx = Received {
            frame: *frame,
            at: now,
        };
        let mut sink = self.sink.lock().unwrap_or_else(PoisonError::into_inner);
        match sink.as_mut() {
            Some(sink) => sink(rx, *self.map.lock().unwrap_or_else(PoisonError::into_inner)),
            // A full buffer loses the frame and counts it (`RxQueue`'s overflow policy).
            None => {
                self.rx.push(rx);
            }
        }
    }

    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}

    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A port on a paced bus driven from another thread (a socketcand or slcan client, the CLI).
/// Its frames arbitrate and take bus time like any node's; it acknowledges frames. Dropping
/// it detaches it.
pub struct ExternalPort {
    port: PortId,
    rx: Arc<RxQueue>,
    sink: Arc<Mutex<Option<Sink>>>,
    handle: SimHandle,
}

impl core::fmt::Debug for ExternalPort {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ExternalPort")
            .field("port", &self.port)
            .finish_non_exhaustive()
    }
}

impl ExternalPort {
    /// The port.
    pub fn port(&self) -> PortId {
        self.port
    }

    /// Queue a frame for transmission now.
    pub fn send(&self, frame: Frame) -> Result<(), BusError> {
        self.handle.with(|sim| sim.transmit(self.port, frame))?
    }

    /// The next received frame, waiting at most `timeout`; `Ok(None)` on timeout,
    /// [`BusError::Stopped`] once the simulation stopped or the port was detached and every
    /// buffered frame was taken.
    pub fn recv_timeout(&self, timeout: std::time::Duration) -> Result<Option<Received>, BusError> {
        self.rx
            .recv_timeout(timeout)
            .map_err(|RxClosed| BusError::Stopped)
    }

    /// Hand every frame this port receives to `sink`, with the time map in force (to stamp it
    /// in wall time), on the thread that runs the simulation at the moment the frame
    /// completes, instead of buffering it for [`ExternalPort::recv_timeout`]. Frames buffered
    /// so far go to the sink first, so it sees every frame once and in bus order. Detaching or
    /// dropping the port drops the sink; another call replaces it.
    ///
    /// This saves a reader thread's wake-up per frame (tens of microseconds on a loaded host),
    /// which a tool waiting for an answer sees in every round trip. The sink runs with the
    /// simulation locked: it must not block (queue the frame when it cannot pass it on at once)
    /// and must not call back into a [`SimHandle`] or [`ExternalPort`]. From then on
    /// [`ExternalPort::recv_timeout`] returns no frames, only [`BusError::Stopped`] once the
    /// simulation stopped or the port was detached.
    pub fn deliver_to(
        &self,
        sink: impl FnMut(Received, TimeMap) + Send + 'static,
    ) -> Result<(), BusError> {
        let mut sink: Sink = Box::new(sink);
        // Under the simulation's lock no frame can complete meanwhile: the buffered frames and
        // the ones after reach the sink in order.
        let map = self.handle.shared.map();
        let old = self.handle.with(|_| {
            while let Ok(Some(rx)) = self.rx.try_recv() {
                sink(rx, map);
            }
            self.sink
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .replace(sink)
        })?;
        drop(old);
        Ok(())
    }

    /// The next received frame if one is buffered.
    pub fn try_recv(&self) -> Result<Option<Received>, BusError> {
        self.rx.try_recv().map_err(|RxClosed| BusError::Stopped)
    }

    /// The port's controller state and counters (error counters, queue, statistics).
    pub fn status(&self) -> Result<crate::PortStatus, BusError> {
        let port = self.port;
        self.handle.with(|sim| match sim.bus(port.bus) {
            Some(bus) => bus.port_status(port),
            None => Err(BusError::NoSuchBus(port.bus)),
        })?
    }

    /// Frames lost because the receive buffer was full.
    pub fn overruns(&self) -> u64 {
        self.rx.overruns()
    }

    /// Detach the port from the bus.
    pub fn detach(self) -> Result<(), BusError> {
        self.detach_inner()
    }

    fn detach_inner(&self) -> Result<(), BusError> {
        // The sink goes first, whatever else happens: it may hold what owns this port.
        let sink = self
            .sink
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        drop(sink);
        if self.rx.is_closed() {
            return Ok(());
        }
        self.let_queue_drain();
        if !self.rx.close() {
            return Ok(());
        }
        let port = self.port;
        let r = self.handle.with(|sim| match sim.bus_mut(port.bus) {
            Some(bus) => bus.detach(port).map(drop),
            None => Err(BusError::NoSuchBus(port.bus)),
        });
        let mut g = self.handle.shared.lock();
        g.externals.retain(|rx| !Arc::ptr_eq(rx, &self.rx));
        drop(g);
        r?
    }
}

impl ExternalPort {
    /// Waits, at most [`DRAIN_LIMIT`] of wall time, until the frames this port queued are on
    /// the bus. A client that leaves right after its last frame (a tool that sends the
    /// closing frame of an SDO transfer and exits) is a controller whose application closed
    /// its socket: the controller still sends what it was given. Detaching at once would cut
    /// that frame off and leave the device in the middle of the transfer. A port that cannot
    /// send (bus-off, unpowered, disconnected) is waited for no longer than the limit.
    fn let_queue_drain(&self) {
        let port = self.port;
        let until = std::time::Instant::now() + DRAIN_LIMIT;
        while self
            .handle
            .with(|sim| sim.bus(port.bus).map(|b| b.transmit_pending(port)))
            .is_ok_and(|pending| matches!(pending, Some(Ok(true))))
            && std::time::Instant::now() < until
        {
            std::thread::sleep(std::time::Duration::from_micros(500));
        }
    }
}

/// How long a detaching external port waits for its queued frames to be sent.
const DRAIN_LIMIT: std::time::Duration = std::time::Duration::from_secs(1);

impl Drop for ExternalPort {
    fn drop(&mut self) {
        // Detaching a port of a stopped simulation has nothing left to do.
        let _ = self.detach_inner();
    }
}
