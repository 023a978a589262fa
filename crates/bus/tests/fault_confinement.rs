//! Acknowledgement, error frames and fault confinement (ISO 11898-1 §10.11, §12.1.4), in
//! exact nanoseconds at 1 Mbit/s.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::{Bus, BusConfig, ErrorKind, FaultRule, FrameSelector, PortConfig, Recorder};
use cantwin_can::{BitRate, ControllerEvent, ErrorState, Instant};
use common::{Probe, bits, std_frame, us};

fn bus() -> Bus {
    Bus::new(BusConfig::new("can0", BitRate::R1M))
}

#[test]
fn iso11898_1_12_1_4_lone_node_sees_ack_errors_goes_error_passive_and_never_bus_off() {
    let f = std_frame(0x123, &[1, 2]);
    let n = bits(&f);
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(Probe::sending(&[f]), PortConfig::default());
    bus.run_until(Instant::from_nanos(20_000_000));

    // Each attempt: error flag after the ACK slot (n - 11 bits), then 17 bits of error
    // frame: n + 6 bits per attempt while error-active.
    let rec = bus.tap::<Recorder>(tap).unwrap();
    let errors: Vec<_> = rec.errors().collect();
    assert_eq!(errors[0].kind, ErrorKind::Ack);
    assert_eq!(errors[0].detected.as_nanos(), us(n - 11));
    assert_eq!(errors[0].idle_at.as_nanos(), us(n + 6));
    assert_eq!(errors[1].start.as_nanos(), us(n + 6));
    // The 16th error makes it error-passive (TEC 128) ...
    let passive_at = us(15 * (n + 6) + n - 11);
    assert_eq!(
        bus.node::<Probe>(a).unwrap().events,
        [(passive_at, ControllerEvent::ErrorPassive)]
    );
    // ... after which it waits 8 more bits after each attempt (suspend transmission).
    assert_eq!(errors[16].start.as_nanos(), us(16 * (n + 6) + 8));
    assert_eq!(errors[17].start.as_nanos(), us(17 * (n + 6) + 16));
    // And ACK errors no longer count: TEC stays at 128, no bus-off.
    let st = bus.port_status(a).unwrap();
    assert_eq!(st.counters.tec(), 128);
    assert_eq!(st.counters.state(), ErrorState::Passive);
    assert!(bus.node::<Probe>(a).unwrap().sent.is_empty());

    // A second node appears: the next attempt is acknowledged, TEC 127, error-active.
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.run_for(cantwin_can::Duration::from_millis(1));
    let pa = bus.node::<Probe>(a).unwrap();
    assert_eq!(pa.sent.len(), 1);
    assert_eq!(pa.events.last().unwrap().1, ControllerEvent::ErrorActive);
    assert_eq!(bus.port_status(a).unwrap().counters.tec(), 127);
    assert_eq!(bus.node::<Probe>(b).unwrap().rx.len(), 1);
}

#[test]
fn iso11898_1_12_1_4_2_bit_errors_drive_the_transmitter_bus_off_and_it_recovers_after_128x11_bits()
{
    let f = std_frame(0x321, &[0xAA; 4]);
    let n = bits(&f);
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(Probe::sending(&[f]), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.inject(
        FaultRule::corrupt(FrameSelector::All)
            .from_port(a)
            .times(32),
    );
    bus.run_until(Instant::from_nanos(100_000_000));

    // A corrupted attempt: bit error at the last CRC bit, flag from n - 13 bits, error frame
    // of n + 4 bits. Error-active for 16 errors, then 8 bits of suspension each.
    let start = |k: u64| k * (n + 4) + 8 * k.saturating_sub(15);
    let rec = bus.tap::<Recorder>(tap).unwrap();
    let errors: Vec<_> = rec.errors().collect();
    assert_eq!(errors.len(), 32);
    for (k, e) in errors.iter().enumerate() {
        assert_eq!(e.kind, ErrorKind::Corrupted);
        assert_eq!(e.start.as_nanos(), us(start(k as u64)), "attempt {k}");
        assert_eq!(e.bits as u64, n + 4);
    }
    let passive = us(start(15) + n - 13);
    let bus_off = us(start(31) + n - 13);
    let recovered = bus_off + us(128 * 11);
    assert_eq!(
        bus.node::<Probe>(a).unwrap().events,
        [
            (passive, ControllerEvent::ErrorPassive),
            (bus_off, ControllerEvent::BusOff),
            // The pending frame is lost with bus-off.
            (bus_off, ControllerEvent::TxDropped),
            (recovered, ControllerEvent::BusOffRecovered),
        ]
    );
    let st = bus.port_status(a).unwrap();
    assert_eq!((st.counters.tec(), st.counters.rec()), (0, 0));
    assert_eq!(st.stats.tx_errors, 32);
    // The receiver counted every error frame: REC 32, still error-active.
    let sb = bus.port_status(b).unwrap();
    assert_eq!(sb.counters.rec(), 32);
    assert_eq!(sb.counters.state(), ErrorState::Active);
    assert!(bus.node::<Probe>(b).unwrap().rx.is_empty());

    // After recovery A sends again; B's REC goes down by one per good frame.
    bus.transmit(a, f).unwrap();
    bus.run_for(cantwin_can::Duration::from_millis(1));
    assert_eq!(bus.node::<Probe>(b).unwrap().rx.len(), 1);
    assert_eq!(bus.port_status(b).unwrap().counters.rec(), 31);
    assert_eq!(bus.stats().error_frames(), 32);
}

#[test]
fn forced_bus_off_without_auto_recovery_waits_for_the_host() {
    let fa = std_frame(0x100, &[]);
    let fb = std_frame(0x200, &[]);
    let mut bus = bus();
    let a = bus.attach(
        Probe::new(),
        PortConfig::default().with_auto_bus_off_recovery(false),
    );
    let b = bus.attach(Probe::new(), PortConfig::default());
    let c = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(1_000));
    bus.force_bus_off(a).unwrap();
    // A bus-off node neither sends nor receives; what it queues waits for recovery.
    bus.transmit(a, fa).unwrap();
    bus.transmit(b, fb).unwrap();
    bus.run_until(Instant::from_nanos(10_000_000));
    assert!(bus.node::<Probe>(a).unwrap().rx.is_empty());
    assert_eq!(
        bus.node::<Probe>(c).unwrap().rx,
        [(1_000 + us(bits(&fb) - 3), fb)]
    );
    assert_eq!(
        bus.port_status(a).unwrap().counters.state(),
        ErrorState::BusOff
    );
    bus.recover_bus_off(a).unwrap();
    let recovered = 10_000_000 + us(128 * 11);
    bus.run_until(Instant::from_nanos(20_000_000));
    assert_eq!(
        bus.node::<Probe>(a).unwrap().events,
        [
            (1_000, ControllerEvent::BusOff),
            (recovered, ControllerEvent::BusOffRecovered)
        ]
    );
    assert_eq!(
        bus.node::<Probe>(c).unwrap().rx[1],
        (recovered + us(bits(&fa) - 3), fa)
    );
}

