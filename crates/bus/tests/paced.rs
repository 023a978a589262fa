//! The paced scheduler and external ports. These tests block on receive with generous
//! timeouts but assert only bus-time facts, which pacing does not change.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration as WallDuration;

use cantwin_bus::{
    BusConfig, BusError, ExternalConfig, PacedConfig, PacedSimulation, PortConfig, Simulation,
    TimeMap,
};
use cantwin_can::{BitRate, Duration, Frame, Instant, Node, Outbox};
use common::{Probe, bits, std_frame, us};

const PATIENCE: WallDuration = WallDuration::from_secs(10);

struct Heartbeat {
    frame: Frame,
    next: Instant,
}

impl Node for Heartbeat {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, out: &mut Outbox) {
        out.push(self.frame);
        self.next += Duration::from_millis(1);
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(self.next)
    }
}

#[test]
fn external_ports_exchange_frames_with_nodes_on_a_paced_bus() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let probe = sim
        .attach(bus, Probe::new(), PortConfig::default())
        .unwrap();
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let one = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let two = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let f = std_frame(0x601, &[0x40, 0x00, 0x10, 0x00]);
    one.send(f).unwrap();
    let got = two.recv_timeout(PATIENCE).unwrap().unwrap();
    assert_eq!(got.frame, f);
    // Delivered to everyone at the same bus instant; the sender does not hear itself.
    assert_eq!(one.try_recv().unwrap(), None);
    let rx = handle
        .with(|sim| sim.node::<Probe>(probe).unwrap().rx.clone())
        .unwrap();
    assert_eq!(rx, [(got.at.as_nanos(), f)]);
    assert_eq!(one.status().unwrap().stats.tx_frames, 1);
    // The wall clock of that instant is known to captures.
    let map = handle.time_map();
    assert!(map.wall_time(got.at) >= map.wall_origin);
    two.detach().unwrap();
    let sim = paced.stop().unwrap();
    assert_eq!(sim.bus(bus).unwrap().ports().count(), 2);
}

#[test]
fn paced_timers_keep_exact_bus_times() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    let f = std_frame(0x701, &[0x05]);
    sim.attach(
        bus,
        Heartbeat {
            frame: f,
            next: Instant::ZERO,
        },
        PortConfig::default(),
    )
    .unwrap();
    // Someone to acknowledge the heartbeats before the external port comes.
    sim.attach(bus, Probe::new(), PortConfig::default())
        .unwrap();
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let ext = paced
        .handle()
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let first = ext.recv_timeout(PATIENCE).unwrap().unwrap();
    let second = ext.recv_timeout(PATIENCE).unwrap().unwrap();
    let third = ext.recv_timeout(PATIENCE).unwrap().unwrap();
    // At 500 kbit/s a bit is 2 µs; heartbeats every 1 ms, delivered at the end of EOF.
    let eof = 2 * us(bits(&f) - 3);
    let k = (first.at.as_nanos() - eof) / 1_000_000;
    assert_eq!(first.at.as_nanos(), k * 1_000_000 + eof);
    assert_eq!(second.at.as_nanos(), (k + 1) * 1_000_000 + eof);
    assert_eq!(third.at.as_nanos(), (k + 2) * 1_000_000 + eof);
    drop(ext);
    drop(paced);
}

#[test]
fn a_full_external_receive_buffer_counts_overruns_and_never_blocks_the_bus() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let h = paced.handle();
    let small = h
        .attach_external(
            bus,
            ExternalConfig {
                rx_capacity: 2,
                ..ExternalConfig::default()
            },
        )
        .unwrap();
    let witness = h.attach_external(bus, ExternalConfig::default()).unwrap();
    let sender = h.attach_external(bus, ExternalConfig::default()).unwrap();
    for i in 0..5u8 {
        sender.send(std_frame(0x100 + u16::from(i), &[i])).unwrap();
    }
    for i in 0..5u8 {
        let r = witness.recv_timeout(PATIENCE).unwrap().unwrap();
        assert_eq!(r.frame.data_bytes(), [i]);
    }
    assert_eq!(small.overruns(), 3);
    assert_eq!(small.try_recv().unwrap().unwrap().frame.data_bytes(), [0]);
    assert_eq!(small.try_recv().unwrap().unwrap().frame.data_bytes(), [1]);
    assert_eq!(small.try_recv().unwrap(), None);
}

