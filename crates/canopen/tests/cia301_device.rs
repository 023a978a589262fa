//! CiA 301 conformance of the composite device: NMT, error control, EMCY, SYNC, TIME,
//! identity and the SDO servers, frame by frame with exact times.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_can::{ControllerEvent, Id, Node};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::abort::AbortCode;
use cantwin_canopen::device::{DeviceConfig, Event};
use cantwin_canopen::nmt::State;
use cantwin_canopen::objects::Cia301Options;
use cantwin_canopen::od::{TimeOfDay, Value};
use cantwin_canopen::sdo::SdoCapabilities;
use cantwin_canopen::wire;
use device_harness::*;

fn u32le(v: u32) -> [u8; 4] {
    v.to_le_bytes()
}

// ---------------------------------------------------------------- NMT (§7.3.2)

#[test]
fn cia301_7_3_2_2_1_power_up_sends_boot_up_and_enters_pre_operational() {
    let mut h = Harness::new();
    assert_eq!(h.dev.state(), State::Initialising);
    // Before power-up nothing reacts, not even to NMT.
    h.rx(ms(1), "000#0105");
    assert_eq!(h.dev.state(), State::Initialising);
    h.power_up(ms(3));
    assert_eq!(h.take(), at_ms(&[(3, "705#00")]));
    assert_eq!(h.dev.state(), State::PreOperational);
    assert!(h.events().contains(&Event::StateChanged {
        from: State::Initialising,
        to: State::PreOperational
    }));
    assert_eq!(h.dev.next_deadline(), None);
}

#[test]
fn cia301_7_3_2_2_1_start_stop_enter_pre_operational_reported_by_heartbeat() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.rx(ms(150), "000#0105");
    assert_eq!(h.dev.state(), State::Operational);
    h.rx(ms(250), "000#0205");
    assert_eq!(h.dev.state(), State::Stopped);
    h.rx(ms(350), "000#8005");
    assert_eq!(h.dev.state(), State::PreOperational);
    h.rx(ms(450), "000#0205");
    h.rx(ms(550), "000#0105");
    h.run_until(ms(600));
    assert_eq!(
        h.take(),
        at_ms(&[
            (100, "705#7F"),
            (200, "705#05"),
            (300, "705#04"),
            (400, "705#7F"),
            (500, "705#04"),
            (600, "705#05"),
        ])
    );
}

#[test]
fn cia301_7_3_2_1_commands_for_other_nodes_are_ignored_broadcast_applies() {
    let mut h = Harness::booted();
    h.rx(ms(1), "000#0106");
    assert_eq!(h.dev.state(), State::PreOperational);
    h.rx(ms(2), "000#0100");
    assert_eq!(h.dev.state(), State::Operational);
    h.rx(ms(3), "000#0206");
    assert_eq!(h.dev.state(), State::Operational);
    // Malformed NMT frames (wrong length, unknown command) change nothing.
    h.rx(ms(4), "000#02");
    h.rx(ms(5), "000#0305");
    h.rx(ms(6), "000#020500");
    assert_eq!(h.dev.state(), State::Operational);
    assert!(h.take().is_empty());
}

#[test]
fn cia301_7_3_2_2_5_stopped_allows_only_nmt_and_error_control() {
    let mut h = Harness::booted();
    // SYNC producer every 10 ms.
    h.write(ms(0), 0x1006, 0, &u32le(10_000)).unwrap();
    h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)).unwrap();
    h.rx(ms(15), "000#0205");
    assert_eq!(h.dev.state(), State::Stopped);
    // SDO: no answer.
    h.rx(ms(16), "605#4000100000000000");
    // EMCY: recorded, not sent.
    h.run_until(ms(17));
    assert!(h.dev.emcy().raise(0x5000, [0; 5]));
    // TIME: not produced even as producer.
    h.write(ms(17), 0x1012, 0, &u32le(0x4000_0100)).unwrap();
    let mut out = cantwin_can::Outbox::new();
    assert!(!h.dev.publish_time(TimeOfDay { ms: 1, days: 1 }, &mut out));
    assert!(out.is_empty());
    // SYNC consumer: a SYNC from elsewhere is ignored (no PDO, no event).
    h.events();
    h.rx(ms(18), "080#");
    assert!(!h.events().iter().any(|e| matches!(e, Event::Sync { .. })));
    // Node guarding is answered.
    h.rx(ms(19), "705#R1");
    h.run_until(ms(60));
    assert_eq!(h.take(), at_ms(&[(10, "080#"), (19, "705#04")]));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x01);
}

#[test]
fn cia301_7_3_2_2_5_pre_operational_has_no_pdos() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1006, 0, &u32le(10_000)).unwrap();
    h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)).unwrap();
    h.dev
        .od_mut()
        .set(0x6000, 0, &Value::Unsigned16(0xBEEF))
        .unwrap();
    // An RPDO in pre-operational is not processed.
    h.rx(ms(5), "205#AA");
    assert_eq!(h.dev.od().get(0x6200, 0).unwrap(), Value::Unsigned8(0));
    h.rx(ms(12), "000#0105");
    h.rx(ms(13), "205#AA");
    assert_eq!(h.dev.od().get(0x6200, 0).unwrap(), Value::Unsigned8(0xAA));
    h.run_until(ms(30));
    // The SYNC producer runs on; only in operational do SYNCs carry the TPDO along.
    assert_eq!(
        h.take(),
        at_ms(&[
            (10, "080#"),
            (20, "080#"),
            (20, "185#EFBE"),
            (30, "080#"),
            (30, "185#EFBE")
        ])
    );
}

