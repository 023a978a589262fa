//! `cantwin bench cia402`: the CiA 402 servo twin (`cantwin-servo`) in cyclic synchronous
//! position mode at 1 ms SYNC, 1 Mbit/s, the master sending RPDO2 (controlword + modes of
//! operation) and RPDO3 (controlword + target position) before each SYNC and the axis
//! answering TPDO3 (statusword + position actual value) and TPDO4 (statusword + velocity
//! actual value): 5 frames a millisecond. Measured against bare CiA 301 devices exchanging
//! frames of the same identifiers and lengths in the same run, and as 64 such axes on 64
//! buses for the real-time factor.
//!
//! Floors (the CiA 402 issue): the axis costs at most twice the CPU of the bare devices, and
//! 64 axes on 64 buses run at five times real time or faster.

use std::sync::Arc;

use anyhow::{Result, anyhow};
use cantwin_bus::{BusConfig, BusId, PortConfig, PortId, Simulation};
use cantwin_can::{BitRate, Duration, Frame, Instant, ListenOnly};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_servo::{Servo, ServoConfig};

/// The bus time each chunk of a measurement covers.
const CHUNK: Duration = Duration::from_millis(250);

/// The communication cycle.
const CYCLE: Duration = Duration::from_millis(1);

/// The most the axis may cost against the bare devices.
pub const CPU_FLOOR: f64 = 2.0;

/// The least real-time factor of 64 axes on 64 buses.
pub const FLEET_FLOOR: f64 = 5.0;

/// Axes in the fleet run.
pub const FLEET: usize = 64;

/// What one run measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    /// Wall ns per simulated second, the median chunk.
    pub ns_per_sim_second: f64,
    /// Frames on the bus(es) per simulated second.
    pub frames_per_sim_second: f64,
    /// The last position actual value the master saw (the axis ran), or 0.
    pub last_position: i32,
}

/// The figures of `cantwin bench cia402`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// One axis.
    pub axis: Run,
    /// Bare CiA 301 devices, the same frames.
    pub bare: Run,
    /// 64 axes on 64 buses.
    pub fleet: Run,
    /// 64 bare devices on 64 buses, the same frames: what the buses and the stack alone
    /// cost at that scale.
    pub bare_fleet: Run,
    /// The threads the fleets ran on.
    pub threads: usize,
}

impl Report {
    /// CPU of the axis over the bare devices'.
    pub fn ratio(&self) -> f64 {
        self.axis.ns_per_sim_second / self.bare.ns_per_sim_second.max(1.0)
    }

    /// Simulated time over wall time of the fleet.
    pub fn fleet_real_time_factor(&self) -> f64 {
        1e9 / self.fleet.ns_per_sim_second.max(1.0)
    }
}

fn ms(v: u64) -> Instant {
    Instant::ZERO + Duration::from_millis(v)
}

/// One bus with its master port.
struct Line {
    bus: BusId,
    master: PortId,
    node: u8,
}

/// The master's frames of cycle `k` to node `node`: RPDO2 (controlword, mode 8), RPDO3
/// (controlword, target position) and the SYNC, in that order. The set-points ramp at 20
/// position units a cycle (20 000 units/s, about five revolutions per second).
fn cycle_frames(node: u8, k: u64) -> Result<[Frame; 3]> {
    let target = i32::try_from(k.saturating_mul(20)).unwrap_or(i32::MAX);
    let t = target.to_le_bytes();
    let n = u16::from(node);
    Ok([
        Frame::std(0x300 + n, &[0x0F, 0x00, 0x08])?,
        Frame::std(0x400 + n, &[0x0F, 0x00, t[0], t[1], t[2], t[3]])?,
        Frame::std(0x080, &[])?,
    ])
}

/// Runs `lines` from 10 ms for `duration` with the master's cycle, timed in chunks.
fn measure(sim: &mut Simulation, lines: &[Line], duration: Duration) -> Result<Run> {
    sim.run_until(ms(10));
    let frames = |sim: &Simulation| -> u64 {
        lines
            .iter()
            .map(|l| sim.bus(l.bus).map_or(0, |b| b.stats().frames()))
            .sum()
    };
    let before = frames(sim);
    let from = ms(10);
    let end = from + duration;
    let mut chunks = Vec::new();
    let mut t = from;
    let mut k = 0u64;
    let mut chunk_start = from;
    let mut wall = std::time::Instant::now();
    while t < end {
        sim.run_until(t);
        for l in lines {
            for f in cycle_frames(l.node, k)? {
                sim.transmit(l.master, f)?;
            }
        }
        k += 1;
        t += CYCLE;
        if t - chunk_start >= CHUNK || t >= end {
            sim.run_until(t.min(end));
            let bus_s = (t.min(end) - chunk_start).as_secs_f64();
            chunks.push(wall.elapsed().as_nanos() as f64 / bus_s.max(1e-12));
            chunk_start = t;
            wall = std::time::Instant::now();
        }
    }
    sim.run_until(end);
    let frames = frames(sim) - before;
    chunks.sort_by(f64::total_cmp);
    Ok(Run {
        ns_per_sim_second: chunks.get(chunks.len() / 2).copied().unwrap_or(0.0),
        frames_per_sim_second: frames as f64 / duration.as_secs_f64().max(1e-12),
        last_position: 0,
    })
}

