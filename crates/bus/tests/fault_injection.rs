//! Seeded fault injection and node faults: drop, corrupt, fractions, identifiers, power
//! cycles, disconnection, babbling.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::{
    Bus, BusConfig, BusEvent, ErrorKind, FaultRule, FrameSelector, PortConfig, Recorder,
};
use cantwin_can::{BitRate, ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use common::{Probe, bits, std_frame, us};

fn bus_with_seed(seed: u64) -> Bus {
    Bus::new(BusConfig::new("can0", BitRate::R1M).with_seed(seed))
}

/// Sends its frame every `period`.
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

fn periodic(id: u16, period_us: u64, phase_us: u64) -> Periodic {
    Periodic {
        frame: std_frame(id, &[id as u8; 8]),
        period: Duration::from_micros(period_us),
        next: Instant::from_nanos(us(phase_us)),
    }
}

fn scenario(seed: u64) -> Vec<BusEvent> {
    let mut bus = bus_with_seed(seed);
    let tap = bus.add_tap(Recorder::new());
    bus.attach(periodic(0x181, 1000, 0), PortConfig::default());
    bus.attach(periodic(0x281, 700, 13), PortConfig::default());
    bus.attach(periodic(0x701, 5000, 100), PortConfig::default());
    bus.inject(FaultRule::corrupt(FrameSelector::Fraction(0.2)));
    bus.inject(FaultRule::drop(FrameSelector::Fraction(0.1)));
    bus.run_until(Instant::from_nanos(200_000_000));
    bus.tap::<Recorder>(tap).unwrap().events.clone()
}

#[test]
fn seeded_fault_injection_replays_identically() {
    let first = scenario(7);
    let again = scenario(7);
    assert_eq!(first, again);
    let errors = first
        .iter()
        .filter(|e| matches!(e, BusEvent::Error(_)))
        .count();
    let dropped = first
        .iter()
        .filter(|e| matches!(e, BusEvent::Frame(f) if f.dropped))
        .count();
    let frames = first
        .iter()
        .filter(|e| matches!(e, BusEvent::Frame(_)))
        .count();
    // About 20 % of attempts corrupted, 10 % of the rest dropped.
    let attempts = (errors + frames) as f64;
    assert!(
        (0.15..0.25).contains(&(errors as f64 / attempts)),
        "{errors}/{attempts}"
    );
    assert!(
        (0.06..0.14).contains(&(dropped as f64 / frames as f64)),
        "{dropped}/{frames}"
    );
    assert_ne!(first, scenario(8), "another seed, other faults");
}

#[test]
fn corrupting_a_given_attempt_costs_an_error_frame_and_a_retransmission() {
    let f = std_frame(0x0AB, &[1, 2, 3, 4]);
    let n = bits(&f);
    let mut bus = bus_with_seed(0);
    let a = bus.attach(Probe::sending(&[f]), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.inject(FaultRule::corrupt(FrameSelector::Attempt(0)));
    bus.run_until(Instant::from_nanos(1_000_000));
    // Flag after n - 13 bits, 17 bits of error frame, then the retransmission.
    let end = us((n + 4) + n - 3);
    assert_eq!(bus.node::<Probe>(b).unwrap().rx, [(end, f)]);
    assert_eq!(bus.node::<Probe>(a).unwrap().sent, [(end, f)]);
    let sa = bus.port_status(a).unwrap();
    // TEC: +8, then -1.
    assert_eq!(sa.counters.tec(), 7);
    assert_eq!(bus.port_status(b).unwrap().counters.rec(), 0);
    assert_eq!(bus.stats().error_frames(), 1);
    assert!(bus.fault_rules().is_empty(), "the rule is spent");
}

#[test]
fn dropping_a_frame_hides_it_from_receivers_but_the_sender_sees_success() {
    let f = std_frame(0x0AB, &[1]);
    let g = std_frame(0x0AC, &[2]);
    let mut bus = bus_with_seed(0);
    let a = bus.attach(Probe::sending(&[f, g]), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    let tap = bus.add_tap(Recorder::new());
    bus.inject(FaultRule::drop(FrameSelector::Id(f.id())));
    bus.run_until(Instant::from_nanos(1_000_000));
    let e1 = us(bits(&f) - 3);
    let e2 = us(bits(&f) + bits(&g) - 3);
    assert_eq!(bus.node::<Probe>(a).unwrap().sent, [(e1, f), (e2, g)]);
    assert_eq!(bus.node::<Probe>(b).unwrap().rx, [(e2, g)]);
    let recs: Vec<bool> = bus
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .map(|r| r.dropped)
        .collect();
    assert_eq!(recs, [true, false]);
    assert_eq!(bus.stats().dropped_frames(), 1);
}

#[test]
fn rules_can_target_one_sender_and_a_limited_number_of_frames() {
    let mut bus = bus_with_seed(0);
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(periodic(0x100, 1000, 0), PortConfig::default());
    bus.attach(periodic(0x200, 1000, 0), PortConfig::default());
    bus.inject(FaultRule::corrupt(FrameSelector::All).from_port(a).times(3));
    bus.run_until(Instant::from_nanos(10_000_000));
    let rec = bus.tap::<Recorder>(tap).unwrap();
    assert_eq!(rec.errors().count(), 3);
    assert!(
        rec.errors()
            .all(|e| e.sender == a && e.kind == ErrorKind::Corrupted)
    );
    // 11 periods of each node (0..=10 ms, the last still in flight at 10 ms is not counted).
    assert_eq!(rec.frames().filter(|f| f.sender == a).count(), 10);
}

#[test]
fn power_cycled_node_misses_frames_while_off_and_powers_up_again() {
    let mut bus = bus_with_seed(0);
    let talker = bus.attach(periodic(0x181, 1000, 0), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    let _c = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(us(2500)));
    bus.set_powered(b, false).unwrap();
    bus.run_until(Instant::from_nanos(us(5500)));
    bus.set_powered(b, true).unwrap();
    bus.run_until(Instant::from_nanos(us(7500)));
    let n = bits(&std_frame(0x181, &[0x81; 8]));
    let times: Vec<u64> = bus
        .node::<Probe>(b)
        .unwrap()
        .rx
        .iter()
        .map(|(t, _)| *t)
        .collect();
    let at = |k: u64| us(k * 1000 + n - 3);
    assert_eq!(times, [at(0), at(1), at(2), at(6), at(7)]);
    assert_eq!(bus.node::<Probe>(b).unwrap().power_ups, [0, us(5500)]);
    assert_eq!(bus.port_status(talker).unwrap().stats.tx_frames, 8);
}

#[test]
fn disconnected_node_neither_sends_nor_receives_until_reconnected() {
    let f = std_frame(0x300, &[3]);
    let mut bus = bus_with_seed(0);
    bus.attach(periodic(0x181, 1000, 0), PortConfig::default());
    let b = bus.attach(Probe::new().at(us(1500), f), PortConfig::default());
    let c = bus.attach(Probe::new().accepting(&[f.id()]), PortConfig::default());
    bus.run_until(Instant::from_nanos(us(1200)));
    bus.set_connected(b, false).unwrap();
    bus.run_until(Instant::from_nanos(us(3200)));
    // B's frame waited in its queue; nothing reached it.
    assert_eq!(bus.node::<Probe>(b).unwrap().rx.len(), 2);
    assert!(bus.node::<Probe>(c).unwrap().rx.is_empty());
    assert_eq!(bus.port_status(b).unwrap().queued, 1);
    // Alone on its stub of cable it saw ACK errors every n + 6 bits from 1500 µs until
    // error-passive at the 16th.
    let n = bits(&f);
    let passive = us(1500 + 15 * (n + 6) + n - 11);
    assert_eq!(
        bus.node::<Probe>(b).unwrap().events,
        [(passive, ControllerEvent::ErrorPassive)]
    );
    assert_eq!(bus.port_status(b).unwrap().counters.tec(), 128);
    bus.set_connected(b, true).unwrap();
    bus.run_until(Instant::from_nanos(us(4200)));
    let sent = us(3200) + us(n - 3);
    assert_eq!(bus.node::<Probe>(c).unwrap().rx, [(sent, f)]);
    assert_eq!(bus.node::<Probe>(b).unwrap().rx.len(), 3);
    // The first good transmission makes it error-active again.
    assert_eq!(
        bus.node::<Probe>(b).unwrap().events[1],
        (sent, ControllerEvent::ErrorActive)
    );
}

#[test]
fn babbling_node_with_a_high_priority_id_starves_the_bus() {
    let babble = std_frame(0x000, &[0xFF; 8]);
    let mut bus = bus_with_seed(0);
    let tap = bus.add_tap(Recorder::new());
    let victim = bus.attach(periodic(0x181, 1000, 0), PortConfig::default());
    let babbler = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(us(500)));
    bus.set_babble(babbler, Some(babble)).unwrap();
    bus.run_until(Instant::from_nanos(us(10_000)));
    let rec = bus.tap::<Recorder>(tap).unwrap();
    // Only the first frame of the victim (at 0) got out.
    assert_eq!(rec.frames().filter(|f| f.sender == victim).count(), 1);
    let babbled: Vec<_> = rec.frames().filter(|f| f.babble).collect();
    let nb = bits(&babble);
    // Back to back from the first idle bus after 500 µs (the bus was idle then).
    assert_eq!(babbled[0].start.as_nanos(), us(500));
    assert_eq!(babbled[1].start.as_nanos(), us(500 + nb));
    assert!(bus.node::<Probe>(babbler).unwrap().sent.is_empty());
    bus.set_babble(babbler, None).unwrap();
    bus.run_until(Instant::from_nanos(us(11_000)));
    assert!(bus.stats().load_percent(bus.now()) > 90.0);
}

#[test]
fn a_node_losing_power_mid_frame_leaves_an_error_frame_behind() {
    let f = std_frame(0x181, &[0x11; 8]);
    let g = std_frame(0x182, &[0x22; 8]);
    let mut bus = bus_with_seed(0);
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(Probe::sending(&[f]), PortConfig::default());
    let b = bus.attach(Probe::sending(&[g]), PortConfig::default());
    let c = bus.attach(Probe::new(), PortConfig::default());
    // 40.5 bits into A's frame.
    bus.run_until(Instant::from_nanos(40_500));
    bus.set_powered(a, false).unwrap();
    bus.run_until(Instant::from_nanos(1_000_000));
    let rec = bus.tap::<Recorder>(tap).unwrap();
    let e = rec.errors().next().unwrap();
    assert_eq!(
        (
            e.kind,
            e.sender,
            e.detected.as_nanos(),
            e.idle_at.as_nanos()
        ),
        (ErrorKind::Aborted, a, 40_500, us(40 + 17))
    );
    // B's frame follows the error frame; receivers counted the error, then the good frame.
    assert_eq!(
        bus.node::<Probe>(c).unwrap().rx,
        [(us(57 + bits(&g) - 3), g)]
    );
    assert_eq!(bus.port_status(c).unwrap().counters.rec(), 0);
    assert_eq!(bus.port_status(b).unwrap().counters.rec(), 1);
    // The powered-off sender's counters were not touched; it lost its queue.
    let sa = bus.port_status(a).unwrap();
    assert_eq!((sa.counters.tec(), sa.queued, sa.powered), (0, 0, false));
}