#[test]
fn cia301_7_3_2_2_1_reset_communication_restores_communication_parameters_only() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x2000, 0, &u32le(99)).unwrap();
    h.rx(ms(150), "000#0105");
    h.rx(ms(250), "000#8205");
    assert_eq!(h.dev.state(), State::PreOperational);
    h.run_until(ms(1000));
    assert_eq!(
        h.take(),
        at_ms(&[(100, "705#7F"), (200, "705#05"), (250, "705#00")])
    );
    assert_eq!(h.read_u32(0x1017, 0).unwrap() & 0xFFFF, 0);
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 99);
    assert!(h.events().contains(&Event::ResetCommunication));
}

#[test]
fn cia301_7_3_2_2_1_reset_node_restores_application_parameters_too() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x2000, 0, &u32le(99)).unwrap();
    h.write(ms(0), 0x100C, 0, &50u16.to_le_bytes()).unwrap();
    h.rx(ms(10), "000#8100");
    assert_eq!(h.take(), at_ms(&[(10, "705#00")]));
    assert_eq!(h.read_u32(0x2000, 0).unwrap(), 7);
    assert_eq!(h.read_u32(0x100C, 0).unwrap() & 0xFFFF, 0);
    let ev = h.events();
    assert!(ev.contains(&Event::ResetApplication));
    assert!(ev.contains(&Event::ResetCommunication));
}

#[test]
fn cia301_7_3_2_2_1_reset_communication_clears_errors_and_the_error_field() {
    let mut h = Harness::booted();
    h.run_until(ms(1));
    h.dev.emcy().raise(0x5000, [0; 5]);
    h.run_until(ms(1));
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 1);
    h.rx(ms(2), "000#8205");
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 0);
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0);
    assert_eq!(
        h.take(),
        at_ms(&[(1, "085#0050010000000000"), (2, "705#00")])
    );
}

// ------------------------------------------------- Error control (§7.2.8.3.2)

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_producer_first_beat_one_period_after_boot_up() {
    let opts = Cia301Options {
        heartbeat_time: 250,
        ..options()
    };
    let mut h = Harness::with_device(device_with(&opts));
    h.power_up(ms(7));
    h.run_until(ms(1000));
    assert_eq!(
        h.take(),
        at_ms(&[
            (7, "705#00"),
            (257, "705#7F"),
            (507, "705#7F"),
            (757, "705#7F")
        ])
    );
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_producer_time_change_restarts_the_cycle() {
    let mut h = Harness::booted();
    h.write(ms(10), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(130), 0x1017, 0, &50u16.to_le_bytes()).unwrap();
    h.run_until(ms(240));
    h.write(ms(240), 0x1017, 0, &0u16.to_le_bytes()).unwrap();
    h.run_until(ms(1000));
    assert_eq!(
        h.take(),
        at_ms(&[(110, "705#7F"), (180, "705#7F"), (230, "705#7F")])
    );
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_consumer_not_armed_before_the_first_heartbeat() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
    h.rx(ms(1), "000#0105");
    h.run_until(ms(10_000));
    assert_eq!(h.dev.state(), State::Operational);
    assert!(h.take().is_empty());
}

/// A device whose dictionary has no 0x1029 (error behaviour): identity, error register,
/// one heartbeat consumer entry.
fn device_without_1029() -> Harness {
    use cantwin_canopen::device::Device;
    use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject};
    use std::sync::Arc;
    let desc = OdBuilder::new()
        .var(0x1000, SubObject::unsigned32("Device type", Access::Ro, 0))
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro),
        )
        .array_of(
            0x1016,
            "Consumer heartbeat time",
            1,
            SubObject::unsigned32("Consumer heartbeat time", Access::Rw, 0x0003_0064),
        )
        .var(
            0x1017,
            SubObject::new("Producer heartbeat time", DataType::Unsigned16, Access::Rw),
        )
        .record(
            0x1018,
            "Identity object",
            [(1, SubObject::unsigned32("Vendor-ID", Access::Ro, 0))],
        )
        .build()
        .unwrap();
    let mut h = Harness::with_device(Device::new(Arc::new(desc), DeviceConfig::new(5)).unwrap());
    h.power_up(ms(0));
    assert_eq!(h.take(), at_ms(&[(0, "705#00")]));
    h
}

#[test]
fn cia301_7_5_2_32_without_0x1029_a_heartbeat_timeout_leaves_operational_for_pre_operational() {
    let mut h = device_without_1029();
    h.rx(ms(1), "000#0105");
    assert_eq!(h.dev.state(), State::Operational);
    h.rx(ms(10), "703#05");
    h.run_until(ms(109));
    assert!(h.take().is_empty());
    h.run_until(ms(110));
    assert_eq!(h.take(), at_ms(&[(110, "085#3081110300000000")]));
    assert_eq!(h.dev.state(), State::PreOperational);
}

