//! DeviceNet Vol. 1 §6 network access: the duplicate MAC ID check at power-up (two
//! requests one second apart), the response from an owner, communication faulted state
//! (LEDs and alarm event, manual §3.7 "Duplicate MacID Check failed"), and bus-off with the
//! DeviceNet object's BOI and bus-off counter.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_can::{ControllerEvent, Node, Outbox};
use cantwin_devicenet::link::LinkState;
use cantwin_devicenet::{Led, NetworkStatus, SlaveEvent};
use common::*;

#[test]
fn power_up_sends_two_requests_one_second_apart_then_online() {
    let mut s = slave(12);
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    assert_eq!(sent(&mut out), ["467#0023010D0C0B0A"]);
    assert_eq!(s.network_status().leds(), (Led::Blink, Led::Blink));
    assert_eq!(s.next_deadline(), Some(at(SEC)));
    // Nothing but the check is answered while checking.
    assert!(deliver(&mut s, "466#0A4B0301010A", at(SEC / 2)).is_empty());
    assert_eq!(tick(&mut s, at(SEC)), ["467#0023010D0C0B0A"]);
    assert_eq!(s.next_deadline(), Some(at(2 * SEC)));
    assert!(tick(&mut s, at(2 * SEC)).is_empty());
    assert_eq!(s.link_state(), LinkState::Online);
    assert_eq!(s.next_deadline(), None);
    assert_eq!(s.app().events, vec![(2 * SEC, SlaveEvent::Online)]);
    assert_eq!(s.network_status(), NetworkStatus::WaitingForMaster);
}

#[test]
fn owner_answers_a_request_for_its_mac_id() {
    let mut s = slave(12);
    online(&mut s);
    // Another device (vendor 0x0456, serial 1) checks MAC 12: we answer with ours.
    assert_eq!(
        deliver(&mut s, "467#00560401000000", at(3 * SEC)),
        ["467#8023010D0C0B0A"]
    );
    assert_eq!(s.link_state(), LinkState::Online);
}

#[test]
fn response_during_check_faults() {
    let mut s = slave(12);
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    assert!(deliver(&mut s, "467#80560401000000", at(SEC / 10)).is_empty());
    assert_eq!(s.link_state(), LinkState::CommFaulted);
    assert_eq!(s.network_status().leds(), (Led::Off, Led::Blink));
    assert_eq!(s.app().events, vec![(SEC / 10, SlaveEvent::DuplicateMac)]);
    // Silent from now on, and no more requests.
    assert!(tick(&mut s, at(SEC)).is_empty());
    assert!(deliver(&mut s, "466#0A4B0301010A", at(3 * SEC)).is_empty());
    assert!(deliver(&mut s, "467#00560401000000", at(3 * SEC)).is_empty());
}

#[test]
fn request_during_second_window_faults() {
    let mut s = slave(12);
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    tick(&mut s, at(SEC));
    assert!(deliver(&mut s, "467#00560401000000", at(SEC + 5)).is_empty());
    assert_eq!(s.link_state(), LinkState::CommFaulted);
    assert!(tick(&mut s, at(2 * SEC)).is_empty());
}

#[test]
fn response_while_online_faults_joined_segments() {
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    assert!(deliver(&mut s, "467#80560401000000", t).is_empty());
    assert_eq!(s.link_state(), LinkState::CommFaulted);
    assert!(s.explicit_connection().is_none());
}

/// Two devices with the same MAC ID on one wire: the one powered second sees the owner's
/// response and faults; the owner stays on-line.
#[test]
fn second_device_with_the_same_mac_id() {
    let mut a = slave(12);
    let mut b = slave(12);
    let mut w = Wire::new();
    {
        let mut nodes: [&mut dyn Node; 2] = [&mut a, &mut b];
        w.power_up_one(&mut nodes, 0);
        w.run_until(&mut nodes, at(3 * SEC));
        w.power_up_one(&mut nodes, 1);
        w.run_until(&mut nodes, at(6 * SEC));
    }
    assert_eq!(
        w.lines(0),
        [
            "0.000 0 467#0023010D0C0B0A",
            "1.000 0 467#0023010D0C0B0A",
            "3.000 1 467#0023010D0C0B0A",
            "3.000 0 467#8023010D0C0B0A",
        ]
    );
    assert_eq!(b.link_state(), LinkState::CommFaulted);
    assert_eq!(a.link_state(), LinkState::Online);
}

#[test]
fn bus_off_counts_and_holds_with_boi_zero() {
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    let mut out = Outbox::new();
    s.on_controller_event(ControllerEvent::BusOff, t, &mut out);
    assert_eq!(s.devicenet_object().bus_off_count, 1);
    assert_eq!(s.link_state(), LinkState::CommFaulted);
    assert!(s.explicit_connection().is_none());
    s.on_controller_event(ControllerEvent::BusOffRecovered, t, &mut out);
    assert!(out.is_empty());
    assert!(deliver(&mut s, "466#0A4B0301010A", t).is_empty());
    assert!(s.app().events.iter().any(|(_, e)| *e == SlaveEvent::BusOff));
}

