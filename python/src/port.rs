//! `cantwin.Port`: a node on a simulated bus driven from Python.
//!
//! # Time while receiving
//!
//! Paced, a receiver waits on the wall clock like any socket. In virtual time nothing moves
//! the clock but Python, so [`Port::recv`] runs the simulation itself: event by event, up to
//! the timeout in bus time, stopping as soon as a frame for this port arrives.
//!
//! A protocol stack in Python (python-canopen) receives on one thread (python-can's
//! Notifier) and sends and waits on others. Two rules keep the threads in step, both bounded
//! by the simulation's reaction time (wall clock):
//!
//! * **Answers** (the reaction rule): after a frame reached Python, the simulation does not
//!   run more than [`REACTION_GAP`] past it until Python sent something: the answer goes out
//!   at the bus time a fast host would have sent it, not after the device's SDO timeout.
//! * **Turns** (`crate::turns`): after a thread acted (sent a frame, changed a device), the
//!   simulation does not run, and no frame is handed over, until that thread waits: the
//!   answer to a frame is never there before its sender listens for it.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, MutexGuard, PoisonError};

use cantwin_bus::{
    BusId, PortConfig, PortId, Received, RxClosed, RxQueue, Simulation as BusSim, TxOrder,
};
use cantwin_can::{Duration, ExtendedId, Frame, Id, Instant, Node, Outbox, StandardId};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::core::{Core, Delivery, Mode, Shared, err, secs};

/// How far past the last frame handed to Python the simulation runs freely: frames that
/// follow within this much bus time (the segments of an SDO block, a PDO burst) come as
/// they come; beyond it, Python gets its reaction time first. Far below any protocol
/// timeout (CiA 301 SDO timeouts are tens of milliseconds and more).
const REACTION_GAP: Duration = Duration::from_millis(1);

/// The transmit queue of a Python port: a socket's FIFO (SocketCAN's default `txqueuelen`
/// is 10 frames; a sender finding it full waits, as a blocking socket write does).
const QUEUE_DEPTH: usize = 32;

/// How long `send` waits for room in the queue when python-can gives no timeout.
const SEND_TIMEOUT: Duration = Duration::from_secs(1);

/// A periodic transmission (python-can's `send_periodic`) kept on the bus's clock: its
/// frames go out every `period` of bus time, in virtual time as paced, whatever Python does
/// meanwhile (a thread sleeping on the wall clock would send at the wrong bus-time rate).
struct Periodic {
    key: u64,
    /// Sent in turn, one per period (python-can's sequence of messages).
    frames: Vec<Frame>,
    next_index: usize,
    period: Duration,
    due: Instant,
    /// No frame goes out at or after this instant (python-can's `duration`).
    end: Option<Instant>,
}

/// The node on the bus: it buffers every frame for Python and notes the delivery, and sends
/// the periodic frames Python started.
struct PyNode {
    rx: Arc<RxQueue>,
    delivery: Arc<Delivery>,
    periodic: Vec<Periodic>,
}

impl Node for PyNode {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        // Only a frame Python will see calls for its reaction (module documentation).
        if self.rx.push(Received {
            frame: *frame,
            at: now,
        }) {
            self.delivery.at.store(now.as_nanos(), Ordering::Relaxed);
            self.delivery.pending.store(true, Ordering::Release);
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.periodic.retain(|p| p.end.is_none_or(|e| p.due < e));
        for p in &mut self.periodic {
            if p.due > now {
                continue;
            }
            out.push(p.frames[p.next_index]);
            p.next_index = (p.next_index + 1) % p.frames.len();
            // A late tick (a paced bus lagging behind the wall clock) sends one frame, not a
            // burst, and keeps the phase: the next one is due at the next multiple.
            while p.due <= now {
                p.due = p.due.checked_add(p.period).unwrap_or(Instant::MAX);
            }
        }
        self.periodic.retain(|p| p.end.is_none_or(|e| p.due < e));
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.periodic.iter().map(|p| p.due).min()
    }
}

