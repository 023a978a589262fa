//! Manual §2.3: DIP switch S1 loads the defaults (except the reserved values) when it went
//! 0 → 1 with the drive off; the drive then ignores CAN until S1 is back at 0 and the drive
//! is powered again; switching it while powered does nothing.
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_opendrive::OpenDrive;
use cantwin_opendrive::params::{P21, P61};
use common::*;

const READ: [u8; 1] = [0x80];

#[test]
fn dip_s1_sequence() {
    let mut d = OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(P21, 500).unwrap();
    d.set_stored_param(P61, 400).unwrap();
    let mut r = rig_with(d);
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80", "1B7#00550000"]);

    // Switching S1 while powered: no action.
    r.drive_mut().set_dip_s1(true);
    r.run_ms(10);
    assert_eq!(r.drive().param(P21), 500);
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80", "1B7#00550000"]);

    // Power-up with S1 at 1 after 0: defaults loaded and saved, reserved P61 kept.
    r.power_cycle(100);
    r.run_ms(1);
    assert_eq!(r.drive().param(P21), 300);
    assert_eq!(r.drive().saved_param(P21), 300);
    assert_eq!(r.drive().param(P61), 400);
    assert!(r.drive().can_locked());
    // CAN is not handled: the request goes unanswered.
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80"]);
    assert_eq!(r.exchange(f(1100, &[0x80])), ["44C#80"]);

    // Powered again with S1 still at 1: no new load, still deaf.
    r.drive_mut().set_param(P21, 700).unwrap();
    r.drive_mut().save();
    r.power_cycle(100);
    r.run_ms(1);
    assert_eq!(r.drive().param(P21), 700);
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80"]);

    // S1 back to 0 while powered: still deaf until the next power-up.
    r.drive_mut().set_dip_s1(false);
    r.run_ms(10);
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80"]);
    r.power_cycle(100);
    r.run_ms(1);
    assert!(!r.drive().can_locked());
    assert_eq!(r.exchange(f(440, &READ)), ["1B8#80", "1B7#00550000"]);
    assert_eq!(r.drive().param(P21), 700);
}

#[test]
fn can_start_is_refused_while_s1_holds_the_drive() {
    let mut r = rig();
    r.drive_mut().set_dip_s1(true);
    r.power_cycle(10);
    r.run_ms(1);
    r.exchange(f(440, &[0, 0b10_10_10_00, 0x88, 0x13]));
    r.run_ms(100);
    assert!(!r.drive().can_control());
    assert!(!r.drive().is_running());
}
