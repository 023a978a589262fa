//! The `cantwin bench bus` scenario: a saturated 1 Mbit/s bus of 127 nodes.
//!
//! Every node offers an 8-byte frame with its own identifier every millisecond into a single
//! transmit mailbox and accepts the identifiers of the next four nodes. An offer made while
//! the mailbox still holds the previous frame is dropped and counted. The bus carries about
//! 8 000 such frames per second against 127 000 offers, so it is saturated: the lowest
//! identifiers win every arbitration.
//!
//! The node reads its mailbox status the way firmware reads a controller's transmit-request
//! flag, and while the mailbox is full it does not wake up for each offer: when the mailbox
//! empties it counts the offers that fell into the full mailbox arithmetically. Every counter
//! stays exact while the bus only works for frames that can actually be sent.

use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};

use crate::bus::BusConfig;
use crate::port::PortConfig;
use crate::sim::Simulation;

pub mod limit;

/// The scenario's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BenchConfig {
    /// Nodes on the bus.
    pub nodes: u16,
    /// The bus bit rate.
    pub bit_rate: BitRate,
    /// Each node's offer period.
    pub period: Duration,
    /// Bus time to simulate.
    pub duration: Duration,
}

impl BenchConfig {
    /// 127 nodes, 1 Mbit/s, an offer per node every 1 ms, for `duration`.
    pub const fn saturated(duration: Duration) -> Self {
        BenchConfig {
            nodes: 127,
            bit_rate: BitRate::R1M,
            period: Duration::from_millis(1),
            duration,
        }
    }

    /// `nodes` nodes at 1 Mbit/s offering `load_percent` of the bus's capacity: each node's
    /// period is the time all `nodes` frames take back to back, stretched by
    /// `100 / load_percent`. Every node offers at the same instants (the multiples of the
    /// period), as devices answering a SYNC do. A load of 0 or less offers once, at 0.
    pub fn at_load(nodes: u16, load_percent: f64, duration: Duration) -> Self {
        let bit_rate = BitRate::R1M;
        let bits: u64 = (0..nodes)
            .map(|i| {
                u64::from(
                    MailboxNode::new(i, nodes, Duration::ZERO)
                        .frame
                        .bit_length(),
                )
            })
            .sum();
        let busy = bits * bit_rate.bit_time().as_nanos();
        let period = if load_percent > 0.0 {
            Duration::from_nanos((busy as f64 * 100.0 / load_percent).round() as u64)
        } else {
            duration + Duration::from_nanos(1)
        };
        BenchConfig {
            nodes,
            bit_rate,
            period,
            duration,
        }
    }
}

/// What a benchmark run measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchReport {
    /// The scenario.
    pub config: BenchConfig,
    /// Bus time simulated.
    pub bus_time: Duration,
    /// Wall time it took.
    pub wall_time: std::time::Duration,
    /// Frames that completed on the bus.
    pub delivered: u64,
    /// Frames handed to nodes whose filter accepted them.
    pub received: u64,
    /// Offers made by all nodes.
    pub offers: u64,
    /// Offers dropped because the mailbox was full.
    pub dropped_offers: u64,
    /// Bus load over the run, percent.
    pub bus_load_percent: f64,
}

impl BenchReport {
    /// Bus time over wall time.
    pub fn real_time_factor(&self) -> f64 {
        self.bus_time.as_secs_f64() / self.wall_time.as_secs_f64().max(1e-9)
    }

    /// Delivered frames per second of wall time.
    pub fn frames_per_wall_second(&self) -> f64 {
        self.delivered as f64 / self.wall_time.as_secs_f64().max(1e-9)
    }

    /// Wall nanoseconds per delivered frame.
    pub fn ns_per_frame(&self) -> f64 {
        self.wall_time.as_nanos() as f64 / self.delivered.max(1) as f64
    }
}

/// A node of the saturated-bus scenario.
#[derive(Debug, Clone)]
pub struct MailboxNode {
    frame: Frame,
    accept: [Id; 4],
    period: Duration,
    next_offer: Instant,
    mailbox_full: bool,
    /// Offers made.
    pub offers: u64,
    /// Offers dropped on a full mailbox.
    pub dropped: u64,
    /// Frames sent.
    pub sent: u64,
    /// Frames received.
    pub received: u64,
}