#[test]
fn cia301_7_5_2_32_without_0x1029_a_heartbeat_timeout_leaves_stopped_and_pre_operational_alone() {
    // Pre-operational: the EMCY goes out, the state stays.
    let mut h = device_without_1029();
    h.rx(ms(10), "703#7F");
    h.run_until(ms(110));
    assert_eq!(h.take(), at_ms(&[(110, "085#3081110300000000")]));
    assert_eq!(h.dev.state(), State::PreOperational);
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x11);
    // Stopped: no EMCY (§7.3.2.2: only NMT and error control), the error is recorded, the
    // state stays.
    let mut h = device_without_1029();
    h.rx(ms(1), "000#0205");
    assert_eq!(h.dev.state(), State::Stopped);
    h.rx(ms(10), "703#05");
    h.run_until(ms(200));
    assert!(h.take().is_empty());
    assert!(h.events().contains(&Event::HeartbeatLost { node: 3 }));
    assert_eq!(h.dev.state(), State::Stopped);
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x11);
}

#[test]
fn cia301_7_5_2_2_error_register_follows_the_active_errors_with_each_emcy() {
    let mut h = Harness::booted();
    h.rx(ms(1), "000#0105");
    // RPDO 1 (one byte) arrives empty: EMCY 0x8210, generic + communication bits.
    h.rx(ms(2), "205#");
    assert_eq!(h.take(), at_ms(&[(2, "085#1082110000000000")]));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x11);
    // The next correct RPDO resets it: EMCY 0x0000 with the register cleared.
    h.rx(ms(3), "205#01");
    assert_eq!(h.take(), at_ms(&[(3, "085#0000000000000000")]));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0);
    // With another communication error active, the communication bit stays set.
    h.event(ms(4), ControllerEvent::ErrorPassive);
    h.rx(ms(5), "205#");
    h.rx(ms(6), "205#02");
    assert_eq!(
        h.take(),
        at_ms(&[
            (4, "085#2081110000000000"),
            (5, "085#1082110000000000"),
            (6, "085#0000110000000000"),
        ])
    );
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x11);
    h.event(ms(7), ControllerEvent::ErrorActive);
    assert_eq!(h.take(), at_ms(&[(7, "085#0000000000000000")]));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0);
    // With an error of another class active, only the communication bit goes.
    h.dev.emcy().raise(0x3210, [0; 5]);
    h.rx(ms(8), "205#");
    h.rx(ms(9), "205#03");
    assert_eq!(
        h.take(),
        at_ms(&[
            (7, "085#1032050000000000"),
            (8, "085#1082150000000000"),
            (9, "085#0000050000000000"),
        ])
    );
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x05);
    h.dev.emcy().clear(0x3210);
    h.run_until(ms(10));
    assert_eq!(h.take(), at_ms(&[(9, "085#0000000000000000")]));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0);
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_consumer_timeout_raises_emcy_8130() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
    h.rx(ms(1), "000#0105");
    h.rx(ms(1000), "703#05");
    h.rx(ms(1090), "703#05");
    h.run_until(ms(1189));
    assert!(h.take().is_empty());
    h.run_until(ms(1190));
    // Error register: generic + communication; first manufacturer byte: the node-ID.
    assert_eq!(h.take(), at_ms(&[(1190, "085#3081110300000000")]));
    // 0x1029 sub 1 = 0: operational → pre-operational.
    assert_eq!(h.dev.state(), State::PreOperational);
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x11);
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 1);
    assert_eq!(h.read_u32(0x1003, 1).unwrap(), 0x8130);
    let ev = h.events();
    assert!(ev.contains(&Event::HeartbeatLost { node: 3 }));
    // Heard again: the error is reset.
    h.rx(ms(1500), "703#05");
    assert_eq!(h.take(), at_ms(&[(1500, "085#0000000000000000")]));
    assert!(h.events().contains(&Event::HeartbeatRecovered { node: 3 }));
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0);
}

#[test]
fn cia301_7_2_8_3_2_2_boot_up_of_the_producer_stops_monitoring() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
    h.rx(ms(10), "703#7F");
    h.rx(ms(50), "703#00");
    h.run_until(ms(5_000));
    assert!(h.take().is_empty());
    assert!(h.events().contains(&Event::RemoteBootUp { node: 3 }));
    // The next heartbeat arms it again.
    h.rx(ms(5_000), "703#7F");
    h.run_until(ms(5_100));
    assert_eq!(h.take(), at_ms(&[(5_100, "085#3081110300000000")]));
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_consumer_watches_several_producers() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
    h.write(ms(0), 0x1016, 2, &u32le(0x0004_00C8)).unwrap();
    h.rx(ms(0), "703#05");
    h.rx(ms(0), "704#05");
    for t in [90, 180, 270] {
        h.rx(ms(t), "703#05");
    }
    // Node 4 is lost at 200 ms.
    assert_eq!(h.take(), at_ms(&[(200, "085#3081110400000000")]));
    // Node 3 is lost at 370 ms: the error is already active, no second EMCY.
    h.run_until(ms(380));
    assert!(h.take().is_empty());
    h.rx(ms(400), "704#05");
    assert!(h.take().is_empty());
    // Only when no producer is lost any more is the error reset.
    h.rx(ms(450), "703#05");
    assert_eq!(h.take(), at_ms(&[(450, "085#0000000000000000")]));
}

