//! Frames the paced bus hands to the gateway on its own thread: a client that stops reading
//! is still dropped without stalling the bus, and frames written at once, frames queued behind
//! a full socket, the tails of partial writes and replies reach a slow client whole and in
//! order. Every wait is bounded.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use cantwin_bus::{BusConfig, PacedConfig, PacedSimulation, Simulation};
use cantwin_can::{BitRate, Frame};
use cantwin_gateway::paced::PacedBus;
use cantwin_gateway::socketcand::Server;
use cantwin_gateway::{BusConnector, BusPort, Limits, PortError};
use common::{GUARD, Peer};

/// A paced 1 Mbit/s bus `can0` with a socketcand server on it.
fn paced_server(limits: Limits) -> (PacedSimulation, PacedBus, Server) {
    let mut sim = Simulation::new();
    sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let buses = PacedBus::new(paced.handle());
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(buses.clone()),
        limits,
    )
    .unwrap();
    (paced, buses, srv)
}

/// A client whose receive buffer is as small as the kernel allows, so that the server's
/// socket fills after a few frames.
fn cramped_peer(addr: SocketAddr) -> Peer {
    let socket = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    socket.set_recv_buffer_size(1024).unwrap();
    socket.connect(&addr.into()).unwrap();
    let s: TcpStream = socket.into();
    s.set_read_timeout(Some(GUARD)).unwrap();
    s.set_nodelay(true).unwrap();
    Peer { s }
}

/// The frame numbered `n`: its data is the number, so order and gaps show.
fn numbered(n: u32) -> Frame {
    Frame::std(0x181, &n.to_be_bytes()).unwrap()
}

/// Send the frames numbered `from..to` back to back, waiting for room in the transmit queue.
fn flood(port: &dyn BusPort, from: u32, to: u32) {
    let give_up = Instant::now() + GUARD;
    let mut n = from;
    while n < to {
        match port.send(numbered(n)) {
            Ok(()) => n += 1,
            Err(PortError::TxQueueFull) if Instant::now() < give_up => {
                thread::sleep(Duration::from_micros(200));
            }
            Err(e) => panic!("frame {n} not sent: {e}"),
        }
    }
}

#[test]
fn a_stuck_reader_on_the_paced_bus_is_dropped_and_every_other_node_gets_every_frame() {
    let limits = Limits {
        client_queue: 16,
        write_timeout: Duration::from_millis(200),
        send_buffer: Some(2_048),
        ..Limits::default()
    };
    let (_paced, buses, srv) = paced_server(limits);
    let watcher = buses.open("can0", 1 << 20).unwrap();
    let mut stuck = cramped_peer(srv.local_addr());
    stuck.socketcand_handshake("can0");
    let node = buses.open("can0", 1).unwrap();
    // The client never reads again; the bus carries frames back to back (about 8,000 a
    // second) until the client is dropped.
    let give_up = Instant::now() + GUARD;
    let mut sent = 0;
    while srv.stats().too_slow == 0 {
        assert!(
            Instant::now() < give_up,
            "the stuck client was never dropped"
        );
        flood(&*node, sent, sent + 500);
        sent += 500;
    }
    assert!(srv.wait_clients(0, GUARD));
    // Nothing on the bus waited for the stuck client: the other node got every frame, in
    // order, and lost none.
    for n in 0..sent {
        let rx = watcher
            .recv_timeout(GUARD)
            .unwrap()
            .expect("a frame in time");
        assert_eq!(rx.frame, numbered(n));
    }
    assert_eq!(watcher.overflows(), 0);
}

/// Split a socketcand stream into its `< … >` elements.
fn elements(stream: &[u8]) -> Vec<String> {
    let text = std::str::from_utf8(stream).unwrap();
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find('<') {
        assert!(
            rest[..start].trim().is_empty(),
            "bytes between elements: {:?}",
            &rest[..start]
        );
        let end = rest[start..].find('>').expect("an element cut short") + start;
        out.push(rest[start..=end].to_owned());
        rest = &rest[end + 1..];
    }
    assert!(rest.trim().is_empty(), "a trailing fragment: {rest:?}");
    out
}

