//! Chapter 2: the DS402 personality — device type, objects, default PDOs, the CiA 402 power
//! state machine (every transition) and velocity mode on the wire.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::alarms::Alarm;
use cantwin_adv200::ds402::State;
use common::*;

fn cw(h: &mut H, cw: u16) -> Vec<String> {
    let b = cw.to_le_bytes();
    h.send(&format!("602#2B406000{:02X}{:02X}0000", b[0], b[1]))
}

fn sw(h: &mut H) -> u16 {
    let r = h.send("602#4041600000000000");
    let d = common::f(&r[0]);
    let b = d.data_bytes();
    u16::from_le_bytes([b[4], b[5]])
}

/// A DS402 drive taken through `path` (control words, written by SDO).
fn at(path: &[u16]) -> H {
    let mut h = H::ds402();
    h.send("000#0102");
    for c in path {
        assert_eq!(cw(&mut h, *c), ["582#6040600000000000"]);
    }
    h
}

const SOD: u16 = 0x0240;
const RTSO: u16 = 0x0231;
const SO: u16 = 0x0233;
const OE: u16 = 0x0637;

#[test]
fn cia402_state_machine_transitions_from_a_table() {
    use State::*;
    // (path to the start state, control word, state reached, status word, transition)
    let table: &[(&[u16], u16, State, u16, &str)] = &[
        (&[], 0x0006, ReadyToSwitchOn, RTSO, "2"),
        (&[0x06], 0x0007, SwitchedOn, SO, "3"),
        (&[0x06, 0x07], 0x000F, OperationEnabled, OE, "4"),
        (&[0x06], 0x000F, OperationEnabled, OE, "3+4"),
        (&[0x06, 0x0F], 0x0007, SwitchedOn, SO, "5"),
        (&[0x06, 0x07], 0x0006, ReadyToSwitchOn, RTSO, "6"),
        (&[0x06], 0x0000, SwitchOnDisabled, SOD, "7 disable voltage"),
        (&[0x06], 0x0002, SwitchOnDisabled, SOD, "7 quick stop"),
        (&[0x06, 0x0F], 0x0006, ReadyToSwitchOn, RTSO, "8"),
        (&[0x06, 0x0F], 0x0000, SwitchOnDisabled, SOD, "9"),
        (
            &[0x06, 0x07],
            0x0000,
            SwitchOnDisabled,
            SOD,
            "10 disable voltage",
        ),
        (
            &[0x06, 0x07],
            0x0002,
            SwitchOnDisabled,
            SOD,
            "10 quick stop",
        ),
        // Quick stop at standstill: 11, shown; 12 follows at the next evaluation.
        (&[0x06, 0x0F], 0x000B, QuickStopActive, 0x0217, "11"),
        // Commands that do not apply in a state leave it.
        (&[], 0x0007, SwitchOnDisabled, SOD, "switch on in SOD"),
        (&[], 0x000F, SwitchOnDisabled, SOD, "enable in SOD"),
        (&[0x06, 0x07], 0x0007, SwitchedOn, SO, "switch on again"),
    ];
    for (path, c, state, status, name) in table {
        let mut h = at(path);
        assert_eq!(cw(&mut h, *c), ["582#6040600000000000"], "{name}");
        assert_eq!(h.d.power_state(), Some(*state), "transition {name}");
        assert_eq!(sw(&mut h), *status, "transition {name}");
    }
}

#[test]
fn cia402_power_up_is_switch_on_disabled() {
    let mut h = H::ds402();
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    assert_eq!(sw(&mut h), SOD);
}

