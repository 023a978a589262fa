//! §1.5: the drive's alarms as EMCY, alarm reset, and the fieldbus faults raised at run time.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::alarms::{Alarm, CardFault};
use cantwin_adv200::params::par;
use cantwin_adv200::{Adv200, Adv200Config, Leds};
use cantwin_can::{ControllerEvent, Instant, Node, Outbox};
use common::*;

fn emcy(code: u16, register: u8, mfr: [u8; 5]) -> String {
    let c = code.to_le_bytes();
    let b = [c[0], c[1], register, mfr[0], mfr[1], mfr[2], mfr[3], mfr[4]];
    let hex: String = b.iter().map(|x| format!("{x:02X}")).collect();
    format!("08C#{hex}")
}

fn register(h: &H) -> u8 {
    h.d.device().unwrap().error_register()
}

#[test]
fn manual_1_5_every_drive_alarm_sends_its_emcy_code() {
    let table: [(Alarm, u16); 14] = [
        (Alarm::Overvoltage, 0x3210),
        (Alarm::Undervoltage, 0x3220),
        (Alarm::GroundFault, 0x2110),
        (Alarm::Overcurrent, 0x2310),
        (Alarm::Desaturation, 0x2130),
        (Alarm::MultiUndervolt, 0xFF06),
        (Alarm::HeatsinkOt, 0x4210),
        (Alarm::MotorOt, 0xFF0C),
        (Alarm::DriveOverload, 0x8311),
        (Alarm::MotorOverload, 0x7121),
        (Alarm::OptEncFault, 0x3130),
        (Alarm::ExternalFault, 0x9000),
        (Alarm::PlcFault(1), 0xFF17),
        (Alarm::ParamError, 0xFF2D),
    ];
    for (a, code) in table {
        assert_eq!(a.emcy_code(), code, "{a:?}");
    }
    for a in Alarm::all() {
        let mut h = H::canopen(|_| {});
        h.send("000#010C");
        h.run_to(MS);
        let from = h.log.len();
        h.d.raise_alarm(a);
        h.run_to(2 * MS);
        let reg = register(&h);
        assert_eq!(reg & 0x01, 0x01, "generic error bit for {a:?}");
        assert_eq!(
            h.since(from),
            [(MS, emcy(a.emcy_code(), reg, a.manufacturer_bytes()))],
            "{a:?}"
        );
        assert_eq!(h.d.param(par::DRIVE_OK), Ok(0));
        assert_eq!(h.d.param(par::ACTIVE_ALARM), Ok(i64::from(a.emcy_code())));
    }
}

#[test]
fn manual_1_5_alarm_reset_clears_the_emcy() {
    let mut h = H::canopen(|_| {});
    h.send("000#010C");
    h.d.raise_alarm(Alarm::Overvoltage);
    h.run_to(MS);
    let from = h.log.len();
    // Alarm reset (PAR 1070 = 0x242E) by SDO.
    assert_eq!(
        h.send("60C#2F2E240101000000"),
        ["58C#602E240100000000", "08C#0000000000000000"]
    );
    assert_eq!(h.since(from).len(), 2);
    assert_eq!(h.d.param(par::DRIVE_OK), Ok(1));
    assert!(h.d.drive().alarms().is_empty());
}

#[test]
fn manual_1_5_opt_bus_fault_only_while_enabled_unless_alarm_mode() {
    // Invalid NMT command (FFC6) while disabled, alarm mode 0: nothing.
    let mut h = H::canopen(|_| {});
    h.send("000#010C");
    assert_eq!(h.send("000#050C"), Vec::<String>::new());
    assert!(h.d.opt_bus_faults().is_empty());
    // Enabled (terminal enable, digital input 1): Opt Bus Fault FFC6.
    h.d.set_digital_input(1, true);
    h.run_to(MS);
    let reg = 0x81;
    assert_eq!(
        h.send("000#050C"),
        [emcy(0xFF11, reg, [0xC6, 0xFF, 0, 0, 0])]
    );
    assert_eq!(h.d.opt_bus_faults(), [0xFFC6]);
    assert_eq!(h.d.param(par::ENABLE_STATE), Ok(0), "the drive trips");
    // Alarm mode 1 (PAR 4012): also while disabled.
    let mut h = H::canopen(|d| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap());
    assert_eq!(
        h.send("000#050C"),
        [emcy(0xFF11, reg, [0xC6, 0xFF, 0, 0, 0])]
    );
}