#[test]
fn cia301_7_5_2_21_reserved_bits_of_a_consumer_entry_abort_06090030() {
    let mut h = Harness::booted();
    for v in [0x0100_0064u32, 0x8003_0064, 0x1003_00C8] {
        assert_eq!(
            h.write(ms(0), 0x1016, 1, &u32le(v)),
            Err(AbortCode::INVALID_VALUE),
            "{v:#010x}"
        );
    }
    // A node-ID above 127 makes the entry unused (the clause's words), not invalid.
    h.write(ms(0), 0x1016, 1, &u32le(0x0080_0064)).unwrap();
}

#[test]
fn cia301_7_5_2_21_two_entries_for_one_node_abort_06040043() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
    assert_eq!(
        h.write(ms(0), 0x1016, 2, &u32le(0x0003_00C8)),
        Err(AbortCode::PARAMETER_INCOMPATIBLE)
    );
    // A time of 0 disables the entry, so it does not conflict.
    h.write(ms(0), 0x1016, 2, &u32le(0x0003_0000)).unwrap();
    // Rewriting the same entry is fine.
    h.write(ms(0), 0x1016, 1, &u32le(0x0003_00C8)).unwrap();
}

#[test]
fn cia301_7_5_2_32_error_behaviour_stopped_and_no_change() {
    for (value, expected) in [(2u8, State::Stopped), (1, State::Operational)] {
        let mut h = Harness::booted();
        h.write(ms(0), 0x1029, 1, &[value]).unwrap();
        h.write(ms(0), 0x1016, 1, &u32le(0x0003_0064)).unwrap();
        h.rx(ms(1), "000#0105");
        h.rx(ms(10), "703#05");
        h.run_until(ms(110));
        assert_eq!(h.dev.state(), expected, "0x1029 = {value}");
        // The EMCY is sent before the state change silences it (stopped).
        assert_eq!(h.take(), at_ms(&[(110, "085#3081110300000000")]));
    }
    let mut h = Harness::booted();
    assert_eq!(
        h.write(ms(0), 0x1029, 1, &[3]),
        Err(AbortCode::INVALID_VALUE)
    );
    h.write(ms(0), 0x1029, 1, &[0x80]).unwrap();
}

#[test]
fn cia301_7_2_8_3_2_1_node_guarding_toggle_bit_and_state() {
    let mut h = Harness::booted();
    h.rx(ms(10), "705#R1");
    h.rx(ms(20), "705#R1");
    h.rx(ms(25), "000#0105");
    h.rx(ms(30), "705#R1");
    h.rx(ms(35), "000#0205");
    h.rx(ms(40), "705#R1");
    // Reset communication sets the toggle bit back to 0.
    h.rx(ms(45), "000#8205");
    h.rx(ms(50), "705#R1");
    // Another node's guarding request is not ours.
    h.rx(ms(60), "706#R1");
    assert_eq!(
        h.take(),
        at_ms(&[
            (10, "705#7F"),
            (20, "705#FF"),
            (30, "705#05"),
            (40, "705#84"),
            (45, "705#00"),
            (50, "705#7F"),
        ])
    );
}

#[test]
fn cia301_7_2_8_3_2_1_life_guarding_loss_raises_emcy_8130_and_applies_1029() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x100C, 0, &100u16.to_le_bytes()).unwrap();
    h.write(ms(0), 0x100D, 0, &[3]).unwrap();
    h.rx(ms(5), "000#0105");
    // Not armed before the first guarding request.
    h.run_until(ms(1_000));
    assert!(h.take().is_empty());
    h.rx(ms(1_000), "705#R1");
    h.rx(ms(1_200), "705#R1");
    h.run_until(ms(1_499));
    assert_eq!(h.take(), at_ms(&[(1_000, "705#05"), (1_200, "705#85")]));
    h.run_until(ms(1_500));
    assert_eq!(h.take(), at_ms(&[(1_500, "085#3081110000000000")]));
    assert_eq!(h.dev.state(), State::PreOperational);
    assert!(h.events().contains(&Event::LifeGuardingLost));
    h.rx(ms(1_600), "705#R1");
    assert_eq!(
        h.take(),
        at_ms(&[(1_600, "705#7F"), (1_600, "085#0000000000000000")])
    );
}

#[test]
fn cia301_7_2_8_3_2_heartbeat_takes_precedence_over_node_guarding() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1017, 0, &100u16.to_le_bytes()).unwrap();
    h.rx(ms(10), "705#R1");
    h.run_until(ms(100));
    assert_eq!(h.take(), at_ms(&[(100, "705#7F")]));
}