#[test]
fn a_stopped_simulation_closes_its_external_ports() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let h = paced.handle();
    let ext = h.attach_external(bus, ExternalConfig::default()).unwrap();
    h.stop();
    assert!(h.is_stopped());
    assert_eq!(ext.recv_timeout(PATIENCE), Err(BusError::Stopped));
    assert_eq!(ext.send(std_frame(1, &[])), Err(BusError::Stopped));
    assert_eq!(h.with(|s| s.now()), Err(BusError::Stopped));
    assert!(paced.stop().is_some());
}

#[test]
fn time_map_converts_both_ways() {
    let origin = std::time::SystemTime::UNIX_EPOCH + WallDuration::from_secs(1_700_000_000);
    let map = TimeMap {
        bus_origin: Instant::from_nanos(5_000),
        wall_origin: origin,
    };
    let t = Instant::from_nanos(1_005_000);
    assert_eq!(map.wall_time(t), origin + WallDuration::from_millis(1));
    assert_eq!(map.bus_time(origin + WallDuration::from_millis(1)), t);
    assert_eq!(
        map.wall_time(Instant::ZERO),
        origin - WallDuration::from_micros(5)
    );
    assert_eq!(map.unix_nanos(t), 1_700_000_000_000_000_000 + 1_000_000);
}

#[test]
fn a_simulation_that_falls_behind_gives_up_the_backlog_and_slips_its_time_map() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    // Frames due at bus time 0, which the thread can only reach some time after it started.
    let f = std_frame(0x123, &[1]);
    sim.attach(bus, Probe::sending(&[f]), PortConfig::default())
        .unwrap();
    let rx = sim
        .attach(bus, Probe::new(), PortConfig::default())
        .unwrap();
    // No lag allowed at all: any lateness is given up and the wall time of bus instants
    // moves later by as much.
    let paced = PacedSimulation::start(
        sim,
        PacedConfig {
            max_lag: Duration::ZERO,
            ..PacedConfig::default()
        },
    );
    let h = paced.handle();
    let before = h.time_map();
    let first = h.now().unwrap();
    let second = h.now().unwrap();
    assert!(second >= first);
    assert!(h.slips() >= 1);
    let after = h.time_map();
    assert_eq!(after.bus_origin, before.bus_origin);
    assert!(after.wall_origin >= before.wall_origin);
    // Nothing was skipped: the frame due at 0 still went out at its exact bus time (a
    // closure may also run the simulation ahead of the wall clock, which then waits).
    h.with(|sim| sim.run_for(Duration::from_millis(1))).unwrap();
    let sim = paced.stop().unwrap();
    assert_eq!(sim.node::<Probe>(rx).unwrap().rx, [(us(bits(&f) - 3), f)]);
}