#[test]
fn manual_1_5_wrong_nmt_length_bus_off_and_overflow() {
    let alarm_mode = |d: &mut Adv200| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap();
    let mut h = H::canopen(alarm_mode);
    assert_eq!(
        h.send("000#01"),
        [emcy(0xFF11, 0x81, [0xC5, 0xFF, 0, 0, 0])]
    );
    let mut h = H::canopen(alarm_mode);
    let mut out = Outbox::new();
    h.d.on_controller_event(ControllerEvent::BusOff, Instant::from_nanos(MS), &mut out);
    assert_eq!(h.d.opt_bus_faults(), [0xFFC7]);
    let mut h = H::canopen(alarm_mode);
    h.d.on_controller_event(
        ControllerEvent::RxOverrun,
        Instant::from_nanos(MS),
        &mut out,
    );
    assert_eq!(h.d.opt_bus_faults(), [0x8110]);
}

#[test]
fn manual_1_1_3_life_guarding_loss_raises_bus_fault_8130() {
    let mut h = H::canopen(|d| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap());
    h.send("000#010C");
    h.run_to(10 * MS);
    // The master guards once: the card answers with toggle 0 and state operational (5).
    assert_eq!(h.send("70C#R"), ["70C#05"]);
    let from = h.log.len();
    // Life time 60 ms × 3 = 180 ms later the card loses the master.
    h.run_to(300 * MS);
    let got = h.since(from);
    assert_eq!(got, [(190 * MS, emcy(0xFF11, 0x81, [0x30, 0x81, 0, 0, 0]))]);
    assert!(h.d.opt_bus_faults().contains(&0x8130));
}

#[test]
fn manual_1_5_communication_cycle_period_exceeded_is_bus_loss() {
    let mut h = H::canopen(|d| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap());
    // 0x1006 = 10 000 µs.
    assert_eq!(h.send("60C#2306100010270000"), ["58C#6006100000000000"]);
    h.send("000#010C");
    for k in 1..=3 {
        h.run_to(k * 10 * MS);
        h.send("080#");
    }
    assert!(h.d.opt_bus_faults().is_empty());
    let from = h.log.len();
    // §1.1.3: the last SYNC at 30 ms; none within SYNC_PERIOD × LIFE_TIME_FACTOR (3 by
    // default): bus loss (sub-code 0) at 60 ms.
    h.run_to(100 * MS);
    assert_eq!(
        h.since(from),
        [(60 * MS, emcy(0xFF11, 0x81, [0, 0, 0, 0, 0]))]
    );
    assert_eq!(h.d.opt_bus_faults(), [0x0000]);
}

#[test]
fn manual_1_1_3_sync_bus_loss_threshold_is_sync_period_times_life_time_factor() {
    let mut h = H::canopen(|d| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap());
    // 0x1006 = 10 ms, 0x100D = 5: 50 ms without SYNC.
    h.send("60C#2306100010270000");
    assert_eq!(h.send("60C#2F0D100005000000"), ["58C#600D100000000000"]);
    h.send("000#010C");
    h.run_to(10 * MS);
    h.send("080#");
    h.run_to(59 * MS);
    assert!(h.d.opt_bus_faults().is_empty(), "not yet at 49 ms");
    let from = h.log.len();
    h.run_to(100 * MS);
    assert_eq!(
        h.since(from),
        [(60 * MS, emcy(0xFF11, 0x81, [0, 0, 0, 0, 0]))]
    );
}

#[test]
fn manual_leds_follow_nmt_and_alarm() {
    let mut h = H::canopen(|d| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap());
    let on = |al, op| Leds {
        al,
        op,
        pwr: true,
        vc5: true,
    };
    assert_eq!(h.d.leds(), on(true, false));
    h.send("000#010C");
    assert_eq!(h.d.leds(), on(false, true));
    assert_eq!(h.d.param(par::FIELDBUS_STATE), Ok(2));
    h.send("000#050C");
    assert_eq!(
        h.d.leds(),
        on(true, true),
        "Opt Bus Fault lights AL in Operational"
    );
    h.send("000#020C");
    assert_eq!(h.d.param(par::FIELDBUS_STATE), Ok(0));
    assert_eq!(h.d.leds(), on(true, false));
    h.send("000#800C");
    assert_eq!(h.d.param(par::FIELDBUS_STATE), Ok(1));
    // Not powered: all off.
    assert_eq!(Adv200::new(Default::default()).leds(), Leds::default());
}

#[test]
fn manual_1_5_enable_outside_operational_is_bus_loss() {
    let mut h = H::canopen(|_| {});
    // Pre-operational; the terminal enable (digital input 1) comes on.
    h.run_to(MS);
    let from = h.log.len();
    h.d.set_digital_input(1, true);
    h.run_to(2 * MS);
    assert_eq!(h.since(from), [(MS, emcy(0xFF11, 0x81, [0, 0, 0, 0, 0]))]);
    assert_eq!(h.d.opt_bus_faults(), [0x0000]);
    assert_eq!(h.d.param(par::ENABLE_STATE), Ok(0));
    // In Operational the same enable is accepted.
    let mut h = H::canopen(|_| {});
    h.send("000#010C");
    h.d.set_digital_input(1, true);
    h.run_to(2 * MS);
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(h.d.param(par::ENABLE_STATE), Ok(1));
}