#[test]
fn bus_off_with_boi_one_recovers_through_a_new_check() {
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    // BOI := 1, then read it back and the bus-off counter.
    assert_eq!(deliver(&mut s, "464#0A1003010301", t), ["463#0A90"]);
    assert_eq!(deliver(&mut s, "464#0A0E030103", t), ["463#0A8E01"]);
    let mut out = Outbox::new();
    s.on_controller_event(ControllerEvent::BusOff, t, &mut out);
    s.on_controller_event(ControllerEvent::BusOffRecovered, t, &mut out);
    assert_eq!(sent(&mut out), ["467#0023010D0C0B0A"]);
    let t2 = t + cantwin_can::Duration::from_secs(2);
    tick(&mut s, t + cantwin_can::Duration::from_secs(1));
    tick(&mut s, t2);
    assert_eq!(s.link_state(), LinkState::Online);
    deliver(&mut s, "466#0A4B0301010A", t2);
    assert_eq!(deliver(&mut s, "464#0A0E030104", t2), ["463#0A8E01"]);
    // The counter can only be cleared.
    assert_eq!(deliver(&mut s, "464#0A1003010401", t2), ["463#0A9409FF"]);
    assert_eq!(deliver(&mut s, "464#0A1003010400", t2), ["463#0A90"]);
    assert_eq!(deliver(&mut s, "464#0A0E030104", t2), ["463#0A8E00"]);
}

#[test]
fn devicenet_object_attributes() {
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    // MAC ID 12, baud rate 500 k (2), class revision 2.
    assert_eq!(deliver(&mut s, "464#0A0E030101", t), ["463#0A8E0C"]);
    assert_eq!(deliver(&mut s, "464#0A0E030102", t), ["463#0A8E02"]);
    assert_eq!(deliver(&mut s, "464#0A0E030001", t), ["463#0A8E0200"]);
    // MAC ID and baud rate come from the drive parameters: not settable over the network.
    assert_eq!(deliver(&mut s, "464#0A1003010105", t), ["463#0A940EFF"]);
    assert_eq!(deliver(&mut s, "464#0A0E030109", t), ["463#0A9414FF"]);
    assert_eq!(deliver(&mut s, "464#0A0E030201", t), ["463#0A9416FF"]);
    assert_eq!(deliver(&mut s, "464#0A010301", t), ["463#0A9408FF"]);
    assert_eq!(deliver(&mut s, "464#0A0E0301", t), ["463#0A9413FF"]);
}

#[test]
fn identity_reset_answers_then_restarts_the_check() {
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    assert_eq!(
        deliver(&mut s, "464#0A05010100", t),
        ["463#0A85", "467#0023010D0C0B0A"]
    );
    assert_eq!(
        s.link_state(),
        LinkState::Checking {
            requests: 1,
            until: t + cantwin_can::Duration::from_secs(1)
        }
    );
    assert!(s.explicit_connection().is_none());
    assert!(
        s.app()
            .events
            .iter()
            .any(|(_, e)| *e == SlaveEvent::Reset(0))
    );
    // Reset type 2 is not defined.
    let mut s = slave(12);
    let t = online(&mut s);
    deliver(&mut s, "466#0A4B0301010A", t);
    assert_eq!(deliver(&mut s, "464#0A05010102", t), ["463#0A9420FF"]);
}

/// Manual §3.6: DeviceNet runs at 125, 250 or 500 kbit/s ("Wrong baudrate" otherwise).
#[test]
fn bit_rates_125_250_500_only() {
    use cantwin_can::BitRate;
    use cantwin_devicenet::{ConfigError, SlaveConfig};
    for (rate, code) in [
        (BitRate::R125K, 0u8),
        (BitRate::R250K, 1),
        (BitRate::R500K, 2),
    ] {
        let mut s = cantwin_devicenet::Slave::new(
            SlaveConfig::new(mac(12), rate, identity()),
            Drive::new(1, 1),
        )
        .unwrap();
        let t = online(&mut s);
        deliver(&mut s, "466#0A4B0301010A", t);
        assert_eq!(
            deliver(&mut s, "464#0A0E030102", t),
            [format!("463#0A8E{code:02X}")]
        );
    }
    let err = cantwin_devicenet::Slave::new(
        SlaveConfig::new(mac(12), BitRate::R1M, identity()),
        Drive::new(1, 1),
    )
    .err();
    assert_eq!(err, Some(ConfigError::BitRate(1_000_000)));
}