/// A node on a simulated bus for Python (from :py:meth:`Simulation.attach`).
///
/// Its frames arbitrate and take bus time like any node's; it acknowledges frames and
/// receives every frame on the bus but its own.
#[pyclass(module = "cantwin._native", frozen)]
pub struct Port {
    shared: Arc<Shared>,
    rx: Arc<RxQueue>,
    port: PortId,
    bus: String,
    next_key: AtomicU64,
    /// The thread that attached the port (`threading.get_ident()`): it answers what it
    /// receives itself, so its receives do not wait for answers.
    owner: u64,
}

pub(crate) fn attach(
    shared: &Arc<Shared>,
    bus: &str,
    rx_capacity: usize,
    owner: u64,
) -> PyResult<Port> {
    if rx_capacity == 0 {
        return Err(PyValueError::new_err("rx_capacity must be at least 1"));
    }
    let rx = Arc::new(RxQueue::new(rx_capacity));
    let node = PyNode {
        rx: Arc::clone(&rx),
        delivery: Arc::clone(&shared.delivery),
        periodic: Vec::new(),
    };
    let mut core = shared.lock();
    let id = core.bus_id(bus)?;
    let port = core
        .with_sim(|sim| {
            sim.attach(
                id,
                node,
                PortConfig::DEFAULT
                    .with_queue_depth(QUEUE_DEPTH)
                    .with_order(TxOrder::Fifo),
            )
        })?
        .map_err(|e| err(e.to_string()))?;
    Ok(Port {
        shared: Arc::clone(shared),
        rx,
        port,
        bus: bus.to_string(),
        next_key: AtomicU64::new(1),
        owner,
    })
}

/// A frame as Python gives it: identifier, data, extended, remote, DLC (of a remote frame).
type PyOutFrame = (u32, Vec<u8>, bool, bool, Option<u8>);

/// Check and build a frame from Python's fields: an 11-bit identifier unless `extended`; a
/// remote frame sends no data and requests `dlc` bytes.
fn make_frame(
    arbitration_id: u32,
    data: &[u8],
    extended: bool,
    remote: bool,
    dlc: Option<u8>,
) -> PyResult<Frame> {
    let id: Id = if extended {
        ExtendedId::new(arbitration_id)
            .map_err(|e| PyValueError::new_err(e.to_string()))?
            .into()
    } else {
        let raw = u16::try_from(arbitration_id)
            .map_err(|_| PyValueError::new_err("a standard identifier is 11 bits"))?;
        StandardId::new(raw)
            .map_err(|e| PyValueError::new_err(e.to_string()))?
            .into()
    };
    if remote {
        let dlc = dlc.unwrap_or(u8::try_from(data.len()).unwrap_or(u8::MAX));
        Frame::remote(id, dlc)
    } else {
        Frame::data(id, data)
    }
    .map_err(|e| PyValueError::new_err(e.to_string()))
}

fn make_frames(frames: Vec<PyOutFrame>) -> PyResult<Vec<Frame>> {
    if frames.is_empty() {
        return Err(PyValueError::new_err(
            "a periodic task needs at least one frame",
        ));
    }
    frames
        .into_iter()
        .map(|(id, data, extended, remote, dlc)| make_frame(id, &data, extended, remote, dlc))
        .collect()
}

/// What `recv` hands to Python: identifier, extended, remote, DLC, data, bus time (s).
type PyFrame = (u32, bool, bool, u8, Vec<u8>, f64);

fn to_py(r: Received) -> PyFrame {
    let (raw, extended) = match r.frame.id() {
        Id::Standard(s) => (u32::from(s.as_raw()), false),
        Id::Extended(e) => (e.as_raw(), true),
    };
    (
        raw,
        extended,
        r.frame.is_remote(),
        r.frame.dlc(),
        r.frame.data_bytes().to_vec(),
        r.at.since_start().as_secs_f64(),
    )
}

/// How many events [`run_to`] runs on past its target to reach a moment when no frame is on
/// the wire (a frame's end, an error frame, the next frame of a burst): a bound, so a bus
/// that is never idle still hands over.
const WIRE_EVENTS: usize = 8;

