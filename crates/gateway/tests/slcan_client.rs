//! The slcan client against cantwin's own slcan server on loopback, and against scripted
//! adapters: the handshake it writes, frames both ways (remote frames included), the
//! adapter's answers in between, refusals and a close that loses no frame.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

use cantwin_can::{BitRate, Frame, Id};
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::slcan::{Client, ClientError, Remote, Server};
use cantwin_gateway::{BusConnector, BusPort, Limits, PortError};
use common::{GUARD, ts};

fn server(bus: &MemoryBus) -> Server {
    Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus.clone()),
        "can0",
        Limits::default(),
    )
    .unwrap()
}

/// Waits until `bus` has `n` nodes attached (the server attaches on `O` and detaches on `C`
/// in its own thread).
fn wait_attached(bus: &MemoryBus, n: usize) {
    let deadline = std::time::Instant::now() + GUARD;
    while bus.attached("can0") != n {
        assert!(std::time::Instant::now() < deadline, "never {n} attached");
        thread::sleep(Duration::from_millis(1));
    }
}

/// A one-shot scripted adapter: for each step, read exactly the bytes expected (if any) and
/// write a reply; then hand back everything the client wrote until it closed.
fn scripted(
    steps: Vec<(&'static [u8], &'static [u8])>,
) -> (SocketAddr, thread::JoinHandle<Vec<u8>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let handle = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(GUARD)).unwrap();
        for (expect, reply) in steps {
            if !expect.is_empty() {
                let mut buf = vec![0u8; expect.len()];
                s.read_exact(&mut buf).unwrap();
                assert_eq!(
                    String::from_utf8_lossy(&buf),
                    String::from_utf8_lossy(expect)
                );
            }
            s.write_all(reply).unwrap();
        }
        let mut rest = Vec::new();
        let _ = s.read_to_end(&mut rest);
        rest
    });
    (addr, handle)
}

#[test]
fn frames_both_ways_through_the_cantwin_server() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let node = bus.open("can0", 16).unwrap();
    let c = Client::connect(srv.local_addr(), Some(BitRate::R500K), GUARD).unwrap();
    wait_attached(&bus, 2);
    let sent = [
        Frame::std(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]).unwrap(),
        Frame::std(0x080, &[]).unwrap(),
        Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap(),
        Frame::data(Id::extended(0x18DA_F110).unwrap(), &[0x02, 0x10]).unwrap(),
        Frame::remote(Id::extended(0x100).unwrap(), 0).unwrap(),
    ];
    for f in sent {
        c.send(f).unwrap();
        assert_eq!(node.recv_timeout(GUARD).unwrap().unwrap().frame, f);
    }
    for f in sent {
        bus.inject("can0", f, ts());
        assert_eq!(c.recv_timeout(GUARD).unwrap().unwrap().frame, f);
    }
    // Each sent frame's `z`/`Z` is read on the way, whenever the server wrote it.
    let deadline = std::time::Instant::now() + GUARD;
    while c.tx_acknowledged() < 5 && std::time::Instant::now() < deadline {
        assert_eq!(c.recv_timeout(Duration::from_millis(10)).unwrap(), None);
    }
    assert_eq!((c.tx_acknowledged(), c.tx_refused()), (5, 0));
}

#[test]
fn the_handshake_closes_sets_the_bit_rate_and_opens() {
    let (addr, adapter) = scripted(vec![
        (b"C\r", b"\x07"),
        (b"S4\r", b"\r"),
        (b"O\r", b"\r"),
        (b"", b"t1232ABCD\rz\r"),
    ]);
    let c = Client::connect(addr, Some(BitRate::R125K), GUARD).unwrap();
    // The frame's record and an answer arrive in one read, split from the record's end.
    assert_eq!(
        c.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x123, &[0xAB, 0xCD]).unwrap()
    );
    assert_eq!(c.recv_timeout(Duration::from_millis(20)).unwrap(), None);
    assert_eq!(c.tx_acknowledged(), 1);
    drop(c);
    assert_eq!(adapter.join().unwrap(), b"C\r");
}

#[test]
fn without_a_bit_rate_no_s_command_is_sent() {
    let (addr, adapter) = scripted(vec![(b"C\r", b"\r"), (b"O\r", b"\r")]);
    let c = Client::connect(addr, None, GUARD).unwrap();
    c.send(Frame::std(0x701, &[0x05]).unwrap()).unwrap();
    drop(c);
    assert_eq!(adapter.join().unwrap(), b"t701105\rC\r");
}