// ------------------------------------------------------------- EMCY (§7.2.7)

#[test]
fn cia301_7_2_7_emcy_raise_and_clear_with_error_register_and_error_field() {
    let mut h = Harness::booted();
    h.run_until(ms(10));
    h.dev.emcy().raise(0x2310, [1, 2, 3, 4, 5]);
    h.run_until(ms(10));
    h.run_until(ms(11));
    h.dev.emcy().raise(0x3210, [0; 5]);
    // Raising an active error again sends nothing.
    h.dev.emcy().raise(0x3210, [0; 5]);
    h.run_until(ms(11));
    h.run_until(ms(12));
    h.dev.emcy().clear(0x2310);
    h.run_until(ms(12));
    assert_eq!(
        h.take(),
        at_ms(&[
            (10, "085#1023030102030405"),
            (11, "085#1032070000000000"),
            (12, "085#0000050000000000"),
        ])
    );
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x05);
    // Newest first.
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 2);
    assert_eq!(h.read_u32(0x1003, 1).unwrap(), 0x3210);
    assert_eq!(h.read_u32(0x1003, 2).unwrap(), 0x2310);
}

#[test]
fn cia301_7_5_2_4_an_error_entry_beyond_the_number_of_errors_is_0x08000024() {
    let mut h = Harness::booted();
    // Empty history: sub 0 reads 0, sub 1 has no data, on the wire too.
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 0);
    assert_eq!(h.read_u32(0x1003, 1), Err(AbortCode::NO_DATA));
    h.rx(ms(1), "605#4003100100000000");
    assert_eq!(h.take(), at_ms(&[(1, "585#8003100124000008")]));
    h.dev.emcy().raise(0x3210, [0; 5]);
    h.run_until(ms(2));
    h.take();
    assert_eq!(h.read_u32(0x1003, 1).unwrap(), 0x3210);
    assert_eq!(h.read_u32(0x1003, 2), Err(AbortCode::NO_DATA));
    assert_eq!(h.read_u32(0x1003, 8), Err(AbortCode::NO_DATA));
    // A sub-index the object does not have is still 0x06090011.
    assert_eq!(h.read_u32(0x1003, 9), Err(AbortCode::NO_SUB_INDEX));
    h.write(ms(3), 0x1003, 0, &[0]).unwrap();
    assert_eq!(h.read_u32(0x1003, 1), Err(AbortCode::NO_DATA));
}

#[test]
fn cia301_7_5_2_4_error_field_cleared_by_writing_zero_other_values_abort() {
    let mut h = Harness::booted();
    for code in [0x1000, 0x2000, 0x3000] {
        h.dev.emcy().raise(code, [0; 5]);
    }
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 3);
    assert_eq!(
        h.write(ms(1), 0x1003, 0, &[1]),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(
        h.write(ms(1), 0x1003, 1, &u32le(0)),
        Err(AbortCode::READ_ONLY)
    );
    h.write(ms(1), 0x1003, 0, &[0]).unwrap();
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 0);
    assert_eq!(h.read_u32(0x1003, 1), Err(AbortCode::NO_DATA));
    // The errors themselves are still active.
    assert_eq!(h.read_u32(0x1001, 0).unwrap(), 0x07);
}

#[test]
fn cia301_7_5_2_4_error_field_keeps_the_newest_entries() {
    let mut h = Harness::booted();
    for code in 0x1001..=0x100A {
        h.dev.emcy().raise(code, [0; 5]);
    }
    assert_eq!(h.read_u32(0x1003, 0).unwrap(), 8);
    assert_eq!(h.read_u32(0x1003, 1).unwrap(), 0x100A);
    assert_eq!(h.read_u32(0x1003, 8).unwrap(), 0x1003);
}

#[test]
fn cia301_7_5_2_14_emcy_inhibit_time_queues_instead_of_dropping() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1015, 0, &25u16.to_le_bytes()).unwrap(); // 2.5 ms
    h.run_until(ms(10));
    for code in [0x1000, 0x2000, 0x3000] {
        h.dev.emcy().raise(code, [0; 5]);
    }
    h.run_until(ms(20));
    assert_eq!(
        h.take(),
        vec![
            (10_000_000, "085#0010010000000000".to_string()),
            (12_500_000, "085#0020030000000000".to_string()),
            (15_000_000, "085#0030070000000000".to_string()),
        ]
    );
}

#[test]
fn cia301_7_5_2_15_emcy_cob_id_fixed_while_valid() {
    let mut h = Harness::booted();
    assert_eq!(
        h.write(ms(0), 0x1014, 0, &u32le(0x86)),
        Err(AbortCode::INVALID_VALUE)
    );
    h.write(ms(0), 0x1014, 0, &u32le(0x8000_0085)).unwrap();
    h.dev.emcy().raise(0x1000, [0; 5]);
    h.run_until(ms(1));
    assert!(h.take().is_empty());
    h.write(ms(2), 0x1014, 0, &u32le(0x86)).unwrap();
    h.dev.emcy().raise(0x2000, [0; 5]);
    h.run_until(ms(2));
    assert_eq!(h.take(), at_ms(&[(2, "086#0020030000000000")]));
}