/// Run the simulation to `t`, then on until no frame is on the port's bus (at most
/// [`WIRE_EVENTS`] events). Python then gets its turn between frames: what it sends next is
/// queued behind no frame that had already started. A heartbeat already on the wire when an
/// NMT command is queued reports the old state (CiA 301 §7.2.8.3.2.1) and would be what
/// `wait_for_heartbeat()` after the command sees.
fn run_to(sim: &mut BusSim, bus: BusId, t: Instant) {
    sim.run_until(t);
    for _ in 0..WIRE_EVENTS {
        if sim.bus(bus).and_then(|b| b.transmitting()).is_none() {
            return;
        }
        match sim.next_event_time() {
            Some(n) => sim.run_until(n),
            None => return,
        }
    }
}

/// The error of every call on a closed port.
fn closed() -> PyErr {
    err("the port is closed")
}

impl Port {
    /// Queue `frame` if the port's queue has room (`Ok(false)`: it is full). `thread` is the
    /// sending Python thread: bus time waits for it to wait (`crate::turns`).
    fn try_queue(&self, core: &mut Core, frame: Frame, thread: u64) -> PyResult<bool> {
        let port = self.port;
        let queued = core.with_sim(|sim| {
            sim.bus(port.bus())
                .and_then(|b| b.port_status(port).ok())
                .map(|s| s.queued)
        })?;
        let Some(queued) = queued else {
            return Err(closed());
        };
        if queued >= QUEUE_DEPTH {
            return Ok(false);
        }
        let r = core
            .with_sim(|sim| sim.transmit(port, frame))?
            .map_err(|e| err(e.to_string()));
        if r.is_ok() {
            core.acted(thread, false);
        }
        self.shared.delivery.pending.store(false, Ordering::Release);
        r.map(|()| true)
    }

    /// Queue `frame`, waiting up to `timeout` for room in the queue (called without the GIL).
    fn transmit(&self, frame: Frame, timeout: Duration, thread: u64) -> PyResult<()> {
        let wall_deadline = std::time::Instant::now() + std::time::Duration::from(timeout);
        let mut bus_deadline = None;
        loop {
            let mut core = self.shared.lock();
            if self.try_queue(&mut core, frame, thread)? {
                // Receivers are woken by `send` once this thread holds the GIL again: the
                // first look they take at it (`crate::turns`) then finds it on its way to
                // its wait, not still inside this call.
                return Ok(());
            }
            match &mut core.mode {
                Mode::Virtual(sim) => {
                    // A full queue drains as the bus runs: run it to the next event.
                    let deadline = *bus_deadline.get_or_insert_with(|| {
                        sim.now().checked_add(timeout).unwrap_or(Instant::MAX)
                    });
                    match sim.next_event_time() {
                        Some(n) if n <= deadline => sim.run_until(n),
                        _ => return Err(err("the transmit queue stayed full")),
                    }
                }
                Mode::Paced(_) => {
                    drop(core);
                    if std::time::Instant::now() >= wall_deadline {
                        return Err(err("the transmit queue stayed full"));
                    }
                    std::thread::sleep(std::time::Duration::from_micros(100));
                }
            }
        }
    }

    /// Note the threads the frame handed to Python before woke (`crate::turns::note_woken`),
    /// letting go of the core's lock for the look (called without the GIL): the lock again.
    /// A look that Python cannot answer (an interpreter shutting down) notes nobody.
    fn note_woken<'a>(&'a self, core: MutexGuard<'a, Core>, thread: u64) -> MutexGuard<'a, Core> {
        drop(core);
        let _ = Python::attach(|py| crate::turns::note_woken(py, &self.shared, thread));
        self.shared.lock()
    }

    /// The next buffered frame, if any.
    fn take(&self) -> PyResult<Option<Received>> {
        self.rx.try_recv().map_err(|RxClosed| closed())
    }

