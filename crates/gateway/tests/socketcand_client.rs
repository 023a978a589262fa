//! The socketcand client: handshake failures give clear errors, and the client copes with
//! what servers send besides frames.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{Read, Write};
use std::net::TcpListener;
use std::sync::Arc;
use std::thread;
use std::time::Duration;

use cantwin_can::{Frame, Id};
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::{Client, ClientError, Server};
use cantwin_gateway::{BusConnector, BusPort, Limits, PortError};
use common::{GUARD, ts};

/// A one-shot scripted server: for each step, read a command (if any) and write a reply.
fn scripted(steps: Vec<(&'static [u8], &'static [u8])>) -> std::net::SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(GUARD)).unwrap();
        for (expect, reply) in steps {
            if !expect.is_empty() {
                let mut buf = vec![0u8; expect.len()];
                s.read_exact(&mut buf).unwrap();
                assert_eq!(buf, expect);
            }
            s.write_all(reply).unwrap();
        }
        // Hold the connection until the client is done.
        let mut rest = Vec::new();
        let _ = s.read_to_end(&mut rest);
    });
    addr
}

#[test]
fn unknown_bus_is_refused_with_the_servers_text() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus),
        Limits::default(),
    )
    .unwrap();
    match Client::connect(srv.local_addr(), "can9", GUARD) {
        Err(ClientError::Refused(text)) => assert_eq!(text, "could not open bus"),
        other => panic!("{:?}", other.map(|_| ())),
    }
}

#[test]
fn a_server_that_does_not_greet_is_a_handshake_error() {
    let addr = scripted(vec![(b"", b"< frame 123 1.0 >")]);
    match Client::connect(addr, "vcan0", GUARD) {
        Err(ClientError::Handshake { expected, .. }) => assert_eq!(expected, "< hi >"),
        other => panic!("{:?}", other.map(|_| ())),
    }
}

#[test]
fn a_silent_server_times_out() {
    let addr = scripted(vec![(b"", b"< hi >")]);
    match Client::connect(addr, "vcan0", Duration::from_millis(100)) {
        Err(ClientError::Timeout(t)) => assert_eq!(t, Duration::from_millis(100)),
        other => panic!("{:?}", other.map(|_| ())),
    }
}

#[test]
fn frames_split_across_reads_and_server_errors_between_them() {
    // A real daemon's byte stream: the handshake, then elements split at odd places, an
    // error element, and junk between elements.
    let addr = scripted(vec![
        (b"", b"< hi >"),
        (b"< open vcan0 >", b"< ok >"),
        (b"< rawmode >", b"< ok >"),
        (b"", b"< frame 080 1700000000.000250  >< fra"),
        (b"", b"me 18FF50E5 1.5 DEADBEEF > junk < error bus off >"),
        (b"", b"< frame 123 2.000001 01 02 >"),
    ]);
    let c = Client::connect(addr, "vcan0", GUARD).unwrap();
    let rx = c.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(rx.frame, Frame::std(0x080, &[]).unwrap());
    assert_eq!(rx.timestamp, ts());
    let rx = c.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(
        rx.frame,
        Frame::data(
            Id::extended(0x18FF_50E5).unwrap(),
            &[0xDE, 0xAD, 0xBE, 0xEF]
        )
        .unwrap()
    );
    let rx = c.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(rx.frame, Frame::std(0x123, &[1, 2]).unwrap());
    assert_eq!(c.server_errors(), 1);
    assert_eq!(c.last_server_error().as_deref(), Some("bus off"));
    assert_eq!(c.recv_timeout(Duration::ZERO).unwrap(), None);
}

#[test]
fn remote_frames_are_sent_as_python_can_does() {
    let bus = MemoryBus::new(["vcan0"]);
    let node = bus.open("vcan0", 8).unwrap();
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus.clone()),
        Limits::default(),
    )
    .unwrap();
    let c = Client::connect(srv.local_addr(), "vcan0", GUARD).unwrap();
    let rtr = Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap();
    c.send(rtr).unwrap();
    assert_eq!(node.recv_timeout(GUARD).unwrap().unwrap().frame, rtr);
}

#[test]
fn server_gone_is_reported_as_closed() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus),
        Limits::default(),
    )
    .unwrap();
    let c = Client::connect(srv.local_addr(), "vcan0", GUARD).unwrap();
    srv.shutdown();
    assert_eq!(c.recv_timeout(GUARD), Err(PortError::Closed));
}

#[test]
fn a_client_closes_without_resetting_so_its_last_frames_are_not_lost() {
    // A client that closes with bus traffic unread in its receive buffer must not reset
    // the connection: a reset discards what the server has not read yet, such as the last
    // segment of an SDO transfer. This server reads only after the client has gone.
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let server = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(GUARD)).unwrap();
        s.write_all(b"< hi >").unwrap();
        let mut open = [0u8; b"< open vcan0 >".len()];
        s.read_exact(&mut open).unwrap();
        s.write_all(b"< ok >").unwrap();
        let mut raw = [0u8; b"< rawmode >".len()];
        s.read_exact(&mut raw).unwrap();
        s.write_all(b"< ok >").unwrap();
        for _ in 0..100 {
            s.write_all(b"< frame 700 1700000000.000000 05 >").unwrap();
        }
        thread::sleep(Duration::from_millis(200));
        let mut rest = Vec::new();
        let read = s.read_to_end(&mut rest);
        (read.map(|_| ()).map_err(|e| e.kind()), rest)
    });
    let c = Client::connect(addr, "vcan0", GUARD).unwrap();
    thread::sleep(Duration::from_millis(50));
    c.send(Frame::std(0x605, &[0x80, 0, 0x20, 0, 0, 0, 0, 0]).unwrap())
        .unwrap();
    drop(c);
    let (read, rest) = server.join().unwrap();
    assert_eq!(read, Ok(()));
    assert_eq!(rest, b"< send 605 8 80 00 20 00 00 00 00 00 >");
}
