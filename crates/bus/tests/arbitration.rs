//! Arbitration, bit timing and delivery (ISO 11898-1 §10.4, §10.5), in exact nanoseconds
//! at 1 Mbit/s (1 bit = 1 µs).
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::{Bus, BusConfig, PortConfig, Recorder, TxOrder};
use cantwin_can::{BitRate, ControllerEvent, Frame, Id, Instant};
use common::{Probe, bits, std_frame, us};

fn bus() -> Bus {
    Bus::new(BusConfig::new("can0", BitRate::R1M))
}

#[test]
fn iso11898_1_10_4_4_2_lower_id_wins_and_the_loser_follows_right_after() {
    let a_frame = std_frame(0x200, &[1, 2, 3]);
    let b_frame = std_frame(0x100, &[4, 5]);
    let mut bus = bus();
    let a = bus.attach(Probe::sending(&[a_frame]), PortConfig::default());
    let b = bus.attach(Probe::sending(&[b_frame]), PortConfig::default());
    bus.run_until(Instant::from_nanos(1_000_000));

    let (na, nb) = (bits(&a_frame), bits(&b_frame));
    // Delivery at the end of EOF: the frame's bits less 3 of intermission.
    let b_end = us(nb - 3);
    let a_end = us(nb + na - 3);
    let pa = bus.node::<Probe>(a).unwrap();
    let pb = bus.node::<Probe>(b).unwrap();
    assert_eq!(pa.rx, [(b_end, b_frame)]);
    assert_eq!(pb.rx, [(a_end, a_frame)]);
    assert_eq!(pb.sent, [(b_end, b_frame)]);
    assert_eq!(pa.sent, [(a_end, a_frame)]);
    assert_eq!(bus.stats().frames(), 2);
    assert_eq!(bus.stats().busy_time().as_nanos(), us(na + nb));
}

#[test]
fn iso11898_1_10_4_4_2_data_beats_remote_and_standard_beats_extended() {
    let remote = Frame::remote(Id::standard(0x100).unwrap(), 2).unwrap();
    let data = std_frame(0x100, &[]);
    let extended = Frame::data(Id::extended(0x100 << 18).unwrap(), &[]).unwrap();
    let lower_extended = Frame::data(Id::extended(0x0FF << 18 | 0x3FFFF).unwrap(), &[]).unwrap();
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    for f in [extended, remote, lower_extended, data] {
        bus.attach(Probe::sending(&[f]), PortConfig::default());
    }
    bus.run_until(Instant::from_nanos(2_000_000));
    let order: Vec<Frame> = bus
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .map(|r| r.frame)
        .collect();
    assert_eq!(order, [lower_extended, data, remote, extended]);
}

#[test]
fn iso11898_1_10_4_6_a_frame_queued_while_busy_waits_for_the_end_of_intermission() {
    let first = std_frame(0x300, &[0; 8]);
    let waiting = std_frame(0x200, &[1]);
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    bus.attach(Probe::sending(&[first]), PortConfig::default());
    let n = bits(&first);
    let idle = us(n);
    // 0x200 is queued mid-frame; 0x010 exactly when the bus goes idle: both arbitrate then,
    // and the later but higher-priority one wins.
    bus.attach(Probe::new().at(10_000, waiting), PortConfig::default());
    let late = std_frame(0x010, &[]);
    bus.attach(Probe::new().at(idle, late), PortConfig::default());
    bus.run_until(Instant::from_nanos(2_000_000));
    let starts: Vec<(u32, u64)> = bus
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .map(|r| (r.frame.id().as_raw(), r.start.as_nanos()))
        .collect();
    assert_eq!(
        starts,
        [(0x300, 0), (0x010, idle), (0x200, idle + us(bits(&late)))]
    );
}

#[test]
fn self_reception_comes_before_on_sent_at_the_end_of_eof() {
    let f = std_frame(0x123, &[9]);
    let mut bus = bus();
    let a = bus.attach(Probe::sending(&[f]), PortConfig::default().with_echo(true));
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(1_000_000));
    let end = us(bits(&f) - 3);
    let pa = bus.node::<Probe>(a).unwrap();
    assert_eq!(pa.rx, [(end, f)]);
    assert_eq!(pa.sent, [(end, f)]);
    assert_eq!(bus.node::<Probe>(b).unwrap().rx, [(end, f)]);
    assert_eq!(bus.port_status(a).unwrap().stats.rx_frames, 1);
}