#[test]
fn a_port_delivering_to_a_sink_hands_over_buffered_frames_first_then_each_as_it_completes() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let tool = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let listener = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let frame = |n: u8| std_frame(0x181, &[n]);
    // Two frames reach the listener's buffer before it has a sink.
    tool.send(frame(0)).unwrap();
    tool.send(frame(1)).unwrap();
    let give_up = std::time::Instant::now() + PATIENCE;
    // Wait for both without taking them: the port's status counts received frames.
    while listener.status().unwrap().stats.rx_frames < 2 {
        assert!(std::time::Instant::now() < give_up, "two frames in time");
        std::thread::sleep(WallDuration::from_millis(1));
    }
    let (tx, rx) = std::sync::mpsc::channel();
    listener
        .deliver_to(move |r: cantwin_bus::Received, map: TimeMap| {
            let _ = tx.send((r.frame, r.at, map.wall_time(r.at)));
        })
        .unwrap();
    for n in 2..6 {
        tool.send(frame(n)).unwrap();
    }
    let got: Vec<_> = (0..6).map(|_| rx.recv_timeout(PATIENCE).unwrap()).collect();
    let frames: Vec<Frame> = got.iter().map(|g| g.0).collect();
    assert_eq!(frames, (0..6).map(frame).collect::<Vec<_>>());
    // Each frame at its own end on the bus, in order, stamped with the time map in force.
    assert!(got.windows(2).all(|w| w[0].1 < w[1].1 && w[0].2 < w[1].2));
    if handle.slips() == 0 {
        assert!(got.iter().all(|g| g.2 == handle.time_map().wall_time(g.1)));
    }
    // Nothing is left for the buffer's reader; detaching ends it.
    assert_eq!(listener.try_recv().unwrap(), None);
    assert_eq!(listener.overruns(), 0);
    paced.stop();
    assert_eq!(
        listener.recv_timeout(WallDuration::ZERO),
        Err(BusError::Stopped)
    );
}

#[test]
fn frames_handed_to_a_sink_after_a_slip_are_stamped_with_the_slipped_map() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    sim.attach(
        bus,
        Heartbeat {
            frame: std_frame(0x705, &[0x05]),
            next: Instant::ZERO,
        },
        PortConfig::default(),
    )
    .unwrap();
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let port = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    port.deliver_to(move |r: cantwin_bus::Received, map: TimeMap| {
        let _ = tx.send((map.wall_time(r.at), std::time::SystemTime::now()));
    })
    .unwrap();
    // Hold the simulation for far longer than its lag limit (50 ms): it slips when it runs
    // again, and the frames it then catches up on are stamped with the new map, not 400 ms
    // in the past.
    handle
        .with(|_| std::thread::sleep(WallDuration::from_millis(400)))
        .unwrap();
    let until = std::time::Instant::now() + WallDuration::from_millis(200);
    let mut seen = 0;
    while std::time::Instant::now() < until {
        let Ok((stamp, delivered)) = rx.recv_timeout(PATIENCE) else {
            panic!("no frames");
        };
        let early = delivered.duration_since(stamp).unwrap_or_default();
        assert!(
            early < WallDuration::from_millis(250),
            "stamped {early:?} early"
        );
        seen += 1;
    }
    assert!(handle.slips() > 0);
    assert!(seen > 0);
}

#[test]
fn dropping_a_port_drops_its_sink_even_after_the_simulation_was_dropped() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let port = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let token = std::sync::Arc::new(());
    let held = std::sync::Arc::clone(&token);
    // A sink holding the simulation's handle: a cycle through the simulation's nodes, which
    // only dropping the sink breaks.
    let inside = handle.clone();
    port.deliver_to(move |_, _| {
        let _ = (&held, &inside);
    })
    .unwrap();
    drop(handle);
    drop(paced);
    drop(port);
    assert_eq!(
        std::sync::Arc::strong_count(&token),
        1,
        "the sink was dropped"
    );
}

#[test]
fn an_external_port_dropped_right_after_sending_still_sends_what_it_queued() {
    // A tool that sends the closing frame of a transfer and exits: its controller still
    // sends what it was given, so the device does not stay in the middle of the transfer.
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R10K));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let listener = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    let leaving = handle
        .attach_external(bus, ExternalConfig::default())
        .unwrap();
    // At 10 kbit/s four frames take some 40 ms of bus time: they are still queued when
    // the port is dropped.
    let frames: Vec<Frame> = (0..4u8).map(|n| std_frame(0x605, &[0xA1, n])).collect();
    for f in &frames {
        leaving.send(*f).unwrap();
    }
    drop(leaving);
    let got: Vec<Frame> = (0..4)
        .map(|_| listener.recv_timeout(PATIENCE).unwrap().unwrap().frame)
        .collect();
    assert_eq!(got, frames);
}
