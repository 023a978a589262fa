//! CiA 402-2 operating modes on a [`Drive`] in virtual time: each test is named after the
//! mode and the object or statusword bit of the standard it checks.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use cantwin_can::Duration;
use cantwin_canopen::od::{ObjectDictionary, OdBuilder, Value};
use cantwin_cia402::dictionary::{MotionDefaults, ServoObjects, servo_objects};
use cantwin_cia402::drive::{Drive, DriveConfig, DriveEvent};
use cantwin_cia402::index::*;
use cantwin_cia402::physics::Switches;
use cantwin_cia402::{Mode, State, objects};

const TAU: f64 = core::f64::consts::TAU;

struct Axis {
    od: ObjectDictionary,
    drive: Drive,
    t: Duration,
}

impl Axis {
    fn with(config: DriveConfig) -> Axis {
        let spec = ServoObjects::all_modes(MotionDefaults::default());
        let desc = objects::add(OdBuilder::new(), servo_objects(&spec))
            .build()
            .unwrap();
        let mut od = ObjectDictionary::new(Arc::new(desc), 1);
        let drive = Drive::new(config, &mut od);
        Axis {
            od,
            drive,
            t: Duration::ZERO,
        }
    }

    fn new() -> Axis {
        Axis::with(DriveConfig::default())
    }

    fn set(&mut self, index: u16, sub: u8, v: Value) {
        self.od.set(index, sub, &v).unwrap();
        self.drive.parameters_changed();
        self.drive.evaluate(&mut self.od);
    }

    fn cw(&mut self, cw: u16) {
        self.set(CONTROLWORD, 0, Value::Unsigned16(cw));
    }

    fn mode(&mut self, m: Mode) {
        self.set(MODES_OF_OPERATION, 0, Value::Integer8(m.code()));
    }

    fn run_ms(&mut self, ms: u64) {
        self.t += Duration::from_millis(ms);
        self.drive.advance(&mut self.od, self.t);
    }

    fn run_us(&mut self, us: u64) {
        self.t += Duration::from_micros(us);
        self.drive.advance(&mut self.od, self.t);
    }

    fn sync(&mut self) {
        self.drive.sync(&mut self.od);
    }

    fn sw(&self) -> u16 {
        self.od.get_unsigned(STATUSWORD, 0).unwrap() as u16
    }

    fn i(&self, index: u16) -> i64 {
        self.od.get(index, 0).unwrap().as_i128().unwrap() as i64
    }

    fn enable(&mut self, m: Mode) {
        self.mode(m);
        self.cw(0x06);
        self.cw(0x0F);
        assert_eq!(self.drive.state(), State::OperationEnabled);
    }

    fn bit(&self, n: u32) -> bool {
        self.sw() & (1 << n) != 0
    }
}

#[test]
fn cia402_6061h_follows_when_the_drive_has_switched() {
    let mut a = Axis::new();
    assert_eq!(a.i(MODES_OF_OPERATION_DISPLAY), 0);
    a.mode(Mode::ProfileVelocity);
    assert_eq!(a.i(MODES_OF_OPERATION_DISPLAY), 3);
    a.enable(Mode::CyclicSyncPosition);
    assert_eq!(a.i(MODES_OF_OPERATION_DISPLAY), 8);
    assert_eq!(a.drive.mode(), Some(Mode::CyclicSyncPosition));
}

#[test]
fn cia402_6060h_unsupported_mode_is_not_taken() {
    let mut a = Axis::with(DriveConfig {
        modes: cantwin_cia402::SupportedModes::of(&[Mode::ProfilePosition]),
        ..DriveConfig::default()
    });
    a.mode(Mode::ProfilePosition);
    a.mode(Mode::CyclicSyncTorque);
    assert_eq!(a.i(MODES_OF_OPERATION_DISPLAY), 1);
    a.set(MODES_OF_OPERATION, 0, Value::Integer8(5));
    assert_eq!(a.i(MODES_OF_OPERATION_DISPLAY), 1);
}

#[test]
fn cia402_pp_single_set_point_acknowledge_handshake() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.run_ms(1);
    assert!(!a.bit(12));
    a.set(TARGET_POSITION, 0, Value::Integer32(4096));
    a.cw(0x3F); // new set-point, change set immediately
    assert!(a.bit(12), "set-point acknowledged at once: {:#06x}", a.sw());
    assert!(!a.bit(10), "moving");
    a.run_ms(5);
    assert!(a.bit(12), "acknowledge held while bit 4 is set");
    a.cw(0x2F);
    assert!(!a.bit(12), "acknowledge cleared with bit 4");
    a.run_ms(400);
    assert!(a.bit(10), "target reached: {:#06x}", a.sw());
    assert!((a.i(POSITION_ACTUAL_VALUE) - 4096).abs() <= 10);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 4096);
}

