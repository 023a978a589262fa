//! The fixed limit of the `cantwin bench bus` scenario: the least work a delivered frame
//! needs with the same nodes, offers and filters.
//!
//! Nothing here is a bus: no ports, no queues, no counters, no node calls, no fault
//! confinement, no taps. The frames are built once with their stuffed lengths; the pending
//! identifiers are a sorted array whose last element is the winner; the receivers of each
//! identifier are a bitset computed once from the nodes' filters. What is left per frame is
//! what any simulation of this bus must do: take the winner, move time by its length, hand the
//! frame to its receivers (one add each), and put the sender back among the nodes waiting for
//! their next offer. The schedule is the bus's own ([`crate::bus`]'s timing model, and
//! [`MailboxNode`]'s offers), so a run of the limit delivers exactly the frames a run of the
//! bus delivers, to the same receivers: its wall time per delivered frame is the floor the
//! bus is compared with.

use std::collections::VecDeque;

use cantwin_can::{Frame, bits::INTERMISSION_BITS};

use super::{BenchConfig, MailboxNode};

/// What a run of the limit measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitReport {
    /// The scenario.
    pub config: BenchConfig,
    /// Wall time of the run (building the tables not included).
    pub wall_time: std::time::Duration,
    /// Frames that completed by the end of the run.
    pub delivered: u64,
    /// Frames handed to accepting nodes.
    pub received: u64,
}

impl LimitReport {
    /// Wall nanoseconds per delivered frame.
    pub fn ns_per_frame(&self) -> f64 {
        self.wall_time.as_nanos() as f64 / self.delivered.max(1) as f64
    }
}

/// The tables of the scenario, built before the clock starts.
struct Tables {
    /// Per node (index = identifier order): its frame's bit length, intermission included.
    bits: Vec<u32>,
    /// Per node: the nodes accepting its identifier, `words` 64-bit words each.
    receivers: Vec<u64>,
    words: usize,
}

impl Tables {
    fn new(config: &BenchConfig) -> Self {
        let n = usize::from(config.nodes);
        let words = n.div_ceil(64).max(1);
        let nodes: Vec<MailboxNode> = (0..config.nodes)
            .map(|i| MailboxNode::new(i, config.nodes, config.period))
            .collect();
        let frames: Vec<Frame> = nodes.iter().map(|m| m.frame).collect();
        let mut receivers = vec![0u64; n * words];
        for (s, frame) in frames.iter().enumerate() {
            for (r, node) in nodes.iter().enumerate() {
                if r != s && node.accept.contains(&frame.id()) {
                    receivers[s * words + r / 64] |= 1 << (r % 64);
                }
            }
        }
        Tables {
            bits: frames.iter().map(Frame::bit_length).collect(),
            receivers,
            words,
        }
    }
}

/// Run the limit of the scenario `config` describes.
///
/// Node `i` has identifier `0x100 + i`, so identifier order is node order and the pending
/// array holds node indices, highest first. Every node offers at the multiples of the
/// period; a node whose mailbox empties at `e` offers next at the first multiple at or after
/// `e` (the ones before met the full mailbox). All periods being equal, the nodes waiting for
/// their next offer are released in the order their mailboxes emptied: a FIFO.
pub fn run(config: BenchConfig) -> LimitReport {
    let tables = Tables::new(&config);
    let n = usize::from(config.nodes);
    let bit_ns = config.bit_rate.bit_time().as_nanos();
    let period = config.period.as_nanos();
    let end = config.duration.as_nanos();
    let mut received = vec![0u64; n];
    // Everyone offers at 0; a lone node's frames are never acknowledged, so none completes.
    let mut pending: Vec<u16> = if n >= 2 {
        (0..config.nodes).rev().collect()
    } else {
        Vec::new()
    };
    let mut waiting: VecDeque<(u64, u16)> = VecDeque::with_capacity(n);
    let mut delivered = 0u64;
    let mut t = 0u64;
    let started = std::time::Instant::now();
    loop {
        while let Some(&(at, node)) = waiting.front() {
            if at > t {
                break;
            }
            waiting.pop_front();
            let pos = pending.partition_point(|&p| p > node);
            pending.insert(pos, node);
        }
        let Some(winner) = pending.pop() else {
            match waiting.front() {
                Some(&(at, _)) if at <= end => {
                    t = at;
                    continue;
                }
                _ => break,
            }
        };
        let w = usize::from(winner);
        let bits = u64::from(tables.bits[w]);
        let eof = t + (bits - u64::from(INTERMISSION_BITS)) * bit_ns;
        if eof > end {
            break;
        }
        delivered += 1;
        for k in 0..tables.words {
            let mut set = tables.receivers[w * tables.words + k];
            while set != 0 {
                received[k * 64 + set.trailing_zeros() as usize] += 1;
                set &= set - 1;
            }
        }
        let next = if period == 0 {
            eof
        } else {
            eof.div_ceil(period) * period
        };
        waiting.push_back((next, winner));
        t += bits * bit_ns;
    }
    let wall_time = started.elapsed();
    LimitReport {
        config,
        wall_time,
        delivered,
        received: std::hint::black_box(&received).iter().sum(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::{BitRate, Duration};

    /// The limit follows the bus's schedule exactly: the same frames delivered, to the same
    /// number of receivers, saturated or not, with any node count.
    #[test]
    fn the_limit_delivers_what_the_bus_delivers() {
        for nodes in [1u16, 2, 8, 32, 127] {
            for load in [25.0, 50.0, 100.0] {
                let config = BenchConfig::at_load(nodes, load, Duration::from_millis(200));
                let bus = super::super::run(config);
                let limit = run(config);
                assert_eq!(
                    (limit.delivered, limit.received),
                    (bus.delivered, bus.received),
                    "{nodes} nodes at {load} %"
                );
                assert_eq!(bus.delivered > 0, nodes > 1);
            }
        }
        let saturated = BenchConfig {
            bit_rate: BitRate::R125K,
            ..BenchConfig::saturated(Duration::from_millis(300))
        };
        let (bus, limit) = (super::super::run(saturated), run(saturated));
        assert_eq!(
            (limit.delivered, limit.received),
            (bus.delivered, bus.received)
        );
    }
}
