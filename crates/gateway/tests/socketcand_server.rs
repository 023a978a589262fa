//! The socketcand server on an in-memory bus: the handshake and framing python-can relies on
//! (protocols notes §3.1.4, §3.1.5), raw-mode frames both ways, and error replies.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Arc;

use cantwin_can::{Frame, Id};
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::Server;
use cantwin_gateway::{BusConnector, BusPort, GatewayError, Limits};
use common::{GUARD, Peer, socketcand_server, ts};

fn server(bus: &MemoryBus) -> Server {
    socketcand_server(bus, Limits::default())
}

#[test]
fn python_can_handshake_each_reply_in_its_own_read() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.socketcand_handshake("vcan0");
    assert_eq!(bus.attached("vcan0"), 1);
}

#[test]
fn zero_length_frame_has_two_spaces_before_the_bracket() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.socketcand_handshake("vcan0");
    // CANopen SYNC, 0x080 with no data: the frame python-can fails on if written with one
    // space.
    bus.inject("vcan0", Frame::std(0x080, &[]).unwrap(), ts());
    c.expect(b"< frame 080 1700000000.000250  >");
    bus.inject("vcan0", Frame::std(0x701, &[0x05]).unwrap(), ts());
    c.expect(b"< frame 701 1700000000.000250 05 >");
    let ext = Frame::data(
        Id::extended(0x18FF_50E5).unwrap(),
        &[0xDE, 0xAD, 0xBE, 0xEF],
    )
    .unwrap();
    bus.inject("vcan0", ext, ts());
    c.expect(b"< frame 18FF50E5 1700000000.000250 DEADBEEF >");
}

#[test]
fn python_can_send_commands_become_bus_frames() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let node = bus.open("vcan0", 16).unwrap();
    let mut c = Peer::connect(srv.local_addr());
    c.socketcand_handshake("vcan0");
    // The exact bytes python-can 4.6.1 was seen to write.
    c.write(b"< send 123 0  >< send 123 2 1 f1 >< send 1AAAAAAA 1 a >");
    c.write(b"< send 605 8 40 0 10 0 0 0 0 0 >< send 705 1  >");
    let expected = [
        Frame::std(0x123, &[]).unwrap(),
        Frame::std(0x123, &[0x01, 0xF1]).unwrap(),
        Frame::data(Id::extended(0x1AAA_AAAA).unwrap(), &[0x0A]).unwrap(),
        Frame::std(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]).unwrap(),
        // python-can's remote frame: a length and no data bytes.
        Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap(),
    ];
    for want in expected {
        let got = node.recv_timeout(GUARD).unwrap().unwrap();
        assert_eq!(got.frame, want);
    }
    // `send` has no reply: nothing but frames may come back.
    c.write(b"< echo >");
    c.expect(b"< echo >");
}

#[test]
fn clients_receive_each_other_but_not_themselves() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut a = Peer::connect(srv.local_addr());
    let mut b = Peer::connect(srv.local_addr());
    a.socketcand_handshake("vcan0");
    b.socketcand_handshake("vcan0");
    a.write(b"< send 181 2 11 22 >");
    let line = b.read_element();
    assert!(line.starts_with("< frame 181 "), "{line}");
    assert!(line.ends_with(" 1122 >"), "{line}");
    // A's own frame never comes back to it: the next thing A reads is B's frame.
    b.write(b"< send 182 0 >");
    let line = a.read_element();
    assert!(line.starts_with("< frame 182 "), "{line}");
}

#[test]
fn remote_frames_are_not_forwarded_in_raw_mode() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.socketcand_handshake("vcan0");
    bus.inject(
        "vcan0",
        Frame::remote(Id::standard(0x701).unwrap(), 1).unwrap(),
        ts(),
    );
    bus.inject("vcan0", Frame::std(0x702, &[]).unwrap(), ts());
    c.expect(b"< frame 702 1700000000.000250  >");
}

#[test]
fn frames_before_rawmode_are_not_sent() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    assert_eq!(c.read_once(), b"< hi >");
    c.write(b"< open vcan0 >");
    assert_eq!(c.read_once(), b"< ok >");
    // In the default (broadcast manager) mode nothing is subscribed.
    bus.inject("vcan0", Frame::std(0x111, &[]).unwrap(), ts());
    c.write(b"< echo >");
    c.expect(b"< echo >");
    c.write(b"< rawmode >");
    c.expect(b"< ok >");
    bus.inject("vcan0", Frame::std(0x222, &[]).unwrap(), ts());
    c.expect(b"< frame 222 1700000000.000250  >");
}

#[test]
fn error_replies_for_bad_commands() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.expect(b"< hi >");
    let cases: [(&[u8], &[u8]); 13] = [
        (b"< send 123 0 >", b"< error no bus open >"),
        (b"< rawmode >", b"< error no bus open >"),
        (b"< open nosuch >", b"< error could not open bus >"),
        (b"< open >", b"< error syntax error in open command >"),
        (b"< bogus >", b"< error unknown command >"),
        (b"< >", b"< error unknown command >"),
        (b"<\xff\xfe>", b"< error unknown command >"),
        (b"< open vcan0 >", b"< ok >"),
        (b"< open vcan0 >", b"< error bus already open >"),
        (b"< send 123 9 >", b"< error syntax error in send command >"),
        (b"< send 800 0 >", b"< error identifier out of range >"),
        (b"< statistics 1000 >", b"< error command not supported >"),
        (b"< isotpmode >", b"< error command not supported >"),
    ];
    for (cmd, reply) in cases {
        c.write(cmd);
        c.expect(reply);
    }
    // Still serving.
    c.write(b"< rawmode >");
    c.expect(b"< ok >");
    assert_eq!(srv.stats().error_replies, 12);
}

#[test]
fn non_loopback_bind_is_refused_without_allow_remote() {
    let bus = MemoryBus::new(["vcan0"]);
    let r = Server::bind(
        "0.0.0.0:0".parse().unwrap(),
        Arc::new(bus),
        Limits::default(),
    );
    assert!(matches!(r, Err(GatewayError::RemoteBindRefused(_))));
}

#[test]
fn ephemeral_port_is_reported() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    assert!(srv.local_addr().ip().is_loopback());
    assert_ne!(srv.local_addr().port(), 0);
    srv.shutdown();
}

#[test]
fn shutdown_disconnects_clients_and_detaches_them() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.socketcand_handshake("vcan0");
    srv.shutdown();
    c.read_to_close();
    assert_eq!(bus.attached("vcan0"), 0);
}
