//! DeviceNet Vol. 1, Predefined Master/Slave Connection Set: Allocate and Release through
//! the group 2 only unconnected port with every error response, the explicit and polled
//! I/O connections, expected packet rate and the inactivity watchdog.
//!
//! Slave MAC 9 (explicit request 0x44C, response 0x44B, unconnected request 0x44E, poll
//! command 0x44D, poll response 0x3C9); master MAC 10 (0x0A).
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_devicenet::objects::connection::ConnState;
use cantwin_devicenet::{Led, NetworkStatus, SlaveEvent};
use common::*;

fn allocated(choice: u8) -> (cantwin_devicenet::Slave<Drive>, cantwin_can::Instant) {
    let mut s = slave(9);
    let t = online(&mut s);
    let req = format!("44E#0A4B0301{choice:02X}0A");
    assert_eq!(deliver(&mut s, &req, t), ["44B#0ACB00"]);
    (s, t)
}

#[test]
fn allocate_explicit_and_poll_then_status_owned() {
    let (mut s, t) = allocated(0x03);
    let dn = s.devicenet_object();
    assert_eq!((dn.choice, dn.master), (0x03, Some(mac(10))));
    // DeviceNet object attribute 5, allocation information.
    assert_eq!(deliver(&mut s, "44C#0A0E030105", t), ["44B#0A8E030A"]);
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Configuring);
    assert!(matches!(
        s.app().events.last(),
        Some((_, SlaveEvent::Allocated { choice: 3, .. }))
    ));
}

#[test]
fn allocate_error_already_allocated_by_another_master() {
    let (mut s, t) = allocated(0x01);
    // Master 11 tries: object state conflict, additional code 0x01.
    assert_eq!(deliver(&mut s, "44E#0B4B0301010B", t), ["44B#0B940C01"]);
}

#[test]
fn allocate_error_already_allocated_choice() {
    let (mut s, t) = allocated(0x01);
    assert_eq!(deliver(&mut s, "44E#0A4B0301010A", t), ["44B#0A940B02"]);
}

#[test]
fn allocate_error_invalid_choices() {
    let mut s = slave(9);
    let t = online(&mut s);
    // All zeros.
    assert_eq!(deliver(&mut s, "44E#0A4B0301000A", t), ["44B#0A942002"]);
    // Bit-strobe, COS, cyclic, multicast poll: not supported by this device.
    for c in [0x04, 0x08, 0x10, 0x20, 0x80] {
        let req = format!("44E#0A4B0301{:02X}0A", c | 1);
        assert_eq!(deliver(&mut s, &req, t), ["44B#0A942002"], "choice {c:#x}");
    }
    // Polled I/O without explicit messaging.
    assert_eq!(deliver(&mut s, "44E#0A4B0301020A", t), ["44B#0A942002"]);
    // The allocator's MAC ID must be the sender's.
    assert_eq!(deliver(&mut s, "44E#0A4B0301010B", t), ["44B#0A942002"]);
    assert_eq!(s.devicenet_object().master, None);
}

#[test]
fn allocate_error_short_and_long_bodies() {
    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B030101", t), ["44B#0A9413FF"]);
    assert_eq!(deliver(&mut s, "44E#0A4B0301010A00", t), ["44B#0A9415FF"]);
    assert_eq!(deliver(&mut s, "44E#0A4B03", t), ["44B#0A9413FF"]);
    // Allocate to a class other than DeviceNet: object does not exist.
    assert_eq!(deliver(&mut s, "44E#0A4B0101010A", t), ["44B#0A9416FF"]);
}

#[test]
fn unconnected_port_accepts_only_allocate_and_release() {
    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A0E010101", t), ["44B#0A940803"]);
    assert_eq!(deliver(&mut s, "44E#0A0E030101", t), ["44B#0A940803"]);
}

