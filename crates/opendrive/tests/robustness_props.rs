//! Bad input gets the protocol's answer, never a panic: any frame on any of the drive's
//! COBs is answered exactly once on the matching response COB (or, for a remote frame on
//! another COB, ignored), and the drive keeps stepping.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_opendrive::{DriveData, MotorData, OpenDrive};
use proptest::prelude::*;

fn frame() -> impl Strategy<Value = Frame> {
    (
        prop::sample::select(vec![440u16, 439, 430, 429, 1100, 1099, 0x123]),
        any::<bool>(),
        prop::collection::vec(any::<u8>(), 0..=8),
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

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    #[test]
    fn every_request_gets_one_answer_on_its_response_cob(
        frames in prop::collection::vec(frame(), 1..20),
        load in 0.0f64..600.0,
    ) {
        let mut d = OpenDrive::new(MotorData::default(), DriveData::default());
        let mut out = Outbox::new();
        d.on_power_up(Instant::ZERO, &mut out);
        d.drive_mut().set_load_torque_pct(load);
        let mut t = Instant::ZERO;
        for f in frames {
            t += Duration::from_micros(500);
            while let Some(next) = d.next_deadline().filter(|n| *n <= t) {
                d.on_tick(next, &mut out);
            }
            out.clear();
            let raw = f.id().as_raw();
            if d.accepts(f.id()) {
                d.on_frame(&f, t, &mut out);
            }
            let expect = match (raw, f.is_remote()) {
                (440, false) | (439, true) => Some(439),
                (430, false) => Some(429),
                (1100, false) => Some(1099),
                _ => None,
            };
            let answers: Vec<u32> = out.frames().iter().map(|a| a.id().as_raw()).collect();
            match expect {
                Some(id) => prop_assert_eq!(answers, vec![id]),
                None => prop_assert!(answers.is_empty()),
            }
            prop_assert!(out.frames().iter().all(|a| !a.is_remote() && !a.is_empty()));
        }
        prop_assert!(d.drive().output_hz().is_finite());
        prop_assert!(d.drive().current_pct().is_finite());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Whatever the commands and the load, the physics keeps its limits: the output stays
    /// within the maximum frequency, the current within the threshold (or the drive trips),
    /// and the DC bus never passes the trip level without alarm A11.
    #[test]
    fn physics_stays_within_its_limits(
        steps in prop::collection::vec((any::<u8>(), 0u16..=5000, 0.0f64..450.0, 1u64..400), 1..12),
    ) {
        let mut d = OpenDrive::new(MotorData::default(), DriveData::default());
        let mut out = Outbox::new();
        d.on_power_up(Instant::ZERO, &mut out);
        let mut t = Instant::ZERO;
        let limit = 150.0 / 0.5;
        for (cmd, reference, load, ms) in steps {
            let [lo, hi] = reference.to_le_bytes();
            d.on_frame(&Frame::std(440, &[0, cmd, lo, hi]).unwrap(), t, &mut out);
            d.drive_mut().set_load_torque_pct(load);
            let end = t + Duration::from_millis(ms);
            while let Some(next) = d.next_deadline().filter(|n| *n <= end) {
                d.on_tick(next, &mut out);
                let m = d.drive();
                prop_assert!(m.output_hz().abs() <= m.fmax_hz() + 1e-9);
                prop_assert!(m.current_pct() <= limit + 1e-9);
                prop_assert!(
                    m.dc_bus_v() <= m.hardware().overvoltage_trip_v
                        || m.alarms().contains(cantwin_opendrive::model::A11)
                );
                prop_assert!(m.motor_thermal().is_finite() && m.heatsink_c().is_finite());
            }
            t = end;
            out.clear();
        }
    }
}