#[test]
fn cia402_pp_absolute_and_relative_targets() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(2000));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(400);
    assert!(a.bit(10));
    // Relative (bit 6): 2000 + 1000.
    a.set(TARGET_POSITION, 0, Value::Integer32(1000));
    a.cw(0x5F);
    a.cw(0x4F);
    a.run_ms(400);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 3000);
    // Absolute again: back to 500.
    a.set(TARGET_POSITION, 0, Value::Integer32(500));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(400);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 500);
    assert!((a.i(POSITION_ACTUAL_VALUE) - 500).abs() <= 10);
}

#[test]
fn cia402_pp_change_set_immediately() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(100_000));
    a.cw(0x3F);
    a.cw(0x2F);
    a.run_ms(100);
    let mid = a.i(POSITION_DEMAND_VALUE);
    assert!(mid > 0 && mid < 100_000);
    // A new set-point with bit 5 replaces the move at once: the axis turns back.
    a.set(TARGET_POSITION, 0, Value::Integer32(0));
    a.cw(0x3F);
    a.cw(0x2F);
    a.run_ms(800);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 0);
    assert!(a.bit(10));
}

#[test]
fn cia402_pp_set_of_set_points_buffers_one() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(8192));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(20);
    // Second set-point while moving, bit 5 = 0: buffered, acknowledged, and bit 12 stays
    // set while the buffer is full.
    a.set(TARGET_POSITION, 0, Value::Integer32(0));
    a.cw(0x1F);
    assert!(a.bit(12));
    a.cw(0x0F);
    assert!(a.bit(12), "buffer full");
    // A third is not taken.
    a.set(TARGET_POSITION, 0, Value::Integer32(99_999));
    a.cw(0x1F);
    a.cw(0x0F);
    let mut max = 0;
    for _ in 0..800 {
        a.run_ms(1);
        max = max.max(a.i(POSITION_DEMAND_VALUE));
    }
    assert_eq!(max, 8192, "the first set-point was reached");
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 0, "then the buffered one");
    assert!(!a.bit(12));
    assert!(a.bit(10));
}

#[test]
fn cia402_pp_change_on_set_point_passes_through() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(4096));
    a.cw(0x1F);
    a.cw(0x0F);
    a.set(TARGET_POSITION, 0, Value::Integer32(20_000));
    a.cw(0x21F & !0x20); // bit 9 + bit 4
    a.cw(0x20F);
    let mut slowest_after_start = f64::MAX;
    let mut passed = false;
    for _ in 0..1000 {
        a.run_ms(1);
        let p = a.i(POSITION_DEMAND_VALUE);
        if p > 1000 && p < 19_000 {
            slowest_after_start = slowest_after_start.min(a.i(VELOCITY_DEMAND_VALUE) as f64);
        }
        passed |= p > 4096;
    }
    assert!(passed);
    assert!(
        slowest_after_start > 10_000.0,
        "no stop at 4096: {slowest_after_start}"
    );
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 20_000);
}

#[test]
fn cia402_pp_target_reached_after_position_window_time() {
    let mut a = Axis::new();
    a.set(POSITION_WINDOW_TIME, 0, Value::Unsigned16(50));
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(2048));
    a.cw(0x1F);
    a.cw(0x0F);
    let mut arrived = None;
    let mut reached = None;
    for ms in 1..1000 {
        a.run_ms(1);
        if arrived.is_none()
            && a.i(POSITION_DEMAND_VALUE) == 2048
            && (a.i(POSITION_ACTUAL_VALUE) - 2048).abs() <= 10
        {
            arrived = Some(ms);
        }
        if reached.is_none() && a.bit(10) {
            reached = Some(ms);
        }
    }
    let (arrived, reached) = (arrived.unwrap(), reached.unwrap());
    assert!(
        reached >= arrived + 50 && reached <= arrived + 52,
        "{arrived} {reached}"
    );
}

#[test]
fn cia402_pp_607dh_software_position_limit() {
    let mut a = Axis::new();
    a.set(SOFTWARE_POSITION_LIMIT, 1, Value::Integer32(-1000));
    a.set(SOFTWARE_POSITION_LIMIT, 2, Value::Integer32(3000));
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(10_000));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(500);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 3000);
    assert!(a.bit(11), "internal limit active");
    a.set(TARGET_POSITION, 0, Value::Integer32(0));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(500);
    assert!(!a.bit(11));
}

#[test]
fn cia402_pp_60f4h_following_error_bit_13_and_fault() {
    let mut a = Axis::new();
    a.enable(Mode::ProfilePosition);
    a.run_ms(2);
    // The shaft is blocked: the demand moves away, the position does not.
    a.drive.motor_mut().jammed = true;
    a.set(TARGET_POSITION, 0, Value::Integer32(40_000));
    a.cw(0x1F);
    a.cw(0x0F);
    let mut bit13 = false;
    for _ in 0..200 {
        a.run_ms(1);
        bit13 |= a.bit(13);
        if a.drive.state() != State::OperationEnabled {
            break;
        }
    }
    assert!(bit13, "statusword bit 13 was shown");
    assert!(a.i(FOLLOWING_ERROR_ACTUAL_VALUE).abs() > 2048);
    a.run_ms(100);
    assert_eq!(a.drive.state(), State::Fault);
    assert_eq!(a.i(ERROR_CODE), 0x8611);
    assert!(a.drive.take_events().contains(&DriveEvent::Fault(0x8611)));
    a.drive.motor_mut().jammed = false;
    a.cw(0x80);
    assert_eq!(a.drive.state(), State::SwitchOnDisabled);
    assert_eq!(a.i(ERROR_CODE), 0);
    assert_eq!(a.drive.take_events(), [DriveEvent::Cleared(0x8611)]);
}

