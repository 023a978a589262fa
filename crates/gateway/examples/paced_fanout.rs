//! Fan-out of a busy paced bus to many socketcand clients: a node in the simulation sends an
//! 8-byte frame every 130 µs (about 90 % of a 1 Mbit/s bus) for a few seconds while N clients
//! read everything. Prints what each client got, how often the simulation fell behind the wall
//! clock, and the CPU time the process used per frame and client.
//!
//! `cargo run --release -p cantwin-gateway --example paced_fanout -- [CLIENTS] [SECONDS]`

use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use cantwin_bus::{BusConfig, PacedConfig, PacedSimulation, Simulation};
use cantwin_can::{BitRate, Frame, Instant as BusInstant, Node, Outbox};
use cantwin_gateway::paced::PacedBus;
use cantwin_gateway::socketcand::{Client, Server};
use cantwin_gateway::{BusPort, Limits};

/// User plus system CPU time of this process, from `/proc/self/stat` (Linux; zero elsewhere).
fn cpu_time() -> Duration {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return Duration::ZERO;
    };
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or("", |(_, rest)| rest)
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<u64>().ok())
            .unwrap_or(0)
    };
    // utime and stime are fields 14 and 15 of the whole line: 11 and 12 after the name.
    Duration::from_millis((ticks(11) + ticks(12)) * 10)
}

/// Sends its frame every `period` from `next` until `end`.
struct Talker {
    frame: Frame,
    next: BusInstant,
    end: BusInstant,
    period: cantwin_can::Duration,
}

impl Node for Talker {
    fn on_frame(&mut self, _: &Frame, _: BusInstant, _: &mut Outbox) {}
    fn on_tick(&mut self, now: BusInstant, out: &mut Outbox) {
        if now >= self.next && now < self.end {
            out.push(self.frame);
            self.next += self.period;
        }
    }
    fn next_deadline(&self) -> Option<BusInstant> {
        (self.next < self.end).then_some(self.next)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let clients: usize = args.next().map_or(Ok(8), |a| a.parse())?;
    let seconds: u64 = args.next().map_or(Ok(3), |a| a.parse())?;
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let frame = Frame::std(0x181, &[1, 2, 3, 4, 5, 6, 7, 8])?;
    // Silent until the clients are connected.
    let start_at = BusInstant::ZERO + cantwin_can::Duration::from_millis(500);
    let run = cantwin_can::Duration::from_secs(seconds);
    let talker = Talker {
        frame,
        next: start_at,
        end: start_at + run,
        period: cantwin_can::Duration::from_micros(130),
    };
    sim.attach(bus, talker, cantwin_bus::PortConfig::default())?;
    let paced = PacedSimulation::start(sim, PacedConfig::default());
    let handle = paced.handle();
    let buses = PacedBus::new(handle.clone());
    let server = Server::bind(
        "127.0.0.1:0".parse()?,
        Arc::new(buses.clone()),
        Limits::default(),
    )?;
    let readers: Vec<_> = (0..clients)
        .map(|_| {
            let client = Client::connect(server.local_addr(), "can0", Duration::from_secs(5))?;
            Ok(thread::spawn(move || {
                let mut got = 0u64;
                loop {
                    match client.recv_timeout(Duration::from_secs(2)) {
                        Ok(Some(_)) => got += 1,
                        // Quiet for long after the run, or the connection ended.
                        _ => return got,
                    }
                }
            }))
        })
        .collect::<Result<_, Box<dyn std::error::Error>>>()?;
    let now = handle.now()?;
    thread::sleep(Duration::from(start_at.saturating_duration_since(now)));
    let cpu0 = cpu_time();
    let wall0 = Instant::now();
    thread::sleep(Duration::from(run));
    let (cpu, wall) = (cpu_time() - cpu0, wall0.elapsed());
    let sent = handle.with(|sim| sim.bus(bus).map_or(0, |b| b.stats().frames()))?;
    let got: Vec<u64> = readers.into_iter().map(|r| r.join().unwrap_or(0)).collect();
    let least = got.iter().copied().min().unwrap_or(0);
    println!(
        "{clients} clients: {sent} frames on the bus by the end, least received by a client \
         {least}, slips {}, CPU {:.2} s in {:.2} s ({:.2} µs per frame and client)",
        handle.slips(),
        cpu.as_secs_f64(),
        wall.as_secs_f64(),
        cpu.as_secs_f64() * 1e6 / (wall.as_secs_f64() / 130e-6) / clients.max(1) as f64
    );
    server.shutdown();
    paced.stop();
    Ok(())
}
