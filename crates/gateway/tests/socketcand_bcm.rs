//! socketcand's broadcast-manager mode (the mode a client is in after `open`): subscriptions,
//! content and multiplex filters, throttling and cyclic transmission jobs, in the daemon's
//! wire format (linux-can/socketcand `doc/protocol.md`, `src/state_bcm.c`). Every wait is
//! bounded; timings are only asserted as orderings.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::{Duration, Instant};

use cantwin_can::Frame;
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::Server;
use cantwin_gateway::{BusConnector, BusPort, Limits};
use common::{GUARD, Peer, socketcand_server, ts};

fn server(bus: &MemoryBus) -> Server {
    socketcand_server(bus, Limits::default())
}

/// A client with `vcan0` open, in broadcast-manager mode.
fn bcm_client(srv: &Server) -> Peer {
    let mut c = Peer::connect(srv.local_addr());
    assert_eq!(c.read_once(), b"< hi >");
    c.write(b"< open vcan0 >");
    assert_eq!(c.read_once(), b"< ok >");
    c
}

/// Send commands, then wait until the server has handled them (its echo comes after).
fn command(c: &mut Peer, commands: &[u8]) {
    c.write(commands);
    c.write(b"< echo >");
    assert_eq!(c.read_element(), "< echo >");
}

#[test]
fn subscribe_delivers_its_identifier_in_the_broadcast_managers_format() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = bcm_client(&srv);
    // Nothing is delivered before a subscription.
    bus.inject("vcan0", Frame::std(0x123, &[0]).unwrap(), ts());
    command(&mut c, b"< subscribe 0 0 123 >");
    bus.inject("vcan0", Frame::std(0x124, &[1]).unwrap(), ts());
    bus.inject("vcan0", Frame::std(0x123, &[0x11, 0x22]).unwrap(), ts());
    bus.inject("vcan0", Frame::std(0x123, &[]).unwrap(), ts());
    assert_eq!(
        c.read_element(),
        "< frame 123 1700000000.000250 11 22  >",
        "bytes each followed by a space"
    );
    assert_eq!(c.read_element(), "< frame 123 1700000000.000250  >");
    command(&mut c, b"< unsubscribe 123 >");
    bus.inject("vcan0", Frame::std(0x123, &[3]).unwrap(), ts());
    // The next element is the echo: the frame after `unsubscribe` was not delivered.
    command(&mut c, b"");
}

#[test]
fn filter_and_muxfilter_deliver_changes_under_their_masks() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = bcm_client(&srv);
    command(
        &mut c,
        b"< filter 0 0 123 1 FF >< muxfilter 0 0 200 2 FF 00 00 00 00 00 00 00 33 FF 00 00 00 00 00 00 >",
    );
    for data in [&[1u8, 1][..], &[1, 2], &[2, 2], &[2, 3]] {
        bus.inject("vcan0", Frame::std(0x123, data).unwrap(), ts());
    }
    for data in [&[0x33u8, 1][..], &[0x33, 1, 9], &[0x44, 7], &[0x33, 2]] {
        bus.inject("vcan0", Frame::std(0x200, data).unwrap(), ts());
    }
    for expected in [
        "< frame 123 1700000000.000250 01 01  >",
        "< frame 123 1700000000.000250 02 02  >",
        "< frame 200 1700000000.000250 33 01  >",
        "< frame 200 1700000000.000250 33 02  >",
    ] {
        assert_eq!(c.read_element(), expected);
    }
    command(&mut c, b"");
}

#[test]
fn a_throttled_subscription_delivers_the_first_frame_then_the_newest_of_the_period() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = bcm_client(&srv);
    command(&mut c, b"< subscribe 0 200000 181 >");
    let start = Instant::now();
    for n in 1..=5u8 {
        bus.inject("vcan0", Frame::std(0x181, &[n]).unwrap(), ts());
    }
    assert_eq!(c.read_element(), "< frame 181 1700000000.000250 01  >");
    assert_eq!(c.read_element(), "< frame 181 1700000000.000250 05  >");
    // Held until the throttle time was up.
    assert!(start.elapsed() >= Duration::from_millis(200));
    command(&mut c, b"");
}