#[test]
fn cia402_pv_acceleration_ramp_and_velocity_window() {
    let mut a = Axis::new();
    a.enable(Mode::ProfileVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(40_960));
    // 409 600 units/s²: 40 960 units/s after 100 ms.
    a.run_ms(50);
    let v = a.i(VELOCITY_DEMAND_VALUE);
    assert!((v - 20_480).abs() < 600, "{v}");
    assert!(!a.bit(10));
    a.run_ms(100);
    assert!(a.bit(10), "within the velocity window: {:#06x}", a.sw());
    assert!((a.i(VELOCITY_ACTUAL_VALUE) - 40_960).abs() <= 100);
    assert!(!a.bit(12), "speed is not 0");
}

#[test]
fn cia402_pv_speed_zero_after_threshold_time() {
    let mut a = Axis::new();
    a.set(VELOCITY_THRESHOLD_TIME, 0, Value::Unsigned16(20));
    a.enable(Mode::ProfileVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(10_000));
    a.run_ms(100);
    assert!(!a.bit(12));
    a.set(TARGET_VELOCITY, 0, Value::Integer32(0));
    let mut zero_at = None;
    let mut stopped_at = None;
    for ms in 1..200 {
        a.run_ms(1);
        if stopped_at.is_none() && a.i(VELOCITY_ACTUAL_VALUE).abs() <= 100 {
            stopped_at = Some(ms);
        }
        if zero_at.is_none() && a.bit(12) {
            zero_at = Some(ms);
        }
    }
    let (s, z) = (stopped_at.unwrap(), zero_at.unwrap());
    assert!(z >= s + 19 && z <= s + 21, "{s} {z}");
}

#[test]
fn cia402_pv_halt_decelerates_with_profile_deceleration() {
    let mut a = Axis::new();
    a.set(PROFILE_DECELERATION, 0, Value::Unsigned32(102_400));
    a.enable(Mode::ProfileVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(40_960));
    a.run_ms(200);
    a.cw(0x10F);
    a.run_ms(200);
    // 102 400 units/s²: 20 480 units/s lost in 200 ms.
    let v = a.i(VELOCITY_DEMAND_VALUE);
    assert!((v - 20_480).abs() < 800, "{v}");
    assert!(!a.bit(10));
    a.run_ms(300);
    assert!(a.bit(10), "halted: target reached");
    assert_eq!(a.drive.state(), State::OperationEnabled);
}

#[test]
fn cia402_pt_torque_slope() {
    let mut a = Axis::new();
    a.set(TORQUE_SLOPE, 0, Value::Unsigned32(1000));
    a.enable(Mode::ProfileTorque);
    a.set(TARGET_TORQUE, 0, Value::Integer16(100));
    a.run_ms(50);
    assert!(
        (a.i(TORQUE_ACTUAL_VALUE) - 50).abs() <= 1,
        "{}",
        a.i(TORQUE_ACTUAL_VALUE)
    );
    assert!(!a.bit(10));
    a.run_ms(51);
    assert_eq!(a.i(TORQUE_ACTUAL_VALUE), 100);
    assert!(a.bit(10));
    // 10 % of 1.27 N·m accelerates the rotor: the motor turns.
    assert!(a.i(VELOCITY_ACTUAL_VALUE) > 0);
    assert!(a.i(CURRENT_ACTUAL_VALUE) > 0);
}

#[test]
fn cia402_pt_6072h_max_torque_is_an_internal_limit() {
    let mut a = Axis::new();
    a.set(MAX_TORQUE, 0, Value::Unsigned16(50));
    a.set(TORQUE_SLOPE, 0, Value::Unsigned32(1_000_000));
    a.enable(Mode::ProfileTorque);
    a.set(TARGET_TORQUE, 0, Value::Integer16(-300));
    a.run_ms(2);
    assert_eq!(a.i(TORQUE_ACTUAL_VALUE), -50);
    assert!(a.bit(11));
}

