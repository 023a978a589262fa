//! Scanner and slave on the virtual CAN bus at 500 kbit/s: real frame lengths,
//! arbitration and delivery at the end of EOF. The slave answers every request the moment
//! it is delivered, so each response starts when the bus goes idle after the request, and
//! cyclic polls start on the exact period.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Duration, Instant};
use cantwin_devicenet::objects::connection::ConnState;
use cantwin_devicenet::scanner::ScannerConfig;
use cantwin_devicenet::wire::choice;
use cantwin_devicenet::{Scanner, ScannerEvent, Slave};
use common::*;

#[test]
fn allocate_epr_and_cyclic_poll_at_500k() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(mac(0), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let ps = sim.attach(bus, slave(9), PortConfig::default()).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.run_until(at(2 * SEC + 100 * MS));
    {
        let m = sim.node_mut::<Scanner>(pm).unwrap();
        assert_eq!(m.poll_event(), Some(ScannerEvent::Online));
        m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
            .unwrap();
        m.set_expected_packet_rate(mac(9), 2, 10).unwrap();
        m.start_polling(
            mac(9),
            Duration::from_millis(10),
            &[1, 2, 3, 4],
            4,
            at(2 * SEC + 110 * MS),
        );
    }
    sim.run_until(at(2 * SEC + 135 * MS));

    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let frames: Vec<_> = rec
        .frames()
        .filter(|r| r.start >= at(2 * SEC + 100 * MS))
        .collect();
    let names: Vec<String> = frames.iter().map(|r| r.frame.to_string()).collect();
    assert_eq!(
        names,
        [
            "44E#404B03010300",
            "44B#40CB00",
            "44C#00100502090A00",
            "44B#00900A00",
            "44D#01020304",
            "3C9#00010203",
            "44D#01020304",
            "3C9#00010203",
            "44D#01020304",
            "3C9#00010203",
        ]
    );
    // Each answer starts the instant the bus is idle after its request (intermission).
    for pair in frames.chunks(2) {
        assert_eq!(pair[1].start, pair[0].idle_at, "{:?}", pair[1].frame);
        assert_eq!(
            pair[0].end.as_nanos() - pair[0].start.as_nanos(),
            u64::from(pair[0].bits - 3) * 2_000
        );
    }
    // The scanner starts on the first instant it is woken after the API call.
    assert_eq!(frames[0].start, at(2 * SEC + 100 * MS));
    // Polls on the 10 ms period.
    let polls: Vec<Instant> = frames
        .iter()
        .filter(|r| r.frame.id().as_raw() == 0x44D)
        .map(|r| r.start)
        .collect();
    assert_eq!(
        polls,
        [
            at(2 * SEC + 110 * MS),
            at(2 * SEC + 120 * MS),
            at(2 * SEC + 130 * MS)
        ]
    );
    let s = sim.node::<Slave<Drive>>(ps).unwrap();
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    assert_eq!(s.app().consumed.len(), 3);
}