#[test]
fn acceptance_filter_decides_who_gets_on_frame() {
    let f1 = std_frame(0x181, &[1]);
    let f2 = std_frame(0x182, &[2]);
    let mut bus = bus();
    bus.attach(Probe::sending(&[f1, f2]), PortConfig::default());
    let only_182 = bus.attach(Probe::new().accepting(&[f2.id()]), PortConfig::default());
    let all = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(1_000_000));
    let e1 = us(bits(&f1) - 3);
    let e2 = us(bits(&f1) + bits(&f2) - 3);
    assert_eq!(bus.node::<Probe>(only_182).unwrap().rx, [(e2, f2)]);
    assert_eq!(bus.node::<Probe>(all).unwrap().rx, [(e1, f1), (e2, f2)]);
}

#[test]
fn priority_queue_sends_lowest_id_first_and_fifo_keeps_queue_order() {
    let frames = [
        std_frame(0x300, &[]),
        std_frame(0x100, &[]),
        std_frame(0x200, &[]),
    ];
    for (order, expect) in [
        (TxOrder::Priority, [0x100, 0x200, 0x300]),
        (TxOrder::Fifo, [0x300, 0x100, 0x200]),
    ] {
        let mut bus = bus();
        bus.attach(
            Probe::sending(&frames),
            PortConfig::default().with_order(order),
        );
        let rx = bus.attach(Probe::new(), PortConfig::default());
        bus.run_until(Instant::from_nanos(1_000_000));
        let ids: Vec<u32> = bus
            .node::<Probe>(rx)
            .unwrap()
            .rx
            .iter()
            .map(|(_, f)| f.id().as_raw())
            .collect();
        assert_eq!(ids, expect, "{order:?}");
    }
}

#[test]
fn transmit_queue_overflow_drops_counts_and_reports_tx_dropped() {
    let frames: Vec<Frame> = (0..5).map(|i| std_frame(0x100 + i, &[])).collect();
    let mut bus = bus();
    let tap = bus.add_tap(Recorder::new());
    let a = bus.attach(
        Probe::sending(&frames),
        PortConfig::default().with_queue_depth(3),
    );
    let b = bus.attach(Probe::new(), PortConfig::default());
    let st = bus.port_status(a).unwrap();
    assert_eq!((st.queued, st.stats.tx_dropped), (3, 2));
    assert_eq!(
        bus.node::<Probe>(a).unwrap().events,
        [
            (0, ControllerEvent::TxDropped),
            (0, ControllerEvent::TxDropped)
        ]
    );
    assert_eq!(
        bus.tap::<Recorder>(tap)
            .unwrap()
            .controller_events()
            .count(),
        2
    );
    // The API path reports it as an error too.
    assert_eq!(
        bus.transmit(a, frames[4]),
        Err(cantwin_bus::BusError::QueueFull(a))
    );
    bus.run_until(Instant::from_nanos(1_000_000));
    assert_eq!(bus.node::<Probe>(b).unwrap().rx.len(), 3);
    assert_eq!(bus.port_status(a).unwrap().stats.tx_dropped, 3);
}

#[test]
fn timers_fire_at_their_deadline_and_frames_start_then() {
    let f = std_frame(0x700, &[5]);
    let mut bus = bus();
    bus.attach(Probe::new().at(123_456, f), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(10_000_000));
    assert_eq!(
        bus.node::<Probe>(b).unwrap().rx,
        [(123_456 + us(bits(&f) - 3), f)]
    );
    assert_eq!(bus.now(), Instant::from_nanos(10_000_000));
}

#[test]
fn detached_node_is_handed_back_with_its_state() {
    let f = std_frame(0x050, &[]);
    let mut bus = bus();
    bus.attach(Probe::sending(&[f]), PortConfig::default());
    let b = bus.attach(Probe::new(), PortConfig::default());
    bus.run_until(Instant::from_nanos(1_000_000));
    let node = bus.detach(b).unwrap();
    let probe = node.into_any().downcast::<Probe>().unwrap();
    assert_eq!(probe.rx.len(), 1);
    assert!(bus.node::<Probe>(b).is_none());
    assert!(bus.port_status(b).is_err());
}