#[test]
fn cia402_csp_interpolates_over_60c2h() {
    let mut a = Axis::new();
    a.enable(Mode::CyclicSyncPosition);
    a.sync();
    a.run_ms(1);
    assert!(a.bit(12), "drive follows the command value");
    // 1 ms period: a set-point of 400 at a SYNC is reached linearly within the period.
    a.set(TARGET_POSITION, 0, Value::Integer32(400));
    a.sync();
    a.run_us(250);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 100);
    a.run_us(500);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 300);
    a.run_us(250);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 400);
    // A 2 ms period halves the slope.
    a.set(INTERPOLATION_TIME_PERIOD, 1, Value::Unsigned8(2));
    a.set(TARGET_POSITION, 0, Value::Integer32(800));
    a.sync();
    a.run_ms(1);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 600);
    // Streaming at 1 ms: the actual follows with a small following error.
    a.set(INTERPOLATION_TIME_PERIOD, 1, Value::Unsigned8(1));
    for k in 1..=200 {
        a.set(TARGET_POSITION, 0, Value::Integer32(800 + k * 20));
        a.sync();
        a.run_ms(1);
    }
    let fe = a.i(FOLLOWING_ERROR_ACTUAL_VALUE);
    assert!(fe.abs() < 20, "{fe}");
    assert!((a.i(POSITION_ACTUAL_VALUE) - 4800).abs() < 30);
    assert!((a.i(VELOCITY_ACTUAL_VALUE) - 20_000).abs() < 1000);
}

#[test]
fn cia402_csp_target_ignored_while_halted() {
    let mut a = Axis::new();
    a.enable(Mode::CyclicSyncPosition);
    a.sync();
    a.run_ms(1);
    assert!(a.bit(12));
    a.cw(0x10F);
    a.set(TARGET_POSITION, 0, Value::Integer32(5000));
    a.sync();
    a.run_ms(10);
    assert!(!a.bit(12), "target position ignored");
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 0);
}

#[test]
fn cia402_csp_missing_sync_holds_the_last_set_point() {
    let mut a = Axis::new();
    a.enable(Mode::CyclicSyncPosition);
    for k in 1..=50 {
        a.set(TARGET_POSITION, 0, Value::Integer32(k * 10));
        a.sync();
        a.run_ms(1);
    }
    // The master stops sending: no extrapolation, the axis settles at the last set-point.
    a.set(TARGET_POSITION, 0, Value::Integer32(99_999));
    a.run_ms(200);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 500);
    assert!((a.i(POSITION_ACTUAL_VALUE) - 500).abs() <= 2);
    assert_eq!(a.drive.state(), State::OperationEnabled);
}

#[test]
fn cia402_csv_follows_target_velocity_at_sync() {
    let mut a = Axis::new();
    a.enable(Mode::CyclicSyncVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(8192));
    a.set(VELOCITY_OFFSET, 0, Value::Integer32(1000));
    a.run_ms(100);
    assert!(a.bit(12));
    assert!(
        (a.i(VELOCITY_ACTUAL_VALUE) - 9192).abs() < 100,
        "{}",
        a.i(VELOCITY_ACTUAL_VALUE)
    );
}

#[test]
fn cia402_cst_follows_target_torque_at_sync() {
    let mut a = Axis::new();
    a.enable(Mode::CyclicSyncTorque);
    a.set(TARGET_TORQUE, 0, Value::Integer16(-40));
    a.set(TORQUE_OFFSET, 0, Value::Integer16(-10));
    a.run_ms(1);
    assert_eq!(a.i(TORQUE_ACTUAL_VALUE), -50);
    a.run_ms(20);
    assert!(a.i(VELOCITY_ACTUAL_VALUE) < 0);
}

#[test]
fn cia402_ip_linear_interpolation_while_enabled() {
    let mut a = Axis::new();
    a.enable(Mode::InterpolatedPosition);
    a.set(INTERPOLATION_DATA_RECORD, 1, Value::Integer32(1000));
    a.sync();
    a.run_ms(5);
    assert!(!a.bit(12), "ip mode not active without bit 4");
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 0);
    a.cw(0x1F);
    a.run_ms(1);
    assert!(a.bit(12), "ip mode active");
    a.sync();
    a.run_us(500);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 500);
    a.run_ms(100);
    assert_eq!(a.i(POSITION_DEMAND_VALUE), 1000);
    assert!(a.bit(10));
}

fn homing_axis(switches: Switches) -> Axis {
    let mut a = Axis::with(DriveConfig {
        switches,
        ..DriveConfig::default()
    });
    a.enable(Mode::Homing);
    a
}

fn home(a: &mut Axis, method: i8) -> u16 {
    a.set(HOMING_METHOD, 0, Value::Integer8(method));
    a.cw(0x1F);
    for _ in 0..20_000 {
        a.run_ms(1);
        let hm = a.sw() & 0x3400;
        if hm == 0x1400 || hm & 0x2000 != 0 {
            break;
        }
    }
    a.run_ms(200);
    a.sw() & 0x3400
}

/// The motor angle (rad) where position `p` reads after homing, and the angle now.
fn angle(a: &Axis) -> f64 {
    a.drive.motor().state.angle
}

