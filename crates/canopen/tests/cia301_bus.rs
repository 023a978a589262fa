//! Devices on the virtual bus at 1 Mbit/s: boot-up arbitration, heartbeat delivery and a
//! heartbeat consumer timeout timed from the real end of the last heartbeat frame.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::nmt::State;
use cantwin_canopen::objects::Cia301Options;
use device_harness::*;
use std::sync::Arc;

const US: u64 = 1_000;

/// A node that only acknowledges frames (a CAN frame needs a second powered node for its
/// ACK, so the consumer's EMCY needs a listener once the producer is gone).
struct Listener;

impl Node for Listener {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_consumer_on_the_bus_times_out_from_the_last_delivery() {
    let opts = Cia301Options {
        heartbeat_time: 100,
        ..options()
    };
    let a = device_with(&opts);
    let desc = Arc::clone(a.od().description());
    let b = Device::new(Arc::clone(&desc), DeviceConfig::new(6)).unwrap();
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let pa = sim.attach(bus, a, PortConfig::default()).unwrap();
    let pb = sim.attach(bus, b, PortConfig::default()).unwrap();
    sim.attach(bus, Listener, PortConfig::default()).unwrap();
    // Device 6 watches device 5 with 200 ms and does not produce heartbeats itself.
    let dev_b = sim.node_mut::<Device>(pb).unwrap();
    dev_b.write(0x1017, 0, &0u16.to_le_bytes()).unwrap();
    dev_b
        .write(0x1016, 1, &0x0005_00C8u32.to_le_bytes())
        .unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.run_until(Instant::from_nanos(350_000_000));
    sim.bus_mut(bus).unwrap().set_powered(pa, false).unwrap();
    sim.run_until(Instant::from_nanos(1_000_000_000));

    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let got: Vec<(u64, u64, String)> = rec
        .frames()
        .map(|f| (f.start.as_nanos(), f.end.as_nanos(), f.frame.to_string()))
        .collect();
    let bits = |s: &str| u64::from(frame(s).bit_length());
    let (boot5, boot6, hb) = (bits("705#00"), bits("706#00"), bits("705#7F"));
    let hb_end = |t_ms: u64| t_ms * 1_000_000 + (hb - 3) * US;
    // Both boot at t = 0: 0x705 wins arbitration, 0x706 follows once the bus is idle.
    let mut want = vec![
        (0, (boot5 - 3) * US, "705#00".to_string()),
        (boot5 * US, (boot5 + boot6 - 3) * US, "706#00".to_string()),
    ];
    for t in [100, 200, 300] {
        want.push((t * 1_000_000, hb_end(t), "705#7F".to_string()));
    }
    // The consumer times out 200 ms after the last heartbeat was delivered.
    let emcy_start = hb_end(300) + 200_000_000;
    let emcy = "086#3081110500000000";
    want.push((
        emcy_start,
        emcy_start + (bits(emcy) - 3) * US,
        emcy.to_string(),
    ));
    assert_eq!(got, want);
    assert_eq!(
        sim.node::<Device>(pb).unwrap().state(),
        State::PreOperational
    );
}