#[test]
fn release_errors_and_success() {
    let (mut s, t) = allocated(0x03);
    // Another master: conflict.
    assert_eq!(deliver(&mut s, "44E#0B4C030102", t), ["44B#0B940C01"]);
    // Invalid choice.
    assert_eq!(deliver(&mut s, "44E#0A4C030100", t), ["44B#0A942002"]);
    assert_eq!(deliver(&mut s, "44E#0A4C030104", t), ["44B#0A942002"]);
    // Release poll: ok; again: already released.
    assert_eq!(deliver(&mut s, "44E#0A4C030102", t), ["44B#0ACC"]);
    assert!(s.poll_connection().is_none());
    assert_eq!(deliver(&mut s, "44E#0A4C030102", t), ["44B#0A940B02"]);
    // Release explicit: the master is no longer owner.
    assert_eq!(deliver(&mut s, "44E#0A4C030101", t), ["44B#0ACC"]);
    assert_eq!(s.devicenet_object().master, None);
    assert_eq!(deliver(&mut s, "44C#0A0E010101", t), Vec::<String>::new());
}

#[test]
fn release_through_the_explicit_connection() {
    let (mut s, t) = allocated(0x03);
    assert_eq!(deliver(&mut s, "44C#0A4C030103", t), ["44B#0ACC"]);
    assert_eq!(s.devicenet_object().choice, 0);
}

#[test]
fn allocate_poll_through_the_explicit_connection() {
    let (mut s, t) = allocated(0x01);
    assert_eq!(deliver(&mut s, "44C#0A4B0301020A", t), ["44B#0ACB00"]);
    assert_eq!(s.devicenet_object().choice, 0x03);
}

#[test]
fn requests_from_a_non_owner_on_the_explicit_identifier_are_ignored() {
    let (mut s, t) = allocated(0x01);
    assert!(deliver(&mut s, "44C#0B0E010101", t).is_empty());
    assert_eq!(deliver(&mut s, "44C#0A0E010101", t), ["44B#0A8E2301"]);
}

#[test]
fn xid_is_echoed() {
    let (mut s, t) = allocated(0x01);
    assert_eq!(deliver(&mut s, "44C#4A0E010101", t), ["44B#4A8E2301"]);
}

/// Expected packet rate → Established; poll of 2 words each way; watchdog = 4 × EPR.
#[test]
fn poll_established_by_expected_packet_rate_and_exchanged() {
    let (mut s, t) = allocated(0x03);
    // Poll before the EPR is set: the connection is configuring, nothing is answered.
    assert!(deliver(&mut s, "44D#11223344", t).is_empty());
    assert_eq!(s.network_status(), NetworkStatus::WaitingForMaster);
    assert_eq!(s.network_status().leds(), (Led::Blink, Led::Off));
    // EPR 100 ms.
    assert_eq!(
        deliver(&mut s, "44C#0A1005020964 00".replace(' ', "").as_str(), t),
        ["44B#0A906400"]
    );
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    assert_eq!(deliver(&mut s, "44D#11223344", t), ["3C9#00010203"]);
    assert_eq!(s.app().consumed, vec![vec![0x11, 0x22, 0x33, 0x44]]);
    assert_eq!(s.network_status().leds(), (Led::On, Led::Off));
    // Status word: owned, I/O in run mode.
    assert_eq!(deliver(&mut s, "44C#0A0E010105", t), ["44B#0A8E6100"]);
    // Zero-length poll: master idle; still answered.
    assert_eq!(deliver(&mut s, "44D#", t), ["3C9#00010203"]);
    assert_eq!(deliver(&mut s, "44C#0A0E010105", t), ["44B#0A8E7100"]);
    // Too long for the consumed size: dropped.
    assert!(deliver(&mut s, "44D#1122334455", t).is_empty());
}