#[test]
fn cia301_7_5_2_31_emcy_consumer_reports_consumed_emcys() {
    let mut h = Harness::booted();
    h.rx(ms(1), "083#3081110300000000");
    h.write(ms(2), 0x1028, 1, &u32le(0x83)).unwrap();
    assert_eq!(
        h.write(ms(2), 0x1028, 1, &u32le(0x84)),
        Err(AbortCode::INVALID_VALUE)
    );
    h.events();
    h.rx(ms(3), "083#3081110300000000");
    assert_eq!(
        h.events(),
        [Event::Emcy {
            id: Id::standard(0x83).unwrap(),
            emcy: wire::Emcy {
                code: 0x8130,
                register: 0x11,
                manufacturer: [3, 0, 0, 0, 0]
            }
        }]
    );
}

#[test]
fn cia301_7_2_7_1_controller_events_raise_and_clear_communication_emcys() {
    let mut h = Harness::booted();
    h.rx(ms(1), "000#0105");
    h.event(ms(10), ControllerEvent::ErrorPassive);
    h.event(ms(20), ControllerEvent::ErrorActive);
    h.event(ms(30), ControllerEvent::RxOverrun);
    h.rx(ms(40), "123#");
    h.event(ms(50), ControllerEvent::BusOff);
    assert_eq!(h.dev.state(), State::PreOperational);
    h.event(ms(60), ControllerEvent::BusOffRecovered);
    h.sent_ok(ms(61), "085#4081110000000000");
    assert_eq!(
        h.take(),
        at_ms(&[
            (10, "085#2081110000000000"),
            (20, "085#0000000000000000"),
            (30, "085#1081110000000000"),
            (40, "085#0000000000000000"),
            (60, "085#4081110000000000"),
            (61, "085#0000000000000000"),
        ])
    );
    assert!(h.events().contains(&Event::BusOff));
}

// ------------------------------------------------------------- SYNC (§7.2.5)

#[test]
fn cia301_7_2_5_sync_producer_with_counter_overflow() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1019, 0, &[3]).unwrap();
    h.write(ms(0), 0x1006, 0, &u32le(1_000)).unwrap();
    h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)).unwrap();
    h.run_until(ms(5));
    assert_eq!(
        h.take(),
        at_ms(&[
            (1, "080#01"),
            (2, "080#02"),
            (3, "080#03"),
            (4, "080#01"),
            (5, "080#02")
        ])
    );
    // §7.5.2.37: no change of the overflow value while the cycle period is not 0.
    assert_eq!(
        h.write(ms(5), 0x1019, 0, &[4]),
        Err(AbortCode::DEVICE_STATE)
    );
}

#[test]
fn cia301_7_5_2_37_counter_overflow_reserved_values_abort() {
    let mut h = Harness::booted();
    for v in [1u8, 241, 255] {
        assert_eq!(
            h.write(ms(0), 0x1019, 0, &[v]),
            Err(AbortCode::INVALID_VALUE),
            "{v}"
        );
    }
    h.write(ms(0), 0x1019, 0, &[240]).unwrap();
    h.write(ms(0), 0x1019, 0, &[0]).unwrap();
}

#[test]
fn cia301_7_5_2_5_sync_cob_id_bit_30_and_identifier_rules() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)).unwrap();
    assert_eq!(
        h.write(ms(0), 0x1005, 0, &u32le(0x4000_0081)),
        Err(AbortCode::INVALID_VALUE)
    );
    h.write(ms(0), 0x1005, 0, &u32le(0x80)).unwrap();
    h.write(ms(0), 0x1005, 0, &u32le(0x81)).unwrap();
    // A device that cannot produce SYNC refuses bit 30.
    let config = DeviceConfig {
        sync_producer: false,
        ..DeviceConfig::new(5)
    };
    let mut h = Harness::with_device(device_with_config(&options(), config));
    h.power_up(ms(0));
    assert_eq!(
        h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)),
        Err(AbortCode::INVALID_VALUE)
    );
}

#[test]
fn cia301_7_2_5_sync_consumer_drives_synchronous_tpdos() {
    let mut h = Harness::booted();
    h.dev
        .od_mut()
        .set(0x6000, 0, &Value::Unsigned16(0x1234))
        .unwrap();
    h.rx(ms(1), "000#0105");
    h.rx(ms(2), "080#");
    h.rx(ms(3), "080#");
    assert_eq!(h.take(), at_ms(&[(2, "185#3412"), (3, "185#3412")]));
}

#[test]
fn cia301_7_2_5_sync_length_not_matching_1019_raises_emcy_8240() {
    let mut h = Harness::booted();
    h.rx(ms(1), "080#01");
    assert_eq!(h.take(), at_ms(&[(1, "085#4082110000000000")]));
}

// ------------------------------------------------------------- TIME (§7.2.6)

