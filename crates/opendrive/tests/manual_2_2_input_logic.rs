//! Manual §2.2: `[(C52 or 114) and CAN_remote_control and /DIP S1]` chooses between CAN
//! (functions 100 CAN_Start, 112 CAN_Reverse) and the terminals.
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_opendrive::OpenDrive;
use cantwin_opendrive::params::{C52, input_connection};
use common::*;

const CAN_START_50HZ: [u8; 4] = [0, 0b10_10_10_01, 0x88, 0x13];

#[test]
fn can_start_runs_the_drive_when_the_expression_is_true() {
    let mut r = rig();
    r.exchange(f(440, &CAN_START_50HZ));
    assert!(r.drive().can_control());
    r.run_ms(100);
    assert!(r.drive().is_running());
    assert!(r.drive().output_hz() > 0.0);
    // CAN-Reverse set: rotation to the left.
    r.exchange(f(440, &[0, 0b00_00_00_10, 0x88, 0x13]));
    r.run_ms(1000);
    assert!(r.drive().output_hz() < 0.0);
}

#[test]
fn without_command_remote_the_terminals_rule() {
    let mut r = rig();
    // Reference remote only: the CAN reference is used, start comes from input 4 (C04 = 0,
    // function 100).
    r.exchange(f(440, &[0, 0b10_01_00_00, 0x88, 0x13]));
    assert!(!r.drive().can_control());
    r.run_ms(100);
    assert!(!r.drive().is_running());
    r.drive_mut().set_input(4, true);
    r.run_ms(3100);
    assert!((r.drive().output_hz() - 50.0).abs() < 1e-9);
    // With command remote set, the terminal start is ignored and CAN-Start is reset: stop.
    r.exchange(f(440, &[0, 0b00_10_00_00, 0x88, 0x13]));
    r.run_ms(20);
    assert!(r.drive().output_hz() < 50.0);
}

#[test]
fn c52_off_needs_a_logic_input_with_function_114() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(C52, 0).unwrap();
    // Input 1 carries function 114 (C01 = 14).
    d.set_stored_param(input_connection(1), 14).unwrap();
    let mut r = rig_with(d);
    r.drive_mut().set_analog_reference_hz(10.0);
    r.exchange(f(440, &CAN_START_50HZ));
    assert!(!r.drive().can_control());
    r.run_ms(100);
    assert!(!r.drive().is_running(), "CAN-Start must be ignored");
    // The CAN reference is not used either: the terminal's 10 Hz is in use.
    assert_eq!(r.drive().reference_hz(), 10.0);
    r.drive_mut().set_input(1, true);
    assert!(r.drive().can_control());
    assert_eq!(r.drive().reference_hz(), 50.0);
    r.run_ms(100);
    assert!(r.drive().is_running());
    r.drive_mut().set_input(1, false);
    r.run_ms(3100);
    assert!(
        !r.drive().is_running(),
        "back to the terminals, where start is off"
    );
}

#[test]
fn terminal_reverse_is_function_112() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(input_connection(2), 12).unwrap();
    let mut r = rig_with(d);
    r.drive_mut().set_analog_reference_hz(20.0);
    r.drive_mut().set_input(4, true);
    r.drive_mut().set_input(2, true);
    r.run_ms(2000);
    assert!((r.drive().output_hz() + 20.0).abs() < 1e-9);
}
