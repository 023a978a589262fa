//! Manual §3.2: message 1, alarm signalling (controlled event on P183 → P184).
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_cal::{ClientEvent, Request};
use cantwin_opendrive::model::{A2, A3, A4, A5, A11};
use cantwin_opendrive::params::C47;
use cantwin_opendrive::{MESSAGE_1, OpenDrive};
use common::*;

/// CAN control at 50 Hz, run up to speed.
fn running(r: &mut Rig) {
    r.exchange(f(440, &[0, 0b10_10_10_01, 0x88, 0x13]));
    r.run_ms(3100);
    assert!((r.drive().output_hz() - 50.0).abs() < 1e-9);
    r.frames();
}

/// Run in 1 ms chunks until `alarm` is raised; the instant of the physics step.
fn until_alarm(r: &mut Rig, alarm: u8, limit_ms: u64) -> u64 {
    for _ in 0..limit_ms {
        r.run_ms(1);
        if r.drive().alarms().contains(alarm) {
            return r.now().as_nanos();
        }
    }
    panic!("alarm A{alarm} not raised within {limit_ms} ms");
}

#[test]
fn enable_and_disable_are_confirmed_with_the_actual_state() {
    let mut r = rig();
    assert_eq!(r.exchange(f(430, &[0x30])), ["1AE#30", "1AD#30"]);
    assert!(r.node().events_enabled());
    assert_eq!(r.exchange(f(430, &[0x20])), ["1AE#20", "1AD#20"]);
    assert!(!r.node().events_enabled());
    // A malformed control: r = 1, the state unchanged, undefined error.
    assert_eq!(r.exchange(f(430, &[0x00])), ["1AE#00", "1AD#280000"]);
}

#[test]
fn events_are_silent_until_enabled() {
    let mut r = rig();
    running(&mut r);
    // An overcurrent with the event disabled: nothing on the bus.
    r.drive_mut().set_load_torque_pct(500.0);
    r.run_ms(5);
    assert!(r.drive().alarms().contains(A2));
    assert_eq!(r.texts(), Vec::<String>::new());
    r.drive_mut().reset_alarms();
    r.drive_mut().set_load_torque_pct(0.0);
    r.run_ms(5);
    assert_eq!(r.texts(), Vec::<String>::new());
    // Enabled: the reset was before, so nothing is pending; the next change notifies.
    assert_eq!(r.exchange(f(430, &[0x30])), ["1AE#30", "1AD#30"]);
    r.run_ms(10);
    assert_eq!(r.texts(), Vec::<String>::new());
}

#[test]
fn overcurrent_load_step_notifies_bit_7_at_the_next_physics_step() {
    let mut r = rig();
    running(&mut r);
    r.request(MESSAGE_1, Request::ControlEvent(true));
    r.run_ms(1);
    assert_eq!(r.texts(), ["1AE#30", "1AD#30"]);
    let t0 = r.now().as_nanos();
    r.drive_mut().set_load_torque_pct(500.0);
    r.run_ms(2);
    let notify = f(429, &[0x10, 0x00, 0x80]);
    let t = t0 + 1_000_000;
    assert_eq!(
        r.frames(),
        vec![("1AD#100080".into(), t, t + ns(&notify) - 3 * BIT_NS)]
    );
    assert!(!r.drive().is_running());
    let ev = r.events();
    assert!(matches!(
        ev.last(),
        Some(ClientEvent::Notified { object: MESSAGE_1, data, .. }) if data.as_slice() == [0x00, 0x80]
    ));
    // The reset of the alarm is a change too.
    r.drive_mut().reset_alarms();
    r.run_ms(2);
    assert_eq!(r.texts(), ["1AD#100000"]);
}

#[test]
fn overload_i2t_trips_a3_and_notifies_bit_7() {
    let mut r = rig();
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    // 200 % load: about 205 % current against P70 = 100 %: the I²t model trips in about
    // 120 s × ln(4.2 / 3.2) ≈ 33 s.
    r.drive_mut().set_load_torque_pct(200.0);
    let start = r.now().as_nanos();
    let trip = until_alarm(&mut r, A3, 40_000);
    let secs = (trip - start) as f64 / 1e9;
    assert!((30.0..36.0).contains(&secs), "tripped after {secs} s");
    r.run_ms(1);
    let frames = r.frames();
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].0, "1AD#100080");
    assert_eq!(frames[0].1, trip);
}

#[test]
fn overload_with_c32_0_is_a_warning_only() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(cantwin_opendrive::params::C32, 0)
        .unwrap();
    let mut r = rig_with(d);
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    r.drive_mut().set_load_torque_pct(200.0);
    r.run_ms(40_000);
    assert!(r.drive().thermal_warning());
    assert!(!r.drive().alarms().any());
    assert_eq!(r.texts(), Vec::<String>::new());
}

