//! Property tests: whatever arrives from the bus, the device never panics, keeps its
//! timers moving and answers SDO requests with exactly one frame.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_can::{ControllerEvent, Frame, Id, Instant, Node, Outbox};
use device_harness::*;
use proptest::prelude::*;

fn any_frame() -> impl Strategy<Value = Frame> {
    let ids = prop_oneof![
        Just(0u16),
        Just(0x80),
        Just(0x85),
        Just(0x100),
        Just(0x185),
        Just(0x205),
        Just(0x605),
        Just(0x703),
        Just(0x705),
        0u16..0x800,
    ];
    (
        ids,
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(id, remote, data)| {
            let id = Id::standard(id).unwrap();
            if remote {
                Frame::remote(id, data.len() as u8).unwrap()
            } else {
                Frame::data(id, &data).unwrap()
            }
        })
}

fn any_event() -> impl Strategy<Value = ControllerEvent> {
    prop_oneof![
        Just(ControllerEvent::ErrorPassive),
        Just(ControllerEvent::ErrorActive),
        Just(ControllerEvent::BusOff),
        Just(ControllerEvent::BusOffRecovered),
        Just(ControllerEvent::RxOverrun),
        Just(ControllerEvent::TxDropped),
    ]
}

#[derive(Debug, Clone)]
enum Step {
    Frame(Frame),
    Event(ControllerEvent),
    Write(u16, u8, Vec<u8>),
}

fn any_step() -> impl Strategy<Value = Step> {
    prop_oneof![
        6 => any_frame().prop_map(Step::Frame),
        1 => any_event().prop_map(Step::Event),
        2 => (0x1000u16..0x1030, 0u8..5, proptest::collection::vec(any::<u8>(), 0..=4))
            .prop_map(|(i, s, d)| Step::Write(i, s, d)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_traffic_never_panics_and_time_moves_on(
        steps in proptest::collection::vec((0u64..50_000, any_step()), 1..60),
    ) {
        let mut dev = device_with(&options());
        let mut out = Outbox::new();
        let mut now = Instant::ZERO;
        dev.on_power_up(now, &mut out);
        for (dt, step) in steps {
            let until = now + cantwin_can::Duration::from_micros(dt);
            let mut guard = 0;
            while let Some(d) = dev.next_deadline().filter(|d| *d <= until) {
                now = d.max(now);
                dev.on_tick(now, &mut out);
                guard += 1;
                prop_assert!(guard < 10_000, "stuck at {}", d);
            }
            now = until;
            match step {
                Step::Frame(f) => {
                    let before = out.len();
                    let sdo = f.id() == Id::standard(0x605).unwrap()
                        && !f.is_remote()
                        && f.len() == 8
                        && dev.state() != cantwin_canopen::nmt::State::Stopped;
                    dev.on_frame(&f, now, &mut out);
                    if sdo {
                        let answers = out.frames()[before..]
                            .iter()
                            .filter(|a| a.id() == Id::standard(0x585).unwrap())
                            .count();
                        prop_assert!(answers <= 1);
                    }
                }
                Step::Event(e) => dev.on_controller_event(e, now, &mut out),
                Step::Write(i, s, d) => {
                    let _ = cantwin_canopen::ObjectAccess::write(&mut dev, i, s, &d);
                }
            }
            out.clear();
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// `wire::decode` classifies any frame without panicking, and every typed message it
    /// returns encodes back to the same frame.
    #[test]
    fn wire_decode_never_panics_and_round_trips(f in any_frame()) {
        use cantwin_canopen::wire::{self, ErrorControl, Message};
        match wire::decode(&f) {
            Message::Nmt(cmd) => prop_assert_eq!(cmd.encode(), f),
            Message::Sync(s) => prop_assert_eq!(s.encode(f.id()), f),
            Message::Emcy { emcy, .. } => prop_assert_eq!(emcy.encode(f.id()), f),
            Message::Time(t) => {
                // The 4 reserved bits are not kept; everything else is.
                prop_assert_eq!(wire::Time::decode(&t.encode(f.id())).unwrap(), t);
            }
            Message::ErrorControl(m @ ErrorControl::State { .. }) => {
                prop_assert_eq!(m.encode(), f)
            }
            Message::ErrorControl(ErrorControl::GuardRequest { node }) => {
                prop_assert!(f.is_remote());
                prop_assert_eq!(u32::from(node) + 0x700, f.id().as_raw());
            }
            Message::Pdo { frame, .. } => prop_assert_eq!(frame, f),
            Message::SdoRequest { data, len, .. } | Message::SdoResponse { data, len, .. } => {
                prop_assert_eq!(&data[..usize::from(len)], f.data_bytes());
            }
            Message::Malformed { frame, .. } | Message::Other(frame) => prop_assert_eq!(frame, f),
        }
    }
}
