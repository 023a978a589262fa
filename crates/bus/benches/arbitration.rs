//! Hot paths of the bus: a whole saturated bus; arbitration among many frames pending at
//! once; and dispatch of a completed frame to many receivers.

// criterion's macros generate undocumented functions.
#![allow(missing_docs, clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Duration as WallDuration;

use cantwin_bus::bench::{BenchConfig, run};
use cantwin_bus::{Bus, BusConfig, PortConfig, PortId, Recorder};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn saturated(c: &mut Criterion) {
    let mut group = c.benchmark_group("saturated_bus");
    for nodes in [8u16, 32, 127] {
        group.bench_function(format!("{nodes}_nodes_100ms"), |b| {
            b.iter(|| {
                run(BenchConfig {
                    nodes,
                    bit_rate: BitRate::R1M,
                    period: Duration::from_millis(1),
                    duration: Duration::from_millis(100),
                })
            })
        });
    }
    group.finish();
}

/// A node that sends only what the benchmark queues on its port and receives one identifier
/// (or none). Its filter never changes, which it says through its acceptance version, as
/// the controllers of a running network do.
struct Station {
    accept: Option<Id>,
    received: u64,
}

impl Station {
    fn accepting(accept: Option<Id>) -> Self {
        Station {
            accept,
            received: 0,
        }
    }
}

impl Node for Station {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {
        self.received += 1;
    }

    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}

    fn next_deadline(&self) -> Option<Instant> {
        None
    }

    fn accepts(&self, id: Id) -> bool {
        self.accept == Some(id)
    }

    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// Runs the bus until nothing is left to do: every queued frame sent and the bus idle.
fn drain(bus: &mut Bus) {
    while bus.step_next().is_some() {}
}

/// `nodes` stations that accept nothing, each with the 8-byte frame it offers. The last
/// port has the lowest identifier, so the winners come in the reverse of port order and
/// nothing that scans ports from the first would find them early.
fn contenders(nodes: u16) -> (Bus, Vec<(PortId, Frame)>) {
    let mut bus = Bus::new(BusConfig::new("arbitration", BitRate::R1M));
    let offers = (0..nodes)
        .map(|i| {
            let port = bus.attach(Station::accepting(None), PortConfig::mailbox());
            let id = 0x100 + nodes - 1 - i;
            (
                port,
                Frame::std(id, &[i as u8, 0x55, 0xAA, 0, 1, 2, 3, 4]).unwrap(),
            )
        })
        .collect();
    (bus, offers)
}

/// Every offer queued at the same instant arbitrates together: the frames go out back to
/// back, lowest identifier first.
fn check_arbitration(nodes: u16) {
    let (mut bus, offers) = contenders(nodes);
    let tap = bus.add_tap(Recorder::new());
    for &(port, frame) in &offers {
        bus.transmit(port, frame).unwrap();
    }
    drain(&mut bus);
    let records: Vec<_> = bus
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .copied()
        .collect();
    assert_eq!(records.len(), usize::from(nodes));
    for pair in records.windows(2) {
        assert!(pair[0].frame.id().as_raw() < pair[1].frame.id().as_raw());
        assert_eq!(pair[1].start, pair[0].idle_at);
    }
}

/// N frames offered at the same instant, one per node, until the last is sent; per frame.
/// The bus is built once and reused, so each iteration sees it as a running network does:
/// nodes' acceptance verdicts known, queues and heaps allocated. Queuing the offers is timed
/// with the rest, since the priority order they enter is half of arbitration.
fn arbitration(c: &mut Criterion) {
    let mut group = c.benchmark_group("arbitration");
    for nodes in [8u16, 32, 127] {
        check_arbitration(nodes);
        let (mut bus, offers) = contenders(nodes);
        group.throughput(Throughput::Elements(u64::from(nodes)));
        group.bench_function(format!("{nodes}_nodes_one_frame_each"), |b| {
            b.iter(|| {
                for &(port, frame) in black_box(&offers) {
                    bus.transmit(port, frame).unwrap();
                }
                drain(&mut bus);
            })
        });
        // Every iteration sent every offer, however many iterations criterion ran.
        assert_eq!(bus.stats().frames() % u64::from(nodes), 0);
    }
    group.finish();
}

/// One sender and `receivers` stations accepting its identifier, with the frame it sends.
fn audience(receivers: u16) -> (Bus, PortId, Frame, Vec<PortId>) {
    let frame = Frame::std(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    let mut bus = Bus::new(BusConfig::new("dispatch", BitRate::R1M));
    let sender = bus.attach(Station::accepting(None), PortConfig::mailbox());
    let ports = (0..receivers)
        .map(|_| bus.attach(Station::accepting(Some(frame.id())), PortConfig::mailbox()))
        .collect();
    (bus, sender, frame, ports)
}

fn received(bus: &Bus, ports: &[PortId]) -> Vec<u64> {
    ports
        .iter()
        .map(|&p| bus.node::<Station>(p).unwrap().received)
        .collect()
}

/// One frame handed to N receivers that all accept it; per frame, with the N deliveries as
/// the throughput. The bus is reused across iterations, as in [`arbitration`].
fn dispatch(c: &mut Criterion) {
    let mut group = c.benchmark_group("dispatch");
    for receivers in [1u16, 16, 127] {
        let (mut bus, sender, frame, ports) = audience(receivers);
        bus.transmit(sender, frame).unwrap();
        drain(&mut bus);
        assert_eq!(received(&bus, &ports), vec![1; usize::from(receivers)]);
        group.throughput(Throughput::Elements(u64::from(receivers)));
        group.bench_function(format!("{receivers}_receivers"), |b| {
            b.iter(|| {
                bus.transmit(sender, black_box(frame)).unwrap();
                drain(&mut bus);
            })
        });
        // Every frame reached every receiver, however many iterations criterion ran.
        let counts = received(&bus, &ports);
        assert!(counts.iter().all(|&n| n == bus.stats().frames()));
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = saturated
}
criterion_group! {
    name = micro;
    config = Criterion::default()
        .warm_up_time(WallDuration::from_secs(1))
        .measurement_time(WallDuration::from_secs(2));
    targets = arbitration, dispatch
}
criterion_main!(benches, micro);
