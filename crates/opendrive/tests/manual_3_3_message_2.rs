//! Manual §3.3: message 2, parameters and connections (Read/Write multiplexed variable on
//! P186 → P187): every multiplexor with its normalisation, limits and error data.
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_opendrive::params::{C40, P68, P70, P94};
use common::*;

fn write(r: &mut Rig, mux: u8, value: u16) -> Vec<String> {
    let [lo, hi] = value.to_le_bytes();
    r.exchange(f(1100, &[mux, lo, hi]))
}

fn read(r: &mut Rig, mux: u8) -> Vec<String> {
    r.exchange(f(1100, &[0x80 | mux]))
}

#[test]
fn mux_00_max_frequency_fmax_p68_in_hundredths_of_hz() {
    let mut r = rig();
    // fMAX = P68, default 120.0 % of 50 Hz = 60.00 Hz (manual's defaults table).
    assert_eq!(read(&mut r, 0x00), ["44C#80", "44B#007017"]);
    assert_eq!(write(&mut r, 0x00, 5500), ["44C#007C15", "44B#007C15"]);
    assert_eq!(r.drive().param(P68), 1100);
    assert_eq!(read(&mut r, 0x00), ["44C#80", "44B#007C15"]);
    // Limits: P68 20.0 % – 400.0 % of 50 Hz = 10.00 Hz – 200.00 Hz.
    assert_eq!(write(&mut r, 0x00, 1000), ["44C#00E803", "44B#00E803"]);
    assert_eq!(write(&mut r, 0x00, 20000), ["44C#00204E", "44B#00204E"]);
    assert_eq!(r.drive().param(P68), 4000);
}

#[test]
fn mux_00_data_outside_p68_20_0_400_0_percent_is_value_not_allowed() {
    let mut r = rig();
    // 999 and 20001 would round into P68's range at its 0.1 % resolution: refused on the
    // data itself, code 2, nothing applied.
    for v in [999u16, 20001, 900, 0, 65535] {
        let [lo, hi] = v.to_le_bytes();
        assert_eq!(
            write(&mut r, 0x00, v),
            [format!("44C#00{lo:02X}{hi:02X}"), "44B#800200".to_string()],
            "{v}"
        );
    }
    assert_eq!(r.drive().param(P68), 1200);
}

#[test]
fn mux_18_current_threshold_reaction_c40_and_p94() {
    let mut r = rig();
    assert_eq!(read(&mut r, 0x18), ["44C#98", "44B#180000"]);
    // 2: STOP delayed by P94 (unchanged, 15 s).
    assert_eq!(write(&mut r, 0x18, 2), ["44C#180200", "44B#180200"]);
    assert_eq!((r.drive().param(C40), r.drive().param(P94)), (1, 150));
    assert_eq!(read(&mut r, 0x18), ["44C#98", "44B#180200"]);
    // 1: STOP with the minimum delay, P94 = 1 s.
    assert_eq!(write(&mut r, 0x18, 1), ["44C#180100", "44B#180100"]);
    assert_eq!((r.drive().param(C40), r.drive().param(P94)), (1, 10));
    assert_eq!(read(&mut r, 0x18), ["44C#98", "44B#180100"]);
    // 3 and 4 behave as 0.
    for v in [3u16, 4, 0] {
        let b = v as u8;
        assert_eq!(
            write(&mut r, 0x18, v),
            [format!("44C#18{b:02X}00"), format!("44B#18{b:02X}00")]
        );
        assert_eq!(r.drive().param(C40), 0);
        assert_eq!(read(&mut r, 0x18), ["44C#98", "44B#180000"]);
    }
    assert_eq!(write(&mut r, 0x18, 5), ["44C#180500", "44B#980200"]);
}