#[test]
fn an_adapter_refusing_open_or_the_bit_rate_is_an_error_naming_the_command() {
    let (addr, _a) = scripted(vec![(b"C\r", b"\x07"), (b"O\r", b"\x07")]);
    assert!(matches!(
        Client::connect(addr, None, GUARD),
        Err(ClientError::Refused("O"))
    ));
    let (addr, _b) = scripted(vec![(b"C\r", b"\x07"), (b"S8\r", b"\x07")]);
    assert!(matches!(
        Client::connect(addr, Some(BitRate::R1M), GUARD),
        Err(ClientError::Refused("S"))
    ));
}

#[test]
fn a_silent_adapter_times_out_and_a_talking_one_is_unexpected() {
    let (addr, _a) = scripted(vec![]);
    match Client::connect(addr, None, Duration::from_millis(100)) {
        Err(ClientError::Timeout { command, timeout }) => {
            assert_eq!((command, timeout), ("C", Duration::from_millis(100)));
        }
        other => panic!("{:?}", other.map(|_| ())),
    }
    let (addr, _b) = scripted(vec![(b"C\r", b"V0101\r")]);
    match Client::connect(addr, None, GUARD) {
        Err(ClientError::Unexpected { command, got }) => {
            assert_eq!((command, &*got), ("C", "V0101"))
        }
        other => panic!("{:?}", other.map(|_| ())),
    }
}

#[test]
fn refused_frames_are_counted() {
    // A listen-only adapter refuses every frame with BEL (the cantwin server as well).
    let (addr, _a) = scripted(vec![
        (b"C\r", b"\x07"),
        (b"O\r", b"\r"),
        (b"t1230\r", b"\x07"),
        (b"", b"t3211AA\r"),
    ]);
    let c = Client::connect(addr, None, GUARD).unwrap();
    c.send(Frame::std(0x123, &[]).unwrap()).unwrap();
    assert_eq!(
        c.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x321, &[0xAA]).unwrap()
    );
    assert_eq!((c.tx_acknowledged(), c.tx_refused()), (0, 1));
}

#[test]
fn close_detaches_from_the_bus_after_the_last_frame_went_out() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let node = bus.open("can0", 16).unwrap();
    let c = Client::connect(srv.local_addr(), None, GUARD).unwrap();
    wait_attached(&bus, 2);
    // Bus traffic left unread in the client's receive buffer must not reset the connection.
    for _ in 0..50 {
        node.send(Frame::std(0x705, &[0x05]).unwrap()).unwrap();
    }
    thread::sleep(Duration::from_millis(50));
    let last = Frame::std(0x605, &[0x80, 0, 0x20, 0, 0, 0, 0, 0]).unwrap();
    c.send(last).unwrap();
    c.close().unwrap();
    assert_eq!(node.recv_timeout(GUARD).unwrap().unwrap().frame, last);
    wait_attached(&bus, 1);
    assert!(srv.wait_clients(0, GUARD));
}

#[test]
fn dropping_the_client_closes_as_well() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let c = Client::connect(srv.local_addr(), None, GUARD).unwrap();
    wait_attached(&bus, 1);
    drop(c);
    wait_attached(&bus, 0);
    assert!(srv.wait_clients(0, GUARD));
}

#[test]
fn server_gone_is_reported_as_closed() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let c = Client::connect(srv.local_addr(), None, GUARD).unwrap();
    srv.shutdown();
    assert_eq!(c.recv_timeout(GUARD), Err(PortError::Closed));
}

#[test]
fn remote_opens_a_connection_per_port() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let remote = Remote {
        addr: srv.local_addr(),
        bit_rate: Some(BitRate::R250K),
        timeout: GUARD,
    };
    let a = remote.open("any", 16).unwrap();
    let b = remote.open("any", 16).unwrap();
    wait_attached(&bus, 2);
    a.send(Frame::std(0x181, &[1, 2]).unwrap()).unwrap();
    assert_eq!(
        b.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x181, &[1, 2]).unwrap()
    );
}

#[test]
fn records_split_across_reads_come_out_whole() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let adapter = thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_nodelay(true).unwrap();
        let mut cmd = [0u8; 2];
        for _ in 0..2 {
            s.read_exact(&mut cmd).unwrap(); // `C\r`, then `O\r`
            s.write_all(b"\r").unwrap();
        }
        // A record and an answer in four pieces, each its own read on the client's side.
        for piece in [&b"t12"[..], b"32AB", b"CD\rZ", b"\r"] {
            s.write_all(piece).unwrap();
            thread::sleep(Duration::from_millis(20));
        }
        let mut rest = Vec::new();
        let _ = s.read_to_end(&mut rest);
    });
    let c = Client::connect(addr, None, GUARD).unwrap();
    assert_eq!(
        c.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x123, &[0xAB, 0xCD]).unwrap()
    );
    assert_eq!(c.recv_timeout(Duration::from_millis(200)).unwrap(), None);
    assert_eq!(c.tx_acknowledged(), 1);
    drop(c);
    adapter.join().unwrap();
}
