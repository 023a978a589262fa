//! Benchmark: one coupler with 14 modules and all 56 TPDOs active on a 1 Mbit/s virtual
//! bus, inputs changing every millisecond ([`cantwin_tm3::full_island`]). Reports the CPU
//! time per simulated millisecond. `cantwin bench tm3-56` measures the same island against
//! bare CiA 301 devices in one run.
//!
//! `cargo test -p cantwin-tm3 --release --test bench_island -- --ignored --nocapture`
#![allow(clippy::unwrap_used)]

use cantwin_bus::{BusConfig, BusId, PortConfig, Recorder, Simulation, TapId};
use cantwin_can::{BitRate, Instant, ListenOnly};
use cantwin_tm3::full_island::FullIsland;

/// The island and a listener on a 1 Mbit/s bus, every frame recorded.
fn island_on_a_bus() -> (Simulation, BusId, TapId) {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.attach(bus, FullIsland::new(3).unwrap(), PortConfig::default())
        .unwrap();
    sim.attach(bus, ListenOnly, PortConfig::default()).unwrap();
    (sim, bus, tap)
}

#[test]
#[ignore = "benchmark: run in release with --ignored --nocapture"]
fn bench_14_modules_56_tpdos_1mbit() {
    let (mut sim, bus, tap) = island_on_a_bus();
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

#[test]
fn the_full_island_sends_every_tpdo_on_its_timer() {
    let (mut sim, bus, tap) = island_on_a_bus();
    sim.run_until(Instant::from_nanos(200_000_000));
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    for n in 0..cantwin_tm3::full_island::TPDOS {
        let id = cantwin_tm3::full_island::tpdo_cob_id(n);
        let sent = rec
            .frames()
            .filter(|f| f.frame.id().as_raw() == id && !f.frame.is_remote())
            .count();
        // 200 ms on a 10 ms event timer, more with input changes.
        assert!(sent >= 15, "TPDO {n} ({id:#x}) sent {sent} times");
    }
}