/// NMT start, csp, and the drive enabled, by frames at 1–3 ms.
fn start(sim: &mut Simulation, lines: &[Line]) -> Result<()> {
    sim.run_until(ms(1));
    for l in lines {
        sim.transmit(l.master, Frame::std(0x000, &[0x01, 0x00])?)?;
    }
    for (at, cw) in [(2, 0x06u8), (3, 0x0F)] {
        sim.run_until(ms(at));
        for l in lines {
            let id = 0x300 + u16::from(l.node);
            sim.transmit(l.master, Frame::std(id, &[cw, 0x00, 0x08])?)?;
        }
    }
    Ok(())
}

/// `n` axes, one per bus, measured for `duration`.
fn axes(n: usize, duration: Duration) -> Result<(Run, Simulation, Vec<PortId>)> {
    let (mut sim, lines, ports) = axes_sim(n)?;
    let run = measure(&mut sim, &lines, duration)?;
    Ok((run, sim, ports))
}

/// `n` axes, one per bus, started.
fn axes_sim(n: usize) -> Result<(Simulation, Vec<Line>, Vec<PortId>)> {
    let mut sim = Simulation::new();
    let mut lines = Vec::with_capacity(n);
    let mut ports = Vec::with_capacity(n);
    for b in 0..n {
        let bus = sim.add_bus(BusConfig::new(format!("can{b}"), BitRate::R1M));
        let servo = Servo::new(ServoConfig::new(1)).map_err(|e| anyhow!("servo: {e}"))?;
        ports.push(sim.attach(bus, servo, PortConfig::default())?);
        let master = sim.attach(bus, ListenOnly, PortConfig::default())?;
        lines.push(Line {
            bus,
            master,
            node: 1,
        });
    }
    start(&mut sim, &lines)?;
    Ok((sim, lines, ports))
}

/// One axis, with the last position it reported on its dictionary (the axis moved).
fn axis(duration: Duration) -> Result<Run> {
    let (mut run, sim, ports) = axes(1, duration)?;
    let servo = sim
        .node::<Servo>(ports[0])
        .ok_or_else(|| anyhow!("the axis is a servo"))?;
    let bytes = servo
        .device()
        .od()
        .get(0x6064, 0)
        .map_err(|e| anyhow!("0x6064: {e}"))?
        .to_le_bytes();
    run.last_position = i32::from_le_bytes(
        bytes
            .get(..4)
            .and_then(|b| b.try_into().ok())
            .ok_or_else(|| anyhow!("0x6064 is 4 bytes"))?,
    );
    Ok(run)
}

/// The bare CiA 301 devices: RPDO 0x301 (3 bytes) and 0x401 (6 bytes) received, TPDO 0x381
/// and 0x481 (6 bytes each) on every SYNC: the identifiers and lengths of the axis's frames;
/// one device on each of `n` buses.
fn bare(n: usize, duration: Duration) -> Result<Run> {
    let (mut sim, lines) = bare_sim(n)?;
    measure(&mut sim, &lines, duration)
}

/// The bare devices of [`bare`], started.
fn bare_sim(n: usize) -> Result<(Simulation, Vec<Line>)> {
    let var = |name: &str, ty| SubObject::new(name, ty, Access::Rw).mappable();
    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .var(0x2000, var("Word", DataType::Unsigned16))
        .var(0x2001, var("Byte", DataType::Unsigned8))
        .var(0x2002, var("Long", DataType::Integer32))
        .var(0x2003, var("Long", DataType::Integer32));
    let word = 0x2000_0010;
    let pdos = PdoObjects::new(3, 4)
        .rpdo(1, 255, &[word, 0x2001_0008])
        .rpdo(2, 255, &[word, 0x2002_0020])
        .tpdo(2, 1, &[word, 0x2002_0020])
        .tpdo(3, 1, &[word, 0x2003_0020]);
    let desc = Arc::new(
        pdos.add_to(b)
            .build()
            .map_err(|e| anyhow!("bare dictionary: {e}"))?,
    );
    let mut sim = Simulation::new();
    let mut lines = Vec::with_capacity(n);
    for b in 0..n {
        let bus = sim.add_bus(BusConfig::new(format!("can{b}"), BitRate::R1M));
        sim.attach(
            bus,
            Device::new(Arc::clone(&desc), DeviceConfig::new(1))?,
            PortConfig::default(),
        )?;
        let master = sim.attach(bus, ListenOnly, PortConfig::default())?;
        lines.push(Line {
            bus,
            master,
            node: 1,
        });
    }
    start(&mut sim, &lines)?;
    Ok((sim, lines))
}