#[test]
fn cia402_hm_methods_35_37_current_position() {
    for method in [35, 37] {
        let mut a = Axis::new();
        a.enable(Mode::ProfileVelocity);
        a.set(TARGET_VELOCITY, 0, Value::Integer32(4096));
        a.run_ms(300);
        a.set(TARGET_VELOCITY, 0, Value::Integer32(0));
        a.run_ms(300);
        a.set(HOME_OFFSET, 0, Value::Integer32(-100));
        a.mode(Mode::Homing);
        // Not started: bits 13, 12, 10 = 0, 0, 1.
        a.run_ms(1);
        assert_eq!(a.sw() & 0x3400, 0x0400);
        assert_eq!(home(&mut a, method), 0x1400, "method {method}");
        assert_eq!(a.i(POSITION_ACTUAL_VALUE), -100);
    }
}

#[test]
fn cia402_hm_methods_1_2_limit_switch_and_index_pulse() {
    let switches = Switches {
        negative_limit: Some(-3.3),
        positive_limit: Some(9.1),
        home: None,
        home_below: false,
        home_end: None,
    };
    let mut a = homing_axis(switches);
    assert_eq!(home(&mut a, 1), 0x1400);
    // Home: the first index pulse (a whole revolution) beyond -3.3 rad going positive, at 0.
    // The axis stopped a little past it, and position 0 is that pulse.
    let p = a.i(POSITION_ACTUAL_VALUE) as f64;
    let expected = (angle(&a) - 0.0) / TAU * 4096.0;
    assert!((p - expected).abs() < 2.0, "{p} {expected}");
    let mut a = homing_axis(switches);
    assert_eq!(home(&mut a, 2), 0x1400);
    // Method 2: the first index pulse below 9.1 rad going negative, 2π.
    let p = a.i(POSITION_ACTUAL_VALUE) as f64;
    let expected = (angle(&a) - TAU) / TAU * 4096.0;
    assert!((p - expected).abs() < 2.0, "{p} {expected}");
}

#[test]
fn cia402_hm_methods_3_to_6_home_switch_and_index_pulse() {
    let switches = Switches {
        negative_limit: Some(-40.0),
        positive_limit: Some(40.0),
        home: Some(8.0),
        home_below: false,
        home_end: None,
    };
    // Method 3 from below the switch: on, back off; home is the pulse below 8 rad (2 rev).
    // Method 4: onto the switch; home is the pulse above 8 rad (2 rev, 12.57 rad).
    for (method, pulse) in [(3, 1.0), (4, 2.0)] {
        let mut a = homing_axis(switches);
        assert_eq!(home(&mut a, method), 0x1400, "method {method}");
        let p = a.i(POSITION_ACTUAL_VALUE) as f64;
        let expected = (angle(&a) - pulse * TAU) / TAU * 4096.0;
        assert!(
            (p - expected).abs() < 2.0,
            "method {method}: {p} {expected}"
        );
    }
    // Methods 5 and 6 mirror 3 and 4 on a negative home switch (active below its edge):
    // started on it, method 5 moves off it and homes on the pulse above the edge (4π),
    // method 6 moves off, back onto it, and homes on the pulse below (2π).
    let negative = Switches {
        home_below: true,
        ..switches
    };
    for (method, pulse) in [(5, 2.0), (6, 1.0)] {
        let mut a = homing_axis(negative);
        assert_eq!(home(&mut a, method), 0x1400, "method {method}");
        let p = a.i(POSITION_ACTUAL_VALUE) as f64;
        let expected = (angle(&a) - pulse * TAU) / TAU * 4096.0;
        assert!(
            (p - expected).abs() < 2.0,
            "method {method}: {p} {expected}"
        );
    }
    // Method 5 on a positive home switch searches negative for a switch that is active
    // only above its edge: it meets the negative limit switch, a homing error at rest.
    let mut a = homing_axis(switches);
    assert_eq!(home(&mut a, 5), 0x2400);
    assert!(angle(&a) < -40.0);
}

#[test]
fn cia402_hm_methods_17_to_22_switch_transition() {
    let switches = Switches {
        negative_limit: Some(-3.3),
        positive_limit: Some(9.1),
        home: Some(2.0),
        home_below: false,
        home_end: None,
    };
    for (method, edge) in [(17, -3.3), (18, 9.1), (19, 2.0), (20, 2.0)] {
        let mut a = homing_axis(switches);
        assert_eq!(home(&mut a, method), 0x1400, "method {method}");
        let p = a.i(POSITION_ACTUAL_VALUE) as f64;
        let expected = (angle(&a) - edge) / TAU * 4096.0;
        // The transition is sampled by the loop: within one cycle at search-for-zero speed.
        assert!(
            (p - expected).abs() < 4.0,
            "method {method}: {p} {expected}"
        );
    }
}

/// A home switch that is a cam from 8 to 14 rad (index pulses at 2π, 4π, 6π: one below
/// it, one on it, one above), between limit switches at −4 and 22 rad.
const CAM: Switches = Switches {
    negative_limit: Some(-4.0),
    positive_limit: Some(22.0),
    home: Some(8.0),
    home_below: false,
    home_end: Some(14.0),
};

