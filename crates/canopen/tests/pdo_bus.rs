//! PDO timers on the virtual bus at 1 Mbit/s: exact frame start and end times for the
//! inhibit time (CiA 301 §7.2.2.5, counted from the end of the previous transmission) and
//! the event timer (§7.5.2.35 sub 5).
#![allow(clippy::unwrap_used)]

mod pdo_harness;

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
use cantwin_canopen::device::NoHooks;
use cantwin_canopen::od::{ObjectDictionary, OdBuilder, Value};
use cantwin_canopen::pdo::{PdoEngine, PdoObjects};
use std::sync::Arc;

/// A device whose application changes 0x6000 at the given instants, with one TPDO.
struct Device {
    od: ObjectDictionary,
    pdo: PdoEngine,
    changes: Vec<Instant>,
    value: u16,
}

impl Device {
    fn new(ttype: u8, inhibit_100us: u16, event_timer_ms: u16, changes: &[Instant]) -> Self {
        let b = PdoObjects::new(0, 1)
            .tpdo(0, ttype, &[0x6000_0010])
            .add_to(pdo_harness::app(OdBuilder::new()));
        let mut od = ObjectDictionary::new(Arc::new(b.build().unwrap()), pdo_harness::NODE);
        od.set(0x1800, 3, &Value::Unsigned16(inhibit_100us))
            .unwrap();
        od.set(0x1800, 5, &Value::Unsigned16(event_timer_ms))
            .unwrap();
        let pdo = PdoEngine::new(&od).unwrap();
        Device {
            od,
            pdo,
            changes: changes.iter().rev().copied().collect(),
            value: 0,
        }
    }
}

impl Node for Device {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.pdo.set_operational(true, now);
        self.pdo.on_tick(now, &self.od, &mut NoHooks, out);
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.pdo
            .on_frame(frame, now, &mut self.od, &mut NoHooks, out);
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while self.changes.last().is_some_and(|t| *t <= now) {
            self.changes.pop();
            self.value += 1;
            self.od
                .set(0x6000, 0, &Value::Unsigned16(self.value))
                .unwrap();
            self.pdo.mark_changed(0x6000, 0);
        }
        self.pdo.on_tick(now, &self.od, &mut NoHooks, out);
    }
    fn next_deadline(&self) -> Option<Instant> {
        let app = self.changes.last().copied();
        match (app, self.pdo.next_deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
    fn on_sent(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.pdo.on_sent(frame, now);
    }
}

/// Acknowledges frames.
struct Listener;

impl Node for Listener {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// (start ns, end ns, frame) of every frame on the bus until `until`.
fn run(device: Device, until: Instant) -> Vec<(u64, u64, String)> {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.attach(bus, device, PortConfig::default()).unwrap();
    sim.attach(bus, Listener, PortConfig::default()).unwrap();
    sim.run_until(until);
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    rec.frames()
        .map(|f| (f.start.as_nanos(), f.end.as_nanos(), f.frame.to_string()))
        .collect()
}

/// The time a frame occupies the bus at 1 Mbit/s up to the end of its EOF.
fn on_wire(frame: &str) -> u64 {
    let (id, data) = frame.split_once('#').unwrap();
    let bytes: Vec<u8> = (0..data.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&data[i..i + 2], 16).unwrap())
        .collect();
    let f = Frame::std(u16::from_str_radix(id, 16).unwrap(), &bytes).unwrap();
    (u64::from(f.bit_length()) - 3) * 1_000
}

#[test]
fn cia301_7_2_2_5_inhibit_time_on_the_bus_counts_from_the_end_of_the_previous_frame() {
    let ms = |v: u64| Instant::from_nanos(v * 1_000_000);
    // 10 ms inhibit; the application changes the value at 1 ms, 4 ms and 30 ms.
    let device = Device::new(254, 100, 0, &[ms(1), ms(4), ms(30)]);
    let trace = run(device, ms(50));
    let first_end = on_wire("185#0000");
    let second_start = first_end + 10_000_000;
    assert_eq!(
        trace,
        [
            // Entering OPERATIONAL at power-up sends the current value.
            (0, first_end, "185#0000".to_string()),
            // Changes at 1 and 4 ms wait for the inhibit time, counted from the end of the
            // first frame, and go out as one PDO with the latest value.
            (
                second_start,
                second_start + on_wire("185#0200"),
                "185#0200".to_string()
            ),
            // The change at 30 ms is outside the inhibit time: sent at once.
            (
                30_000_000,
                30_000_000 + on_wire("185#0300"),
                "185#0300".to_string()
            ),
        ]
    );
}

#[test]
fn cia301_7_5_2_35_event_timer_on_the_bus_sends_every_period() {
    let ms = |v: u64| Instant::from_nanos(v * 1_000_000);
    // Event timer 20 ms, no inhibit; one application event at 25 ms restarts the period.
    let device = Device::new(255, 0, 20, &[ms(25)]);
    let trace: Vec<(u64, String)> = run(device, ms(70))
        .into_iter()
        .map(|(start, _, f)| (start, f))
        .collect();
    assert_eq!(
        trace,
        [
            (0, "185#0000".to_string()),
            (20_000_000, "185#0000".to_string()),
            (25_000_000, "185#0100".to_string()),
            (45_000_000, "185#0100".to_string()),
            (65_000_000, "185#0100".to_string()),
        ]
    );
}
