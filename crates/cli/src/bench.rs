//! `cantwin bench`: named macro benchmarks, printed as a table and recorded in
//! `BENCHMARKS.md` with `--write`.

use std::path::PathBuf;

use anyhow::{Result, bail};
use cantwin_bus::bench::{BenchConfig, run as run_bus_bench};
use cantwin_can::Duration;

use crate::benchmarks_md;

mod canopen;

/// The benchmarks `cantwin bench` knows.
const NAMES: &[(&str, &str)] = &[
    (
        "bus",
        "127 nodes on a saturated 1 Mbit/s bus, one mailbox each, 60 s of bus time",
    ),
    (
        "network",
        "64 CiA 301 devices at 1 Mbit/s, SYNC every 10 ms, TPDO per SYNC, heartbeats, 60 s",
    ),
    (
        "fleet",
        "how many such networks one process simulates in real time (2 s trials)",
    ),
    (
        "sdo",
        "expedited SDO round trips per wall second; segmented and block download efficiency",
    ),
    (
        "memory",
        "bytes per CiA 301 device; build time of a 127-device scenario",
    ),
];

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Benchmarks to run (all when none is named): bus, network, fleet, sdo, memory.
    names: Vec<String>,
    /// Record the figures in BENCHMARKS.md.
    #[arg(long)]
    write: bool,
    /// Where BENCHMARKS.md is.
    #[arg(long, default_value = "BENCHMARKS.md")]
    file: PathBuf,
    /// Bus time to simulate, in seconds, for every benchmark named (recorded figures use
    /// each benchmark's default: 60 for bus, network and sdo, 2 per fleet trial).
    #[arg(long)]
    seconds: Option<f64>,
    /// fleet: run this many networks once instead of searching for the largest real-time
    /// count.
    #[arg(long)]
    buses: Option<usize>,
    /// List the benchmarks and exit.
    #[arg(long)]
    list: bool,
}

pub fn run(args: &Args) -> Result<()> {
    if args.list {
        for (name, what) in NAMES {
            println!("{name:8} {what}");
        }
        return Ok(());
    }
    let names: Vec<&str> = if args.names.is_empty() {
        NAMES.iter().map(|(n, _)| *n).collect()
    } else {
        args.names.iter().map(String::as_str).collect()
    };
    for name in &names {
        if !NAMES.iter().any(|(n, _)| n == name) {
            let known: Vec<&str> = NAMES.iter().map(|(n, _)| *n).collect();
            bail!("unknown benchmark {name:?}; known: {}", known.join(", "));
        }
    }
    if let Some(seconds) = args.seconds
        && !(seconds > 0.0 && seconds.is_finite())
    {
        bail!("--seconds must be a positive number, not {seconds}");
    }
    if args.buses == Some(0) {
        bail!("--buses must be at least 1");
    }
    if cfg!(debug_assertions) {
        eprintln!("note: this is a debug build; figures are only meaningful with --release");
    }
    for name in names {
        match name {
            "bus" => bench_bus(args)?,
            "network" => bench_network(args)?,
            "fleet" => bench_fleet(args)?,
            "sdo" => bench_sdo(args)?,
            _ => bench_memory(args)?,
        }
    }
    Ok(())
}

fn bench_bus(args: &Args) -> Result<()> {
    let config = BenchConfig::saturated(seconds(args, 60.0));
    eprintln!(
        "bench bus: {} nodes, {}, one offer per node every {}, {} of bus time …",
        config.nodes, config.bit_rate, config.period, config.duration
    );
    let r = run_bus_bench(config);
    let rtf = r.real_time_factor();
    let table = format!(
        "| figure | value |\n|---|---|\n\
         | bus time simulated | {bus:.1} s |\n\
         | wall time | {wall:.3} s |\n\
         | **real-time factor** (bus time / wall time) | **{rtf:.0}** |\n\
         | delivered frames | {delivered} |\n\
         | delivered frames per wall second | {fps:.0} |\n\
         | wall ns per delivered frame | {ns:.0} |\n\
         | frames received by filtering nodes | {received} |\n\
         | offers / dropped into a full mailbox | {offers} / {dropped} |\n\
         | bus load | {load:.1} % |",
        bus = r.bus_time.as_secs_f64(),
        wall = r.wall_time.as_secs_f64(),
        delivered = r.delivered,
        fps = r.frames_per_wall_second(),
        ns = r.ns_per_frame(),
        received = r.received,
        offers = r.offers,
        dropped = r.dropped_offers,
        load = r.bus_load_percent,
    );
    println!("{table}");
    let verdict = if rtf >= 1000.0 {
        "meets the aim (≥ 1000)"
    } else if rtf >= 300.0 {
        "meets the floor (≥ 300), below the aim of 1000"
    } else {
        "BELOW THE FLOOR of 300"
    };
    println!("real-time factor {rtf:.0}: {verdict}");
    if args.write {
        let body = format!(
            "## bus — saturated 1 Mbit/s bus\n\n\
             {} nodes at {}, each offering an 8-byte frame with its own id every {} into a \
             single transmit mailbox (an offer into a full mailbox is dropped and counted), \
             filters accepting 4 other nodes' ids, {} of bus time. Floor: real-time factor \
             ≥ 300 (foundation: ≥ 100); aim 1000.\n\n{table}\n\n\
             Measured {} on {}.\nReproduce: `cargo run --release --bin cantwin -- bench bus --write`",
            config.nodes,
            config.bit_rate,
            config.period,
            config.duration,
            benchmarks_md::today(),
            benchmarks_md::machine_description(),
        );
        benchmarks_md::write_section(&args.file, "bus", &body)?;
        println!("recorded in {}", args.file.display());
    }
    Ok(())
}