#[test]
fn cia301_7_2_6_time_producer_and_consumer_bits() {
    let mut h = Harness::booted();
    // Default 0x100: neither consumer nor producer.
    h.events();
    h.rx(ms(1), "100#010000000200");
    assert!(h.events().is_empty());
    let mut out = cantwin_can::Outbox::new();
    let t = TimeOfDay { ms: 1, days: 2 };
    assert!(!h.dev.publish_time(t, &mut out));
    h.write(ms(2), 0x1012, 0, &u32le(0xC000_0100)).unwrap();
    // The identifier is fixed while the object is used.
    assert_eq!(
        h.write(ms(2), 0x1012, 0, &u32le(0xC000_0101)),
        Err(AbortCode::INVALID_VALUE)
    );
    h.rx(ms(3), "100#010000000200");
    assert_eq!(h.events(), [Event::Time(t)]);
    assert!(h.dev.publish_time(t, &mut out));
    assert_eq!(out.frames(), [frame("100#010000000200")]);
}

// ------------------------------------------------ Identity, fixed objects, SDO

#[test]
fn cia301_7_5_2_identity_and_fixed_objects_are_read_only() {
    let mut h = Harness::booted();
    assert_eq!(h.read_u32(0x1000, 0).unwrap(), 0x0001_0191);
    assert_eq!(h.read_u32(0x1018, 0).unwrap(), 4);
    assert_eq!(h.read_u32(0x1018, 1).unwrap(), 0x0500_005A);
    assert_eq!(h.read_u32(0x1018, 2).unwrap(), 811_044);
    assert_eq!(h.read_u32(0x1018, 3).unwrap(), 0x0001_0015);
    assert_eq!(h.read_u32(0x1018, 4).unwrap(), 1234);
    let mut name = [0u8; 16];
    let info = h.dev.read(0x1008, 0, 0, &mut name).unwrap();
    assert_eq!(&name[..info.size], b"TEST");
    for (index, sub) in [
        (0x1000, 0),
        (0x1018, 1),
        (0x1001, 0),
        (0x1008, 0),
        (0x1200, 1),
    ] {
        assert_eq!(
            h.write(ms(0), index, sub, &u32le(0)),
            Err(AbortCode::READ_ONLY),
            "{index:#06X}:{sub}"
        );
    }
}

#[test]
fn cia301_7_2_4_default_sdo_server_on_0x600_0x580() {
    let mut h = Harness::booted();
    h.rx(ms(1), "605#4000100000000000");
    h.rx(ms(2), "605#2B17100064000000");
    h.run_until(ms(102));
    assert_eq!(
        h.take(),
        at_ms(&[
            (1, "585#4300100091010100"),
            (2, "585#6017100000000000"),
            (102, "705#7F"),
        ])
    );
    // A communication object rule answered through the SDO server.
    h.rx(ms(103), "605#2314100086000000");
    assert_eq!(h.take(), at_ms(&[(103, "585#8014100030000906")]));
}

#[test]
fn cia301_7_5_2_33_additional_sdo_server_with_configured_cob_ids() {
    let mut h = Harness::booted();
    // Outside the restricted CAN-IDs (CiA 301 §7.3.5).
    h.write(ms(0), 0x1201, 1, &u32le(0x6C1)).unwrap();
    h.write(ms(0), 0x1201, 2, &u32le(0x6A1)).unwrap();
    h.rx(ms(1), "6C1#4018100100000000");
    assert_eq!(h.take(), at_ms(&[(1, "6A1#431810015A000005")]));
    assert_eq!(
        h.write(ms(2), 0x1201, 1, &u32le(0x6C2)),
        Err(AbortCode::INVALID_VALUE)
    );
    // Invalidated, it is silent; the default server still answers.
    h.write(ms(2), 0x1201, 1, &u32le(0x8000_06C1)).unwrap();
    h.rx(ms(3), "6C1#4018100100000000");
    h.rx(ms(4), "605#4018100100000000");
    assert_eq!(h.take(), at_ms(&[(4, "585#431810015A000005")]));
}

// ------------------------------------------------------------- Footprint

#[test]
fn default_device_fits_in_8_kib_beside_its_shared_description() {
    use cantwin_canopen::device::Device;
    use cantwin_canopen::objects::cia301_defaults;
    use cantwin_canopen::od::OdBuilder;
    use std::sync::Arc;
    let desc = Arc::new(
        cia301_defaults(OdBuilder::new(), &Cia301Options::default())
            .build()
            .unwrap(),
    );
    let mut dev = Device::new(Arc::clone(&desc), DeviceConfig::new(1)).unwrap();
    let mut out = cantwin_can::Outbox::new();
    dev.on_power_up(ms(0), &mut out);
    let total = core::mem::size_of::<Device>() + dev.heap_bytes();
    assert!(total <= 8 * 1024, "{total} bytes");
    // The description is shared, not copied.
    assert!(Arc::ptr_eq(dev.od().description(), &desc));
}