/// `n` buses of one node each (`make` builds and starts one), spread over the machine's
/// threads as `cantwin bench fleet` spreads its networks: each thread steps its buses, each
/// its own simulation (the buses do not meet), one communication cycle at a time. The
/// figure is the wall time of the measured part, all threads together.
fn fleet(
    n: usize,
    duration: Duration,
    make: fn() -> Result<(Simulation, Vec<Line>)>,
) -> Result<(Run, usize)> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |t| t.get())
        .clamp(1, n.max(1));
    let per = n.div_ceil(threads);
    let ready = std::sync::Barrier::new(threads + 1);
    let from = ms(10);
    let end = from + duration;
    let (wall, frames) = std::thread::scope(|s| -> Result<(std::time::Duration, u64)> {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let count = per.min(n.saturating_sub(t * per));
                let ready = &ready;
                s.spawn(move || -> Result<u64> {
                    let built: Result<Vec<_>> = (0..count).map(|_| make()).collect();
                    // Every thread waits for the others even when its buses failed to build.
                    let built = built.map(|mut v| {
                        for (sim, _) in &mut v {
                            sim.run_until(from);
                        }
                        v
                    });
                    ready.wait();
                    let mut units = built?;
                    let count_frames = |units: &[(Simulation, Vec<Line>)]| -> u64 {
                        units
                            .iter()
                            .flat_map(|(sim, lines)| {
                                lines
                                    .iter()
                                    .map(move |l| sim.bus(l.bus).map_or(0, |b| b.stats().frames()))
                            })
                            .sum()
                    };
                    let before = count_frames(&units);
                    let mut t = from;
                    let mut k = 0u64;
                    while t < end {
                        for (sim, lines) in &mut units {
                            sim.run_until(t);
                            for l in lines.iter() {
                                for f in cycle_frames(l.node, k)? {
                                    sim.transmit(l.master, f)?;
                                }
                            }
                        }
                        k += 1;
                        t += CYCLE;
                    }
                    for (sim, _) in &mut units {
                        sim.run_until(end);
                    }
                    Ok(count_frames(&units) - before)
                })
            })
            .collect();
        ready.wait();
        let wall = std::time::Instant::now();
        let mut frames = 0;
        for h in handles {
            frames += h.join().map_err(|_| anyhow!("a fleet thread panicked"))??;
        }
        Ok((wall.elapsed(), frames))
    })?;
    let secs = duration.as_secs_f64().max(1e-12);
    Ok((
        Run {
            ns_per_sim_second: wall.as_nanos() as f64 / secs,
            frames_per_sim_second: frames as f64 / secs,
            last_position: 0,
        },
        threads,
    ))
}

/// One started axis on its bus, for [`fleet`].
fn one_axis() -> Result<(Simulation, Vec<Line>)> {
    let (sim, lines, _) = axes_sim(1)?;
    Ok((sim, lines))
}

/// One started bare device on its bus, for [`fleet`].
fn one_bare() -> Result<(Simulation, Vec<Line>)> {
    bare_sim(1)
}

/// The axis, the bare devices and the fleet, `trials` times in turn; each at its fastest.
pub fn run(duration: Duration, fleet_duration: Duration, trials: usize) -> Result<Report> {
    let fastest = |a: Run, b: Run| {
        if b.ns_per_sim_second < a.ns_per_sim_second {
            b
        } else {
            a
        }
    };
    let mut best: Option<Report> = None;
    for _ in 0..trials.max(1) {
        let (fleet_run, threads) = fleet(FLEET, fleet_duration, one_axis)?;
        let r = Report {
            axis: axis(duration)?,
            bare: bare(1, duration)?,
            fleet: fleet_run,
            bare_fleet: fleet(FLEET, fleet_duration, one_bare)?.0,
            threads,
        };
        best = Some(match best {
            None => r,
            Some(b) => Report {
                axis: fastest(b.axis, r.axis),
                bare: fastest(b.bare, r.bare),
                fleet: fastest(b.fleet, r.fleet),
                bare_fleet: fastest(b.bare_fleet, r.bare_fleet),
                threads: r.threads,
            },
        });
    }
    best.ok_or_else(|| anyhow!("no trial"))
}