    /// Receive in either mode; `timeout` in seconds, `None` waits until a frame arrives.
    /// `thread` is the receiving Python thread, which waits from now on.
    fn receive(
        &self,
        timeout: Option<Duration>,
        wait_for_answers: bool,
        thread: u64,
    ) -> PyResult<Option<Received>> {
        let wall_deadline = timeout.map(|t| std::time::Instant::now() + t.into());
        let mut core = self.shared.lock();
        core.waits(thread);
        let mut bus_deadline: Option<Option<Instant>> = None;
        // A frame the pacing thread delivered while a thread that acted had not waited yet.
        let mut held: Option<Received> = None;
        // Whether the threads that the frame handed over before may have woken were looked
        // at (`crate::turns::note_woken`): once a call, and only where it matters, since a
        // look takes the GIL from the thread it looks at.
        let mut looked = !wait_for_answers;
        loop {
            // The turn rule (`crate::turns`): neither run the simulation nor hand over a frame
            // while a thread that acted has not reached its wait. Checked under the same lock
            // that the simulation then runs under, so no act slips in between; a thread that
            // keeps acting delays each step by at most the reaction time.
            if !core.acting_threads().is_empty() {
                let limit = std::time::Instant::now() + core.reaction_time;
                drop(core);
                let all_wait = crate::turns::settle(&self.shared, limit);
                core = self.shared.lock();
                if all_wait {
                    continue;
                }
            }
            // Paced, the next frame may be in the buffer already: look before handing it over.
            if !looked && matches!(core.mode, Mode::Paced(_)) {
                looked = true;
                core = self.note_woken(core, thread);
                continue;
            }
            if let Some(r) = held.take() {
                return Ok(Some(r));
            }
            if let Some(r) = self.take()? {
                return Ok(Some(r));
            }
            let sim = match &mut core.mode {
                Mode::Virtual(sim) => sim,
                Mode::Paced(_) => {
                    // Wait on the wall clock; the pacing thread fills the buffer. Wake at
                    // least every 100 ms to notice a switch back to virtual time.
                    drop(core);
                    let left = match wall_deadline {
                        Some(d) => d.saturating_duration_since(std::time::Instant::now()),
                        None => std::time::Duration::from_millis(100),
                    };
                    if left.is_zero() {
                        return Ok(None);
                    }
                    let waited = self
                        .rx
                        .recv_timeout(left.min(std::time::Duration::from_millis(100)))
                        .map_err(|RxClosed| closed())?;
                    core = self.shared.lock();
                    held = waited;
                    continue;
                }
            };
            let deadline = *bus_deadline.get_or_insert_with(|| {
                timeout.map(|t| sim.now().checked_add(t).unwrap_or(Instant::MAX))
            });
            let next = sim.next_event_time();
            let target = match (next, deadline) {
                (Some(n), Some(d)) if n <= d => Some(n),
                (Some(n), None) => Some(n),
                _ => None,
            };
            // The reaction rule (module documentation).
            let horizon = target.or(deadline);
            let delivery = &self.shared.delivery;
            if let Some(h) = horizon
                && wait_for_answers
                && delivery.pending.load(Ordering::Acquire)
            {
                let at = Instant::from_nanos(delivery.at.load(Ordering::Relaxed));
                if h > at.checked_add(REACTION_GAP).unwrap_or(Instant::MAX) {
                    delivery.pending.store(false, Ordering::Release);
                    let wait = core.reaction_time;
                    core = self
                        .shared
                        .changed
                        .wait_timeout(core, wait)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0;
                    continue;
                }
                // Within the gap the simulation runs on to the next frame without waiting
                // for an answer: not past a thread the last frame woke.
                if !looked {
                    looked = true;
                    core = self.note_woken(core, thread);
                    continue;
                }
            }
            match (target, deadline) {
                (Some(n), _) => run_to(sim, self.port.bus(), n),
                (None, Some(d)) => {
                    sim.run_until(d);
                    return self.take();
                }
                (None, None) => {
                    // Nothing will ever happen unless another thread sends: wait for that.
                    core = self
                        .shared
                        .changed
                        .wait_timeout(core, std::time::Duration::from_millis(100))
                        .unwrap_or_else(PoisonError::into_inner)
                        .0;
                    continue;
                }
            }
            // Let other threads in between events.
            drop(core);
            core = self.shared.lock();
        }
    }
}