/// A silent master: the poll connection times out 4 × EPR after the last poll; the
/// explicit connection (EPR 2500 ms) is deleted 10 s after its last message.
#[test]
fn silent_master_watchdog() {
    let (mut s, t) = allocated(0x03);
    deliver(&mut s, "44C#0A100502096400", t);
    let t_poll = t + cantwin_can::Duration::from_millis(50);
    deliver(&mut s, "44D#00000000", t_poll);
    use cantwin_can::Node;
    assert_eq!(
        s.next_deadline(),
        Some(t_poll + cantwin_can::Duration::from_millis(400))
    );
    tick(&mut s, t_poll + cantwin_can::Duration::from_millis(399));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    tick(&mut s, t_poll + cantwin_can::Duration::from_millis(400));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::TimedOut);
    assert_eq!(s.network_status().leds(), (Led::Off, Led::Blink));
    assert!(
        deliver(
            &mut s,
            "44D#00000000",
            t_poll + cantwin_can::Duration::from_millis(500)
        )
        .is_empty()
    );
    // Extended status: faulted I/O connection.
    let t2 = t + cantwin_can::Duration::from_millis(600);
    assert_eq!(deliver(&mut s, "44C#0A0E010105", t2), ["44B#0A8E2100"]);
    // Reset service on the connection brings it back.
    assert_eq!(deliver(&mut s, "44C#0A050502", t2), ["44B#0A85"]);
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    // The explicit connection: 4 × 2500 ms after its last request.
    assert_eq!(
        s.next_deadline(),
        Some(t2 + cantwin_can::Duration::from_millis(400))
    );
    tick(&mut s, t2 + cantwin_can::Duration::from_millis(400));
    tick(&mut s, t2 + cantwin_can::Duration::from_millis(9_999));
    assert!(s.explicit_connection().is_some());
    tick(&mut s, t2 + cantwin_can::Duration::from_millis(10_000));
    assert!(s.explicit_connection().is_none());
    assert!(
        s.app()
            .events
            .iter()
            .any(|(_, e)| *e == SlaveEvent::ExplicitTimedOut { instance: 1 })
    );
    assert!(
        s.app()
            .events
            .iter()
            .any(|(_, e)| *e == SlaveEvent::IoTimedOut)
    );
}

#[test]
fn watchdog_actions_auto_delete_and_auto_reset() {
    let (mut s, t) = allocated(0x03);
    deliver(&mut s, "44C#0A100502096400", t);
    // Auto reset: the connection stays established.
    assert_eq!(deliver(&mut s, "44C#0A1005020C02", t), ["44B#0A90"]);
    tick(&mut s, t + cantwin_can::Duration::from_millis(400));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    // Auto delete: the connection disappears and its allocation bit with it.
    assert_eq!(deliver(&mut s, "44C#0A1005020C01", t), ["44B#0A90"]);
    tick(&mut s, t + cantwin_can::Duration::from_millis(800));
    assert!(s.poll_connection().is_none());
    assert_eq!(s.devicenet_object().choice, 0x01);
    // Invalid action.
    assert_eq!(deliver(&mut s, "44C#0A1005010C00", t), ["44B#0A9409FF"]);
}

#[test]
fn poll_sizes_from_pdc_configuration_fragment_16_words() {
    let mut s = slave_with(9, Drive::new(16, 16));
    let t = online(&mut s);
    deliver(&mut s, "44E#0A4B0301030A", t);
    // Produced and consumed sizes (attributes 7 and 8) are 32 bytes.
    assert_eq!(deliver(&mut s, "44C#0A0E050207", t), ["44B#0A8E2000"]);
    assert_eq!(deliver(&mut s, "44C#0A0E050208", t), ["44B#0A8E2000"]);
    deliver(&mut s, "44C#0A100502096400", t);
    // 32 bytes of output in 5 unacknowledged fragments.
    let out: Vec<u8> = (0x40..0x60).collect();
    let frames = cantwin_devicenet::wire::io_fragments(&out);
    assert_eq!(frames.len(), 5);
    for fr in &frames[..4] {
        let hex: String = fr.iter().map(|b| format!("{b:02X}")).collect();
        assert!(deliver(&mut s, &format!("44D#{hex}"), t).is_empty());
    }
    let hex: String = frames[4].iter().map(|b| format!("{b:02X}")).collect();
    assert_eq!(
        deliver(&mut s, &format!("44D#{hex}"), t),
        [
            "3C9#00000102030405 06".replace(' ', ""),
            "3C9#410708090A0B0C0D".into(),
            "3C9#420E0F10111213 14".replace(' ', ""),
            "3C9#4315161718191A1B".into(),
            "3C9#841C1D1E1F".into(),
        ]
    );
    assert_eq!(s.app().consumed, vec![out]);
}