#[test]
fn manual_1_5_ff04_error_initializing_can_interface_keeps_the_card_off_the_bus() {
    // The defect is found when the card configures itself at a drive reset (`Cfg` column).
    let mut h = H::canopen(|d| d.inject_card_fault(CardFault::CanInit));
    assert_eq!(h.frames(), Vec::<String>::new(), "no boot-up, no EMCY");
    assert_eq!(h.d.opt_bus_faults(), [0xFF04]);
    assert_eq!(h.d.nmt_state(), None);
    assert_eq!(h.d.param(par::ACTIVE_ALARM), Ok(0xFF11));
    assert!(h.d.leds().al);
    // Alarm reset does not repair the card.
    h.d.set_param(par::ALARM_RESET, 1).unwrap();
    h.run_to(MS);
    assert_eq!(h.d.opt_bus_faults(), [0xFF04]);
    // Repaired, the next drive reset brings it on the bus.
    h.d.clear_card_faults();
    let mut out = Outbox::new();
    h.d.reset_drive(Instant::from_nanos(2 * MS), &mut out);
    assert_eq!(out.frames()[0].to_string(), "70C#00");
    assert!(h.d.opt_bus_faults().is_empty());
}

#[test]
fn manual_1_5_ffb4_to_ffc3_internal_database_error_on_channel_n() {
    for n in 1..=16u8 {
        let code = 0xFFB4 + u16::from(n) - 1;
        let mut h = H::canopen(|d| d.inject_card_fault(CardFault::Database(n)));
        let c = code.to_le_bytes();
        // The card boots and reports Opt Bus Fault with the channel's sub-code.
        assert_eq!(
            h.frames(),
            [
                "70C#00".to_string(),
                emcy(0xFF11, 0x81, [c[0], c[1], 0, 0, 0])
            ],
            "channel {n}"
        );
        assert_eq!(h.d.opt_bus_faults(), [code]);
        assert_eq!(
            h.d.nmt_state(),
            Some(cantwin_canopen::nmt::State::PreOperational)
        );
        // Alarm reset (PAR 1070 by SDO): the cause is still there, the alarm stays.
        h.send("60C#2F2E240101000000");
        h.run_to(MS);
        assert_eq!(h.d.opt_bus_faults(), [code], "channel {n}");
        assert_eq!(h.d.param(par::DRIVE_OK), Ok(0));
    }
    // Repaired: the next drive reset is clean.
    let mut h = H::canopen(|d| d.inject_card_fault(CardFault::Database(3)));
    h.d.clear_card_faults();
    let mut out = Outbox::new();
    h.d.reset_drive(Instant::from_nanos(MS), &mut out);
    assert_eq!(out.frames().len(), 1, "boot-up only");
    assert!(h.d.opt_bus_faults().is_empty());
}

/// A controller event at `ms`, after the card ran every deadline before it.
fn controller(h: &mut H, event: ControllerEvent, ms: u64) {
    h.run_to(ms * MS);
    let mut out = Outbox::new();
    h.d.on_controller_event(event, Instant::from_nanos(ms * MS), &mut out);
    for f in out.drain() {
        h.log.push((h.now, f.to_string()));
    }
    h.run_to(ms * MS);
}

#[test]
fn manual_1_5_bus_off_is_ffc7_and_8100_when_it_repeats_after_recovery() {
    let alarm_mode = |d: &mut Adv200| d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap();
    // A single bus-off: FFC7 only, even after a recovery long before.
    let mut h = H::canopen(alarm_mode);
    controller(&mut h, ControllerEvent::BusOff, 1);
    controller(&mut h, ControllerEvent::BusOffRecovered, 4);
    controller(&mut h, ControllerEvent::BusOff, 1100);
    assert_eq!(h.d.opt_bus_faults(), [0xFFC7]);
    // Bus-off again within a second of the recovery: the line has a hardware problem.
    let mut h = H::canopen(alarm_mode);
    controller(&mut h, ControllerEvent::BusOff, 1);
    controller(&mut h, ControllerEvent::BusOffRecovered, 4);
    controller(&mut h, ControllerEvent::BusOff, 500);
    controller(&mut h, ControllerEvent::BusOffRecovered, 503);
    assert_eq!(h.d.opt_bus_faults(), [0xFFC7, 0x8100]);
    // Each sub-code travels in its own Opt Bus Fault EMCY.
    h.run_to(600 * MS);
    let sent: Vec<String> = h
        .frames()
        .into_iter()
        .filter(|f| f.starts_with("08C#11FF"))
        .collect();
    assert_eq!(sent.len(), 2, "{sent:?}");
    assert!(sent[0].ends_with("C7FF000000"), "{sent:?}");
    assert!(sent[1].ends_with("0081000000"), "{sent:?}");
    // Disabled with alarm mode 0: neither (§1.5: only while enabled).
    let mut h = H::canopen(|_| {});
    controller(&mut h, ControllerEvent::BusOff, 1);
    controller(&mut h, ControllerEvent::BusOffRecovered, 4);
    controller(&mut h, ControllerEvent::BusOff, 5);
    assert!(h.d.opt_bus_faults().is_empty());
}