#[pymethods]
impl Port {
    /// The bus the port is on.
    #[getter]
    fn bus(&self) -> String {
        self.bus.clone()
    }

    /// Queue a frame for transmission now. `arbitration_id` is 11-bit unless `extended`;
    /// a remote frame sends no data and requests `dlc` bytes.
    ///
    /// When the port's transmit queue is full the call waits for room, at most `timeout`
    /// seconds (default 1 s): of bus time in virtual time (the simulation runs meanwhile),
    /// of wall time when paced.
    ///
    /// From then on, receivers neither run the simulation nor hand over a frame until the
    /// calling thread waits (the turn rule, module documentation), so the answer is there
    /// for the wait that follows the send.
    #[pyo3(signature = (arbitration_id, data, *, extended=false, remote=false, dlc=None, timeout=None))]
    #[allow(clippy::too_many_arguments)]
    fn send(
        &self,
        py: Python<'_>,
        arbitration_id: u32,
        data: &[u8],
        extended: bool,
        remote: bool,
        dlc: Option<u8>,
        timeout: Option<f64>,
    ) -> PyResult<()> {
        let frame = make_frame(arbitration_id, data, extended, remote, dlc)?;
        let timeout = timeout.map(secs).transpose()?.unwrap_or(SEND_TIMEOUT);
        let thread = crate::turns::thread_ident(py)?;
        // With room in the queue and the core free (nearly always) the frame is queued
        // holding the GIL, a lock and a push: the sender keeps the GIL until its wait, where a
        // receiver that waits to look at it (`crate::turns`) gets it, instead of handing it
        // over and back here. A full queue, or a core another thread holds while it runs the
        // simulation, is waited for without the GIL, so other Python threads run meanwhile.
        let queued = match self.shared.try_lock() {
            Some(mut core) => {
                let queued = self.try_queue(&mut core, frame, thread);
                if matches!(queued, Ok(true)) {
                    core.returned(thread);
                }
                queued
            }
            None => Ok(false),
        };
        let r = match queued {
            Ok(true) => Ok(()),
            Ok(false) => {
                let r = py.detach(|| self.transmit(frame, timeout, thread));
                self.shared.lock().returned(thread);
                r
            }
            Err(e) => Err(e),
        };
        self.shared.changed.notify_all();
        r
    }

    /// The next frame as ``(arbitration_id, extended, remote, dlc, data, time)`` (time: bus time
    /// in seconds at its end of frame), or `None` after `timeout` seconds (`None`: wait until
    /// one arrives). In virtual time the wait runs the simulation (module documentation),
    /// once every thread that sent a frame or changed a device waits too (the turn rule).
    ///
    /// `wait_for_answers` applies the reaction rule (let other threads answer a frame before
    /// the simulation runs past it); a thread that both receives and answers passes `False`.
    /// By default (`None`) every thread but the one that attached the port waits for answers:
    /// python-can's Notifier receives, and the thread that opened the bus answers.
    #[pyo3(signature = (timeout=None, *, wait_for_answers=None))]
    fn recv(
        &self,
        py: Python<'_>,
        timeout: Option<f64>,
        wait_for_answers: Option<bool>,
    ) -> PyResult<Option<PyFrame>> {
        let timeout = timeout.map(secs).transpose()?;
        let thread = crate::turns::thread_ident(py)?;
        let wait_for_answers = wait_for_answers.unwrap_or(thread != self.owner);
        py.detach(|| self.receive(timeout, wait_for_answers, thread))
            .map(|r| r.map(to_py))
    }