/// `cantwin bench cia402`.
pub(super) fn bench(args: &super::Args) -> Result<()> {
    let duration = super::seconds(args, 20.0);
    let fleet_duration = super::seconds(args, 5.0);
    eprintln!(
        "bench cia402: one csp axis and the bare CiA 301 devices, {duration} of bus time each, \
         then {FLEET} axes on {FLEET} buses for {fleet_duration} …"
    );
    let r = run(duration, fleet_duration, args.trials)?;
    let us = |run: &Run| run.ns_per_sim_second / 1e3;
    let ratio = r.ratio();
    let rtf = r.fleet_real_time_factor();
    let met = |ok: bool| if ok { "met" } else { "**not met**" };
    let table = format!(
        "| figure | value |\n|---|---|\n\
         | bus time measured, one axis and bare devices | {bus:.1} s each |\n\
         | frames on the bus per simulated second, axis / bare devices | {af:.0} / {bf:.0} |\n\
         | **CPU per simulated second, one csp axis** (bus, axis and master) | **{axis:.0} µs** |\n\
         | CPU per simulated second, bare CiA 301 devices (same run) | {bare:.0} µs |\n\
         | **axis / bare devices** | **{ratio:.2}** (floor ≤ {CPU_FLOOR}: {m1}) |\n\
         | bus time measured, {FLEET} axes on {FLEET} buses | {fleet_s:.1} s |\n\
         | frames per simulated second, all {FLEET} buses | {ff:.0} |\n\
         | **real-time factor, {FLEET} axes on {FLEET} buses** ({threads} threads) | **{rtf:.1}** (floor ≥ {FLEET_FLOOR}: {m2}) |\n\
         | real-time factor, {FLEET} bare CiA 301 devices on {FLEET} buses, the same frames (same run) | {bare_rtf:.1} |",
        bus = duration.as_secs_f64(),
        af = r.axis.frames_per_sim_second,
        bf = r.bare.frames_per_sim_second,
        axis = us(&r.axis),
        bare = us(&r.bare),
        m1 = met(ratio <= CPU_FLOOR),
        fleet_s = fleet_duration.as_secs_f64(),
        ff = r.fleet.frames_per_sim_second,
        m2 = met(rtf >= FLEET_FLOOR),
        bare_rtf = 1e9 / r.bare_fleet.ns_per_sim_second.max(1.0),
        threads = r.threads,
    );
    let intro = format!(
        "One CiA 402 servo axis (`kind = \"cia402\"`, the built-in dictionary and PDOs) in \
         cyclic synchronous position mode at 1 ms SYNC, 1 Mbit/s: before every SYNC the master \
         sends RPDO2 (controlword, modes of operation) and RPDO3 (controlword, target position, \
         a ramp of 20 000 units/s); the axis answers TPDO3 (statusword, position actual \
         value) and TPDO4 (statusword, velocity actual value) at each SYNC, its control loop \
         running every 250 µs. Baseline in the same run: one CiA 301 `Device` receiving RPDOs \
         and sending synchronous TPDOs of the same identifiers and lengths. Measured after \
         start-up in chunks of {CHUNK} of bus time, best of {trials} trials: the median \
         chunk's wall time per simulated second (≈ CPU of one core). The fleet: {FLEET} such \
         axes, each on its own bus with its master, spread over the machine's threads as \
         `cantwin bench fleet` spreads its networks (each bus its own simulation, stepped one \
         communication cycle at a time); its figure is the wall time of the whole, beside {FLEET} \
         bare devices run the same way.",
        trials = args.trials.max(1),
    );
    super::record(
        args,
        "cia402",
        "a servo axis in csp at 1 ms SYNC",
        &intro,
        &table,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axis_and_the_bare_devices_carry_the_same_frames() {
        let d = Duration::from_millis(200);
        let a = axis(d).unwrap();
        let b = bare(1, d).unwrap();
        // SYNC, 2 RPDOs and 2 TPDOs every millisecond.
        assert!((a.frames_per_sim_second - 5000.0).abs() < 50.0, "{a:?}");
        assert!((b.frames_per_sim_second - 5000.0).abs() < 50.0, "{b:?}");
        // The axis followed the ramp of set-points (20 units a cycle for 200 cycles).
        assert!(a.last_position > 3_800 && a.last_position < 4_000, "{a:?}");
        // Four axes over the threads carry four buses' frames.
        let (f, threads) = fleet(4, d, one_axis).unwrap();
        assert!(threads >= 1);
        assert!((f.frames_per_sim_second - 20_000.0).abs() < 200.0, "{f:?}");
    }
}
