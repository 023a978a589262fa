//! One CAN bus: arbitration, bit timing, acknowledgement, fault confinement, fault injection.
//!
//! # Timing model
//!
//! With `b` the bit time and `n = Frame::bit_length()` (stuffed SOF … EOF plus 3 bits of
//! intermission), a frame that starts (SOF) at `s`:
//!
//! * completes at the end of its EOF, `s + (n - 3)·b`: receivers get `on_frame`, the sender
//!   gets `on_sent` (the [`cantwin_can::Node`] contract), taps see [`BusEvent::Frame`];
//! * leaves the bus idle at the end of intermission, `s + n·b`. Frames queued before or at that
//!   instant arbitrate together then; so do frames queued at the same instant on an idle bus.
//!   A frame queued while the bus is busy waits for it to become idle.
//!
//! An error frame after `e` bits of the frame occupies `e + 17` bits (error flag 6, error
//! delimiter 8, intermission 3). Counters change, controller events are delivered and taps
//! see [`BusEvent::Error`] at `s + e·b`, when the flag starts; the bus is idle at
//! `s + (e + 17)·b` and the transmitter retransmits automatically, arbitrating again. `e` per
//! cause is given by [`ErrorKind`].
//!
//! Within one instant the bus works in this order: the end of the frame in flight (with all
//! its callbacks, receivers in port order, then the sender's echo and `on_sent`), bus-off
//! recoveries, timers (`on_tick`, earliest deadline first, ties by port), and last, if the
//! bus is idle, arbitration among every frame then pending.
//!
//! # Fault confinement (ISO 11898-1 §12.1.4)
//!
//! The transmitter's TEC moves by [`ErrorCounters`] rules (+8 per error, an error-passive
//! transmitter does not count ACK errors, −1 per success); every receiving node's REC +1 per
//! error frame and −1 per good frame. An error-passive node that has just transmitted waits 8
//! more bit times after intermission before it may start again ("suspend transmission",
//! §10.4.6.4), so error-active nodes go first. A bus-off node takes no part in the bus: it
//! neither sends, receives nor acknowledges, and its transmit queue is cleared (one
//! [`ControllerEvent::TxDropped`] per frame). It recovers after 128 × 11 recessive bits, which
//! cantwin counts as 1408 bit times from the moment it went bus-off.
//!
//! A frame is acknowledged when at least one other node is powered, connected, not bus-off
//! and at the bus's bit rate (external ports count: they are nodes). A lone node sees ACK
//! errors and keeps retransmitting, error-passive with TEC = 128.

use cantwin_can::{
    BitRate, ControllerEvent, Duration, ErrorCounters, ErrorState, Frame, Instant, Outbox,
};

use cantwin_twin::{Context, Twin};

use crate::arbiter::Arbiter;
use crate::error::BusError;
use crate::fault::{FaultAction, FaultRule, FrameSelector};
use crate::ids::{BusId, PortId};
use crate::port::{AnyNode, BoxedNode, PortConfig, PortStatus, TwinAccess};
use crate::queue::TxQueue;
use crate::rng::SplitMix64;
use crate::stats::{BusStats, IdIndex, PortStats};
use crate::tap::{AnyTap, BusEvent, BusInfo, ErrorKind, ErrorRecord, FrameRecord};
use crate::time_map::TimeMap;
use crate::timers::Timers;

/// How a bus is set up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusConfig {
    /// A name for captures and traces (`can0`, `field`, …).
    pub name: String,
    /// The bit rate.
    pub bit_rate: BitRate,
    /// The seed of the fault injection generator.
    pub seed: u64,
    /// The sliding window of [`BusStats::window_load_percent`].
    pub load_window: Duration,
}

impl BusConfig {
    /// A bus with this name and bit rate, seed 0, a 1 s load window.
    pub fn new(name: impl Into<String>, bit_rate: BitRate) -> Self {
        BusConfig {
            name: name.into(),
            bit_rate,
            seed: 0,
            load_window: Duration::from_secs(1),
        }
    }

    /// With this fault injection seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// With this sliding load window.
    pub fn with_load_window(mut self, window: Duration) -> Self {
        self.load_window = window;
        self
    }
}

/// A tap on a bus, for typed access back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TapId(usize);

/// Where the frame a port offers to arbitration comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    Queue { seq: u64 },
    Babble,
}

/// The fields every receiver touches on every frame come first, in the order the bus reads
/// them, so that a delivery touches the first two cache lines of the port only.
#[repr(C)]
struct Port {
    node: Option<Box<dyn AnyNode>>,
    counters: ErrorCounters,
    powered: bool,
    connected: bool,
    /// The node's [`Node::acceptance_version`] when the acceptance cache last learnt that
    /// its verdicts may have changed.
    accept_version: Option<u64>,
    /// The epoch in which its acceptance verdicts last may have changed.
    accept_changed: u64,
    deadline: Option<Instant>,
    last_tick: Option<Instant>,
    stats: PortStats,
    // What the port sends.
    source: Option<Source>,
    queue: TxQueue,
    last_bits: Option<(Frame, u32)>,
    config: PortConfig,
    suspend_until: Option<Instant>,
    mismatch: Option<BitRate>,
    babble: Option<(Frame, u32)>,
    recover_at: Option<Instant>,
    /// Disconnected with frames to send: when the next ACK error on its own stub of cable
    /// is detected.
    stub_at: Option<Instant>,
    /// How to reach the node as a twin, when it is one.
    twin: Option<TwinAccess>,
}

impl Port {
    fn attached(&self) -> bool {
        self.node.is_some()
    }

    /// Takes part in the bus as a receiver: receives, acknowledges, counts errors it sees.
    fn on_the_bus(&self) -> bool {
        self.attached() && self.powered && self.connected && !self.bus_off()
    }

    fn bus_off(&self) -> bool {
        self.counters.state() == ErrorState::BusOff
    }

