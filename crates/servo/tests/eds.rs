//! A servo from a vendor's CiA 402 EDS (`tests/eds/linear-axis.eds`, written for this test:
//! a linear axis in micrometres, profile position and homing only): the dictionary is the
//! file's, the behaviour the profile's, the units those of the file's factor group.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_cia402::{Mode, State};
use cantwin_servo::{Servo, ServoConfig, od};

fn servo() -> Servo {
    let text = include_bytes!("eds/linear-axis.eds");
    let loaded = cantwin_eds::load_bytes(text);
    let desc = cantwin_eds::to_od(&loaded.eds).unwrap();
    let desc = od::hooked(&desc).unwrap();
    Servo::with_description(Arc::clone(&desc), ServoConfig::new(9)).unwrap()
}

fn at(ms: u64) -> Instant {
    Instant::from_nanos(ms * 1_000_000)
}

fn sdo(servo: &mut Servo, ms: u64, index: u16, sub: u8, value: &[u8]) -> Vec<u8> {
    let cmd = [0x2F, 0x2B, 0x27, 0x23][value.len() - 1];
    let mut d = vec![cmd, index as u8, (index >> 8) as u8, sub];
    d.extend_from_slice(value);
    d.resize(8, 0);
    let mut out = Outbox::new();
    servo.on_tick(at(ms), &mut out);
    out.clear();
    servo.on_frame(&Frame::std(0x609, &d).unwrap(), at(ms), &mut out);
    let answer = out
        .frames()
        .iter()
        .find(|f| f.id().as_raw() == 0x589)
        .unwrap();
    answer.data_bytes().to_vec()
}

fn run(servo: &mut Servo, from: u64, to: u64) {
    let mut out = Outbox::new();
    for ms in from..=to {
        servo.on_tick(at(ms), &mut out);
        out.clear();
    }
}

#[test]
fn cia402_eds_dictionary_with_the_profile_behaviour_and_the_file_units() {
    let mut s = servo();
    let mut out = Outbox::new();
    s.on_power_up(Instant::ZERO, &mut out);
    // 0x6502 of the file: pp and hm only.
    assert!(s.drive().config().modes.contains(Mode::ProfilePosition));
    assert!(!s.drive().config().modes.contains(Mode::CyclicSyncPosition));
    assert_eq!(s.drive().config().encoder, 8192);
    // pv is not among them: 0x06090030.
    assert_eq!(sdo(&mut s, 1, 0x6060, 0, &[3])[0], 0x80);
    assert_eq!(sdo(&mut s, 2, 0x6060, 0, &[1])[0], 0x60);
    sdo(&mut s, 3, 0x6040, 0, &[0x06, 0x00]);
    sdo(&mut s, 4, 0x6040, 0, &[0x0F, 0x00]);
    assert_eq!(s.drive().state(), State::OperationEnabled);
    // 10 000 µm: two shaft revolutions of the 5 mm feed, two motor revolutions.
    sdo(&mut s, 5, 0x607A, 0, &10_000i32.to_le_bytes());
    sdo(&mut s, 6, 0x6040, 0, &[0x1F, 0x00]);
    sdo(&mut s, 7, 0x6040, 0, &[0x0F, 0x00]);
    run(&mut s, 8, 600);
    let pos = s.device().od().get(0x6064, 0).unwrap().as_i128().unwrap();
    assert!((pos - 10_000).abs() <= 5, "{pos}");
    let revolutions = s.drive().motor().state.angle / core::f64::consts::TAU;
    assert!((revolutions - 2.0).abs() < 0.002, "{revolutions}");
    let sw = s.device().od().get_unsigned(0x6041, 0).unwrap();
    assert_eq!(sw & 0x046F, 0x0427, "target reached: {sw:#06x}");
    // An object the file does not have is not there.
    assert_eq!(sdo(&mut s, 601, 0x60FF, 0, &[0, 0, 0, 0])[0], 0x80);
}