#[test]
fn a_slow_reader_gets_every_frame_and_every_reply_whole_and_in_order() {
    const FRAMES: u32 = 2_000;
    // A send buffer of a few frames, so that the bus thread's writes meet a full socket.
    let limits = Limits {
        send_buffer: Some(2_048),
        ..Limits::default()
    };
    let (_paced, buses, srv) = paced_server(limits);
    let mut slow = cramped_peer(srv.local_addr());
    slow.socketcand_handshake("can0");
    // Past the stream's start pause, so that frames are written as they complete.
    thread::sleep(Limits::default().settle * 2);
    let node = buses.open("can0", 1).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let sender = {
        let done = Arc::clone(&done);
        thread::spawn(move || {
            flood(&*node, 0, FRAMES);
            done.store(true, Ordering::SeqCst);
            // Detaching the node would drop the frames still in its transmit queue.
            node
        })
    };
    // Read in small pieces with pauses (about a tenth of the bus's rate), and ask for an
    // echo now and then: the server's socket fills, frames queue behind it, writes are cut
    // short, and replies must find their place between whole frames.
    let mut stream = Vec::new();
    let mut echoes = 0;
    let mut buf = [0u8; 97];
    let give_up = Instant::now() + GUARD * 3;
    // Counted as the bytes come, so that a loaded machine does not spend the time limit
    // rescanning what it has already read.
    let (mut frames, mut replies, mut scanned) = (0u32, 0usize, 0usize);
    loop {
        // Every element is longer than 8 bytes, so a new one starts at or after `scanned`.
        while stream.len() >= scanned + 8 {
            let rest = &stream[scanned..];
            frames += u32::from(rest.starts_with(b"< frame"));
            replies += usize::from(rest.starts_with(b"< echo >"));
            scanned += 1;
        }
        if frames == FRAMES && replies == echoes {
            break;
        }
        assert!(
            Instant::now() < give_up,
            "{frames} frames, {replies}/{echoes} echoes"
        );
        if echoes < 40 && stream.len() / 2_000 > echoes {
            slow.s.write_all(b"< echo >").unwrap();
            echoes += 1;
        }
        let n = match slow.s.read(&mut buf) {
            Ok(n) => n,
            Err(e) => panic!(
                "{e}: {frames} frames, {replies}/{echoes} echoes, last bytes {:?}",
                String::from_utf8_lossy(&stream[stream.len().saturating_sub(200)..])
            ),
        };
        assert!(n > 0, "the server closed the connection");
        stream.extend_from_slice(&buf[..n]);
        if !done.load(Ordering::SeqCst) {
            thread::sleep(Duration::from_micros(300));
        }
    }
    let _node = sender.join().unwrap();
    let elements = elements(&stream);
    let mut next = 0u32;
    let mut replies = 0;
    for e in &elements {
        if e == "< echo >" {
            replies += 1;
            continue;
        }
        let fields: Vec<&str> = e.split_whitespace().collect();
        assert_eq!(&fields[..3], ["<", "frame", "181"], "{e}");
        assert_eq!(
            fields[4],
            format!("{next:08X}"),
            "frame {next} in order: {e}"
        );
        next += 1;
    }
    assert_eq!((next, replies), (FRAMES, echoes));
    assert!(echoes >= 10, "too few replies crossed the stream: {echoes}");
    assert_eq!(srv.stats().too_slow, 0);
}

#[test]
fn a_broadcast_manager_subscription_selects_frames_on_the_bus_thread() {
    let (_paced, buses, srv) = paced_server(Limits::default());
    let node = buses.open("can0", 1).unwrap();
    let mut c = Peer::connect(srv.local_addr());
    assert_eq!(c.read_once(), b"< hi >");
    c.write(b"< open can0 >");
    assert_eq!(c.read_once(), b"< ok >");
    c.write(b"< subscribe 0 0 182 >< echo >");
    assert_eq!(c.read_element(), "< echo >");
    for n in 0..20u8 {
        let id = if n % 2 == 0 { 0x181 } else { 0x182 };
        node.send(Frame::std(id, &[n]).unwrap()).unwrap();
    }
    for n in (1..20u8).step_by(2) {
        let e = c.read_element();
        assert!(
            e.starts_with("< frame 182 ") && e.ends_with(&format!(" {n:02X}  >")),
            "{e}"
        );
    }
}

#[test]
fn an_slcan_client_that_closes_and_opens_again_gets_each_frame_once() {
    let mut sim = Simulation::new();
    sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let buses = PacedBus::new(paced.handle());
    let srv = cantwin_gateway::slcan::Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(buses.clone()),
        "can0",
        Limits::default(),
    )
    .unwrap();
    let node = buses.open("can0", 1).unwrap();
    let mut c = Peer::connect(srv.local_addr());
    for _ in 0..3 {
        c.write(b"O\r");
        c.expect(b"\r");
        // Past the stream's start pause.
        thread::sleep(Limits::default().settle * 2);
        node.send(Frame::std(0x123, &[0xAB]).unwrap()).unwrap();
        c.expect(b"t1231AB\r");
        c.write(b"C\r");
        c.expect(b"\r");
    }
    // Nothing more came: a frame sent while closed is not delivered, and the next reply is
    // the one to this command.
    node.send(Frame::std(0x124, &[]).unwrap()).unwrap();
    thread::sleep(Duration::from_millis(50));
    c.write(b"V\r");
    let reply = c.read_once();
    assert_eq!(
        reply.first(),
        Some(&b'V'),
        "{:?}",
        String::from_utf8_lossy(&reply)
    );
    drop(paced);
}