    fn bits_of(&mut self, frame: Frame) -> u32 {
        // Nodes tend to send the same frame again and again; computing the CRC and stuffing
        // once per distinct frame keeps the hot path cheap.
        match self.last_bits {
            Some((f, bits)) if f == frame => bits,
            _ => {
                let bits = frame.bit_length();
                self.last_bits = Some((frame, bits));
                bits
            }
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Ok {
        dropped: bool,
    },
    Error {
        kind: ErrorKind,
        bits_before_flag: u32,
    },
}

#[derive(Debug, Clone, Copy)]
struct InFlight {
    port: usize,
    frame: Frame,
    bits: u32,
    source: Source,
    start: Instant,
    end: Instant,
    idle_at: Instant,
    outcome: Outcome,
}

/// One virtual CAN bus with its nodes.
///
/// A bus runs on its own ([`Bus::run_until`]) or inside a [`crate::Simulation`] with others.
pub struct Bus {
    id: BusId,
    name: String,
    bit_rate: BitRate,
    bit_ns: u64,
    now: Instant,
    ports: Vec<Port>,
    /// Per port: `arbitration_key << 32 | port`, or `u64::MAX` when it offers nothing; and
    /// the least of them.
    arbiter: Arbiter,
    offering: usize,
    listeners: usize,
    /// Bit `i`: port `i` takes part in the bus as a receiver ([`Port::on_the_bus`]).
    receiving: Vec<u64>,
    /// Ports with a bit-rate mismatch.
    mismatched: usize,
    /// Completions so far; stamps the acceptance cache.
    epoch: u64,
    /// The latest epoch in which some port's acceptance verdicts may have changed: cached
    /// verdicts taken after it are all still valid.
    accept_changed: u64,
    /// Numbers the identifiers of the acceptance cache.
    accept_index: IdIndex,
    /// The acceptance cache, per identifier number `k`: `accept_bits[k * accept_words..]`
    /// holds its cached verdicts (bit `i`: port `i`'s answer), valid for ports whose verdicts
    /// cannot have changed since `accept_epochs[k]`. One flat table rather than a vector per
    /// identifier, so a delivery reads the verdicts without chasing another allocation.
    accept_epochs: Vec<u64>,
    accept_bits: Vec<u64>,
    /// 64-bit words per identifier in `accept_bits`: enough for every port.
    accept_words: usize,
    /// Some receiver needs its counters touched on every frame (REC above 0, or a
    /// bit-rate mismatch): deliver the slow way.
    rx_slow: bool,
    deadlines: Timers,
    dirty: Vec<u32>,
    in_flight: Option<InFlight>,
    idle_at: Instant,
    suspended: Vec<u32>,
    recovering: Vec<u32>,
    /// What front ends call ports that are no device of their own (a gateway's client:
    /// `socketcand 127.0.0.1:54012`), by port index; kept after the port is detached, as
    /// port numbers are never reused.
    labels: std::collections::BTreeMap<u32, String>,
    stubs: Vec<u32>,
    rules: Vec<FaultRule>,
    rng: SplitMix64,
    attempts: u64,
    stats: BusStats,
    taps: Vec<Box<dyn AnyTap>>,
    time_map: Option<TimeMap>,
    outbox: Outbox,
}

impl core::fmt::Debug for Bus {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Bus")
            .field("id", &self.id)
            .field("name", &self.name)
            .field("bit_rate", &self.bit_rate)
            .field("now", &self.now)
            .field("ports", &self.ports.len())
            .finish_non_exhaustive()
    }
}

impl Bus {
    /// An empty bus at time zero.
    pub fn new(config: BusConfig) -> Self {
        Bus::with_id(BusId(0), config, Instant::ZERO)
    }

    pub(crate) fn with_id(id: BusId, config: BusConfig, now: Instant) -> Self {
        Bus {
            id,
            name: config.name,
            bit_rate: config.bit_rate,
            bit_ns: config.bit_rate.bit_time().as_nanos(),
            now,
            ports: Vec::new(),
            arbiter: Arbiter::new(),
            offering: 0,
            listeners: 0,
            receiving: Vec::new(),
            mismatched: 0,
            epoch: 1,
            accept_changed: 0,
            accept_index: IdIndex::default(),
            accept_epochs: Vec::new(),
            accept_bits: Vec::new(),
            accept_words: 0,
            rx_slow: false,
            deadlines: Timers::default(),
            dirty: Vec::new(),
            in_flight: None,
            idle_at: now,
            suspended: Vec::new(),
            recovering: Vec::new(),
            labels: std::collections::BTreeMap::new(),
            stubs: Vec::new(),
            rules: Vec::new(),
            rng: SplitMix64::new(config.seed),
            attempts: 0,
            stats: BusStats::new(now, config.load_window),
            taps: Vec::new(),
            time_map: None,
            outbox: Outbox::new(),
        }
    }

    /// The bus's identifier.
    pub fn id(&self) -> BusId {
        self.id
    }

    /// The bus's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The bit rate.
    pub fn bit_rate(&self) -> BitRate {
        self.bit_rate
    }

    /// The current bus time: everything up to and including it has been processed, except
    /// what API calls made at this instant have just started.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// The statistics.
    pub fn stats(&self) -> &BusStats {
        &self.stats
    }

    /// The statistics, to reset them.
    pub fn stats_mut(&mut self) -> &mut BusStats {
        &mut self.stats
    }

    /// How many transmission attempts (starts of frame) the bus has seen.
    pub fn attempts(&self) -> u64 {
        self.attempts
    }

    /// The frame on the bus now and its sender, if any.
    pub fn transmitting(&self) -> Option<(PortId, Frame)> {
        self.in_flight.map(|f| (self.port_id(f.port), f.frame))
    }

    pub(crate) fn set_time_map(&mut self, map: Option<TimeMap>) {
        self.time_map = map;
    }

    fn port_id(&self, index: usize) -> PortId {
        PortId {
            bus: self.id,
            index: index as u32,
        }
    }

    fn index_of(&self, port: PortId) -> Result<usize, BusError> {
        let i = port.index as usize;
        if port.bus == self.id && self.ports.get(i).is_some_and(Port::attached) {
            Ok(i)
        } else {
            Err(BusError::NoSuchPort(port))
        }
    }

    fn bits(&self, n: u32) -> Duration {
        Duration::from_nanos(u64::from(n) * self.bit_ns)
    }

    // ----------------------------------------------------------------------------------
    // Nodes

    /// Attach a node. If the port is configured powered (the default), the node is powered
    /// now: `on_power_up` runs at [`Bus::now`] and what it queues arbitrates at once.
    pub fn attach<N: AnyNode>(&mut self, node: N, config: PortConfig) -> PortId {
        self.attach_boxed(Box::new(node), config)
    }

    /// Attach an already boxed node.
    pub fn attach_boxed(&mut self, node: Box<dyn AnyNode>, config: PortConfig) -> PortId {
        self.attach_with(node, None, config)
    }

    /// Attach a twin: front ends then reach it through [`Bus::twin`] without naming its
    /// type.
    pub fn attach_twin<N: AnyNode + Twin>(&mut self, node: N, config: PortConfig) -> PortId {
        self.attach_node(BoxedNode::twin(node), config)
    }

    /// Attach a boxed node, a twin or not (see [`BoxedNode`]).
    pub fn attach_node(&mut self, node: BoxedNode, config: PortConfig) -> PortId {
        self.attach_with(node.node, node.twin, config)
    }