impl MailboxNode {
    /// Node `index` of `nodes`: identifier `0x100 + index`, accepting the next four nodes'.
    pub fn new(index: u16, nodes: u16, period: Duration) -> Self {
        let id = |i: u16| {
            Id::standard(0x100 + i % nodes.max(1))
                .unwrap_or(Id::Standard(cantwin_can::StandardId::MAX))
        };
        let data = [index as u8, (index >> 8) as u8, 0x55, 0xAA, 0, 1, 2, 3];
        MailboxNode {
            frame: Frame::data_array(id(index), data),
            accept: [id(index + 1), id(index + 2), id(index + 3), id(index + 4)],
            period,
            next_offer: Instant::ZERO,
            mailbox_full: false,
            offers: 0,
            dropped: 0,
            sent: 0,
            received: 0,
        }
    }

    /// Count the offers due at or before `end` that the run did not reach.
    fn finish(&mut self, end: Instant) {
        if self.mailbox_full && self.next_offer <= end && !self.period.is_zero() {
            let n = (end - self.next_offer).as_nanos() / self.period.as_nanos() + 1;
            self.offers += n;
            self.dropped += n;
            self.next_offer += self.period * n;
        }
    }
}

impl Node for MailboxNode {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {
        self.received += 1;
    }

    fn on_tick(&mut self, _now: Instant, out: &mut Outbox) {
        self.offers += 1;
        if self.mailbox_full {
            self.dropped += 1;
        } else {
            out.push(self.frame);
            self.mailbox_full = true;
        }
        self.next_offer += self.period;
    }

    fn next_deadline(&self) -> Option<Instant> {
        // While the mailbox is full every offer is dropped: nothing to do until it empties.
        (!self.mailbox_full).then_some(self.next_offer)
    }

    fn on_sent(&mut self, _frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.sent += 1;
        self.mailbox_full = false;
        // Offers strictly before `now` met the full mailbox. The bus completes frames before
        // it runs timers at the same instant, so an offer at `now` finds the mailbox empty.
        if self.next_offer < now && !self.period.is_zero() {
            let n = (now - self.next_offer)
                .as_nanos()
                .div_ceil(self.period.as_nanos());
            self.offers += n;
            self.dropped += n;
            self.next_offer += self.period * n;
        }
    }

    fn accepts(&self, id: Id) -> bool {
        self.accept.contains(&id)
    }

    fn acceptance_version(&self) -> Option<u64> {
        // The identifiers are fixed at construction.
        Some(0)
    }
}

/// Run the scenario described by `config`.
pub fn run(config: BenchConfig) -> BenchReport {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("bench", config.bit_rate));
    let mut ports = Vec::with_capacity(usize::from(config.nodes));
    for i in 0..config.nodes {
        let node = MailboxNode::new(i, config.nodes, config.period);
        if let Ok(p) = sim.attach(bus, node, PortConfig::mailbox()) {
            ports.push(p);
        }
    }
    let end = Instant::ZERO + config.duration;
    let started = std::time::Instant::now();
    sim.run_until(end);
    let wall_time = started.elapsed();
    let mut report = BenchReport {
        config,
        bus_time: config.duration,
        wall_time,
        delivered: 0,
        received: 0,
        offers: 0,
        dropped_offers: 0,
        bus_load_percent: 0.0,
    };
    for &p in &ports {
        if let Some(n) = sim.node_mut::<MailboxNode>(p) {
            n.finish(end);
            report.received += n.received;
            report.offers += n.offers;
            report.dropped_offers += n.dropped;
        }
    }
    if let Some(b) = sim.bus(bus) {
        report.delivered = b.stats().frames();
        report.bus_load_percent = b.stats().load_percent(end);
    }
    report
}

/// The `cantwin bench bus` scenario for `duration` of bus time (60 s in the benchmark).
pub fn saturated_bus(duration: Duration) -> BenchReport {
    run(BenchConfig::saturated(duration))
}
