//! Gateway faults and hardening: garbage, oversized lines, half-closed sockets, slow-loris,
//! floods, stuck readers, vanished clients and many clients coming and going. Everything runs
//! on 127.0.0.1 with ephemeral ports; every wait is bounded.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::Write;
use std::net::Shutdown;
use std::time::Duration;

use cantwin_can::Frame;
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::Server;
use cantwin_gateway::{BusConnector, BusPort, Limits};
use common::{GUARD, Peer, socketcand_server, ts};

fn server(bus: &MemoryBus, limits: Limits) -> Server {
    socketcand_server(bus, limits)
}

#[test]
fn garbage_between_elements_is_dropped_and_the_session_goes_on() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus, Limits::default());
    let mut c = Peer::connect(srv.local_addr());
    c.expect(b"< hi >");
    // Bytes outside `< … >` are not commands (socketcand scans for `<`).
    let mut junk: Vec<u8> = (0u8..=255)
        .filter(|b| *b != b'<')
        .cycle()
        .take(100_000)
        .collect();
    junk.extend_from_slice(b"< echo >");
    c.write(&junk);
    c.expect(b"< echo >");
    assert_eq!(srv.stats().error_replies, 0);
}

#[test]
fn oversized_element_gets_an_error_and_memory_stays_bounded() {
    let bus = MemoryBus::new(["vcan0"]);
    let limits = Limits {
        max_line: 64,
        ..Limits::default()
    };
    let srv = server(&bus, limits);
    let mut c = Peer::connect(srv.local_addr());
    c.expect(b"< hi >");
    // One megabyte inside a single element: answered once, skipped up to its `>`.
    let mut big = vec![b'<'];
    big.resize(1 << 20, b'A');
    big.extend_from_slice(b">< echo >");
    c.write(&big);
    c.expect(b"< error command too long >< echo >");
}

#[test]
fn too_many_clients_are_refused_with_an_error() {
    let bus = MemoryBus::new(["vcan0"]);
    let limits = Limits {
        max_clients: 2,
        ..Limits::default()
    };
    let srv = server(&bus, limits);
    let mut a = Peer::connect(srv.local_addr());
    let mut b = Peer::connect(srv.local_addr());
    a.expect(b"< hi >");
    b.expect(b"< hi >");
    let mut c = Peer::connect(srv.local_addr());
    assert_eq!(c.read_to_close(), b"< error too many clients >");
    assert_eq!(srv.stats().refused, 1);
    // Room again once one leaves.
    drop(a);
    assert!(srv.wait_clients(1, GUARD));
    let mut d = Peer::connect(srv.local_addr());
    d.expect(b"< hi >");
}

#[test]
fn half_closed_socket_ends_the_session_and_detaches_the_node() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus, Limits::default());
    let mut c = Peer::connect(srv.local_addr());
    c.write(b"< open vcan0 >< send 123 1 aa >");
    c.s.shutdown(Shutdown::Write).unwrap();
    // The replies still arrive, then the server closes its side too.
    assert_eq!(c.read_to_close(), b"< hi >< ok >");
    assert!(srv.wait_clients(0, GUARD));
    assert_eq!(bus.attached("vcan0"), 0);
}

#[test]
fn slow_loris_is_cut_off_at_the_handshake_timeout() {
    let bus = MemoryBus::new(["vcan0"]);
    let limits = Limits {
        handshake_timeout: Duration::from_millis(200),
        ..Limits::default()
    };
    let srv = server(&bus, limits);
    let mut c = Peer::connect(srv.local_addr());
    // Half a command, never finished.
    c.write(b"< op");
    assert_eq!(c.read_to_close(), b"< hi >");
    assert!(srv.wait_clients(0, GUARD));
    assert_eq!(srv.stats().handshake_timeouts, 1);
}

#[test]
fn stuck_reader_is_disconnected_and_never_stalls_the_bus() {
    let bus = MemoryBus::new(["vcan0"]);
    let limits = Limits {
        client_queue: 16,
        write_timeout: Duration::from_millis(200),
        ..Limits::default()
    };
    let srv = server(&bus, limits);
    let watcher = bus.open("vcan0", 1024).unwrap();
    let mut stuck = Peer::connect(srv.local_addr());
    stuck.socketcand_handshake("vcan0");
    let node = bus.open("vcan0", 1).unwrap();
    // The client never reads again. The bus goes on at full speed: `send` never waits for
    // it, and the client is dropped once its socket and its buffer are full.
    let frame = Frame::std(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    let (mut sent, mut got) = (0u64, 0u64);
    while srv.stats().too_slow == 0 {
        node.send(frame).unwrap();
        sent += 1;
        while watcher.recv_timeout(Duration::ZERO).unwrap().is_some() {
            got += 1;
        }
        assert!(sent < 50_000_000, "the stuck client was never dropped");
    }
    assert!(srv.wait_clients(0, GUARD));
    assert_eq!(bus.attached("vcan0"), 2);
    // Every frame reached the other node: nothing on the bus waited or was lost.
    node.send(frame).unwrap();
    while watcher.recv_timeout(Duration::ZERO).unwrap().is_some() {
        got += 1;
    }
    assert_eq!(got, sent + 1);
    assert_eq!(watcher.overflows(), 0);
}

#[test]
fn vanished_client_leaves_the_bus_running() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus, Limits::default());
    let mut gone = Peer::connect(srv.local_addr());
    gone.socketcand_handshake("vcan0");
    let mut stays = Peer::connect(srv.local_addr());
    stays.socketcand_handshake("vcan0");
    drop(gone);
    assert!(srv.wait_clients(1, GUARD));
    bus.inject("vcan0", Frame::std(0x080, &[]).unwrap(), ts());
    stays.expect(b"< frame 080 1700000000.000250  >");
    assert_eq!(bus.attached("vcan0"), 1);
}

#[test]
fn a_hundred_clients_connect_misbehave_and_leave() {
    let bus = MemoryBus::new(["vcan0"]);
    let limits = Limits {
        max_clients: 128,
        ..Limits::default()
    };
    let srv = server(&bus, limits);
    let node = bus.open("vcan0", 1024).unwrap();
    let mut peers = Vec::new();
    for i in 0..100 {
        let mut p = Peer::connect(srv.local_addr());
        match i % 4 {
            0 => p.socketcand_handshake("vcan0"),
            // The greeting proves the server accepted the client.
            _ => p.expect(b"< hi >"),
        }
        match i % 4 {
            0 => {}
            1 => p.write(b"<<<< garbage \x00\xff >"),
            2 => p.write(b"< open vcan0 >< send 7FF 8 ff ff ff ff ff ff ff ff >"),
            _ => p.s.shutdown(Shutdown::Write).unwrap(),
        }
        peers.push(p);
    }
    // 25 clients sent one frame each.
    for _ in 0..25 {
        let rx = node.recv_timeout(GUARD).unwrap().unwrap();
        assert_eq!(rx.frame, Frame::std(0x7FF, &[0xFF; 8]).unwrap());
    }
    for mut p in peers.drain(..) {
        // Leave abruptly, some with unread data.
        let _ = p.s.flush();
        drop(p);
    }
    assert!(srv.wait_clients(0, GUARD));
    let stats = srv.stats();
    assert_eq!(stats.accepted, 100);
    assert_eq!(stats.refused, 0);
    assert_eq!(bus.attached("vcan0"), 1);
    // The server still serves.
    let mut late = Peer::connect(srv.local_addr());
    late.socketcand_handshake("vcan0");
}
