//! How the runner reaches the device under test: a [`Transport`] sends frames and hands
//! back what the bus carries, each with the time it was seen, in the transport's clock.
//!
//! * [`VirtualBus`]: the device runs in the same process on a simulated bus and time is
//!   virtual: a wait of ten heartbeat periods costs no wall time.
//! * [`PortTransport`]: any [`BusPort`] (a socketcand connection, the slcan client,
//!   SocketCAN) with the wall clock.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration as WallDuration, Instant as WallInstant, SystemTime};

use cantwin_bus::{BusId, PortConfig, PortId, Simulation};
use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_gateway::BusPort;

/// Why the transport failed. The runner ends the run on the first one: the device can no
/// longer be reached.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TransportError {
    /// The connection or the bus is gone.
    #[error("the bus connection is closed")]
    Closed,
    /// The frame could not be queued.
    #[error("cannot send: {0}")]
    Send(String),
    /// Anything else the transport reports.
    #[error("{0}")]
    Other(String),
}

/// The runner's link to the bus of the device under test.
pub trait Transport {
    /// Queue `frame` for the bus.
    fn send(&mut self, frame: Frame) -> Result<(), TransportError>;

    /// The next frame the bus carried (other than the runner's own), waiting until
    /// `deadline` at the latest; `Ok(None)` when the deadline passes first. The instant is
    /// when the frame was seen, in the clock of [`Transport::now`].
    fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError>;

    /// The transport's clock.
    fn now(&self) -> Instant;

    /// A short description for reports ("virtual bus can0", "socketcand 127.0.0.1:29536").
    fn describe(&self) -> String;
}

impl<T: Transport + ?Sized> Transport for &mut T {
    fn send(&mut self, frame: Frame) -> Result<(), TransportError> {
        (**self).send(frame)
    }
    fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
        (**self).recv(deadline)
    }
    fn now(&self) -> Instant {
        (**self).now()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}

/// Frames a [`VirtualBus`] keeps for the runner before it reads them: a device cannot
/// flood the runner's memory while it is not listening.
const VIRTUAL_RX_CAPACITY: usize = 16_384;

#[derive(Debug, Default)]
struct Inbox {
    frames: VecDeque<(Instant, Frame)>,
    dropped: u64,
}

/// The runner's node on the simulated bus: it acknowledges frames, queues what it
/// receives and sends nothing on its own.
struct ProbeNode {
    inbox: Arc<Mutex<Inbox>>,
}

impl Node for ProbeNode {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        if let Ok(mut inbox) = self.inbox.lock() {
            if inbox.frames.len() >= VIRTUAL_RX_CAPACITY {
                inbox.dropped += 1;
            } else {
                inbox.frames.push_back((now, *frame));
            }
        }
    }
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A simulation in virtual time with the runner attached to one of its buses.
pub struct VirtualBus {
    sim: Simulation,
    port: PortId,
    name: String,
    inbox: Arc<Mutex<Inbox>>,
}

impl VirtualBus {
    /// Attaches the runner to bus `bus` of `sim` (its transmit queue holds a whole SDO
    /// block of 127 segments, CiA 301 §7.2.4.3.13). Returns `None` if `sim` has no such
    /// bus. Attach before the simulation first runs to see the device's boot-up.
    pub fn new(mut sim: Simulation, bus: BusId) -> Option<VirtualBus> {
        let inbox = Arc::new(Mutex::new(Inbox::default()));
        let name = sim.bus(bus)?.name().to_string();
        let port = sim
            .attach(
                bus,
                ProbeNode {
                    inbox: Arc::clone(&inbox),
                },
                PortConfig::DEFAULT.with_queue_depth(128),
            )
            .ok()?;
        Some(VirtualBus {
            sim,
            port,
            name,
            inbox,
        })
    }

    /// The simulation (to read a twin's state after a run).
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// Frames dropped because the runner did not read them in time.
    pub fn dropped(&self) -> u64 {
        self.inbox.lock().map(|i| i.dropped).unwrap_or(0)
    }

    fn pop(&self) -> Option<(Instant, Frame)> {
        self.inbox.lock().ok()?.frames.pop_front()
    }
}

impl Transport for VirtualBus {
    fn send(&mut self, frame: Frame) -> Result<(), TransportError> {
        self.sim
            .transmit(self.port, frame)
            .map_err(|e| TransportError::Send(e.to_string()))
    }

    fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
        loop {
            if let Some(f) = self.pop() {
                return Ok(Some(f));
            }
            match self.sim.next_event_time() {
                Some(t) if t <= deadline => {
                    self.sim.step_next();
                }
                _ => {
                    self.sim.run_until(deadline);
                    return Ok(self.pop());
                }
            }
        }
    }

    fn now(&self) -> Instant {
        self.sim.now()
    }

    fn describe(&self) -> String {
        format!("virtual bus {}", self.name)
    }
}

/// A [`BusPort`] (socketcand, slcan, SocketCAN) driven with the wall clock: the transport's
/// time is the time since it was made.
pub struct PortTransport<P: BusPort> {
    port: P,
    start: WallInstant,
    start_system: SystemTime,
    name: String,
}

impl<P: BusPort> PortTransport<P> {
    /// Wraps `port`; `name` describes it in reports.
    pub fn new(port: P, name: impl Into<String>) -> Self {
        PortTransport {
            port,
            start: WallInstant::now(),
            start_system: SystemTime::now(),
            name: name.into(),
        }
    }

    /// Frames the port dropped because its receive buffer was full.
    pub fn overflows(&self) -> u64 {
        self.port.overflows()
    }
}

impl<P: BusPort> Transport for PortTransport<P> {
    fn send(&mut self, frame: Frame) -> Result<(), TransportError> {
        self.port.send(frame).map_err(|e| match e {
            cantwin_gateway::PortError::Closed => TransportError::Closed,
            other => TransportError::Send(other.to_string()),
        })
    }

    fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
        let now = self.now();
        let wait = WallDuration::from_nanos(deadline.saturating_duration_since(now).as_nanos());
        match self.port.recv_timeout(wait) {
            Ok(Some(rx)) => {
                // The bus's own timestamp, where the transport gives one from this run's
                // clock (in the last second, not ahead); else the time of reception. A
                // remote server's clock may be set differently.
                let received = self.now();
                let at = rx
                    .timestamp
                    .duration_since(self.start_system)
                    .ok()
                    .and_then(|d| u64::try_from(d.as_nanos()).ok())
                    .map(Instant::from_nanos)
                    .filter(|t| {
                        *t <= received
                            && received.saturating_duration_since(*t)
                                < cantwin_can::Duration::from_secs(1)
                    })
                    .unwrap_or(received);
                Ok(Some((at, rx.frame)))
            }
            Ok(None) => Ok(None),
            Err(cantwin_gateway::PortError::Closed) => Err(TransportError::Closed),
            Err(e) => Err(TransportError::Other(e.to_string())),
        }
    }

    fn now(&self) -> Instant {
        Instant::from_nanos(u64::try_from(self.start.elapsed().as_nanos()).unwrap_or(u64::MAX))
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}