/// Starts left of the cam, on it, and right of it (rad).
const STARTS: [f64; 3] = [1.0, 11.0, 17.0];

/// Homes with `method` from motor angle `start` on [`CAM`]: the statusword's bits 13, 12
/// and 10, the motor angle the home position is at (position 0, home offset 0), the
/// lowest and highest angles of the search, and how often it reversed before homing was
/// attained.
fn home_on_cam(method: i8, start: f64) -> (u16, f64, f64, f64, u32) {
    let mut a = Axis::with(DriveConfig {
        switches: CAM,
        ..DriveConfig::default()
    });
    // Placed before the drive is enabled, so that it holds the start.
    a.drive.motor_mut().state.angle = start;
    a.enable(Mode::Homing);
    a.set(HOMING_METHOD, 0, Value::Integer8(method));
    a.cw(0x1F);
    let (mut lo, mut hi) = (start, start);
    let (mut sign, mut reversals) = (0.0, 0);
    for _ in 0..20_000 {
        a.run_ms(1);
        lo = lo.min(angle(&a));
        hi = hi.max(angle(&a));
        // A reversal: the speed (rad/s) changes sign beyond a band around rest.
        let speed = a.drive.motor().state.speed;
        if speed.abs() > 1.0 && a.sw() & 0x1000 == 0 {
            if sign != 0.0 && speed.signum() != sign {
                reversals += 1;
            }
            sign = speed.signum();
        }
        let hm = a.sw() & 0x3400;
        if hm == 0x1400 || hm & 0x2000 != 0 {
            break;
        }
    }
    a.run_ms(200);
    assert!(a.bit(12) == (a.sw() & 0x3400 == 0x1400));
    let home = angle(&a) - a.i(POSITION_ACTUAL_VALUE) as f64 / 4096.0 * TAU;
    (a.sw() & 0x3400, home, lo, hi, reversals)
}

/// Methods 7–14 and 23–30 from each of [`STARTS`]: homing attained (bit 12) and completed
/// at the `expected` angle (within `tol` rad) from every start; returns the searched
/// ranges (lowest, highest angle) and the reversals per start.
fn cam_method(method: i8, expected: f64, tol: f64) -> [(f64, f64, u32); 3] {
    STARTS.map(|start| {
        let (hm, home, lo, hi, reversals) = home_on_cam(method, start);
        assert_eq!(
            hm, 0x1400,
            "method {method} from {start} rad: homing attained"
        );
        assert!(
            (home - expected).abs() < tol,
            "method {method} from {start} rad: home at {home} rad, not {expected}"
        );
        (lo, hi, reversals)
    })
}

/// One increment in rad.
const INC: f64 = TAU / 4096.0;

#[test]
fn cia402_hm_methods_7_to_10_home_switch_with_reversal_and_index_pulse() {
    // Positive first; home on the index pulse beyond the cam's negative edge moving
    // negative (7: 2π), moving positive (8: 4π), beyond its positive edge moving negative
    // (9: 4π) and moving positive (10: 6π).
    for (method, pulse) in [(7, 1.0), (8, 2.0), (9, 2.0), (10, 3.0)] {
        let r = cam_method(method, pulse * TAU, 2.0 * INC);
        // Started left of the cam it is found without the limit switch; started right of
        // it, the search reverses at the positive limit switch (22 rad).
        assert!(r[0].1 < 22.0, "method {method}: {:?}", r[0]);
        assert!(r[2].1 > 22.0, "method {method}: {:?}", r[2]);
        // None of them meets the negative limit switch.
        assert!(
            r.iter().all(|(lo, ..)| *lo > -4.0),
            "method {method}: {r:?}"
        );
        // Method 7 from the left: onto the cam and back off it (one reversal); from it:
        // none; from the right: at the limit switch only.
        let want = match method {
            7 => [1, 0, 1],
            // From the left it enters the cam through the edge sought, the way it is
            // sought, and goes on to the pulse; on the cam it moves off and back on; from
            // the right it reverses at the limit switch and again beyond the cam.
            8 => [0, 1, 2],
            // Through the cam and back onto it; off it and back; from the right it enters
            // it through the positive edge on the way back from the limit switch.
            9 => [1, 1, 1],
            // Through the cam; off it; back from the limit switch and off it again.
            _ => [0, 0, 2],
        };
        assert_eq!(r.map(|r| r.2), want, "method {method}: {r:?}");
    }
}