    /// Start sending `frames` (``(arbitration_id, data, extended, remote, dlc)`` each) in
    /// turn, one every `period` seconds of bus time, the first now; none from `duration`
    /// seconds on (`None`: until stopped). The node sends them on the simulation's clock, in
    /// virtual time as paced. Returns the task's key for [`Port::modify_periodic`] and
    /// [`Port::stop_periodic`].
    #[pyo3(signature = (frames, period, duration=None))]
    fn start_periodic(
        &self,
        py: Python<'_>,
        frames: Vec<PyOutFrame>,
        period: f64,
        duration: Option<f64>,
    ) -> PyResult<u64> {
        let frames = make_frames(frames)?;
        let period = secs(period)?;
        if period == Duration::ZERO {
            return Err(PyValueError::new_err("a period must be more than 0 s"));
        }
        let duration = duration.map(secs).transpose()?;
        let key = self.next_key.fetch_add(1, Ordering::Relaxed);
        let thread = crate::turns::thread_ident(py)?;
        let port = self.port;
        let r = py.detach(|| {
            let mut core = self.shared.lock();
            let started = core.with_sim(|sim| {
                let now = sim.now();
                let node = sim.node_mut::<PyNode>(port)?;
                node.periodic.push(Periodic {
                    key,
                    frames,
                    next_index: 0,
                    period,
                    due: now,
                    end: duration.map(|d| now.checked_add(d).unwrap_or(Instant::MAX)),
                });
                Some(())
            })?;
            if started.is_none() {
                return Err(closed());
            }
            // Frames go out from now on: bus time waits for this thread as after a send.
            core.acted(thread, false);
            Ok(key)
        });
        self.shared.lock().returned(thread);
        self.shared.changed.notify_all();
        r
    }

    /// Replace the frames of periodic task `key` (same count or not); the next one due goes
    /// out at its time, starting again with the first.
    fn modify_periodic(&self, py: Python<'_>, key: u64, frames: Vec<PyOutFrame>) -> PyResult<()> {
        let frames = make_frames(frames)?;
        let port = self.port;
        py.detach(|| {
            let mut core = self.shared.lock();
            let found = core.with_sim(|sim| {
                let node = sim.node_mut::<PyNode>(port)?;
                let task = node.periodic.iter_mut().find(|p| p.key == key)?;
                task.frames = frames;
                task.next_index = 0;
                Some(())
            })?;
            found.ok_or_else(|| err("the periodic task is not running"))
        })
    }

    /// Stop periodic task `key`; stopping one that ended or was stopped does nothing.
    fn stop_periodic(&self, py: Python<'_>, key: u64) -> PyResult<()> {
        let port = self.port;
        py.detach(|| {
            let mut core = self.shared.lock();
            core.with_sim(|sim| {
                if let Some(node) = sim.node_mut::<PyNode>(port) {
                    node.periodic.retain(|p| p.key != key);
                }
            })
        })
    }

    /// Frames lost because the receive buffer was full.
    #[getter]
    fn overruns(&self) -> u64 {
        self.rx.overruns()
    }

    /// Frames this port sent successfully.
    #[getter]
    fn tx_frames(&self) -> PyResult<u64> {
        let port = self.port;
        self.shared.lock().with_sim(|sim| {
            sim.bus(port.bus())
                .and_then(|b| b.port_status(port).ok())
                .map_or(0, |s| s.stats.tx_frames)
        })
    }

    /// Detach the port from its bus; further calls fail, buffered frames are dropped.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        if !self.rx.close() {
            return Ok(());
        }
        // The queue refuses frames once closed, so nothing arrives after this.
        self.rx.clear();
        let shared = Arc::clone(&self.shared);
        let port = self.port;
        py.detach(move || {
            let mut core = shared.lock();
            let r = core.with_sim(|sim| match sim.bus_mut(port.bus()) {
                Some(bus) => bus.detach(port).map(drop).map_err(|e| err(e.to_string())),
                None => Ok(()),
            });
            drop(core);
            shared.changed.notify_all();
            r?
        })
    }
}

impl Drop for Port {
    fn drop(&mut self) {
        if self.rx.close() {
            let port = self.port;
            let mut core = self.shared.lock();
            let _ = core.with_sim(|sim| sim.bus_mut(port.bus()).map(|b| b.detach(port)));
        }
    }
}