#[test]
fn fast_deceleration_without_intelligent_braking_trips_overvoltage_bit_5() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(C47, 0).unwrap();
    let mut r = rig_with(d);
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    // Stop: CAN-Start reset.
    r.exchange(f(440, &[0, 0b00_00_01_00, 0x88, 0x13]));
    let trip = until_alarm(&mut r, A11, 3000);
    assert!(r.drive().dc_bus_v() > r.drive().hardware().overvoltage_trip_v);
    r.run_ms(1);
    let frames = r.frames();
    assert_eq!(frames.len(), 1);
    assert_eq!((frames[0].0.as_str(), frames[0].1), ("1AD#100020", trip));
}

#[test]
fn intelligent_braking_stretches_the_ramp_instead() {
    let mut r = rig();
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    r.exchange(f(440, &[0, 0b00_00_01_00, 0x88, 0x13]));
    r.run_ms(3100);
    // Not stopped within the 3 s ramp: C47 held it while the DC bus was high.
    assert!(r.drive().output_hz() > 1.0, "{}", r.drive().output_hz());
    assert!(r.drive().dc_bus_v() <= r.drive().hardware().overvoltage_trip_v);
    r.run_ms(60_000);
    assert_eq!(r.drive().output_hz(), 0.0);
    assert!(!r.drive().is_running());
    assert!(!r.drive().alarms().any());
    assert_eq!(r.texts(), Vec::<String>::new());
}

#[test]
fn heatsink_overtemperature_notifies_bit_6() {
    let mut r = rig();
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    r.drive_mut().set_ambient_c(85.0);
    r.drive_mut().set_load_torque_pct(100.0);
    let trip = until_alarm(&mut r, A4, 600_000);
    assert!(r.drive().heatsink_c() >= r.drive().hardware().heatsink_trip_c);
    r.run_ms(1);
    let frames = r.frames();
    assert_eq!((frames[0].0.as_str(), frames[0].1), ("1AD#100040", trip));
}

#[test]
fn power_module_overtemperature_a5_notifies_bit_6_before_the_heatsink_trips() {
    let mut r = rig();
    running(&mut r);
    r.exchange(f(430, &[0x30]));
    // Thermal current P70 = 200 % (mux 0x19 = 256), so the motor's I²t (A3) allows the
    // overload for over a minute.
    assert_eq!(
        r.exchange(f(1100, &[0x19, 0x00, 0x01])),
        ["44C#190001", "44B#190001"]
    );
    // 290 % of the motor's rated torque: about 294 % of its current, 147 % of the drive's
    // (P61 = 50 %), just under the current limit. The junctions sit 20 K × 1.47² = 43 K above
    // the heatsink, which climbs towards 40 + 40 × 1.47² = 127 °C with its minute-long time
    // constant (60 s): it reaches 125 − 43 = 82 °C after 60 s × ln(86.5 / 41.7) ≈ 40 s, and
    // the junctions follow with their 3 s lag: A5 after about 42.6 s, with the heatsink near
    // 82 °C, under A4's 90 °C.
    r.drive_mut().set_load_torque_pct(290.0);
    assert!(!r.drive().in_limit());
    let start = r.now().as_nanos();
    let trip = until_alarm(&mut r, A5, 60_000);
    let secs = (trip - start) as f64 / 1e9;
    assert!((41.0..44.0).contains(&secs), "tripped after {secs} s");
    let hw = *r.drive().hardware();
    assert!(r.drive().module_c() >= hw.module_trip_c);
    assert!(r.drive().heatsink_c() < hw.heatsink_trip_c - 5.0);
    assert!(!r.drive().alarms().contains(A4));
    assert!(!r.drive().alarms().contains(A3));
    assert!(!r.drive().is_running());
    r.run_ms(1);
    let frames = r.frames();
    assert_eq!(frames.len(), 1);
    assert_eq!((frames[0].0.as_str(), frames[0].1), ("1AD#100040", trip));
}

#[test]
fn power_module_stays_cool_at_rated_current_in_a_hot_cabinet() {
    let mut r = rig();
    running(&mut r);
    // The heatsink test's conditions: A4 trips, A5 does not (the junctions are only a few
    // kelvin above the heatsink at the motor's rated current).
    r.drive_mut().set_ambient_c(85.0);
    r.drive_mut().set_load_torque_pct(100.0);
    until_alarm(&mut r, A4, 600_000);
    assert!(!r.drive().alarms().contains(A5));
    assert!(r.drive().module_c() < r.drive().heatsink_c() + 10.0);
}
