//! The gateways on the virtual bus, paced to the wall clock: clients are nodes whose frames
//! take bus time, and received frames carry the wall time the bus maps their end to.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Arc;
use std::time::Duration;

use cantwin_bus::{BusConfig, PacedConfig, PacedSimulation, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame};
use cantwin_gateway::paced::PacedBus;
use cantwin_gateway::socketcand::{Client, Remote, Server};
use cantwin_gateway::{BusConnector, BusPort, Limits};
use common::{GUARD, Peer};

#[test]
fn socketcand_clients_are_nodes_on_the_paced_bus() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(PacedBus::new(handle.clone())),
        Limits::default(),
    )
    .unwrap();
    let a = Client::connect(srv.local_addr(), "can0", GUARD).unwrap();
    let b = Client::connect(srv.local_addr(), "can0", GUARD).unwrap();
    let frame = Frame::std(0x181, &[0x11, 0x22, 0x33]).unwrap();
    a.send(frame).unwrap();
    let rx = b.recv_timeout(GUARD).unwrap().unwrap();
    assert_eq!(rx.frame, frame);
    // A does not hear itself.
    assert_eq!(a.recv_timeout(Duration::from_millis(1)).unwrap(), None);

    let map = handle.time_map();
    srv.shutdown();
    let sim = paced.stop().unwrap();
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let records: Vec<_> = rec.frames().collect();
    assert_eq!(records.len(), 1);
    let r = records[0];
    assert_eq!(r.frame, frame);
    // The frame took its real time on the bus: 2 µs a bit at 500 kbit/s, without the
    // 3 bits of intermission that follow the end of frame.
    assert_eq!(
        (r.end - r.start).as_nanos(),
        u64::from(frame.bit_length() - 3) * 2_000
    );
    // The timestamp B got is the wall time of the end of the frame, to the microsecond
    // (unless the host stalled the simulation past its lag limit, which moves the mapping).
    let slipped = handle.slips() > 0;
    let want = map
        .wall_time(r.end)
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap();
    let got = rx.timestamp.duration_since(std::time::UNIX_EPOCH).unwrap();
    assert!(
        slipped || got.as_micros() == want.as_micros(),
        "{got:?} != {want:?}"
    );
}

#[test]
fn remote_connector_opens_a_socketcand_bus_like_a_local_one() {
    let mut sim = Simulation::new();
    sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let local = PacedBus::new(paced.handle());
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(local.clone()),
        Limits::default(),
    )
    .unwrap();
    let remote = Remote {
        addr: srv.local_addr(),
        timeout: GUARD,
    };
    let buses: [&dyn BusConnector; 2] = [&local, &remote];
    let ports: Vec<Box<dyn BusPort>> = buses.iter().map(|b| b.open("can0", 64).unwrap()).collect();
    let f = Frame::std(0x701, &[0x05]).unwrap();
    ports[0].send(f).unwrap();
    assert_eq!(ports[1].recv_timeout(GUARD).unwrap().unwrap().frame, f);
    let g = Frame::std(0x601, &[0x40, 0x00, 0x10, 0x00]).unwrap();
    ports[1].send(g).unwrap();
    assert_eq!(ports[0].recv_timeout(GUARD).unwrap().unwrap().frame, g);
    // An unknown bus is refused by the server, and reported as such.
    assert!(matches!(
        remote.open("nosuch", 1),
        Err(cantwin_gateway::PortError::UnknownChannel(_))
    ));
}

#[test]
fn flooding_client_is_held_back_and_every_frame_reaches_the_bus() {
    // 10 kbit/s: an 8-byte frame takes about 13 ms, so a burst of commands fills the
    // 4-frame transmit queue at once; the server waits for room instead of refusing frames.
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R10K));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let connector =
        PacedBus::new(paced.handle()).with_port_config(PortConfig::DEFAULT.with_queue_depth(4));
    let srv = Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(connector),
        Limits::default(),
    )
    .unwrap();
    let listener = Client::connect(srv.local_addr(), "can0", GUARD).unwrap();
    let mut flood = Peer::connect(srv.local_addr());
    flood.socketcand_handshake("can0");
    const N: usize = 60;
    let mut burst = Vec::new();
    for i in 0..N {
        burst.extend_from_slice(format!("< send 100 1 {:X} >", i).as_bytes());
    }
    burst.extend_from_slice(b"< echo >");
    flood.write(&burst);
    // Nothing is refused: the echo is the only reply.
    assert_eq!(flood.read_element(), "< echo >");
    for i in 0..N {
        let got = listener.recv_timeout(GUARD).unwrap().unwrap().frame;
        assert_eq!(
            got,
            Frame::std(0x100, &[i as u8]).unwrap(),
            "frame {i} in order"
        );
    }
    srv.shutdown();
    let sim = paced.stop().unwrap();
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    // Exactly the frames sent went out, in order, none lost or doubled.
    let sent: Vec<Frame> = rec
        .frames()
        .filter(|r| !r.dropped)
        .map(|r| r.frame)
        .collect();
    let expected: Vec<Frame> = (0..N)
        .map(|i| Frame::std(0x100, &[i as u8]).unwrap())
        .collect();
    assert_eq!(sent, expected);
}