#[test]
fn add_sends_cyclically_update_changes_the_frame_and_delete_stops_it() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let node = bus.open("vcan0", 1024).unwrap();
    let mut c = bcm_client(&srv);
    command(&mut c, b"< add 0 10000 321 2 AA BB >");
    let first = node.recv_timeout(GUARD).unwrap().unwrap().frame;
    assert_eq!(first, Frame::std(0x321, &[0xAA, 0xBB]).unwrap());
    assert_eq!(
        node.recv_timeout(GUARD).unwrap().unwrap().frame,
        first,
        "again one interval later"
    );
    command(&mut c, b"< update 321 1 CC >");
    let updated = Frame::std(0x321, &[0xCC]).unwrap();
    let deadline = Instant::now() + GUARD;
    while node.recv_timeout(GUARD).unwrap().unwrap().frame != updated {
        assert!(Instant::now() < deadline, "the update never went out");
    }
    command(&mut c, b"< delete 321 >");
    // At most a frame that was already due; then the job is gone.
    while node
        .recv_timeout(Duration::from_millis(300))
        .unwrap()
        .is_some()
    {}
    assert_eq!(node.recv_timeout(Duration::from_millis(100)).unwrap(), None);
}

#[test]
fn leaving_the_broadcast_manager_ends_its_jobs_and_raw_mode_refuses_its_commands() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let node = bus.open("vcan0", 1024).unwrap();
    let mut c = bcm_client(&srv);
    command(&mut c, b"< add 0 10000 321 0 >");
    assert!(node.recv_timeout(GUARD).unwrap().is_some());
    c.write(b"< rawmode >");
    assert_eq!(c.read_element(), "< ok >");
    while node
        .recv_timeout(Duration::from_millis(300))
        .unwrap()
        .is_some()
    {}
    assert_eq!(node.recv_timeout(Duration::from_millis(100)).unwrap(), None);
    c.write(b"< subscribe 0 0 123 >");
    assert_eq!(c.read_element(), "< error unknown command >");
    // Raw mode carries every frame again, in its own format.
    bus.inject("vcan0", Frame::std(0x124, &[1, 2]).unwrap(), ts());
    assert_eq!(c.read_element(), "< frame 124 1700000000.000250 0102 >");
}

#[test]
fn broadcast_manager_commands_need_a_bus_and_valid_arguments() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = Peer::connect(srv.local_addr());
    assert_eq!(c.read_once(), b"< hi >");
    c.write(b"< subscribe 0 0 123 >");
    assert_eq!(c.read_element(), "< error no bus open >");
    c.write(b"< open vcan0 >");
    assert_eq!(c.read_element(), "< ok >");
    c.write(b"< add 0 1000000 123 0 >");
    assert_eq!(c.read_element(), "< error syntax error in add command >");
    c.write(b"< filter 0 0 123 2 FF >");
    assert_eq!(c.read_element(), "< error syntax error in filter command >");
    // Deleting what does not exist is silent, as with the daemon.
    command(&mut c, b"< delete 7FF >< unsubscribe 7FF >");
}

#[test]
fn a_client_subscribed_to_what_it_sends_sees_its_own_frames() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let node = bus.open("vcan0", 1024).unwrap();
    let mut c = bcm_client(&srv);
    command(&mut c, b"< subscribe 0 0 321 >< subscribe 0 0 322 >");
    // A cyclic job with a zero interval sends once, at once, and the kernel loops it back.
    c.write(b"< add 0 0 321 1 AA >");
    let e = c.read_element();
    assert!(
        e.starts_with("< frame 321 ") && e.ends_with(" AA  >"),
        "{e}"
    );
    assert_eq!(
        node.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x321, &[0xAA]).unwrap()
    );
    c.write(b"< send 322 2 1 2 >");
    let e = c.read_element();
    assert!(
        e.starts_with("< frame 322 ") && e.ends_with(" 01 02  >"),
        "{e}"
    );
    assert_eq!(
        node.recv_timeout(GUARD).unwrap().unwrap().frame,
        Frame::std(0x322, &[1, 2]).unwrap()
    );
    // The zero-interval job sent only once.
    assert_eq!(node.recv_timeout(Duration::from_millis(100)).unwrap(), None);
}

#[test]
fn a_multiplex_filter_is_not_throttled_as_with_the_daemon() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = server(&bus);
    let mut c = bcm_client(&srv);
    command(
        &mut c,
        b"< muxfilter 10 0 200 2 FF 00 00 00 00 00 00 00 33 FF 00 00 00 00 00 00 >",
    );
    let start = Instant::now();
    for n in 1..=3u8 {
        bus.inject("vcan0", Frame::std(0x200, &[0x33, n]).unwrap(), ts());
    }
    for n in 1..=3u8 {
        assert_eq!(
            c.read_element(),
            format!("< frame 200 1700000000.000250 33 {n:02X}  >")
        );
    }
    assert!(
        start.elapsed() < Duration::from_secs(10),
        "no 10 s throttle"
    );
}