/// A drive whose PDC maps M2S channel 2 on a value (FF15, a `Cfg` code of §1.5).
fn misconfigured(d: &mut Adv200) {
    d.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
    d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
    d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
    d.set_param_str(par::m2s_sys(1), "Count 16").unwrap();
    d.set_param(par::m2s_ipa(1), i64::from(par::WORD_DECOMP_SRC))
        .unwrap();
    d.set_param_str(par::m2s_sys(2), "Eu").unwrap();
    d.set_param(par::m2s_ipa(2), i64::from(par::DIG_RAMP_REF_1))
        .unwrap();
}

#[test]
fn manual_1_5_configuration_fault_emcy_follows_every_boot_up() {
    let fault = emcy(0xFF11, 0x81, [0x15, 0xFF, 0, 0, 0]);
    // Until the boot-up has gone out, no EMCY: both queued at once, the EMCY would win
    // arbitration and precede it.
    let mut d = Adv200::new(Adv200Config::default());
    misconfigured(&mut d);
    let mut out = Outbox::new();
    d.on_power_up(Instant::ZERO, &mut out);
    let mut frames: Vec<String> = out.drain().map(|f| f.to_string()).collect();
    while let Some(t) = d.next_deadline().filter(|t| t.as_nanos() <= 10 * MS) {
        d.on_tick(t, &mut out);
        frames.extend(out.drain().map(|f| f.to_string()));
    }
    assert_eq!(frames, ["70C#00"]);
    d.on_sent(&f("70C#00"), Instant::from_nanos(10 * MS), &mut out);
    while let Some(t) = d.next_deadline().filter(|t| t.as_nanos() <= 10 * MS) {
        d.on_tick(t, &mut out);
    }
    let frames: Vec<String> = out.drain().map(|f| f.to_string()).collect();
    assert_eq!(frames, std::slice::from_ref(&fault));
    // A master that starts later resets communication: boot-up, then the fault again, and
    // the error register shows it.
    let mut h = H::new(Adv200Config::default(), misconfigured);
    assert_eq!(h.frames(), ["70C#00", fault.as_str()]);
    h.run_to(100 * MS);
    assert_eq!(h.send("000#820C"), ["70C#00", fault.as_str()]);
    assert_eq!(register(&h), 0x81);
    assert_eq!(h.send("60C#4001100000000000"), ["58C#4F01100081000000"]);
    // The drive's Active alarm parameter (PAR 1072 at 0x2430 sub 1) shows Opt Bus Fault.
    assert!(h.d.opt_bus_faults().contains(&0xFF15));
    assert_eq!(h.send("60C#4030240100000000"), ["58C#4B30240111FF0000"]);
    // §1.1.5 lists no pre-defined error field: 0x1003 does not exist.
    assert_eq!(h.send("60C#4003100000000000"), ["58C#8003100000000206"]);
}

#[test]
fn manual_1_1_3_heartbeat_loss_is_one_alarm_one_emcy_and_pre_operational() {
    // Master heartbeat (node 1) consumed with 100 ms; the drive enabled from terminal 1.
    let mut h = H::canopen(|_| {});
    h.send("000#010C");
    assert_eq!(h.send("60C#2316100164000100"), ["58C#6016100100000000"]);
    h.d.set_digital_input(1, true);
    h.send("701#05");
    let from = h.log.len();
    h.run_to(500 * MS);
    // One EMCY, Opt Bus Fault 8130; CiA 301's default reaction without 0x1029:
    // OPERATIONAL → PRE-OPERATIONAL, which is no second alarm.
    assert_eq!(
        h.since(from),
        [(100 * MS, emcy(0xFF11, 0x81, [0x30, 0x81, 0, 0, 0]))]
    );
    assert_eq!(h.d.opt_bus_faults(), [0x8130]);
    assert_eq!(
        h.d.nmt_state(),
        Some(cantwin_canopen::nmt::State::PreOperational)
    );
    // Disabled with alarm mode 0: no alarm and no EMCY at all (§1.5).
    let mut h = H::canopen(|_| {});
    h.send("000#010C");
    h.send("60C#2316100164000100");
    h.send("701#05");
    let from = h.log.len();
    h.run_to(500 * MS);
    assert_eq!(h.since(from), []);
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(register(&h), 0);
}