#[test]
fn cia402_quick_stop_ramps_down_then_switch_on_disabled() {
    let mut h = at(&[0x06, 0x0F]);
    // Target 1500 rpm (0x6042 = 0x05DC), accelerate at the 0x6048 default 1000 rpm/s.
    h.send("602#2B426000DC050000");
    h.run_to(h.now + 1600 * MS);
    assert_eq!(h.d.param(260), Ok(1500));
    cw(&mut h, 0x000B);
    assert_eq!(h.d.power_state(), Some(State::QuickStopActive));
    assert_eq!(sw(&mut h), 0x0217);
    // Fast stop decel 3000 rpm/s: 500 ms to zero.
    let t = h.now;
    h.run_to(t + 250 * MS);
    assert_eq!(h.d.param(260), Ok(750));
    assert_eq!(h.d.power_state(), Some(State::QuickStopActive));
    h.run_to(t + 501 * MS);
    assert_eq!(h.d.param(260), Ok(0));
    assert_eq!(
        h.d.power_state(),
        Some(State::SwitchOnDisabled),
        "transition 12"
    );
}

#[test]
fn cia402_fault_reaction_and_fault_reset() {
    let mut h = at(&[0x06, 0x0F]);
    h.d.raise_alarm(Alarm::Overcurrent);
    h.run_to(h.now + MS);
    // 13 and 14: the drive trips at once, Fault reaction active ends immediately.
    assert_eq!(h.d.power_state(), Some(State::Fault));
    assert_eq!(sw(&mut h), 0x0218);
    // A control word without bit 7 does not leave Fault.
    cw(&mut h, 0x000F);
    assert_eq!(h.d.power_state(), Some(State::Fault));
    // 15: fault reset on the rising edge of bit 7 clears the alarm (EMCY 0000).
    let r = cw(&mut h, 0x0080);
    assert_eq!(r, ["582#6040600000000000", "082#0000000000000000"]);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    assert_eq!(sw(&mut h), SOD);
}

#[test]
fn manual_2_device_type_objects_and_default_pdos() {
    let mut h = H::ds402();
    // Device type 0x192 (402).
    assert_eq!(h.send("602#4000100000000000"), ["582#4300100092010000"]);
    // Modes of operation: velocity (2) only; display 2.
    assert_eq!(h.send("602#2F60600003000000"), ["582#8060600031000906"]);
    assert_eq!(h.send("602#2F60600002000000"), ["582#6060600000000000"]);
    assert_eq!(h.send("602#4061600000000000"), ["582#4F61600002000000"]);
    // Statusword is read-only.
    assert_eq!(h.send("602#2B41600000000000"), ["582#8041600002000106"]);
    // PDO 6: RPDO1 = 0x6040 + 0x6042, TPDO1 = 0x6041 + 0x6044; RPDO2 not valid.
    assert_eq!(h.send("602#4000160100000000"), ["582#4300160110004060"]);
    assert_eq!(h.send("602#4000160200000000"), ["582#4300160210004260"]);
    assert_eq!(h.send("602#40001A0100000000"), ["582#43001A0110004160"]);
    assert_eq!(h.send("602#40001A0200000000"), ["582#43001A0210004460"]);
    assert_eq!(h.send("602#4001140100000000"), ["582#4301140102030080"]);
    // vl velocity acceleration: delta speed 1000 rpm per delta time 1 s.
    assert_eq!(h.send("602#4048600100000000"), ["582#43486001E8030000"]);
    assert_eq!(h.send("602#4048600200000000"), ["582#4B48600201000000"]);
}

#[test]
fn manual_2_velocity_mode_follows_the_ramp_on_sync() {
    let mut h = at(&[0x06, 0x0F]);
    // RPDO1: controlword 0x000F, target velocity 500 rpm; synchronous: applied at SYNC.
    h.run_to(10 * MS);
    h.send("202#0F00F401");
    let mut speeds = Vec::new();
    for k in 1..=7u64 {
        h.run_to((10 + 100 * k) * MS);
        let r = h.send("080#");
        assert_eq!(r.len(), 1);
        let fr = common::f(&r[0]);
        let b = fr.data_bytes();
        speeds.push((
            u16::from_le_bytes([b[0], b[1]]),
            i16::from_le_bytes([b[2], b[3]]),
        ));
    }
    // 1000 rpm/s from the first SYNC (110 ms): +100 rpm per 100 ms, target reached (bit 10)
    // at 500 rpm.
    assert_eq!(
        speeds,
        [
            (0x0637, 0),
            (0x0237, 100),
            (0x0237, 200),
            (0x0237, 300),
            (0x0237, 400),
            (0x0637, 500),
            (0x0637, 500)
        ]
    );
    // vl velocity demand follows too.
    assert_eq!(h.send("602#4043600000000000"), ["582#4B436000F4010000"]);
}

