//! Benchmark: one coupler with 14 modules and all 56 TPDOs active on a 1 Mbit/s virtual
//! bus, inputs changing every millisecond. Reports the CPU time per simulated millisecond.
//!
//! `cargo test -p cantwin-tm3 --release --test bench_island -- --ignored --nocapture`
#![allow(clippy::unwrap_used)]

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_tm3::coupler::{CouplerConfig, Tm3Coupler};
use cantwin_tm3::island::Island;

const MODULES: [&str; 14] = [
    "TM3DI32K",
    "TM3DI32K",
    "TM3DI32K",
    "TM3DI32K",
    "TM3DQ32TK",
    "TM3DM24R",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AQ4",
    "TM2AMI2HT",
];

/// The coupler plus a process whose inputs change every millisecond.
struct Plant {
    coupler: Tm3Coupler,
    next: Instant,
    step: u32,
}

impl Node for Plant {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.coupler.on_power_up(now, out);
        let d = self.coupler.device_mut();
        // All 56 TPDOs valid, event-driven with a 10 ms event timer (about 60 % bus load
        // with the input events): 4 map the 18 input bytes, 52 map 4 of the 50 analog inputs.
        for n in 0..56u16 {
            let comm = 0x1800 + n;
            let map = 0x1A00 + n;
            d.write(
                comm,
                1,
                &(0x8000_0000u32 | (0x1C0 + u32::from(n))).to_le_bytes(),
            )
            .unwrap();
            d.write(map, 0, &[0]).unwrap();
            let entries: Vec<u32> = if n < 4 {
                (0..8)
                    .map(|k| 0x6000_0008 | u32::from((n * 8 + k) % 18 + 1) << 8)
                    .collect()
            } else {
                (0..4)
                    .map(|k| 0x6401_0010 | u32::from(((n - 4) * 4 + k) % 50 + 1) << 8)
                    .collect()
            };
            for (k, e) in entries.iter().enumerate() {
                d.write(map, k as u8 + 1, &e.to_le_bytes()).unwrap();
            }
            d.write(map, 0, &[entries.len() as u8]).unwrap();
            d.write(comm, 5, &10u16.to_le_bytes()).unwrap();
            d.write(comm, 1, &(0x1C0 + u32::from(n)).to_le_bytes())
                .unwrap();
        }
        d.write(0x6423, 0, &[1]).unwrap();
        let mut o = Outbox::new();
        self.coupler
            .on_frame(&Frame::std(0, &[1, 3]).unwrap(), now, &mut o);
        for f in o.drain() {
            out.push(f);
        }
        self.next = now + Duration::from_millis(1);
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_frame(frame, now, out);
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if now >= self.next {
            self.step += 1;
            let s = self.step;
            // One digital input toggles, one analog channel moves by a ramp.
            let m = (s % 4) as usize + 1;
            self.coupler
                .set_digital_input(m, (s % 32) as u8, s % 2 == 0)
                .unwrap();
            let a = (s % 6) as usize + 7;
            self.coupler
                .set_analog_input(a, (s % 8) as u8, (s * 37 % 20_000) as i16)
                .unwrap();
            self.next = now + Duration::from_millis(1);
        }
        self.coupler.on_tick(now, out);
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(match self.coupler.next_deadline() {
            Some(t) => t.min(self.next),
            None => self.next,
        })
    }
    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_sent(frame, now, out);
    }
}

struct Listener;

impl Node for Listener {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

#[test]
#[ignore = "benchmark: run in release with --ignored --nocapture"]
fn bench_14_modules_56_tpdos_1mbit() {
    let island = Island::from_references(&MODULES).unwrap();
    let coupler = Tm3Coupler::new(CouplerConfig::new(3, island)).unwrap();
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.attach(
        bus,
        Plant {
            coupler,
            next: Instant::ZERO,
            step: 0,
        },
        PortConfig::default(),
    )
    .unwrap();
    sim.attach(bus, Listener, PortConfig::default()).unwrap();
    // Warm-up, then the measured run.
    sim.run_until(Instant::from_nanos(100_000_000));
    let simulated_ms = 10_000u64;
    let wall = std::time::Instant::now();
    sim.run_until(Instant::from_nanos(100_000_000 + simulated_ms * 1_000_000));
    let elapsed = wall.elapsed();
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let frames = rec.frames().count();
    let bits: u64 = rec.frames().map(|f| u64::from(f.bits)).sum();
    println!(
        "tm3 island, 14 modules, 56 TPDOs at 1 Mbit/s: {} ns CPU per simulated ms, {frames} frames, bus load {:.1} %",
        elapsed.as_nanos() as u64 / simulated_ms,
        bits as f64 / ((100 + simulated_ms) as f64 * 1_000.0) * 100.0
    );
    assert!(frames as u64 > simulated_ms * 5, "the TPDOs ran");
}
