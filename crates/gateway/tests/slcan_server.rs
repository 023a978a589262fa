//! The slcan-over-TCP server on an in-memory bus: the exchange python-can's `slcan` interface
//! performs (protocols notes §3.2), remote frames both ways, and the adapter's error replies.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Arc;

use cantwin_can::{Frame, Id};
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::slcan::Server;
use cantwin_gateway::{BusConnector, BusPort, GatewayError, Limits};
use common::{GUARD, Peer, ts};

fn server(bus: &MemoryBus) -> Server {
    Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus.clone()),
        "can0",
        Limits::default(),
    )
    .unwrap()
}

/// What python-can writes when it opens `slcan` with `bitrate=500000`: close, bit rate, an
/// empty data bit rate, open, and open again.
fn python_can_open(c: &mut Peer) {
    c.write(b"C\r");
    c.expect(b"\x07"); // not open: the adapter refuses `C`
    c.write(b"S6\r");
    c.expect(b"\r");
    c.write(b"\r");
    c.expect(b"\r");
    c.write(b"O\r");
    c.expect(b"\r");
    c.write(b"O\r");
    c.expect(b"\x07"); // already open
}

#[test]
fn python_can_open_sequence_attaches_a_node() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    python_can_open(&mut c);
    assert_eq!(bus.attached("can0"), 1);
    c.write(b"C\r");
    c.expect(b"\r");
    assert_eq!(bus.attached("can0"), 0);
}

#[test]
fn remote_frames_both_ways() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let node = bus.open("can0", 16).unwrap();
    let mut c = Peer::connect(srv.local_addr());
    python_can_open(&mut c);
    // Node guarding request as python-can writes it.
    c.write(b"r7051\r");
    c.expect(b"z\r");
    let rx = node.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(
        rx.frame,
        Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap()
    );
    c.write(b"R1ABCDEF08\r");
    c.expect(b"Z\r");
    let rx = node.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(
        rx.frame,
        Frame::remote(Id::extended(0x1ABC_DEF0).unwrap(), 8).unwrap()
    );
    bus.inject(
        "can0",
        Frame::remote(Id::standard(0x701).unwrap(), 1).unwrap(),
        ts(),
    );
    c.expect(b"r7011\r");
    bus.inject(
        "can0",
        Frame::remote(Id::extended(0x100).unwrap(), 0).unwrap(),
        ts(),
    );
    c.expect(b"R000001000\r");
}

#[test]
fn data_frames_both_ways() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let node = bus.open("can0", 16).unwrap();
    let mut c = Peer::connect(srv.local_addr());
    python_can_open(&mut c);
    c.write(b"t60584000100000000000\r");
    c.expect(b"z\r");
    assert_eq!(
        node.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]).unwrap()
    );
    node.send(Frame::std(0x585, &[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]).unwrap())
        .unwrap();
    c.expect(b"t58584300100092010200\r");
    node.send(Frame::std(0x080, &[]).unwrap()).unwrap();
    c.expect(b"t0800\r");
    node.send(Frame::data(Id::extended(0x18DA_F110).unwrap(), &[0x02, 0x10]).unwrap())
        .unwrap();
    c.expect(b"T18DAF11020210\r");
}

#[test]
fn adapter_queries() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.write(b"V\rN\rF\rZ0\rZ1\r");
    c.expect(b"V0101\rNCTW1\rF00\r\r\x07");
}

#[test]
fn errors_get_bel_and_the_session_goes_on() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    let cases: [(&[u8], &[u8]); 9] = [
        (b"t1230\r", b"\x07"),   // not open
        (b"X\r", b"\x07"),       // unknown
        (b"t12\r", b"\x07"),     // truncated
        (b"d1231AA\r", b"\x07"), // CAN FD
        (b"O\r", b"\r"),
        (b"S6\r", b"\x07"),    // bit rate while open
        (b"t8000\r", b"\x07"), // identifier out of range
        (b"t1231\r", b"\x07"), // DLC 1, no data
        (b"t1231AB\r", b"z\r"),
    ];
    for (cmd, reply) in cases {
        c.write(cmd);
        c.expect(reply);
    }
    // An over-long line: one BEL at its end, then normal service.
    let mut long = vec![b't'; 100_000];
    long.extend_from_slice(b"\rV\r");
    c.write(&long);
    c.expect(b"\x07V0101\r");
}

#[test]
fn listen_only_refuses_transmission() {
    let bus = MemoryBus::new(["can0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    c.write(b"L\rt1230\r");
    c.expect(b"\r\x07");
    bus.inject("can0", Frame::std(0x123, &[]).unwrap(), ts());
    c.expect(b"t1230\r");
}

#[test]
fn non_loopback_bind_is_refused_without_allow_remote() {
    let bus = MemoryBus::new(["can0"]);
    let r = Server::bind(
        "0.0.0.0:0".parse().unwrap(),
        Arc::new(bus),
        "can0",
        Limits::default(),
    );
    assert!(matches!(r, Err(GatewayError::RemoteBindRefused(_))));
}
