//! Several buses in one simulation, statistics, and the benchmark scenario's bookkeeping.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::bench::{BenchConfig, run};
use cantwin_bus::{BusConfig, BusEvent, FnTap, PortConfig, Simulation};
use cantwin_can::{BitRate, Duration, Frame, Instant, Node, Outbox};
use common::{Probe, bits, std_frame, us};

struct Periodic {
    frame: Frame,
    period: Duration,
    next: Instant,
}

impl Node for Periodic {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, out: &mut Outbox) {
        out.push(self.frame);
        self.next += self.period;
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(self.next)
    }
}

#[test]
fn two_buses_run_in_one_time_line_at_their_own_bit_rates() {
    let mut sim = Simulation::new();
    let fast = sim.add_bus(BusConfig::new("fast", BitRate::R1M));
    let slow = sim.add_bus(BusConfig::new("slow", BitRate::R125K));
    let f = std_frame(0x123, &[1, 2, 3]);
    for bus in [fast, slow] {
        sim.attach(bus, Probe::sending(&[f]), PortConfig::default())
            .unwrap();
    }
    let rf = sim
        .attach(fast, Probe::new(), PortConfig::default())
        .unwrap();
    let rs = sim
        .attach(slow, Probe::new(), PortConfig::default())
        .unwrap();
    sim.run_for(Duration::from_millis(5));
    assert_eq!(sim.now(), Instant::from_nanos(5_000_000));
    let eof = bits(&f) - 3;
    assert_eq!(sim.node::<Probe>(rf).unwrap().rx, [(us(eof), f)]);
    assert_eq!(sim.node::<Probe>(rs).unwrap().rx, [(8 * us(eof), f)]);
    assert_eq!(sim.bus(slow).unwrap().name(), "slow");
    assert_eq!(rs.bus(), slow);
}

#[test]
fn step_next_jumps_event_to_event_and_closure_taps_see_them() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let f = std_frame(0x010, &[]);
    sim.attach(bus, Probe::new().at(5_000, f), PortConfig::default())
        .unwrap();
    sim.attach(bus, Probe::new(), PortConfig::default())
        .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    sim.bus_mut(bus).unwrap().add_tap(FnTap(
        move |info: &cantwin_bus::BusInfo<'_>, e: &BusEvent| {
            if let BusEvent::Frame(r) = e {
                tx.send((info.name.to_string(), r.end.as_nanos())).unwrap();
            }
        },
    ));
    let n = bits(&f);
    // The timer, then the end of EOF, then the end of intermission; then nothing.
    assert_eq!(sim.step_next(), Some(Instant::from_nanos(5_000)));
    assert_eq!(
        sim.step_next(),
        Some(Instant::from_nanos(5_000 + us(n - 3)))
    );
    assert_eq!(
        rx.try_recv().unwrap(),
        ("can0".to_string(), 5_000 + us(n - 3))
    );
    assert_eq!(sim.step_next(), None);
}

#[test]
fn statistics_count_frames_and_bits_per_identifier_and_bus_load() {
    let mut sim = Simulation::new();
    let bus = sim
        .add_bus(BusConfig::new("can0", BitRate::R1M).with_load_window(Duration::from_millis(10)));
    let f = std_frame(0x181, &[0; 8]);
    let g = std_frame(0x701, &[5]);
    sim.attach(
        bus,
        Periodic {
            frame: f,
            period: Duration::from_millis(1),
            next: Instant::ZERO,
        },
        PortConfig::default(),
    )
    .unwrap();
    sim.attach(
        bus,
        Periodic {
            frame: g,
            period: Duration::from_millis(10),
            next: Instant::ZERO,
        },
        PortConfig::default(),
    )
    .unwrap();
    // Run to just before the 101st 0x181 would start: 100 of it, 10 of 0x701.
    sim.run_until(Instant::from_nanos(99_999_999));
    let stats = sim.bus(bus).unwrap().stats();
    let (nf, ng) = (bits(&f), bits(&g));
    assert_eq!(stats.id(f.id()).frames, 100);
    assert_eq!(stats.id(f.id()).bits, 100 * nf);
    assert_eq!(stats.id(g.id()).frames, 10);
    assert_eq!(stats.bits(), 100 * nf + 10 * ng);
    let per_id: Vec<u32> = stats.per_id().iter().map(|(id, _)| id.as_raw()).collect();
    assert_eq!(per_id, [0x181, 0x701]);
    let expected = 100.0 * (100 * nf + 10 * ng) as f64 / 99_999.999;
    assert!((stats.load_percent(sim.now()) - expected).abs() < 1e-6);
    // The last 10 ms hold 10 of 0x181 and one 0x701.
    let window = 100.0 * (10 * nf + ng) as f64 / 10_000.0;
    assert!((stats.window_load_percent(sim.now()) - window).abs() < 1e-6);
    assert_eq!(stats.error_frames(), 0);
}

#[test]
fn benchmark_skips_offers_into_a_full_mailbox_but_counts_them_exactly() {
    let config = BenchConfig {
        nodes: 40,
        bit_rate: BitRate::R250K,
        period: Duration::from_millis(1),
        duration: Duration::from_millis(50),
    };
    let report = run(config);
    // Every node offers at 0, 1, …, 50 ms.
    assert_eq!(report.offers, 40 * 51);
    // The same bus with naive nodes, the bus counting the refused offers.
    let (delivered, refused, received) = common::naive_bench(config);
    assert_eq!(report.delivered, delivered);
    assert_eq!(report.dropped_offers, refused);
    assert_eq!(report.received, received);
    assert!(report.dropped_offers > report.offers / 2, "saturated");
    assert!(report.bus_load_percent > 99.0);
}

#[test]
#[ignore = "benchmark: run with --release -- --ignored"]
fn saturated_bus_real_time_factor() {
    let r = cantwin_bus::bench::saturated_bus(Duration::from_secs(60));
    println!(
        "real-time factor {:.0}, {:.0} frames/s, {:.0} ns/frame",
        r.real_time_factor(),
        r.frames_per_wall_second(),
        r.ns_per_frame()
    );
    assert!(r.real_time_factor() >= 100.0);
}