#[test]
fn cia301_7_2_5_sync_counter_restarts_at_1_after_stopped() {
    let mut h = Harness::booted();
    h.write(ms(0), 0x1019, 0, &[10]).unwrap();
    h.write(ms(0), 0x1006, 0, &u32le(10_000)).unwrap();
    h.write(ms(0), 0x1005, 0, &u32le(0x4000_0080)).unwrap();
    h.rx(ms(25), "000#0205");
    h.rx(ms(41), "000#8005");
    // The producer's own SYNC coming back (self-reception) is not a second SYNC.
    h.rx(ms(51), "080#01");
    h.run_until(ms(62));
    assert_eq!(
        h.take(),
        at_ms(&[
            (10, "080#01"),
            (20, "080#02"),
            (51, "080#01"),
            (61, "080#02")
        ])
    );
    let syncs = h
        .events()
        .into_iter()
        .filter(|e| matches!(e, Event::Sync { .. }))
        .count();
    assert_eq!(syncs, 4);
}

#[test]
fn cia301_7_5_2_32_device_specific_error_applies_its_sub_index() {
    let mut h = Harness::booted();
    h.rx(ms(1), "000#0105");
    let mut out = cantwin_can::Outbox::new();
    // 0x1029 sub 1 = 0: pre-operational from operational.
    assert_eq!(
        h.dev.error_detected(1, ms(2), &mut out),
        Some(State::PreOperational)
    );
    assert_eq!(h.dev.error_detected(1, ms(3), &mut out), None);
    // The test dictionary has no sub-index 2.
    assert_eq!(h.dev.error_detected(2, ms(3), &mut out), None);
    h.write(ms(4), 0x1029, 1, &[2]).unwrap();
    assert_eq!(
        h.dev.error_detected(1, ms(5), &mut out),
        Some(State::Stopped)
    );
    assert!(out.is_empty());
}

#[test]
fn cia301_7_2_2_rpdo_faults_raise_and_clear_their_emcys() {
    let mut h = Harness::booted();
    // RPDO1 deadline monitoring: event timer 100 ms.
    h.write(ms(0), 0x1400, 5, &100u16.to_le_bytes()).unwrap();
    h.rx(ms(1), "000#0105");
    h.rx(ms(10), "205#01");
    h.run_until(ms(150));
    h.rx(ms(200), "205#02");
    // Too short: not processed; too long: processed, reported.
    h.rx(ms(250), "205#");
    h.rx(ms(260), "205#03");
    h.rx(ms(270), "205#0405");
    h.rx(ms(280), "205#06");
    assert_eq!(
        h.take(),
        at_ms(&[
            (110, "085#5082110000000000"),
            (200, "085#0000000000000000"),
            (250, "085#1082110000000000"),
            (260, "085#0000000000000000"),
            (270, "085#2082110000000000"),
            (280, "085#0000000000000000"),
        ])
    );
    assert_eq!(h.dev.od().get(0x6200, 0).unwrap(), Value::Unsigned8(6));
}

#[test]
fn cia301_7_5_2_12_time_producer_bit_refused_when_the_device_cannot_produce() {
    let config = DeviceConfig {
        time_producer: false,
        ..DeviceConfig::new(5)
    };
    let mut h = Harness::with_device(device_with_config(&options(), config));
    h.power_up(ms(0));
    assert_eq!(
        h.write(ms(0), 0x1012, 0, &u32le(0x4000_0100)),
        Err(AbortCode::INVALID_VALUE)
    );
    // Consuming is always possible.
    h.write(ms(0), 0x1012, 0, &u32le(0x8000_0100)).unwrap();
}

#[test]
fn cia301_7_5_2_15_emcy_cob_id_bit_30_is_reserved() {
    let mut h = Harness::booted();
    assert_eq!(
        h.write(ms(0), 0x1014, 0, &u32le(0x4000_0085)),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(h.read_u32(0x1014, 0).unwrap(), 0x85);
}

#[test]
fn cia301_7_2_4_3_3_expedited_download_without_size_through_the_device_takes_the_type_size() {
    // e = 1, s = 0 (command 0x22): the server takes the object's type size, so an
    // UNSIGNED16 object is written with its 2 bytes, not refused for a 4-byte length.
    let mut h = Harness::booted();
    h.rx(ms(1), "605#2217100064000000");
    h.rx(ms(2), "605#4017100000000000");
    assert_eq!(
        h.take(),
        at_ms(&[(1, "585#6017100000000000"), (2, "585#4B17100064000000")])
    );
}

#[test]
fn cia301_7_2_4_1_minimum_capability_device_offers_expedited_sdo_only() {
    let config = DeviceConfig {
        sdo: SdoCapabilities::EXPEDITED_ONLY,
        ..DeviceConfig::new(5)
    };
    let mut h = Harness::with_device(device_with_config(&options(), config));
    h.power_up(ms(0));
    h.take();
    // Initiate segmented download of 0x1017, block upload of 0x1008, upload segment.
    h.rx(ms(1), "605#2117100002000000");
    h.rx(ms(2), "605#A40810007F000000");
    h.rx(ms(3), "605#6000000000000000");
    // Expedited download of 0x1017 works.
    h.rx(ms(4), "605#2B171000E8030000");
    assert_eq!(
        h.take(),
        at_ms(&[
            (1, "585#8017100001000405"),
            (2, "585#8008100001000405"),
            (3, "585#8000000001000405"),
            (4, "585#6017100000000000"),
        ])
    );
}