#[test]
fn mux_18_stop_delayed_reads_back_2_while_p94_is_1_s() {
    let mut r = rig();
    // 1 sets P94 = 1 s; 2 then keeps P94 and reads back as written, "STOP ritardato".
    assert_eq!(write(&mut r, 0x18, 1), ["44C#180100", "44B#180100"]);
    assert_eq!(write(&mut r, 0x18, 2), ["44C#180200", "44B#180200"]);
    assert_eq!((r.drive().param(C40), r.drive().param(P94)), (1, 10));
    assert_eq!(read(&mut r, 0x18), ["44C#98", "44B#180200"]);
}

#[test]
fn mux_19_thermal_current_p70_base_256_is_200_percent() {
    let mut r = rig();
    assert_eq!(read(&mut r, 0x19), ["44C#99", "44B#198000"]);
    assert_eq!(write(&mut r, 0x19, 256), ["44C#190001", "44B#190001"]);
    assert_eq!(r.drive().param(P70), 2000);
    assert_eq!(write(&mut r, 0x19, 64), ["44C#194000", "44B#194000"]);
    assert_eq!(r.drive().param(P70), 500);
    assert_eq!(write(&mut r, 0x19, 13), ["44C#190D00", "44B#190D00"]);
    assert_eq!(r.drive().param(P70), 102);
    assert_eq!(write(&mut r, 0x19, 12), ["44C#190C00", "44B#990200"]);
    assert_eq!(write(&mut r, 0x19, 257), ["44C#190101", "44B#990200"]);
    assert_eq!(r.drive().param(P70), 102);
}

#[test]
fn mux_1b_stop_delay_p94_in_tenths_of_a_second() {
    let mut r = rig();
    assert_eq!(read(&mut r, 0x1B), ["44C#9B", "44B#1B9600"]);
    assert_eq!(write(&mut r, 0x1B, 10), ["44C#1B0A00", "44B#1B0A00"]);
    assert_eq!(write(&mut r, 0x1B, 1000), ["44C#1BE803", "44B#1BE803"]);
    assert_eq!(r.drive().param(P94), 1000);
    assert_eq!(write(&mut r, 0x1B, 9), ["44C#1B0900", "44B#9B0200"]);
    assert_eq!(write(&mut r, 0x1B, 1001), ["44C#1BE903", "44B#9B0200"]);
}

#[test]
fn mux_34_software_version_is_read_only() {
    let mut r = rig();
    assert_eq!(read(&mut r, 0x34), ["44C#B4", "44B#340003"]);
    assert_eq!(write(&mut r, 0x34, 1), ["44C#340100", "44B#B40100"]);
}

#[test]
fn mux_3a_save_to_flash_survives_a_power_cycle() {
    let mut r = rig();
    write(&mut r, 0x00, 6000);
    r.power_cycle(10);
    r.run_ms(1);
    // Not saved: back to the flash value.
    assert_eq!(r.drive().param(P68), 1200);
    write(&mut r, 0x00, 5000);
    assert_eq!(write(&mut r, 0x3A, 0), ["44C#3A0000", "44B#BA0200"]);
    assert_eq!(write(&mut r, 0x3A, 1), ["44C#3A0100", "44B#3A0100"]);
    assert_eq!(read(&mut r, 0x3A), ["44C#BA", "44B#3A0000"]);
    r.power_cycle(10);
    r.run_ms(1);
    assert_eq!(r.drive().param(P68), 1000);
}

#[test]
fn undefined_mux_and_malformed_requests() {
    let mut r = rig();
    assert_eq!(read(&mut r, 0x01), ["44C#81", "44B#810100"]);
    assert_eq!(write(&mut r, 0x7F, 1), ["44C#7F0100", "44B#FF0100"]);
    // Wrong data length: undefined error.
    assert_eq!(
        r.exchange(f(1100, &[0x00, 0x01])),
        ["44C#0001", "44B#800000"]
    );
    assert_eq!(
        r.exchange(f(1100, &[0x80, 0x01])),
        ["44C#8001", "44B#800000"]
    );
    assert_eq!(r.exchange(f(1100, &[])), ["44C#", "44B#800000"]);
}
