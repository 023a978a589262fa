//! Property tests: whatever arrives on the bus, from the controller or from the plant, the
//! coupler does not panic, 0x1002 and 0x1003 stay consistent, and every EMCY it sends
//! carries the manufacturer status of that moment.
#![allow(clippy::unwrap_used)]

use cantwin_can::{ControllerEvent, Frame, Instant, Node, Outbox};
use cantwin_tm3::coupler::{CouplerConfig, Fitted, Tm3Coupler};
use cantwin_tm3::island::Island;
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Op {
    Frame(u16, Vec<u8>),
    Sdo(u8, u16, u8, [u8; 4]),
    Nmt(u8),
    Event(u8),
    Digital(usize, u8, bool),
    Analog(usize, u8, i16),
    Remove(usize),
    Tick,
    PowerUp,
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (0u16..0x800, proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(i, d)| Op::Frame(i, d)),
        (
            any::<u8>(),
            prop_oneof![
                0x1000u16..0x1030,
                0x1400u16..0x1420,
                0x1600u16..0x1620,
                0x1800u16..0x1840,
                0x1A00u16..0x1A40,
                0x6000u16..0x6450
            ],
            0u8..10,
            any::<[u8; 4]>()
        )
            .prop_map(|(c, i, s, d)| Op::Sdo(c, i, s, d)),
        prop_oneof![Just(1u8), Just(2), Just(0x80), Just(0x81), Just(0x82)].prop_map(Op::Nmt),
        (0u8..6).prop_map(Op::Event),
        (1usize..=4, 0u8..20, any::<bool>()).prop_map(|(m, c, o)| Op::Digital(m, c, o)),
        (1usize..=4, 0u8..5, any::<i16>()).prop_map(|(m, c, v)| Op::Analog(m, c, v)),
        (1usize..=5).prop_map(Op::Remove),
        Just(Op::Tick),
        Just(Op::PowerUp),
    ]
}

const EVENTS: [ControllerEvent; 6] = [
    ControllerEvent::ErrorPassive,
    ControllerEvent::ErrorActive,
    ControllerEvent::BusOff,
    ControllerEvent::BusOffRecovered,
    ControllerEvent::RxOverrun,
    ControllerEvent::TxDropped,
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]
    #[test]
    fn coupler_survives_anything_and_keeps_1002_1003_consistent(
        ops in proptest::collection::vec((op(), 0u64..20_000_000), 1..120),
    ) {
        let island = Island::from_references(&["TM3DI16", "TM3DQ8R", "TM3AI4", "TM3AQ2"]).unwrap();
        let mut c = Tm3Coupler::new(CouplerConfig::new(3, island)).unwrap();
        let mut out = Outbox::new();
        let mut now = Instant::ZERO;
        c.on_power_up(now, &mut out);
        for (op, dt) in ops {
            now = Instant::from_nanos(now.as_nanos() + dt);
            if let Some(t) = c.next_deadline() && t <= now {
                c.on_tick(t.max(Instant::from_nanos(now.as_nanos() - dt)), &mut out);
            }
            out.clear();
            match op {
                Op::Frame(id, d) => c.on_frame(&Frame::std(id, &d).unwrap(), now, &mut out),
                Op::Sdo(cmd, i, s, d) => {
                    let [lo, hi] = i.to_le_bytes();
                    let f = Frame::std(0x603, &[cmd, lo, hi, s, d[0], d[1], d[2], d[3]]).unwrap();
                    c.on_frame(&f, now, &mut out);
                }
                Op::Nmt(cs) => c.on_frame(&Frame::std(0, &[cs, 3]).unwrap(), now, &mut out),
                Op::Event(e) => c.on_controller_event(EVENTS[usize::from(e)], now, &mut out),
                Op::Digital(m, ch, on) => { let _ = c.set_digital_input(m, ch, on); }
                Op::Analog(m, ch, v) => { let _ = c.set_analog_input(m, ch, v); }
                Op::Remove(m) => { let _ = c.fit(m, Fitted::Empty, now, &mut out); }
                Op::Tick => c.on_tick(now, &mut out),
                Op::PowerUp => c.on_power_up(now, &mut out),
            }
            let status = c.manufacturer_status();
            prop_assert_eq!(c.device().od().get_unsigned(0x1002, 0), Some(u64::from(status)));
            let count = c.device().od().get_unsigned(0x1003, 0).unwrap();
            prop_assert!(count <= 10);
            for sub in 1..=10u8 {
                let v = c.device().od().get_unsigned(0x1003, sub).unwrap();
                prop_assert_eq!(v == 0, u64::from(sub) > count, "0x1003 sub {} = {:#x}, count {}", sub, v, count);
            }
            let emcy = c.device().od().get_unsigned(0x1014, 0).unwrap() as u32;
            for f in out.frames() {
                if f.to_string().starts_with(&format!("{:03X}#", emcy & 0x7FF)) {
                    prop_assert_eq!(f.len(), 8);
                    prop_assert_eq!(&f.data_bytes()[3..7], &status.to_le_bytes()[..]);
                }
            }
        }
    }
}
