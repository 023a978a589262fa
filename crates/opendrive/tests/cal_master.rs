//! A CAL master drives the drive with typed requests: message 0 start at 50.00 Hz, message 1
//! enabled, message 2 read; confirmations and the notification decode into the manual's
//! meanings.
#![allow(clippy::unwrap_used)]

mod common;
use cantwin_cal::{ClientEvent, Payload, Request};
use cantwin_opendrive::messages::{
    Code, CommandByte, ErrorFlags, Message0State, centi_hz, message0_write, mux, mux_entry,
};
use cantwin_opendrive::{MESSAGE_0, MESSAGE_1, MESSAGE_2};
use common::*;

#[test]
fn master_starts_the_drive_and_receives_the_overload_notification() {
    let mut r = rig();
    let start = CommandByte {
        reference_remote: Code::Set,
        command_remote: Code::Set,
        can_start: Code::Set,
        can_reverse: Code::Reset,
    };
    let data = message0_write(start, centi_hz(50.0).unwrap());
    r.request(MESSAGE_0, Request::WriteBasic(Payload::new(&data).unwrap()));
    r.run_ms(1);
    let Some(ClientEvent::Confirmed { data, .. }) = r.events().pop() else {
        panic!("no confirmation")
    };
    let state = Message0State::decode(data.as_slice()).unwrap();
    assert!(state.commands.can_start && state.commands.command_remote);
    assert_eq!(state.reference_centi_hz, 5000);

    r.request(MESSAGE_1, Request::ControlEvent(true));
    let max = mux(mux_entry("max-frequency").unwrap()).unwrap();
    r.request(MESSAGE_2, Request::ReadMux(max));
    r.run_ms(3100);
    let ev = r.events();
    assert!(matches!(
        ev[0],
        ClientEvent::EventState { enabled: true, .. }
    ));
    assert!(
        matches!(ev[2], ClientEvent::Confirmed { object: MESSAGE_2, data, .. } if data.as_u16() == Some(6000))
    );

    r.drive_mut().set_load_torque_pct(500.0);
    r.run_ms(2);
    let Some(ClientEvent::Notified { data, .. }) = r.events().pop() else {
        panic!("no notification")
    };
    let flags = ErrorFlags::decode(data.as_slice()).unwrap();
    assert!(flags.overload && !flags.overtemperature && !flags.overvoltage);
}

#[test]
fn master_remote_read_of_message_0() {
    let mut r = rig();
    r.request(MESSAGE_0, Request::ReadBasicRemote);
    r.run_ms(1);
    assert_eq!(r.texts(), ["1B7#R4", "1B7#00550000"]);
    assert!(matches!(
        r.events()[..],
        [ClientEvent::Confirmed { object: MESSAGE_0, data, .. }] if data.as_slice() == [0x55, 0, 0]
    ));
}