#[test]
fn bit_rate_mismatched_node_turns_its_frames_into_error_frames_after_six_bits() {
    let f = std_frame(0x111, &[1]);
    let g = std_frame(0x222, &[2]);
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(Probe::new(), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    // A mismatched node cannot acknowledge: C is there to do it.
    let c = bus.attach(Probe::new(), PortConfig::default());
    bus.set_bit_rate_mismatch(a, Some(BitRate::R500K)).unwrap();
    bus.transmit(a, f).unwrap();
    bus.transmit(b, g).unwrap();
    bus.run_until(Instant::from_nanos(us(6)));
    // 0x111 wins arbitration, and is destroyed after 6 bits: 23 bits of error frame.
    let rec = bus.tap::<Recorder>(tap).unwrap();
    let e = rec.errors().next().unwrap();
    assert_eq!(
        (e.kind, e.detected.as_nanos(), e.idle_at.as_nanos()),
        (ErrorKind::BitRateMismatch, us(6), us(23))
    );
    // A wins every arbitration while error-active (16 errors of 23 bits); error-passive,
    // it suspends 8 bits and B's frame goes first; then A errs on until bus-off.
    bus.run_until(Instant::from_nanos(2_000_000));
    let ng = bits(&g);
    let b_start = us(16 * 23);
    assert_eq!(
        bus.node::<Probe>(b).unwrap().sent,
        [(b_start + us(ng - 3), g)]
    );
    let bus_off = b_start + us(ng) + us(15 * 31 + 6);
    assert_eq!(
        bus.node::<Probe>(a).unwrap().events,
        [
            (us(15 * 23 + 6), ControllerEvent::ErrorPassive),
            (bus_off, ControllerEvent::BusOff),
            (bus_off, ControllerEvent::TxDropped),
        ]
    );
    // A cannot decode the bus: it receives nothing and counts an error for B's frame.
    assert!(bus.node::<Probe>(a).unwrap().rx.is_empty());
    let sa = bus.port_status(a).unwrap();
    assert_eq!((sa.stats.tx_errors, sa.counters.rec()), (32, 1));
    // B saw 32 error frames; C too, less one for B's good frame.
    assert_eq!(bus.port_status(b).unwrap().counters.rec(), 32);
    assert_eq!(bus.port_status(c).unwrap().counters.rec(), 31);
    assert_eq!(
        bus.node::<Probe>(c).unwrap().rx,
        [(b_start + us(ng - 3), g)]
    );
    assert_eq!(bus.stats().error_frames(), 32);
}

#[test]
fn iso11898_1_12_1_4_2_a_listener_at_the_wrong_bit_rate_destroys_frames_until_error_passive() {
    let f = std_frame(0x181, &[1, 2, 3, 4]);
    let n = bits(&f);
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(Probe::new(), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    let m = bus.attach(Probe::new(), PortConfig::default());
    bus.set_bit_rate_mismatch(m, Some(BitRate::R250K)).unwrap();
    bus.transmit(a, f).unwrap();
    bus.run_until(Instant::from_nanos(2_000_000));

    // M flags every frame after 6 bits and counts 1 + 8 per error: error-passive after 15
    // (REC 135). A's 16th attempt then goes through.
    let rec = bus.tap::<Recorder>(tap).unwrap();
    assert_eq!(rec.errors().count(), 15);
    assert!(
        rec.errors()
            .all(|e| e.kind == ErrorKind::BitRateMismatch && e.bits == 23)
    );
    assert_eq!(
        bus.node::<Probe>(m).unwrap().events,
        [(us(14 * 23 + 6), ControllerEvent::ErrorPassive)]
    );
    assert_eq!(bus.node::<Probe>(b).unwrap().rx, [(us(15 * 23 + n - 3), f)]);
    assert!(bus.node::<Probe>(m).unwrap().rx.is_empty());
    // A: 15 × 8 - 1; B: 15 - 1; M: 135, + 1 for the frame it could not decode.
    assert_eq!(bus.port_status(a).unwrap().counters.tec(), 119);
    assert_eq!(bus.port_status(b).unwrap().counters.rec(), 14);
    assert_eq!(bus.port_status(m).unwrap().counters.rec(), 136);
}