#[test]
fn connection_object_attributes() {
    let (mut s, t) = allocated(0x03);
    // Instance 1: state established, explicit, class 3 server, IDs 0x44B / 0x44C,
    // initial comm 0x21, sizes 32, EPR 2500, watchdog auto delete.
    let get = |s: &mut cantwin_devicenet::Slave<Drive>, inst: u8, a: u8| {
        deliver(s, &format!("44C#0A0E05{inst:02X}{a:02X}"), t)
    };
    assert_eq!(get(&mut s, 1, 1), ["44B#0A8E03"]);
    assert_eq!(get(&mut s, 1, 2), ["44B#0A8E00"]);
    assert_eq!(get(&mut s, 1, 3), ["44B#0A8E83"]);
    assert_eq!(get(&mut s, 1, 4), ["44B#0A8E4B04"]);
    assert_eq!(get(&mut s, 1, 5), ["44B#0A8E4C04"]);
    assert_eq!(get(&mut s, 1, 6), ["44B#0A8E21"]);
    assert_eq!(get(&mut s, 1, 9), ["44B#0A8EC409"]);
    assert_eq!(get(&mut s, 1, 12), ["44B#0A8E01"]);
    // Instance 2: configuring, I/O, class 2 server, IDs 0x3C9 / 0x44D.
    assert_eq!(get(&mut s, 2, 1), ["44B#0A8E01"]);
    assert_eq!(get(&mut s, 2, 3), ["44B#0A8E82"]);
    assert_eq!(get(&mut s, 2, 4), ["44B#0A8EC903"]);
    assert_eq!(get(&mut s, 2, 5), ["44B#0A8E4D04"]);
    assert_eq!(get(&mut s, 2, 6), ["44B#0A8E01"]);
    // Unsupported attribute, not settable attribute, missing instance.
    assert_eq!(get(&mut s, 2, 10), ["44B#0A9414FF"]);
    assert_eq!(deliver(&mut s, "44C#0A1005020701", t), ["44B#0A940EFF"]);
    assert_eq!(get(&mut s, 3, 1), ["44B#0A9416FF"]);
    // EPR with a short value.
    assert_eq!(deliver(&mut s, "44C#0A1005020964", t), ["44B#0A9413FF"]);
}