    fn attach_with(
        &mut self,
        node: Box<dyn AnyNode>,
        twin: Option<TwinAccess>,
        config: PortConfig,
    ) -> PortId {
        let index = self.ports.len();
        let config = PortConfig {
            queue_depth: config.queue_depth.max(1),
            ..config
        };
        self.ports.push(Port {
            node: Some(node),
            twin,
            config,
            queue: TxQueue::new(config.queue_depth, config.order),
            counters: ErrorCounters::new(),
            powered: false,
            connected: true,
            mismatch: None,
            babble: None,
            deadline: None,
            last_tick: None,
            suspend_until: None,
            recover_at: None,
            stub_at: None,
            source: None,
            last_bits: None,
            accept_version: None,
            accept_changed: 0,
            stats: PortStats::default(),
        });
        self.arbiter.set(index, u64::MAX);
        self.mark_called(index);
        if config.powered {
            self.power_up(index);
        }
        self.port_id(index)
    }

    /// Names `port` for front ends (who sent a frame), e.g. a gateway's client by its
    /// protocol and address. A port of another bus is ignored.
    ///
    /// ```
    /// use cantwin_bus::{Bus, BusConfig, PortConfig};
    /// use cantwin_can::{BitRate, ListenOnly};
    ///
    /// let mut bus = Bus::new(BusConfig::new("can0", BitRate::R500K));
    /// let port = bus.attach(ListenOnly, PortConfig::default());
    /// bus.set_port_label(port, "socketcand 127.0.0.1:54012");
    /// // The name outlives the port: its frames may still be shown after it left.
    /// assert!(bus.detach(port).is_ok());
    /// assert_eq!(bus.port_label(port), Some("socketcand 127.0.0.1:54012"));
    /// assert_eq!(bus.port_labels().count(), 1);
    /// ```
    pub fn set_port_label(&mut self, port: PortId, label: impl Into<String>) {
        if port.bus == self.id {
            self.labels.insert(port.index, label.into());
        }
    }

    /// The name given to `port` with [`Bus::set_port_label`], also after it was detached.
    pub fn port_label(&self, port: PortId) -> Option<&str> {
        (port.bus == self.id)
            .then(|| self.labels.get(&port.index).map(String::as_str))
            .flatten()
    }

    /// Every port name given with [`Bus::set_port_label`].
    pub fn port_labels(&self) -> impl Iterator<Item = (PortId, &str)> + '_ {
        self.labels
            .iter()
            .map(|(i, l)| (self.port_id(*i as usize), l.as_str()))
    }

    /// Detach a node and hand it back. A frame it is sending is cut off (receivers see an
    /// error frame). The port number is never reused.
    pub fn detach(&mut self, port: PortId) -> Result<Box<dyn AnyNode>, BusError> {
        let i = self.index_of(port)?;
        self.abort_if_sending(i);
        let p = &mut self.ports[i];
        p.queue.clear();
        p.deadline = None;
        p.babble = None;
        p.twin = None;
        let node = p.node.take().ok_or(BusError::NoSuchPort(port))?;
        self.refresh(i);
        self.count_listeners();
        Ok(node)
    }