#[test]
fn cia402_hm_methods_11_to_14_home_switch_with_reversal_and_index_pulse() {
    // Negative first, mirrored: 11 beyond the positive edge moving positive (6π), 12
    // beyond it moving negative (4π), 13 beyond the negative edge moving positive (4π),
    // 14 moving negative (2π).
    for (method, pulse) in [(11, 3.0), (12, 2.0), (13, 2.0), (14, 1.0)] {
        let r = cam_method(method, pulse * TAU, 2.0 * INC);
        // Started right of the cam it is found without the limit switch; started left of
        // it, the search reverses at the negative limit switch (−4 rad).
        assert!(r[2].0 > -4.0, "method {method}: {:?}", r[2]);
        assert!(r[0].0 < -4.0, "method {method}: {:?}", r[0]);
        assert!(
            r.iter().all(|(_, hi, _)| *hi < 22.0),
            "method {method}: {r:?}"
        );
        // The reversals of 7–10, mirrored (starts left, on, right of the cam).
        let want = match method {
            11 => [1, 0, 1],
            12 => [2, 1, 0],
            13 => [1, 1, 1],
            _ => [2, 0, 0],
        };
        assert_eq!(r.map(|r| r.2), want, "method {method}: {r:?}");
    }
}

#[test]
fn cia402_hm_methods_23_to_30_home_switch_with_reversal() {
    // As 7–14 without the index pulse: the cam's edge is the home position, sampled by the
    // loop at the search-for-zero speed (4096 units/s, about one increment a cycle).
    for (method, edge) in [
        (23, 8.0),
        (24, 8.0),
        (25, 14.0),
        (26, 14.0),
        (27, 14.0),
        (28, 14.0),
        (29, 8.0),
        (30, 8.0),
    ] {
        let r = cam_method(method, edge, 4.0 * INC);
        let (reverses, found) = if method <= 26 {
            (r[2].1 > 22.0, r[0].1 < 22.0)
        } else {
            (r[0].0 < -4.0, r[2].0 > -4.0)
        };
        assert!(reverses && found, "method {method}: {r:?}");
    }
}

#[test]
fn cia402_hm_methods_7_to_14_need_the_limit_switch_they_reverse_at() {
    // Without the positive limit switch wired, method 7 is a homing error at once; with
    // the cam missing (no home switch beyond the start), method 7 reverses at the positive
    // limit switch and then meets the negative one: a homing error.
    let mut a = homing_axis(Switches {
        positive_limit: None,
        ..CAM
    });
    assert_eq!(home(&mut a, 7), 0x2400);
    let mut a = homing_axis(Switches {
        negative_limit: Some(-2.0),
        positive_limit: Some(3.0),
        ..CAM
    });
    assert_eq!(home(&mut a, 7), 0x2400);
    assert!(angle(&a) < -2.0);
}

#[test]
fn cia402_hm_methods_33_34_index_pulse() {
    for (method, dir) in [(33, -1.0), (34, 1.0)] {
        let mut a = homing_axis(Switches::NONE);
        a.drive.motor_mut().state.angle = 1.0;
        assert_eq!(home(&mut a, method), 0x1400, "method {method}");
        let pulse = if dir < 0.0 { 0.0 } else { TAU };
        let p = a.i(POSITION_ACTUAL_VALUE) as f64;
        let expected = (angle(&a) - pulse) / TAU * 4096.0;
        assert!(
            (p - expected).abs() < 2.0,
            "method {method}: {p} {expected}"
        );
    }
}

#[test]
fn cia402_hm_error_on_a_limit_switch_in_the_search() {
    // Method 1 needs the negative limit switch: without it wired, a homing error at once.
    let mut a = homing_axis(Switches::NONE);
    assert_eq!(home(&mut a, 1), 0x2400);
    // Method 3 runs into the positive limit switch before any home switch.
    let mut a = homing_axis(Switches {
        negative_limit: None,
        positive_limit: Some(3.0),
        home: Some(50.0),
        home_below: false,
        home_end: None,
    });
    assert_eq!(home(&mut a, 3), 0x2400);
    assert!(angle(&a) > 3.0);
}

#[test]
fn cia402_hm_interrupted_by_bit_4() {
    let mut a = homing_axis(Switches {
        negative_limit: Some(-1000.0),
        positive_limit: None,
        home: None,
        home_below: false,
        home_end: None,
    });
    a.set(HOMING_METHOD, 0, Value::Integer8(1));
    a.cw(0x1F);
    a.run_ms(50);
    assert_eq!(a.sw() & 0x3400, 0x0000, "in progress");
    a.cw(0x0F);
    a.run_ms(300);
    assert_eq!(a.sw() & 0x3400, 0x0400, "interrupted, at rest");
}

#[test]
fn cia402_vl_in_the_servo_drive() {
    let mut a = Axis::new();
    a.enable(Mode::Velocity);
    a.cw(0x7F);
    a.set(VL_TARGET_VELOCITY, 0, Value::Integer16(600));
    a.run_ms(300);
    // 1000 rpm/s: 300 rpm after 300 ms, and the motor follows.
    assert_eq!(a.i(VL_VELOCITY_DEMAND), 300);
    assert!((a.i(VL_VELOCITY_ACTUAL_VALUE) - 300).abs() <= 3);
    a.run_ms(400);
    assert!(a.bit(10));
}