/// The stack's table-driven Parameter object, for devices without their own class 0x0F.
#[test]
fn table_driven_parameter_object_on_the_explicit_connection() {
    use cantwin_devicenet::objects::parameter::{Param, ParameterObject, data_type};
    use cantwin_devicenet::{Application, SlaveConfig};
    struct NoParams;
    impl Application for NoParams {
        fn poll_sizes(&self) -> (u16, u16) {
            (2, 2)
        }
        fn produce(&mut self, _: cantwin_can::Instant) -> Vec<u8> {
            vec![0, 0]
        }
        fn consume(&mut self, _: &[u8], _: cantwin_can::Instant) {}
    }
    let params = ParameterObject::new(vec![Param {
        instance: 3,
        data_type: data_type::UINT,
        read_only: false,
        limits: Some((0, 1000)),
        value: vec![0x10, 0x00],
    }]);
    let mut s = cantwin_devicenet::Slave::new(
        SlaveConfig::new(mac(9), cantwin_can::BitRate::R250K, identity()),
        NoParams,
    )
    .unwrap()
    .with_parameters(params);
    let mut out = cantwin_can::Outbox::new();
    use cantwin_can::Node;
    s.on_power_up(at(0), &mut out);
    s.on_tick(at(SEC), &mut out);
    s.on_tick(at(2 * SEC), &mut out);
    let t = at(2 * SEC);
    assert_eq!(deliver(&mut s, "44E#0A4B0301010A", t), ["44B#0ACB00"]);
    assert_eq!(deliver(&mut s, "44C#0A0E0F0301", t), ["44B#0A8E1000"]);
    assert_eq!(deliver(&mut s, "44C#0A100F0301E803", t), ["44B#0A90"]);
    assert_eq!(deliver(&mut s, "44C#0A100F0301E903", t), ["44B#0A9409FF"]);
    assert_eq!(s.parameters().unwrap().value(3), Some(&[0xE8, 0x03][..]));
    assert_eq!(deliver(&mut s, "44C#0A0E0F0401", t), ["44B#0A9416FF"]);
}

/// Manual §3.2: explicit messages up to 32 bytes. A reply that would not fit is answered
/// "reply data too large"; one that fits goes in acknowledged fragments.
#[test]
fn reply_over_32_bytes_is_refused() {
    use cantwin_devicenet::SlaveConfig;
    let mut id = identity();
    id.product_name = "EXP-CAN/DN-ADV for ADV200 drives".into();
    assert_eq!(id.product_name.len(), 32);
    let mut s = cantwin_devicenet::Slave::new(
        SlaveConfig::new(mac(9), cantwin_can::BitRate::R500K, id),
        Drive::new(1, 1),
    )
    .unwrap();
    let t = online(&mut s);
    deliver(&mut s, "44E#0A4B0301010A", t);
    assert_eq!(deliver(&mut s, "44C#0A010101", t), ["44B#0A9411FF"]);
    // Attribute 7 alone (33 bytes + service) is too large too; attribute 1 is not.
    assert_eq!(deliver(&mut s, "44C#0A0E010107", t), ["44B#0A9411FF"]);
    assert_eq!(deliver(&mut s, "44C#0A0E010101", t), ["44B#0A8E2301"]);
}

/// Message Router (class 0x02): routes requests; exposes only its class revision. Unknown
/// classes, instances, attributes and services get their general status codes.
#[test]
fn message_router_and_general_status_codes() {
    let (mut s, t) = allocated(0x01);
    assert_eq!(deliver(&mut s, "44C#0A0E020001", t), ["44B#0A8E0100"]);
    assert_eq!(deliver(&mut s, "44C#0A0E020101", t), ["44B#0A9414FF"]);
    assert_eq!(deliver(&mut s, "44C#0A0E020201", t), ["44B#0A9416FF"]);
    assert_eq!(
        deliver(&mut s, "44C#0A10020101 00".replace(' ', "").as_str(), t),
        ["44B#0A9414FF"]
    );
    // Unknown class, unknown Identity attribute, Get with extra data, request too short.
    assert_eq!(deliver(&mut s, "44C#0A0E990101", t), ["44B#0A9416FF"]);
    assert_eq!(deliver(&mut s, "44C#0A0E010163", t), ["44B#0A9414FF"]);
    assert_eq!(deliver(&mut s, "44C#0A0E01010100", t), ["44B#0A9415FF"]);
    assert_eq!(deliver(&mut s, "44C#0A0E01", t), ["44B#0A9413FF"]);
    // Identity: class revision, and Set of a Get-only attribute.
    assert_eq!(deliver(&mut s, "44C#0A0E010001", t), ["44B#0A8E0100"]);
    assert_eq!(
        deliver(&mut s, "44C#0A1001010101 00".replace(' ', "").as_str(), t),
        ["44B#0A940EFF"]
    );
}