    /// The node on `port`, if it is a `T`.
    pub fn node<T: 'static>(&self, port: PortId) -> Option<&T> {
        let i = self.index_of(port).ok()?;
        self.ports[i].node.as_deref()?.as_any().downcast_ref::<T>()
    }

    /// The node on `port`, mutably, if it is a `T`. The bus asks the node for its next
    /// deadline again before it next advances, so changes made here take effect. Frames the
    /// node should send go through [`Bus::transmit`] (or [`Bus::with_node`]).
    pub fn node_mut<T: 'static>(&mut self, port: PortId) -> Option<&mut T> {
        let i = self.index_of(port).ok()?;
        self.dirty.push(i as u32);
        self.mark_called(i);
        self.ports[i]
            .node
            .as_deref_mut()?
            .as_any_mut()
            .downcast_mut::<T>()
    }

    /// Run `f` on the node on `port` (if it is a `T`) at [`Bus::now`] with an outbox whose
    /// frames are queued for transmission afterwards, as if the node had been called by the
    /// bus.
    pub fn with_node<T: 'static, R>(
        &mut self,
        port: PortId,
        f: impl FnOnce(&mut T, Instant, &mut Outbox) -> R,
    ) -> Option<R> {
        let i = self.index_of(port).ok()?;
        let now = self.now;
        let node = self.ports[i]
            .node
            .as_deref_mut()?
            .as_any_mut()
            .downcast_mut::<T>()?;
        let r = f(node, now, &mut self.outbox);
        self.after_call(i);
        Some(r)
    }

    /// The node on `port` as a [`Twin`], if it was attached as one.
    pub fn twin(&self, port: PortId) -> Option<&dyn Twin> {
        let i = self.index_of(port).ok()?;
        let p = &self.ports[i];
        p.twin?.get(p.node.as_deref()?)
    }

    /// The node on `port` as a mutable [`Twin`], if it was attached as one. As with
    /// [`Bus::node_mut`], the bus asks the node for its next deadline again before it next
    /// advances; frames the twin should send go through [`Bus::with_twin`].
    pub fn twin_mut(&mut self, port: PortId) -> Option<&mut dyn Twin> {
        let i = self.index_of(port).ok()?;
        let access = self.ports[i].twin?;
        self.dirty.push(i as u32);
        self.mark_called(i);
        access.get_mut(self.ports[i].node.as_deref_mut()?)
    }

    /// Run `f` on the twin on `port` (if it was attached as one) at [`Bus::now`] with a
    /// [`Context`] whose frames are queued for transmission afterwards, as if the node had
    /// been called by the bus.
    pub fn with_twin<R>(
        &mut self,
        port: PortId,
        f: impl FnOnce(&mut dyn Twin, &mut Context<'_>) -> R,
    ) -> Option<R> {
        let i = self.index_of(port).ok()?;
        let access = self.ports[i].twin?;
        let now = self.now;
        let twin = access.get_mut(self.ports[i].node.as_deref_mut()?)?;
        let r = f(twin, &mut Context::new(now, &mut self.outbox));
        self.after_call(i);
        Some(r)
    }

    /// The ports with a node attached.
    pub fn ports(&self) -> impl Iterator<Item = PortId> + '_ {
        (0..self.ports.len())
            .filter(|&i| self.ports[i].attached())
            .map(|i| self.port_id(i))
    }

    /// Whether `port` still has a frame to send: queued, or on the wires now.
    pub fn transmit_pending(&self, port: PortId) -> Result<bool, BusError> {
        let i = self.index_of(port)?;
        Ok(self.ports[i].queue.len() > 0 || self.in_flight.is_some_and(|f| f.port == i))
    }

    /// A snapshot of a port's state.
    pub fn port_status(&self, port: PortId) -> Result<PortStatus, BusError> {
        let p = &self.ports[self.index_of(port)?];
        Ok(PortStatus {
            counters: p.counters,
            powered: p.powered,
            connected: p.connected,
            bit_rate_mismatch: p.mismatch,
            babbling: p.babble.is_some(),
            queued: p.queue.len(),
            stats: p.stats,
        })
    }

    /// Queue a frame on `port` at [`Bus::now`], as if its node had sent it (external ports,
    /// tests, scripted stimuli). A full queue drops the frame, counts it, reports
    /// [`ControllerEvent::TxDropped`] to the node and taps, and returns
    /// [`BusError::QueueFull`].
    pub fn transmit(&mut self, port: PortId, frame: Frame) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        if !self.ports[i].powered {
            return Err(BusError::PoweredOff(port));
        }
        self.outbox.clear();
        self.outbox.push(frame);
        let dropped = self.absorb(i);
        if dropped > 0 {
            self.tx_dropped(i, dropped);
            self.after_call(i);
            return Err(BusError::QueueFull(port));
        }
        self.refresh(i);
        Ok(())
    }

    // ----------------------------------------------------------------------------------
    // Faults

    /// Add a fault injection rule. Rules are checked in the order added; the first that
    /// selects a frame decides.
    pub fn inject(&mut self, rule: FaultRule) {
        self.rules.push(rule);
    }

    /// The fault injection rules still in force (spent rules are removed).
    pub fn fault_rules(&self) -> &[FaultRule] {
        &self.rules
    }

    /// Remove every fault injection rule.
    pub fn clear_faults(&mut self) {
        self.rules.clear();
    }

    /// Power a node off or on. Off: a frame it is sending is cut off, its queue and timers are
    /// lost, it receives nothing. On: fresh error counters and `on_power_up` at [`Bus::now`].
    pub fn set_powered(&mut self, port: PortId, powered: bool) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        if self.ports[i].powered == powered {
            return Ok(());
        }
        if powered {
            self.power_up(i);
        } else {
            self.abort_if_sending(i);
            let p = &mut self.ports[i];
            p.powered = false;
            p.queue.clear();
            p.deadline = None;
            p.last_tick = None;
            p.suspend_until = None;
            p.recover_at = None;
            self.refresh(i);
            self.count_listeners();
        }
        Ok(())
    }

    /// Cut or restore a node's connection to the bus wires. A disconnected node keeps
    /// running (its timers fire, it queues frames) but receives and acknowledges nothing,
    /// and nobody hears what it sends: alone on its piece of cable, it sends its
    /// highest-priority frame again and again and sees an ACK error each time (one every
    /// `bit_length + 6` bits, the first `bit_length - 11` bits after it starts), until it is
    /// error-passive (TEC 128), where ACK errors no longer count. Its frames wait for the
    /// reconnection. A frame it is sending when cut off ends in an error frame for the
    /// others.
    pub fn set_connected(&mut self, port: PortId, connected: bool) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        if !connected {
            self.abort_if_sending(i);
        }
        self.ports[i].connected = connected;
        if connected {
            self.ports[i].stub_at = None;
        }
        self.refresh(i);
        self.count_listeners();
        Ok(())
    }

    /// Force a node's controller bus-off now (as 32 transmit errors would).
    pub fn force_bus_off(&mut self, port: PortId) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        if !self.ports[i].powered {
            return Err(BusError::PoweredOff(port));
        }
        self.abort_if_sending(i);
        self.update_counters(i, ErrorCounters::force_bus_off);
        Ok(())
    }

    /// Start bus-off recovery on a node whose port does not recover by itself: it is
    /// error-active again after 128 × 11 recessive bits from now. Does nothing if the node is
    /// not bus-off or is already recovering.
    pub fn recover_bus_off(&mut self, port: PortId) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        if self.ports[i].bus_off() && self.ports[i].recover_at.is_none() {
            self.schedule_recovery(i);
        }
        Ok(())
    }

    /// Make a node's controller babble: it offers `frame` to every arbitration, besides its
    /// node's own frames, and sends it again as soon as it is out. `None` stops it. Babbled
    /// frames are real frames on the bus (receivers get them) but are not the node's: no
    /// `on_sent`.
    pub fn set_babble(&mut self, port: PortId, frame: Option<Frame>) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        let p = &mut self.ports[i];
        p.babble = frame.map(|f| (f, p.bits_of(f)));
        self.refresh(i);
        Ok(())
    }

    /// Misconfigure a node's bit rate (`Some(rate)` other than the bus's), or fix it (`None`).
    /// Every frame it sends becomes an error frame after 6 bits ([`ErrorKind::BitRateMismatch`]);
    /// it receives and acknowledges nothing. As a receiver it cannot decode anything: while
    /// error-active it destroys every other frame with an active error flag after 6 bits too
    /// (the transmitter's TEC += 8, other receivers' REC += 1) and, seeing the others' error
    /// flags right after its own, counts REC += 1 + 8 (ISO 11898-1 §12.1.4.2 rules a and b);
    /// after 15 such errors it is error-passive, its flags are recessive and traffic resumes,
    /// while it counts REC += 1 for every frame it sees.
    pub fn set_bit_rate_mismatch(
        &mut self,
        port: PortId,
        rate: Option<BitRate>,
    ) -> Result<(), BusError> {
        let i = self.index_of(port)?;
        self.ports[i].mismatch = rate.filter(|r| *r != self.bit_rate);
        self.mismatched = self.ports.iter().filter(|p| p.mismatch.is_some()).count();
        self.count_listeners();
        self.update_rx_slow();
        Ok(())
    }

    // ----------------------------------------------------------------------------------
    // Taps

    /// Add an observer of every bus event.
    pub fn add_tap<T: AnyTap>(&mut self, tap: T) -> TapId {
        self.taps.push(Box::new(tap));
        TapId(self.taps.len() - 1)
    }

    /// A tap, if it is a `T`.
    pub fn tap<T: 'static>(&self, id: TapId) -> Option<&T> {
        self.taps.get(id.0)?.as_ref().as_any().downcast_ref::<T>()
    }

    /// A tap, mutably, if it is a `T`.
    pub fn tap_mut<T: 'static>(&mut self, id: TapId) -> Option<&mut T> {
        self.taps
            .get_mut(id.0)?
            .as_mut()
            .as_any_mut()
            .downcast_mut::<T>()
    }

    /// Show `event` to the taps. Inlined, so that without taps the event is not even built.
    #[inline]
    fn emit(&mut self, event: BusEvent) {
        if !self.taps.is_empty() {
            self.emit_to_taps(&event);
        }
    }

    #[inline(never)]
    fn emit_to_taps(&mut self, event: &BusEvent) {
        let info = BusInfo {
            id: self.id,
            name: &self.name,
            bit_rate: self.bit_rate,
            time_map: self.time_map,
        };
        for tap in &mut self.taps {
            tap.on_event(&info, event);
        }
    }

    // ----------------------------------------------------------------------------------
    // Running

    /// Advance bus time to `t`, processing every event at or before it.
    pub fn run_until(&mut self, t: Instant) {
        while let Some(next) = self.next_event_time() {
            if next > t {
                break;
            }
            self.step(next);
            self.start_at_idle(t);
        }
        if t > self.now {
            self.now = t;
        }
    }

    /// Right after a frame completed, when the bus's next event is the end of its
    /// intermission (at or before `t`) and nothing else is due until then, do what the step
    /// there would do, which is only to start the next transmission, without going round
    /// the event loop: on a loaded bus that is every other step.
    #[inline]
    fn start_at_idle(&mut self, t: Instant) {
        let idle_at = self.idle_at;
        let quiet = self.in_flight.is_none()
            && self.offering > 0
            && idle_at > self.now
            && idle_at <= t
            && self.dirty.is_empty()
            && self.suspended.is_empty()
            && self.recovering.is_empty()
            && self.stubs.is_empty()
            // A timer due at `idle_at` runs before the arbitration there (a stale entry
            // only makes this give up).
            && self.deadlines.peek().is_none_or(|(d, _)| d > idle_at);
        if quiet {
            self.now = idle_at;
            self.start_transmission(idle_at);
        }
    }

    /// Advance bus time by `d`.
    pub fn run_for(&mut self, d: Duration) {
        self.run_until(self.now + d);
    }

    /// When the bus next has something to do, if ever.
    pub fn next_event_time(&mut self) -> Option<Instant> {
        self.flush_dirty();
        // Drop stale timer entries from the top of the heap.
        while let Some((t, i)) = self.deadlines.peek() {
            let p = &self.ports[i];
            if p.deadline == Some(t) && p.powered && p.attached() {
                break;
            }
            self.deadlines.pop();
        }
        let mut next = self.deadlines.peek().map(|(t, _)| t);
        let mut consider = |t: Instant| {
            next = Some(next.map_or(t, |n| n.min(t)));
        };
        match &self.in_flight {
            Some(f) => consider(f.end),
            None if self.offering > 0 => consider(self.idle_at.max(self.now)),
            None => {}
        }
        for &i in &self.suspended {
            if let Some(t) = self.ports[i as usize].suspend_until {
                consider(t);
            }
        }
        for &i in &self.recovering {
            if let Some(t) = self.ports[i as usize].recover_at {
                consider(t);
            }
        }
        for &i in &self.stubs {
            if let Some(t) = self.ports[i as usize].stub_at {
                consider(t);
            }
        }
        next
    }

    /// Process the next instant with something to do; returns it, or `None` if nothing will
    /// ever happen again.
    pub fn step_next(&mut self) -> Option<Instant> {
        let t = self.next_event_time()?;
        self.step(t);
        Some(t)
    }

    pub(crate) fn step(&mut self, t: Instant) {
        if t > self.now {
            self.now = t;
        }
        let t = self.now;
        if self.in_flight.as_ref().is_some_and(|f| f.end <= t)
            && let Some(f) = self.in_flight.take()
        {
            self.complete(&f);
        }
        if !self.recovering.is_empty() {
            let mut k = 0;
            while k < self.recovering.len() {
                let i = self.recovering[k] as usize;
                if self.ports[i].recover_at.is_none_or(|r| r <= t) {
                    self.recovering.swap_remove(k);
                    if self.ports[i].recover_at.take().is_some() {
                        self.update_counters(i, ErrorCounters::recover);
                    }
                } else {
                    k += 1;
                }
            }
        }
        if !self.stubs.is_empty() {
            let mut k = 0;
            while k < self.stubs.len() {
                let i = self.stubs[k] as usize;
                match self.ports[i].stub_at {
                    Some(s) if s > t => k += 1,
                    due => {
                        self.stubs.swap_remove(k);
                        self.ports[i].stub_at = None;
                        if due.is_some() {
                            self.stub_error(i);
                        }
                    }
                }
            }
        }
        if !self.suspended.is_empty() {
            let mut k = 0;
            while k < self.suspended.len() {
                let i = self.suspended[k] as usize;
                if self.ports[i].suspend_until.is_none_or(|s| s <= t) {
                    self.suspended.swap_remove(k);
                    self.ports[i].suspend_until = None;
                    self.refresh(i);
                } else {
                    k += 1;
                }
            }
        }
        self.flush_dirty();
        while let Some((d, i)) = self.deadlines.peek() {
            if d > t {
                break;
            }
            self.deadlines.pop();
            let p = &mut self.ports[i];
            if p.deadline != Some(d) || !p.powered {
                continue;
            }
            p.deadline = None;
            p.last_tick = Some(t);
            if let Some(node) = p.node.as_mut() {
                node.on_tick(t, &mut self.outbox);
                self.after_call(i);
            }
        }
        if self.in_flight.is_none() && self.idle_at <= t && self.offering > 0 {
            self.start_transmission(t);
        }
    }

    /// Ask the nodes reached from outside since the last event for their deadlines.
    #[inline]
    fn flush_dirty(&mut self) {
        if !self.dirty.is_empty() {
            self.flush_dirty_ports();
        }
    }

    #[inline(never)]
    fn flush_dirty_ports(&mut self) {
        while let Some(i) = self.dirty.pop() {
            self.update_deadline(i as usize);
        }
    }

    // ----------------------------------------------------------------------------------
    // Node calls

    fn power_up(&mut self, i: usize) {
        let now = self.now;
        let p = &mut self.ports[i];
        p.powered = true;
        // A controller starts empty: nothing queued while it was off survives.
        p.queue.clear();
        p.counters = ErrorCounters::new();
        p.last_tick = None;
        if let Some(node) = p.node.as_mut() {
            node.on_power_up(now, &mut self.outbox);
        }
        self.count_listeners();
        self.refresh(i);
        self.after_call(i);
    }

    /// Queue what the node put in the outbox; returns how many frames did not fit.
    fn absorb(&mut self, i: usize) -> u32 {
        let p = &mut self.ports[i];
        let mut dropped = 0;
        for &frame in self.outbox.frames() {
            let bits = match p.last_bits {
                Some((f, bits)) if f == frame => bits,
                _ => {
                    let bits = frame.bit_length();
                    p.last_bits = Some((frame, bits));
                    bits
                }
            };
            if !p.queue.push(frame, bits) {
                dropped += 1;
            }
        }
        self.outbox.clear();
        dropped
    }

    /// After a node was called: queue its frames, report overflow, refresh its arbitration
    /// entry and its deadline.
    #[inline(always)]
    fn after_call(&mut self, i: usize) {
        if !self.outbox.is_empty() {
            self.queue_outbox(i);
        }
        // Both questions in one call (`Node::after_call`), asked once the frames are queued:
        // a node told that one was dropped has been called again.
        let answers = self.ports[i].node.as_ref().map(|n| n.after_call());
        self.note_acceptance(i, answers.and_then(|a| a.acceptance_version));
        self.set_deadline(i, answers.and_then(|a| a.next_deadline));
    }

    /// The queueing part of [`Bus::after_call`], when the node queued something.
    #[inline(never)]
    fn queue_outbox(&mut self, i: usize) {
        let dropped = self.absorb(i);
        if dropped > 0 {
            self.tx_dropped(i, dropped);
            // Frames queued in reaction to TxDropped that do not fit either are counted
            // but not reported again, so a node cannot loop on its own overflow.
            let again = self.absorb(i);
            self.ports[i].stats.tx_dropped += u64::from(again);
        }
        // Only new frames change what the port offers; every other change of state
        // refreshes its entry where it happens.
        self.refresh(i);
    }

    /// Count and report `n` frames dropped from port `i`'s queue.
    fn tx_dropped(&mut self, i: usize, n: u32) {
        let now = self.now;
        self.ports[i].stats.tx_dropped += u64::from(n);
        for _ in 0..n {
            self.emit(BusEvent::Controller {
                port: self.port_id(i),
                event: ControllerEvent::TxDropped,
                at: now,
            });
            if let Some(node) = self.ports[i].node.as_mut() {
                node.on_controller_event(ControllerEvent::TxDropped, now, &mut self.outbox);
            }
        }
    }

    /// After port `i`'s node was called: its acceptance verdicts are asked again unless it
    /// says they cannot have changed (an unchanged [`Node::acceptance_version`]).
    #[inline(always)]
    fn note_acceptance(&mut self, i: usize, version: Option<u64>) {
        let p = &mut self.ports[i];
        if version.is_none() || version != p.accept_version {
            p.accept_version = version;
            self.mark_called(i);
        }
    }

    /// Note that port `i`'s node was called in this epoch.
    fn mark_called(&mut self, i: usize) {
        self.ports[i].accept_changed = self.epoch;
        self.accept_changed = self.epoch;
    }

    fn update_deadline(&mut self, i: usize) {
        let d = self.ports[i].node.as_ref().and_then(|n| n.next_deadline());
        self.set_deadline(i, d);
    }

    /// Port `i`'s deadline from its node's answer `d` (none while unpowered).
    #[inline(always)]
    fn set_deadline(&mut self, i: usize, d: Option<Instant>) {
        let now = self.now;
        let p = &mut self.ports[i];
        let d = if p.powered { d } else { None };
        let d = match d {
            // The usual answer of a node that was called without being due (a receiver):
            // still nothing to do.
            None if p.deadline.is_none() => return,
            None => None,
            // A node that asks again for an instant it was already ticked at is ticked 1 ns
            // later: time must move on even if a node misbehaves.
            Some(d) => Some(match p.last_tick {
                Some(last) if d <= last => last + Duration::from_nanos(1),
                _ => d.max(now),
            }),
        };
        if d != p.deadline {
            p.deadline = d;
            if let Some(d) = d {
                self.deadlines.push(d, i);
            }
        }
    }

    /// Recompute port `i`'s arbitration entry.
    fn refresh(&mut self, i: usize) {
        let now = self.now;
        let p = &mut self.ports[i];
        let mut key = u64::MAX;
        p.source = None;
        let can_send = p.attached()
            && p.powered
            && p.connected
            && !p.bus_off()
            && p.suspend_until.is_none_or(|s| s <= now);
        if can_send {
            let queued = p
                .queue
                .head()
                .map(|e| (e.frame.arbitration_key(), Source::Queue { seq: e.seq }));
            let babble = p.babble.map(|(f, _)| (f.arbitration_key(), Source::Babble));
            let best = match (queued, babble) {
                (Some(q), Some(b)) => Some(if b.0 < q.0 { b } else { q }),
                (q, b) => q.or(b),
            };
            if let Some((k, source)) = best {
                p.source = Some(source);
                key = (u64::from(k) << 32) | i as u64;
            }
        }
        let old = self.arbiter.set(i, key);
        match (old == u64::MAX, key == u64::MAX) {
            (true, false) => self.offering += 1,
            (false, true) => self.offering -= 1,
            _ => {}
        }
        if !self.ports[i].connected {
            self.start_stub(i);
        }
    }

    /// The frame a port would send next, with its length.
    fn next_frame(&self, i: usize) -> Option<(Frame, u32)> {
        let p = &self.ports[i];
        let queued = p.queue.head().map(|e| (e.frame, e.bits));
        match (queued, p.babble) {
            (Some(q), Some(b)) => Some(if b.0.arbitration_key() < q.0.arbitration_key() {
                b
            } else {
                q
            }),
            (q, b) => q.or(b),
        }
    }

    /// A disconnected node with something to send starts its lone attempts, if they can
    /// still change its counters (only while error-active).
    fn start_stub(&mut self, i: usize) {
        let p = &self.ports[i];
        if p.stub_at.is_some()
            || !p.attached()
            || !p.powered
            || p.counters.state() != ErrorState::Active
        {
            return;
        }
        if let Some((_, bits)) = self.next_frame(i) {
            self.ports[i].stub_at = Some(self.now + self.bits(bits - 11));
            self.stubs.push(i as u32);
        }
    }

    /// An ACK error on a disconnected node's stub of cable.
    fn stub_error(&mut self, i: usize) {
        let p = &self.ports[i];
        if p.connected || !p.powered || p.counters.state() != ErrorState::Active {
            return;
        }
        let Some((_, bits)) = self.next_frame(i) else {
            return;
        };
        // Rest of the error frame, then the next attempt up to its ACK slot; planned before
        // the counters move so the refresh they cause does not plan another.
        let next = self.now + self.bits(ErrorKind::OVERHEAD_BITS + bits - 11);
        self.ports[i].stub_at = Some(next);
        self.stubs.push(i as u32);
        self.ports[i].stats.tx_errors += 1;
        self.update_counters(i, |c| c.on_transmit_error(true));
        if self.ports[i].counters.state() != ErrorState::Active {
            // Error-passive: further ACK errors change nothing (§12.1.4.2 rule c, exception 1).
            self.ports[i].stub_at = None;
        }
    }

    /// Recount the nodes that acknowledge, and note which ports receive: called wherever
    /// a port's power, connection, controller state or node changes.
    fn count_listeners(&mut self) {
        self.listeners = self
            .ports
            .iter()
            .filter(|p| p.on_the_bus() && p.mismatch.is_none())
            .count();
        self.receiving.clear();
        self.receiving.resize(self.ports.len().div_ceil(64), 0);
        for (i, p) in self.ports.iter().enumerate() {
            if p.on_the_bus() {
                self.receiving[i / 64] |= 1 << (i % 64);
            }
        }
    }

    fn update_counters(
        &mut self,
        i: usize,
        f: impl FnOnce(&mut ErrorCounters) -> Option<ErrorState>,
    ) {
        let before = self.ports[i].counters.state();
        let Some(after) = f(&mut self.ports[i].counters) else {
            return;
        };
        let event = match after {
            ErrorState::Passive => ControllerEvent::ErrorPassive,
            ErrorState::BusOff => ControllerEvent::BusOff,
            ErrorState::Active if before == ErrorState::BusOff => ControllerEvent::BusOffRecovered,
            ErrorState::Active => ControllerEvent::ErrorActive,
        };
        let now = self.now;
        self.emit(BusEvent::Controller {
            port: self.port_id(i),
            event,
            at: now,
        });
        if let Some(node) = self.ports[i].node.as_mut() {
            node.on_controller_event(event, now, &mut self.outbox);
        }
        if after == ErrorState::BusOff {
            // A bus-off controller sends nothing: its pending frames are lost.
            let n = self.ports[i].queue.clear() as u32;
            if n > 0 {
                self.tx_dropped(i, n);
            }
            if self.ports[i].config.auto_bus_off_recovery {
                self.schedule_recovery(i);
            }
        } else if before == ErrorState::BusOff {
            self.ports[i].recover_at = None;
        }
        self.count_listeners();
        self.refresh(i);
        self.after_call(i);
    }

    fn schedule_recovery(&mut self, i: usize) {
        let bits = ErrorCounters::RECOVERY_SEQUENCES * ErrorCounters::RECOVERY_SEQUENCE_BITS;
        self.ports[i].recover_at = Some(self.now + self.bits(bits));
        self.recovering.push(i as u32);
    }

    // ----------------------------------------------------------------------------------
    // The wire

    fn start_transmission(&mut self, t: Instant) {
        let key = self.arbiter.winner();
        if key == u64::MAX {
            return;
        }
        let i = (key & 0xFFFF_FFFF) as usize;
        let p = &self.ports[i];
        let (frame, bits, source) = match p.source {
            Some(Source::Babble) => match p.babble {
                Some((f, b)) => (f, b, Source::Babble),
                None => return,
            },
            Some(Source::Queue { seq }) => match p.queue.head() {
                Some(e) if e.seq == seq => (e.frame, e.bits, Source::Queue { seq }),
                _ => return,
            },
            None => return,
        };
        let sender_listens = usize::from(p.on_the_bus() && p.mismatch.is_none());
        let mismatch = p.mismatch.is_some();
        let attempt = self.attempts;
        self.attempts += 1;
        let action = if self.rules.is_empty() {
            None
        } else {
            self.fault_for(attempt, self.port_id(i), &frame)
        };
        // An error-active node at the wrong bit rate flags every frame it hears.
        let disturbed = self.mismatched > 0
            && self.ports.iter().enumerate().any(|(j, q)| {
                j != i
                    && q.mismatch.is_some()
                    && q.on_the_bus()
                    && q.counters.state() == ErrorState::Active
            });
        let outcome = if mismatch || disturbed {
            Outcome::Error {
                kind: ErrorKind::BitRateMismatch,
                bits_before_flag: 6,
            }
        } else if action == Some(FaultAction::Corrupt) {
            Outcome::Error {
                kind: ErrorKind::Corrupted,
                bits_before_flag: bits - 13,
            }
        } else if self.listeners <= sender_listens {
            Outcome::Error {
                kind: ErrorKind::Ack,
                bits_before_flag: bits - 11,
            }
        } else {
            Outcome::Ok {
                dropped: action == Some(FaultAction::Drop),
            }
        };
        let (end, idle_at) = match outcome {
            Outcome::Ok { .. } => (
                t + self.bits(bits - cantwin_can::bits::INTERMISSION_BITS),
                t + self.bits(bits),
            ),
            Outcome::Error {
                bits_before_flag, ..
            } => (
                t + self.bits(bits_before_flag),
                t + self.bits(bits_before_flag + ErrorKind::OVERHEAD_BITS),
            ),
        };
        self.in_flight = Some(InFlight {
            port: i,
            frame,
            bits,
            source,
            start: t,
            end,
            idle_at,
            outcome,
        });
        self.idle_at = idle_at;
    }

    fn fault_for(&mut self, attempt: u64, sender: PortId, frame: &Frame) -> Option<FaultAction> {
        let mut hit = None;
        for rule in &mut self.rules {
            if rule.sender.is_some_and(|s| s != sender) || rule.remaining == Some(0) {
                continue;
            }
            let selected = match rule.selector {
                FrameSelector::Attempt(n) => n == attempt,
                FrameSelector::Fraction(p) => self.rng.next_f64() < p,
                FrameSelector::Id(id) => frame.id() == id,
                FrameSelector::All => true,
            };
            if selected {
                if let Some(r) = rule.remaining.as_mut() {
                    *r -= 1;
                }
                hit = Some(rule.action);
                break;
            }
        }
        // Spent rules go: those out of hits, and those for an attempt now past.
        self.rules.retain(|r| {
            r.remaining != Some(0)
                && !matches!(r.selector, FrameSelector::Attempt(n) if n <= attempt)
        });
        hit
    }

    /// Cut off the frame port `i` is sending now: receivers see an error at the current bit.
    fn abort_if_sending(&mut self, i: usize) {
        let Some(mut f) = self.in_flight else {
            return;
        };
        if f.port != i {
            return;
        }
        let elapsed = (self.now - f.start).as_nanos() / self.bit_ns;
        let e = u32::try_from(elapsed).unwrap_or(u32::MAX).min(f.bits);
        f.outcome = Outcome::Error {
            kind: ErrorKind::Aborted,
            bits_before_flag: e,
        };
        f.end = self.now;
        f.idle_at = f.start + self.bits(e + ErrorKind::OVERHEAD_BITS);
        self.idle_at = f.idle_at;
        self.in_flight = Some(f);
    }

    fn complete(&mut self, f: &InFlight) {
        self.epoch += 1;
        let now = self.now;
        let sender_id = self.port_id(f.port);
        match f.outcome {
            Outcome::Ok { dropped } => {
                let babble = f.source == Source::Babble;
                self.stats
                    .frame(f.frame.id(), f.bits, f.start, f.idle_at, dropped);
                if !self.taps.is_empty() {
                    self.emit(BusEvent::Frame(FrameRecord {
                        frame: f.frame,
                        sender: sender_id,
                        start: f.start,
                        end: f.end,
                        idle_at: f.idle_at,
                        bits: f.bits,
                        dropped,
                        babble,
                    }));
                }
                if let Source::Queue { seq } = f.source {
                    self.ports[f.port].queue.remove(seq);
                    self.ports[f.port].stats.tx_frames += 1;
                }
                self.refresh(f.port);
                // A success moves only a TEC above 0 (§12.1.4.2 rule g): at 0 nothing changes.
                if self.ports[f.port].counters.tec() > 0 {
                    self.update_counters(f.port, ErrorCounters::on_transmit_success);
                }
                self.suspend_if_passive(f.port, f.idle_at);
                if self.rx_slow {
                    self.receive_slow(f, dropped);
                    self.update_rx_slow();
                } else if !dropped {
                    self.receive_fast(f);
                }
                if babble {
                    return;
                }
                let p = &mut self.ports[f.port];
                if !p.powered {
                    return;
                }
                if let Some(node) = p.node.as_mut() {
                    if p.config.echo && !dropped {
                        p.stats.rx_frames += 1;
                        node.on_frame(&f.frame, now, &mut self.outbox);
                    }
                    node.on_sent(&f.frame, now, &mut self.outbox);
                    self.after_call(f.port);
                }
            }
            Outcome::Error {
                kind,
                bits_before_flag,
            } => {
                let bits = bits_before_flag + ErrorKind::OVERHEAD_BITS;
                self.stats.error(f.frame.id(), bits, f.start, f.idle_at);
                self.emit(BusEvent::Error(ErrorRecord {
                    frame: f.frame,
                    sender: sender_id,
                    start: f.start,
                    detected: f.end,
                    idle_at: f.idle_at,
                    bits,
                    kind,
                }));
                if kind != ErrorKind::Aborted {
                    self.ports[f.port].stats.tx_errors += 1;
                    self.update_counters(f.port, |c| c.on_transmit_error(kind == ErrorKind::Ack));
                    self.suspend_if_passive(f.port, f.idle_at);
                }
                for i in 0..self.ports.len() {
                    if i != f.port && self.ports[i].on_the_bus() {
                        let flagged = kind == ErrorKind::BitRateMismatch
                            && self.ports[i].mismatch.is_some()
                            && self.ports[i].counters.state() == ErrorState::Active;
                        self.update_counters(i, ErrorCounters::on_receive_error);
                        if flagged {
                            // Rule b: the dominant error flags of the others follow its own.
                            self.update_counters(i, ErrorCounters::on_receive_error_severe);
                        }
                    }
                }
                self.update_rx_slow();
            }
        }
    }

    fn update_rx_slow(&mut self) {
        self.rx_slow = self
            .ports
            .iter()
            .any(|p| p.counters.rec() > 0 || p.mismatch.is_some());
    }

    /// Hand a good frame to every receiver whose filter accepts it, when no receiver's
    /// counters need touching. A node's `accepts` can only change when the node was called
    /// (it takes `&self`), so verdicts are cached per identifier and asked again only of the
    /// nodes called since whose acceptance version changed (or that keep none).
    fn receive_fast(&mut self, f: &InFlight) {
        let id = f.frame.id();
        let n = self.ports.len();
        let words = n.div_ceil(64);
        if words != self.accept_words {
            self.restride_acceptance(words);
        }
        let k = self.accept_index.number(id);
        if k == self.accept_epochs.len() {
            self.accept_epochs.push(0);
            self.accept_bits.resize((k + 1) * words, 0);
        }
        let since = self.accept_epochs[k];
        // Verdicts taken after the last possible change are all valid: nothing to ask (the
        // usual case on a bus whose nodes keep their acceptance versions).
        let valid = since > self.accept_changed;
        for w in 0..words {
            if valid {
                break;
            }
            // The ports whose verdicts may have changed since they were taken (in the same
            // epoch included); every port when they never were (`since` 0).
            let mut stale = self.ports[w * 64..n.min(w * 64 + 64)]
                .iter()
                .enumerate()
                .filter(|(_, p)| p.accept_changed >= since)
                .fold(0u64, |m, (j, _)| m | 1 << j);
            while stale != 0 {
                let j = stale.trailing_zeros() as usize;
                stale &= stale - 1;
                let i = w * 64 + j;
                let yes = self.ports[i]
                    .node
                    .as_ref()
                    .is_some_and(|node| node.accepts(id));
                let word = &mut self.accept_bits[k * words + w];
                if yes {
                    *word |= 1 << j;
                } else {
                    *word &= !(1 << j);
                }
            }
        }
        self.accept_epochs[k] = self.epoch;
        let now = self.now;
        // Nothing below changes the cached verdicts, nor which ports receive (a node's
        // callbacks change no port's power, connection or counters): a word read at its turn
        // is the word as taken above.
        for w in 0..words {
            let sender = if f.port / 64 == w {
                1 << (f.port % 64)
            } else {
                0
            };
            let receiving = self.receiving.get(w).copied().unwrap_or(0);
            let mut bits = self.accept_bits[k * words + w] & receiving & !sender;
            while bits != 0 {
                let i = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let p = &mut self.ports[i];
                if let Some(node) = p.node.as_mut() {
                    p.stats.rx_frames += 1;
                    node.on_frame(&f.frame, now, &mut self.outbox);
                    self.after_call(i);
                }
            }
        }
    }

    /// Give every identifier of the acceptance cache `words` words of verdicts, keeping the
    /// ones it has (more ports attached: the new ports' verdicts start unknown, and they
    /// are asked since they were called when attached).
    #[cold]
    fn restride_acceptance(&mut self, words: usize) {
        let old = self.accept_words;
        let mut bits = vec![0u64; self.accept_epochs.len() * words];
        for (k, row) in bits.chunks_exact_mut(words).enumerate() {
            let keep = old.min(words);
            row[..keep].copy_from_slice(&self.accept_bits[k * old..k * old + keep]);
        }
        self.accept_bits = bits;
        self.accept_words = words;
    }

    /// Hand a good frame to its receivers, moving every receiver's REC.
    fn receive_slow(&mut self, f: &InFlight, dropped: bool) {
        let now = self.now;
        let id = f.frame.id();
        for i in 0..self.ports.len() {
            if i == f.port {
                continue;
            }
            let p = &mut self.ports[i];
            if !p.on_the_bus() {
                continue;
            }
            if p.mismatch.is_some() {
                self.update_counters(i, ErrorCounters::on_receive_error);
                continue;
            }
            if p.counters.rec() > 0 {
                self.update_counters(i, ErrorCounters::on_receive_success);
            }
            let p = &mut self.ports[i];
            if dropped {
                continue;
            }
            if let Some(node) = p.node.as_mut()
                && node.accepts(id)
            {
                p.stats.rx_frames += 1;
                node.on_frame(&f.frame, now, &mut self.outbox);
                self.after_call(i);
            }
        }
    }

    /// §10.4.6.4: an error-passive node that was the transmitter waits 8 bits after
    /// intermission before it starts again.
    fn suspend_if_passive(&mut self, i: usize, idle_at: Instant) {
        if self.ports[i].counters.state() == ErrorState::Passive {
            let until = idle_at + self.bits(8);
            let p = &mut self.ports[i];
            p.suspend_until = Some(until);
            self.suspended.push(i as u32);
            self.refresh(i);
        }
    }
}
