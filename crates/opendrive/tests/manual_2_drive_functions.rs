//! Manual §2.3 defaults table in action: ramps P21–P24, the current threshold reaction
//! (C40, P94, message 2 mux 0x18), automatic alarm reset at mains return (C35) and the
//! flying restart (C50).
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_opendrive::OpenDrive;
use cantwin_opendrive::model::A2;
use cantwin_opendrive::params::{C35, C50, P21, P22, P23, P24};
use common::*;

const MS: u64 = 1_000_000;

/// Run in 1 ms steps until `done`; the instant it first holds.
fn until(r: &mut Rig, limit_ms: u64, done: impl Fn(&Rig) -> bool) -> u64 {
    for _ in 0..limit_ms {
        r.run_ms(1);
        if done(r) {
            return r.now().as_nanos();
        }
    }
    panic!("not reached within {limit_ms} ms");
}

/// Send message 0 and return the instant the drive received it (end of the frame).
fn command(r: &mut Rig, cmd: u8, reference: u16) -> u64 {
    r.frames();
    let [lo, hi] = reference.to_le_bytes();
    r.send(f(440, &[0, cmd, lo, hi]));
    r.run_ms(1);
    let frames = r.frames();
    assert_eq!(frames[0].0, format!("1B8#00{cmd:02X}{lo:02X}{hi:02X}"));
    frames[0].2
}

#[test]
fn ramps_reach_the_reference_in_the_configured_time_per_direction() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    for (p, v) in [(P21, 200), (P22, 150), (P23, 100), (P24, 250)] {
        d.set_stored_param(p, v).unwrap();
    }
    let mut r = rig_with(d);
    // A load keeps the deceleration motoring, so the DC bus stays at the mains level.
    r.drive_mut().set_load_torque_pct(50.0);
    let steps = [
        // (command byte, expected output, ramp time in ms); the ramps run from 0 to fMAX
        // (P68 = 120 % of 50 Hz).
        (0b10_10_10_01u8, 60.0, 2000u64), // CW start: P21
        (0b00_00_01_00, 0.0, 1500),       // CW stop: P22
        (0b00_00_10_10, -60.0, 1000),     // CCW start: P23
        (0b00_00_01_00, 0.0, 2500),       // CCW stop: P24
    ];
    for (cmd, target, ramp_ms) in steps {
        let t0 = command(&mut r, cmd, 6000);
        let reached = until(&mut r, 5000, |r| r.drive().output_hz() == target);
        let expected = t0 + ramp_ms * MS;
        assert!(
            reached.abs_diff(expected) <= MS,
            "{cmd:08b}: reached {target} Hz at {reached} ns, expected {expected} ns ± 1 ms"
        );
    }
    assert!(!r.drive().alarms().any());
}

#[test]
fn ramp_to_half_the_maximum_frequency_takes_half_the_time() {
    let mut r = rig();
    let t0 = command(&mut r, 0b10_10_10_01, 3000);
    let reached = until(&mut r, 5000, |r| r.drive().output_hz() == 30.0);
    assert!(reached.abs_diff(t0 + 1500 * MS) <= MS);
}

#[test]
fn current_threshold_with_mux_18_1_stops_after_p94_1_s() {
    let mut r = rig();
    assert_eq!(
        r.exchange(f(1100, &[0x18, 0x01, 0x00])),
        ["44C#180100", "44B#180100"]
    );
    command(&mut r, 0b10_10_10_01, 5000);
    r.run_ms(3100);
    let t0 = r.now().as_nanos();
    // 320 % of rated torque: above the current limit (150 % of the drive = 300 % of the
    // motor with P61 = 50 %), below the overcurrent trip.
    r.drive_mut().set_load_torque_pct(320.0);
    let stop = until(&mut r, 3000, |r| r.drive().limit_stopped());
    assert!(stop.abs_diff(t0 + 1000 * MS) <= MS, "stopped at {stop}");
    until(&mut r, 60_000, |r| !r.drive().is_running());
    assert!(!r.drive().alarms().any());
    // The stop holds until the start command is removed and given again.
    r.drive_mut().set_load_torque_pct(0.0);
    r.run_ms(100);
    assert!(!r.drive().is_running());
    command(&mut r, 0b00_00_01_00, 5000);
    command(&mut r, 0b00_00_10_00, 5000);
    r.run_ms(10);
    assert!(r.drive().is_running());
}

#[test]
fn current_threshold_with_mux_18_0_keeps_running_in_limit() {
    let mut r = rig();
    command(&mut r, 0b10_10_10_01, 5000);
    r.run_ms(3100);
    r.drive_mut().set_load_torque_pct(320.0);
    r.run_ms(2000);
    assert!(r.drive().is_running());
    assert!(r.drive().in_limit());
    assert!(!r.drive().limit_stopped());
    // The limiter holds the current at the threshold and lowers the frequency.
    assert!((r.drive().current_pct() - 300.0).abs() < 1e-9);
    assert!(r.drive().output_hz() < 50.0);
}

fn trip_a2(r: &mut Rig) {
    command(r, 0b10_10_10_01, 5000);
    r.run_ms(3100);
    r.drive_mut().set_load_torque_pct(500.0);
    r.run_ms(2);
    assert!(r.drive().alarms().contains(A2));
    r.drive_mut().set_load_torque_pct(0.0);
}

#[test]
fn c35_1_resets_alarms_at_mains_return() {
    let mut r = rig();
    trip_a2(&mut r);
    r.power_cycle(1000);
    r.run_ms(1);
    assert!(!r.drive().alarms().any());
}

#[test]
fn c35_0_keeps_alarms_across_mains_loss() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(C35, 0).unwrap();
    let mut r = rig_with(d);
    trip_a2(&mut r);
    r.power_cycle(1000);
    r.run_ms(1);
    assert!(r.drive().alarms().contains(A2));
    command(&mut r, 0b10_10_10_01, 5000);
    r.run_ms(100);
    assert!(!r.drive().is_running());
}

fn restart_after_mains_dip(c50: i32) -> Rig {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(C50, c50).unwrap();
    let mut r = rig_with(d);
    command(&mut r, 0b10_10_10_01, 5000);
    r.run_ms(3100);
    r.power_cycle(100);
    r.run_ms(1);
    // The motor coasted 100 ms against friction (2 % torque, starting time 0.5 s): 2 Hz/s.
    let coasting = r.drive().motor_hz();
    assert!((coasting - 49.8).abs() < 0.01, "{coasting}");
    command(&mut r, 0b10_10_10_01, 5000);
    r
}

#[test]
fn c50_1_flying_restart_catches_the_coasting_motor() {
    let r = restart_after_mains_dip(1);
    assert!(r.drive().is_running());
    assert!(r.drive().output_hz() > 49.7, "{}", r.drive().output_hz());
    assert!(!r.drive().alarms().any());
}

#[test]
fn c50_0_start_into_a_turning_motor_trips_overcurrent() {
    let r = restart_after_mains_dip(0);
    assert!(r.drive().alarms().contains(A2));
    assert!(!r.drive().is_running());
}