#[test]
fn cia402_60fdh_limit_switch_stops_and_allows_moving_away() {
    let mut a = Axis::with(DriveConfig {
        switches: Switches {
            negative_limit: None,
            positive_limit: Some(6.0),
            home: None,
            home_below: false,
            home_end: None,
        },
        ..DriveConfig::default()
    });
    a.enable(Mode::ProfileVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(8192));
    a.run_ms(1000);
    assert_eq!(a.i(DIGITAL_INPUTS) & 2, 2, "on the positive limit switch");
    assert!(a.bit(11), "internal limit active");
    assert!(a.i(VELOCITY_ACTUAL_VALUE).abs() <= 100, "stopped");
    let stop = angle(&a);
    // 8192 units/s at 819 200 units/s²: 40 units of braking beyond the switch.
    assert!(stop > 6.0 && stop < 6.0 + 0.2, "{stop}");
    a.set(TARGET_VELOCITY, 0, Value::Integer32(-8192));
    a.run_ms(500);
    assert!(angle(&a) < 6.0);
    assert!(!a.bit(11));
}

#[test]
fn cia402_605ah_quick_stop_options_stop_and_stay() {
    for (option, stays) in [(2i16, false), (6, true)] {
        let mut a = Axis::new();
        a.set(QUICK_STOP_OPTION_CODE, 0, Value::Integer16(option));
        a.enable(Mode::ProfileVelocity);
        a.set(TARGET_VELOCITY, 0, Value::Integer32(40_960));
        a.run_ms(200);
        a.cw(0x0B);
        assert_eq!(a.drive.state(), State::QuickStopActive);
        // 819 200 units/s² stops 40 960 units/s in 50 ms.
        a.run_ms(20);
        assert!(a.i(VELOCITY_ACTUAL_VALUE) > 10_000);
        a.run_ms(80);
        assert!(a.i(VELOCITY_ACTUAL_VALUE).abs() <= 100);
        let expected = if stays {
            State::QuickStopActive
        } else {
            State::SwitchOnDisabled
        };
        assert_eq!(a.drive.state(), expected, "option {option}");
        if stays {
            assert!(a.bit(10), "stopped");
            a.cw(0x0F);
            assert_eq!(a.drive.state(), State::OperationEnabled, "transition 16");
        }
    }
}

#[test]
fn cia402_605ah_quick_stop_option_0_coasts() {
    let mut a = Axis::new();
    a.set(QUICK_STOP_OPTION_CODE, 0, Value::Integer16(0));
    a.enable(Mode::ProfileVelocity);
    a.set(TARGET_VELOCITY, 0, Value::Integer32(40_960));
    a.run_ms(200);
    a.cw(0x0B);
    a.run_ms(1);
    assert_eq!(a.drive.state(), State::SwitchOnDisabled);
    // Friction alone slows the motor: still turning 20 ms later.
    a.run_ms(20);
    assert!(a.i(VELOCITY_ACTUAL_VALUE) > 20_000);
    assert_eq!(a.i(TORQUE_ACTUAL_VALUE), 0);
}

#[test]
fn cia402_fsa_halt_605dh_stops_with_target_reached() {
    let mut a = Axis::new();
    a.set(HALT_OPTION_CODE, 0, Value::Integer16(2));
    a.enable(Mode::ProfilePosition);
    a.set(TARGET_POSITION, 0, Value::Integer32(1_000_000));
    a.cw(0x1F);
    a.cw(0x0F);
    a.run_ms(100);
    a.cw(0x10F);
    a.run_ms(100);
    assert!(a.bit(10), "halted");
    assert_eq!(a.drive.state(), State::OperationEnabled);
}

#[test]
fn cia402_603fh_over_current_trips() {
    let mut a = Axis::new();
    a.enable(Mode::ProfileVelocity);
    a.run_ms(1);
    a.drive.inverter_mut().phase_short = true;
    a.run_ms(1);
    assert_eq!(a.drive.state(), State::Fault);
    assert_eq!(a.i(ERROR_CODE), 0x2310);
    // With the bridge off the trip can be reset; switching on again trips again.
    a.cw(0x80);
    assert_eq!(a.drive.state(), State::SwitchOnDisabled);
    a.cw(0x06);
    a.cw(0x0F);
    a.run_ms(1);
    assert_eq!(a.drive.state(), State::Fault);
}

#[test]
fn cia402_603fh_dc_link_under_voltage() {
    let mut a = Axis::new();
    a.cw(0x06);
    a.run_ms(1);
    assert!(a.bit(4), "voltage enabled");
    assert_eq!(a.i(DC_LINK_CIRCUIT_VOLTAGE), 325_000);
    a.drive.inverter_mut().dc_link = 100.0;
    a.run_ms(1);
    assert!(!a.bit(4));
    a.cw(0x0F);
    a.run_ms(1);
    assert_eq!(a.drive.state(), State::Fault);
    assert_eq!(a.i(ERROR_CODE), 0x3220);
}
