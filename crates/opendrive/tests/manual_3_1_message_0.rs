//! Manual §3.1: message 0, commands and frequency reference (Read/Write basic variable on
//! P180 → P181).
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

#[test]
fn manual_example_0x1388_is_50_hz_with_exact_frame_times() {
    let mut r = rig();
    // Reference remote set, command remote set, start and reverse unchanged; 88 13.
    let req = f(440, &[0x00, 0b10_10_00_00, 0x88, 0x13]);
    let resp = f(439, &[0x00, 0b10_10_01_01, 0x88, 0x13]);
    r.send(req);
    r.run_ms(1);
    assert_eq!(
        r.frames(),
        vec![
            ("1B8#00A08813".into(), 0, ns(&req) - 3 * BIT_NS),
            (
                "1B7#00A58813".into(),
                ns(&req),
                ns(&req) + ns(&resp) - 3 * BIT_NS
            ),
        ]
    );
    assert_eq!(r.drive().can_reference(), 0x1388);
    assert_eq!(r.drive().reference_hz(), 50.0);
}

fn pair(b: bool) -> u8 {
    if b { 0b10 } else { 0b01 }
}

/// Every code (00, 01, 10, 11) on every bit pair from both states of the bit.
#[test]
fn command_code_table_every_transition() {
    for shift in [6u8, 4, 2, 0] {
        for initially in [false, true] {
            for code in 0u8..4 {
                let mut r = rig();
                // Start from command remote set (so start/reverse codes are valid) and the
                // bit under test at `initially`.
                let mut init = 0b00_10_00_00u8;
                init = (init & !(0b11 << shift)) | (pair(initially) << shift);
                if shift == 4 && !initially {
                    init = 0b00_01_00_00;
                }
                r.exchange(f(440, &[0, init, 0, 0]));
                let cmd = (0b00u8 << shift) | (code << shift);
                // Keep command remote as it is unless it is the pair under test.
                let out = r.exchange(f(440, &[0, cmd, 0x10, 0x00]));
                let after = match code {
                    0b01 => false,
                    0b10 => true,
                    _ => initially,
                };
                let c = r.drive().commands();
                let got = [
                    c.reference_remote,
                    c.command_remote,
                    c.can_start,
                    c.can_reverse,
                ][usize::from(3 - shift / 2)];
                assert_eq!(
                    got, after,
                    "shift {shift} initially {initially} code {code:02b}"
                );
                let state = pair(c.reference_remote) << 6
                    | pair(c.command_remote) << 4
                    | pair(c.can_start) << 2
                    | pair(c.can_reverse);
                // The answer carries the reference in use: the CAN one only with reference
                // remote set, else the terminal's (0 Hz here).
                let reference = if c.reference_remote { "1000" } else { "0000" };
                assert_eq!(
                    out,
                    [
                        format!("1B8#00{cmd:02X}1000"),
                        format!("1B7#00{state:02X}{reference}")
                    ]
                );
            }
        }
    }
}

#[test]
fn start_and_reverse_are_valid_only_with_command_remote_set() {
    let mut r = rig();
    // Start and reverse set, command remote not set: ignored.
    assert_eq!(
        r.exchange(f(440, &[0, 0b00_00_10_10, 0x88, 0x13])),
        ["1B8#000A8813", "1B7#00550000"]
    );
    // In one byte: command remote set makes start and reverse of the same byte valid.
    assert_eq!(
        r.exchange(f(440, &[0, 0b00_10_10_10, 0x88, 0x13])),
        ["1B8#002A8813", "1B7#006A0000"]
    );
    // Command remote reset: start and reverse fall back to reset with it.
    assert_eq!(
        r.exchange(f(440, &[0, 0b00_01_10_10, 0x88, 0x13])),
        ["1B8#001A8813", "1B7#00550000"]
    );
}

#[test]
fn read_answers_reference_and_command_state_by_data_and_remote_frame() {
    let mut r = rig();
    r.drive_mut().set_analog_reference_hz(12.5);
    // Reference remote reset: the reference in use is the terminal's, 12.50 Hz = 0x04E2.
    assert_eq!(r.exchange(f(440, &[0x80])), ["1B8#80", "1B7#0055E204"]);
    r.exchange(f(440, &[0, 0b10_10_10_00, 0x88, 0x13]));
    assert_eq!(r.exchange(f(440, &[0x80])), ["1B8#80", "1B7#00A98813"]);
    let remote = cantwin_can::Frame::remote(cantwin_can::Id::standard(439).unwrap(), 4).unwrap();
    assert_eq!(r.exchange(remote), ["1B7#R4", "1B7#00A98813"]);
}

#[test]
fn error_responses_carry_r_and_the_error_code() {
    let mut r = rig();
    // Too short, reserved bits, a read with data: undefined error.
    assert_eq!(r.exchange(f(440, &[0, 0xA0])), ["1B8#00A0", "1B7#800000"]);
    assert_eq!(
        r.exchange(f(440, &[0x01, 0xA0, 0x88, 0x13])),
        ["1B8#01A08813", "1B7#800000"]
    );
    assert_eq!(
        r.exchange(f(440, &[0x80, 0x01])),
        ["1B8#8001", "1B7#800000"]
    );
}

#[test]
fn cob_ids_come_from_p180_p181_at_power_up() {
    use cantwin_opendrive::params::{P180, P181};
    let mut d = cantwin_opendrive::OpenDrive::new(Default::default(), Default::default());
    d.set_stored_param(P180, 0x100).unwrap();
    d.set_stored_param(P181, 0x0FF).unwrap();
    let mut r = rig_with(d);
    assert_eq!(r.exchange(f(440, &[0x80])), ["1B8#80"]);
    assert_eq!(r.exchange(f(0x100, &[0x80])), ["100#80", "0FF#00550000"]);
}

#[test]
fn manual_3_1_a_reference_above_fmax_is_taken_and_limited_to_fmax_p68() {
    let mut r = rig();
    // 55.00 Hz is within fMAX (P68 = 120 % of 50 Hz = 60.00 Hz): used as sent.
    assert_eq!(
        r.exchange(f(440, &[0, 0b10_10_10_00, 0x7C, 0x15])),
        ["1B8#00A87C15", "1B7#00A97C15"]
    );
    // Message 0 has no error data (manual §3.1): 100.00 Hz is taken, its commands applied,
    // and the reference in use, which the answer carries, is fMAX.
    assert_eq!(
        r.exchange(f(440, &[0, 0b10_10_10_00, 0x10, 0x27])),
        ["1B8#00A81027", "1B7#00A97017"]
    );
    assert_eq!(r.drive().can_reference(), 10_000);
    assert!(r.drive().commands().can_start);
    assert_eq!(r.drive().reference_hz(), 60.0);
}