#[test]
fn manual_2_0_fault_reset_acts_on_its_rising_edge_and_takes_priority() {
    let mut h = at(&[0x06, 0x0F]);
    h.d.raise_alarm(Alarm::Overcurrent);
    h.run_to(h.now + MS);
    assert_eq!(h.d.power_state(), Some(State::Fault));
    // 0x0086 in FAULT: transition 15 only, never chained into the shutdown of bits 0-3.
    cw(&mut h, 0x0086);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    h.run_to(h.now + 5 * MS);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    assert_eq!(sw(&mut h), SOD);
    // Bit 7 held: the other bits command nothing.
    cw(&mut h, 0x0006);
    assert_eq!(h.d.power_state(), Some(State::ReadyToSwitchOn));
    cw(&mut h, 0x0087);
    h.run_to(h.now + 5 * MS);
    assert_eq!(h.d.power_state(), Some(State::ReadyToSwitchOn));
    // A level of bit 7 held across a fault does not reset it: only a new rising edge does.
    h.d.raise_alarm(Alarm::Overcurrent);
    h.run_to(h.now + MS);
    assert_eq!(h.d.power_state(), Some(State::Fault));
    cw(&mut h, 0x0087);
    assert_eq!(h.d.power_state(), Some(State::Fault));
    cw(&mut h, 0x0007);
    cw(&mut h, 0x0087);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
}

#[test]
fn manual_2_0_fault_reaction_active_while_the_motor_coasts_after_a_fault() {
    let mut h = at(&[0x06, 0x0F]);
    h.send("602#2B426000DC050000");
    h.run_to(h.now + 1600 * MS);
    assert_eq!(h.d.param(260), Ok(1500));
    h.d.raise_alarm(Alarm::Overcurrent);
    h.run_to(h.now + MS);
    // Transition 13: the drive function is disabled, the motor coasts down; statusword
    // xxxx xxxx x0xx 1111.
    assert_eq!(h.d.power_state(), Some(State::FaultReactionActive));
    let s = sw(&mut h);
    assert_eq!(s & 0x4F, 0x0F, "{s:#06x}");
    // Transition 14 once the motor stands still (1500 rpm at the deceleration rate).
    h.run_to(h.now + 10_000 * MS);
    assert_eq!(h.d.param(260), Ok(0));
    assert_eq!(h.d.power_state(), Some(State::Fault));
    assert_eq!(sw(&mut h), 0x0218);
}

#[test]
fn manual_2_0_quick_stop_active_is_observable_at_standstill_then_transition_12() {
    let mut h = at(&[0x06, 0x0F]);
    // 11: QUICK STOP ACTIVE in the statusword read right after the command.
    cw(&mut h, 0x000B);
    assert_eq!(h.d.power_state(), Some(State::QuickStopActive));
    assert_eq!(sw(&mut h), 0x0217);
    // 12 with 0x605A = 2 (slow down, then SWITCH ON DISABLED) at the next evaluation.
    h.run_to(h.now + 2 * MS);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    assert_eq!(sw(&mut h), SOD);
}

#[test]
fn manual_2_0_disable_voltage_goes_straight_to_switch_on_disabled() {
    // 9 from OPERATION ENABLED while running, 12 from QUICK STOP ACTIVE.
    let mut h = at(&[0x06, 0x0F]);
    h.send("602#2B426000DC050000");
    h.run_to(h.now + 500 * MS);
    cw(&mut h, 0x0000);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
    assert_eq!(sw(&mut h), SOD);
    let mut h = at(&[0x06, 0x0F]);
    h.send("602#2B426000DC050000");
    h.run_to(h.now + 500 * MS);
    cw(&mut h, 0x000B);
    assert_eq!(h.d.power_state(), Some(State::QuickStopActive));
    cw(&mut h, 0x0000);
    assert_eq!(h.d.power_state(), Some(State::SwitchOnDisabled));
}
