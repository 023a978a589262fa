//! `cantwin bench`: named macro benchmarks, printed as a table and recorded in
//! `BENCHMARKS.md` with `--write`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use cantwin_bus::bench::limit::{LimitReport, run as run_limit};
use cantwin_bus::bench::{BenchConfig, BenchReport as BusReport, run as run_bus_bench};
use cantwin_can::Duration;
use indicatif::ProgressBar;

use crate::benchmarks_md;

mod canopen;
mod cia402;
mod memory_twins;
mod process;
mod python;
mod silkit;
mod table_json;
mod trials;
mod twins;

/// The benchmarks `cantwin bench` knows.
const NAMES: &[(&str, &str)] = &[
    (
        "silkit",
        "CAN frames per second and latency through cantwin as SIL Kit's network simulator, 2 and 8 participants, vs SIL Kit alone",
    ),
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
        "bytes per CiA 301 device; RSS and start-up time of `cantwin sim` with 127 devices; RSS per TM3BCCO with 14 modules and per ADV200",
    ),
    (
        "python",
        "python-canopen round trips and 64 KiB transfers: the twin vs python-canopen's LocalNode",
    ),
    (
        "cia402",
        "a CiA 402 servo axis in csp at 1 ms SYNC vs bare CiA 301 devices; 64 axes on 64 buses",
    ),
];

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Benchmarks to run (all when none is named; `--list` says what each measures): silkit,
    /// bus, network, fleet, sdo, memory, python, cia402, and one per twin: adv200-canopen,
    /// adv200-ds402, adv200-devicenet, tm3, tm3-56, opendrive. `python` needs python-can and
    /// python-canopen (the interop suite's virtualenv, or CANTWIN_PYTHON), `silkit` needs SIL
    /// Kit (`scripts/fetch-silkit.sh`); when not named they are skipped without them.
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
    /// bus, network, sdo, silkit: trials of the same run; each figure measured in
    /// wall time is reported as the best trial (the floors are judged on it) and the median.
    /// Twin benchmarks: the twin and its baselines are each reported at their best trial.
    #[arg(long, default_value_t = 5)]
    trials: usize,
    /// fleet: run this many networks once instead of searching for the largest real-time
    /// count.
    #[arg(long)]
    buses: Option<usize>,
    /// python: expedited SDO uploads per server.
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(1..))]
    requests: u64,
    /// python: 64 KiB segmented uploads and downloads per server.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    transfers: u64,
    /// List the benchmarks and exit.
    #[arg(long)]
    list: bool,
}

pub fn run(args: &Args) -> Result<()> {
    if args.list {
        for (name, what) in NAMES.iter().chain(twins::TWINS) {
            crate::output::result(
                format_args!("{name:16} {what}"),
                || serde_json::json!({"bench": name, "about": what}),
            )?;
        }
        return Ok(());
    }
    let all = || NAMES.iter().chain(twins::TWINS);
    let names: Vec<&str> = if args.names.is_empty() {
        all().map(|(n, _)| *n).collect()
    } else {
        args.names.iter().map(String::as_str).collect()
    };
    for name in &names {
        if !all().any(|(n, _)| n == name) {
            let known: Vec<&str> = all().map(|(n, _)| *n).collect();
            bail!("unknown benchmark {name:?}; known: {}", known.join(", "));
        }
    }
    if let Some(seconds) = args.seconds
        && !(seconds > 0.0 && seconds.is_finite())
    {
        bail!("--seconds must be a positive number, not {seconds}");
    }
    if args.trials == 0 {
        bail!(
            "--trials must be at least 1, not 0: bus, network and sdo report the best and the \
             median of that many trials"
        );
    }
    if args.buses == Some(0) {
        bail!("--buses must be at least 1");
    }
    if cfg!(debug_assertions) {
        eprintln!("note: this is a debug build; figures are only meaningful with --release");
    }
    let root = args.file.parent().unwrap_or(std::path::Path::new(""));
    for name in names {
        if name == "python"
            && args.names.is_empty()
            && let Some(why) = python::missing(root)
        {
            eprintln!("bench python: skipped: {why}");
            continue;
        }
        if name == "python" {
            // python-canopen prints its own progress; a spinner would tear its lines.
            python::run(
                root,
                &args.file,
                usize::try_from(args.requests).unwrap_or(usize::MAX),
                usize::try_from(args.transfers).unwrap_or(usize::MAX),
                args.write,
            )?;
            continue;
        }
        // The benchmarks run inside the simulator's loops: a spinner with the elapsed time
        // shows the run is alive.
        let spinner = crate::output::spinner(&format!("bench {name}"));
        let r = match name {
            "bus" => bench_bus(args, &spinner),
            "network" => bench_network(args, &spinner),
            "fleet" => bench_fleet(args),
            "sdo" => bench_sdo(args, &spinner),
            "memory" => bench_memory(args),
            "cia402" => cia402::bench(args),
            "silkit" => silkit::bench(args.write, &args.file, !args.names.is_empty(), args.trials),
            twin => bench_twin(args, twin),
        };
        spinner.finish_and_clear();
        r?;
    }
    Ok(())
}

/// Print a benchmark's table, or its JSON object with `--json`.
fn print_table(name: &str, table: &str) -> Result<()> {
    if crate::output::json() {
        crate::output::emit(&table_json::table_json(name, table))?;
    } else {
        println!("{table}");
    }
    Ok(())
}

/// Node counts and offered loads of the growth tables.
const GROWTH_NODES: [u16; 4] = [8, 32, 64, 127];
const GROWTH_LOADS: [f64; 3] = [25.0, 50.0, 100.0];

/// The bus and its fixed limit ([`cantwin_bus::bench::limit`]) on the same scenario, each
/// the best of `n` trials run in turn, so that a burst of load from other processes disturbs
/// one trial of each rather than every trial of one.
fn bus_and_limit(
    config: BenchConfig,
    n: usize,
    label: &str,
    spinner: &ProgressBar,
    mut each: impl FnMut(usize, &BusReport, &LimitReport),
) -> Result<(trials::Trials<BusReport>, trials::Trials<LimitReport>)> {
    let mut buses = Vec::with_capacity(n);
    let mut limits = Vec::with_capacity(n);
    for i in 1..=n {
        spinner.set_message(format!("{label}: trial {i}/{n}"));
        let bus = run_bus_bench(config);
        let limit = run_limit(config);
        if (bus.delivered, bus.received) != (limit.delivered, limit.received) {
            bail!(
                "{label}: the limit delivered {} frames to {} receivers, the bus {} to {}: the \
                 limit no longer follows the bus's schedule",
                limit.delivered,
                limit.received,
                bus.delivered,
                bus.received
            );
        }
        each(i, &bus, &limit);
        buses.push(bus);
        limits.push(limit);
    }
    Ok((
        trials::Trials::new(label, buses)?,
        trials::Trials::new(&format!("{label}, limit"), limits)?,
    ))
}

/// The growth table: wall ns per delivered frame of the bus (and of its limit, and their
/// ratio) for every node count and offered load, best of `n` trials each.
fn bus_growth(args: &Args, n: usize, spinner: &ProgressBar) -> Result<String> {
    let duration = seconds(args, 20.0);
    let mut table = String::from(
        "| nodes | offered load | bus load | frames | **bus ns per frame** | limit ns per frame | bus / limit |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for nodes in GROWTH_NODES {
        for load in GROWTH_LOADS {
            let config = BenchConfig::at_load(nodes, load, duration);
            let label = format!("bench bus: {nodes} nodes at {load:.0} %");
            let (bus, limit) = bus_and_limit(config, n, &label, spinner, |_, _, _| {})?;
            let (b, l) = (bus.best(), limit.best());
            table.push_str(&format!(
                "| {nodes} | {load:.0} % | {:.1} % | {} | **{:.0}** | {:.1} | {:.1} |\n",
                b.bus_load_percent,
                b.delivered,
                b.ns_per_frame(),
                l.ns_per_frame(),
                b.ns_per_frame() / l.ns_per_frame().max(1e-9),
            ));
        }
    }
    Ok(table)
}

fn bench_bus(args: &Args, spinner: &ProgressBar) -> Result<()> {
    let config = BenchConfig::saturated(seconds(args, 60.0));
    let n = args.trials;
    let load = load_average();
    eprintln!(
        "bench bus: {} nodes, {}, one offer per node every {}, {} of bus time, {}, each \
         beside its fixed limit …",
        config.nodes,
        config.bit_rate,
        config.period,
        config.duration,
        trials_count(n)
    );
    let (trials, limits) = bus_and_limit(config, n, "bench bus", spinner, |i, r, l| {
        spinner.suspend(|| {
            eprintln!(
                "  trial {i}/{n}: real-time factor {:.0}, {:.0} ns per frame, limit {:.1} ns",
                r.real_time_factor(),
                r.ns_per_frame(),
                l.ns_per_frame()
            );
        });
    })?;
    let (r, median) = (trials.best(), trials.median());
    let (l, l_median) = (limits.best(), limits.median());
    let rtf = r.real_time_factor();
    let ratio = r.ns_per_frame() / l.ns_per_frame().max(1e-9);
    let median_ratio = median.ns_per_frame() / l_median.ns_per_frame().max(1e-9);
    let growth = bus_growth(args, n, spinner)?;
    let table = format!(
        "| figure | {header} |\n|---|---|\n\
         | bus time simulated | {bus:.1} s |\n\
         | wall time | {wall} |\n\
         | **real-time factor** (bus time / wall time) | **{rtf:.0}** (median {median_rtf:.0}) |\n\
         | delivered frames | {delivered} |\n\
         | delivered frames per wall second | {fps} |\n\
         | wall ns per delivered frame | {ns} |\n\
         | wall ns per delivered frame, fixed limit (same run) | {limit_ns} |\n\
         | **bus / fixed limit** (best trials) | **{ratio:.1}×** (medians {median_ratio:.1}×; {v} of 3×) |\n\
         | frames received by filtering nodes | {received} |\n\
         | offers / dropped into a full mailbox | {offers} / {dropped} |\n\
         | bus load | {load_pct:.1} % |\n\
         | machine load (1, 5, 15 min) at the start | {load} |\n\n\
         Wall ns per delivered frame by node count and offered load ({growth_s} of bus time \
         each, best of {trials}; the limit in the same run):\n\n{growth}",
        header = trials_header(n),
        bus = r.bus_time.as_secs_f64(),
        wall = trials::best_median(
            r.wall_time.as_secs_f64(),
            median.wall_time.as_secs_f64(),
            3,
            " s"
        ),
        median_rtf = median.real_time_factor(),
        delivered = r.delivered,
        fps = trials::best_median(
            r.frames_per_wall_second(),
            median.frames_per_wall_second(),
            0,
            ""
        ),
        ns = trials::best_median(r.ns_per_frame(), median.ns_per_frame(), 0, ""),
        limit_ns = trials::best_median(l.ns_per_frame(), l_median.ns_per_frame(), 1, ""),
        v = verdict(ratio, 3.0, false),
        received = r.received,
        offers = r.offers,
        dropped = r.dropped_offers,
        load_pct = r.bus_load_percent,
        growth_s = seconds(args, 20.0),
        trials = trials_count(n),
        growth = growth.trim_end(),
    );
    print_table("bus", &table)?;
    let verdict = if rtf >= 1000.0 {
        "meets the aim (≥ 1000)"
    } else if rtf >= 300.0 {
        "meets the floor (≥ 300), below the aim of 1000"
    } else {
        "BELOW THE FLOOR of 300"
    };
    if !crate::output::json() {
        println!(
            "real-time factor {rtf:.0} (best of {}; median {:.0}): {verdict}; {ratio:.1}× the \
             fixed limit",
            trials_count(n),
            median.real_time_factor()
        );
    }
    if args.write {
        let body = format!(
            "## bus — saturated 1 Mbit/s bus\n\n\
             {} nodes at {}, each offering an 8-byte frame with its own id every {} into a \
             single transmit mailbox (an offer into a full mailbox is dropped and counted), \
             filters accepting 4 other nodes' ids, {} of bus time. The fixed limit \
             (`cantwin_bus::bench::limit`, criterion: `cargo bench -p cantwin-bus --bench \
             limit`) runs the same schedule with the least work a delivered frame needs: \
             pre-built frames, the winner from a sorted array of pending identifiers, \
             precomputed lengths and identifier→receiver bitsets, no counters; each trial \
             checks it delivers exactly the bus's frames to the same receivers. {} Floors: \
             within 3× of the fixed limit; real-time factor ≥ 300, aim 1000.\n\n{table}\n\n\
             Measured {} on {}.\nReproduce: `cargo run --release --bin cantwin -- bench bus --write`",
            config.nodes,
            config.bit_rate,
            config.period,
            config.duration,
            trials_intro(n),
            benchmarks_md::today(),
            benchmarks_md::machine_description(),
        );
        benchmarks_md::write_section(&args.file, "bus", &body)?;
        if crate::output::json() {
            eprintln!("recorded in {}", args.file.display());
        } else {
            println!("recorded in {}", args.file.display());
        }
    }
    Ok(())
}

/// The machine's load averages now (`/proc/loadavg`), for the record beside wall-time
/// figures measured on a shared machine; `unknown` where the system does not say.
pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| {
            let v: Vec<&str> = s.split_whitespace().take(3).collect();
            (v.len() == 3).then(|| v.join(", "))
        })
        .unwrap_or_else(|| "unknown".to_string())
}

/// The value column's header of a table of figures measured over `n` trials.
fn trials_header(n: usize) -> String {
    format!("best of {} (median)", trials_count(n))
}

/// The sentence of a benchmark's intro saying what its wall-time figures are.
fn trials_intro(n: usize) -> String {
    format!(
        "Figures in wall time are the best of {} of the same deterministic run, which is \
         the code's own cost on a shared machine; the median shows the spread. The floor is \
         judged on the best trial.",
        trials_count(n)
    )
}

/// `1 trial`, `5 trials`.
fn trials_count(n: usize) -> String {
    if n == 1 {
        "1 trial".to_string()
    } else {
        format!("{n} trials")
    }
}

/// The bus time of a run: `--seconds`, or the benchmark's default.
fn seconds(args: &Args, default: f64) -> Duration {
    Duration::from_secs_f64(args.seconds.unwrap_or(default))
}

/// Print `table` and, with `--write`, record `body` as the section of `name`, with the
/// machine, the date and the command that reproduces it.
fn record(args: &Args, name: &str, title: &str, intro: &str, table: &str) -> Result<()> {
    print_table(name, table)?;
    if args.write {
        let body = format!(
            "## {name} — {title}\n\n{intro}\n\n{table}\n\n\
             Measured {} on {}.\nReproduce: `cargo run --release --bin cantwin -- bench {name} --write`",
            benchmarks_md::today(),
            benchmarks_md::machine_description(),
        );
        benchmarks_md::write_section(&args.file, name, &body)?;
        if crate::output::json() {
            eprintln!("recorded in {}", args.file.display());
        } else {
            println!("recorded in {}", args.file.display());
        }
    }
    Ok(())
}

fn verdict(value: f64, floor: f64, higher_is_better: bool) -> &'static str {
    let met = if higher_is_better {
        value >= floor
    } else {
        value < floor
    };
    if met {
        "meets the floor"
    } else {
        "BELOW THE FLOOR"
    }
}

fn bench_network(args: &Args, spinner: &ProgressBar) -> Result<()> {
    let duration = seconds(args, 60.0);
    let n = args.trials;
    eprintln!(
        "bench network: {} CiA 301 devices at 1 Mbit/s, {duration} of bus time, four ways, \
         {} …",
        canopen::NETWORK_DEVICES,
        trials_count(n)
    );
    let modes = [
        (canopen::Filtering::Firmware, "firmware acceptance filters"),
        (
            canopen::Filtering::Device,
            "the devices' own acceptance filters",
        ),
        (
            canopen::Filtering::Everything,
            "every frame handed to every device, which filters it",
        ),
        (
            canopen::Filtering::Unfiltered,
            "every frame through every device's whole stack",
        ),
    ];
    // Each trial runs the four ways one after the other, so that a burst of load from other
    // processes disturbs one trial of each way rather than every trial of one way.
    let mut runs: Vec<Vec<canopen::NetworkReport>> = vec![Vec::with_capacity(n); modes.len()];
    for i in 1..=n {
        for ((filtering, what), reports) in modes.iter().zip(&mut runs) {
            spinner.set_message(format!("bench network: trial {i}/{n}, {what}"));
            let r = canopen::run_networks(1, duration, *filtering)?;
            spinner.suspend(|| {
                eprintln!(
                    "  trial {i}/{n}, {what}: real-time factor {:.0}",
                    r.real_time_factor()
                );
            });
            reports.push(r);
        }
    }
    let mut ways = Vec::with_capacity(modes.len());
    for ((_, what), reports) in modes.iter().zip(runs) {
        ways.push((
            *what,
            trials::Trials::new(&format!("bench network, {what}"), reports)?,
        ));
    }
    let [(_, firmware), (_, device), _, (_, unfiltered)] = ways.as_slice() else {
        bail!(
            "bench network: expected four ways of filtering, not {}",
            ways.len()
        );
    };
    let r = firmware.best();
    let mut table = format!(
        "| figure | value |\n|---|---|\n\
         | bus time simulated | {bus:.1} s |\n\
         | delivered frames | {frames} |\n\
         | bus load | {load:.1} % |\n\
         | build time (65 nodes) | {build:.2} ms |\n",
        bus = r.bus_time.as_secs_f64(),
        frames = r.frames,
        load = r.bus_load_percent,
        build = r.build_time.as_secs_f64() * 1e3,
    );
    table.push_str(&format!(
        "\n| how frames reach the devices — {header} | wall time | real-time factor | wall ns per frame |\n\
         |---|---|---|---|\n",
        header = trials_header(n),
    ));
    for (k, (what, trials)) in ways.iter().enumerate() {
        let (best, median) = (trials.best(), trials.median());
        let f = best.real_time_factor();
        let bold = if k < 2 { "**" } else { "" };
        table.push_str(&format!(
            "| {what} | {wall} | {bold}{f:.0}{bold} (median {mf:.0}; {v} of 200) | {ns} |\n",
            wall = trials::best_median(
                best.wall_time.as_secs_f64(),
                median.wall_time.as_secs_f64(),
                3,
                " s"
            ),
            mf = median.real_time_factor(),
            v = verdict(f, 200.0, true),
            ns = trials::best_median(best.ns_per_frame(), median.ns_per_frame(), 0, ""),
        ));
    }
    table.push_str(&network_growth(args, n, spinner)?);
    table.push_str(&format!(
        "\nThe devices' own filter against every frame through the whole stack: {:.1}× faster \
         (best trials).",
        unfiltered.best().wall_time.as_secs_f64() / device.best().wall_time.as_secs_f64().max(1e-9)
    ));
    let intro = format!(
        "{} `canopen::device::Device`s (CiA 301 defaults, TPDO 1 of 8 bytes with transmission \
         type 1, producer heartbeat {} ms set through 0x1017) and a master that starts them \
         all (NMT) and sends SYNC every {}, on one 1 Mbit/s bus. Measured four ways in one \
         run: acceptance filters listed by hand as firmware would program them (NMT, SYNC, \
         TIME, its own SDO request and guarding identifiers); the bus asking each `Device`, \
         which derives its filter from its own COB-IDs; every frame handed to every device, \
         which skips what its filter does not pass; and every frame through every device's \
         whole stack with its filter off. Each trial runs the four ways in turn. {} Floor: \
         real-time factor ≥ 200.",
        canopen::NETWORK_DEVICES,
        canopen::HEARTBEAT_MS,
        canopen::SYNC_PERIOD,
        trials_intro(n),
    );
    record(
        args,
        "network",
        "a realistic CiA 301 network",
        &intro,
        &table,
    )
}

/// The growth table of `bench network`: wall ns per delivered frame for every device count
/// and offered load (the SYNC period set for it), firmware filters, best of `n` trials.
fn network_growth(args: &Args, n: usize, spinner: &ProgressBar) -> Result<String> {
    let duration = seconds(args, 10.0);
    let mut table = format!(
        "\nWall ns per delivered frame by device count and offered load (firmware filters; SYNC \
         period set for the load: per SYNC one TPDO per device, heartbeats every {} ms; \
         {duration} of bus time each, best of {}; machine load (1, 5, 15 min) {}):\n\n\
         | devices | offered load | SYNC period | bus load | frames | **ns per frame** | real-time factor |\n\
         |---|---|---|---|---|---|---|\n",
        canopen::HEARTBEAT_MS,
        trials_count(n),
        load_average(),
    );
    for devices in GROWTH_NODES {
        let devices = u8::try_from(devices).unwrap_or(127);
        for load in GROWTH_LOADS {
            let Some(period) = canopen::sync_period_for_load(devices, load) else {
                continue;
            };
            spinner.set_message(format!("bench network: {devices} devices at {load:.0} %"));
            let mut runs = Vec::with_capacity(n);
            for _ in 0..n {
                runs.push(canopen::run_network_of(devices, period, duration)?);
            }
            let t = trials::Trials::new(&format!("bench network, {devices} devices"), runs)?;
            let b = t.best();
            table.push_str(&format!(
                "| {devices} | {load:.0} % | {period} | {:.1} % | {} | **{:.0}** | {:.0} |\n",
                b.bus_load_percent,
                b.frames,
                b.ns_per_frame(),
                b.real_time_factor(),
            ));
        }
    }
    Ok(table)
}

fn bench_fleet(args: &Args) -> Result<()> {
    let trial = seconds(args, 2.0);
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let load = load_average();
    let progress = |r: &canopen::NetworkReport| {
        eprintln!(
            "  {} networks on {} threads: real-time factor {:.2} (build {:.1} s)",
            r.buses,
            r.threads,
            r.real_time_factor(),
            r.build_time.as_secs_f64()
        );
    };
    // The baseline of the same run: one network alone on one thread, best of the trials.
    let n = args.trials;
    eprintln!(
        "bench fleet: one network alone, {trial} of bus time, {} …",
        trials_count(n)
    );
    let mut singles = Vec::with_capacity(n);
    for _ in 0..n {
        singles.push(canopen::run_networks(
            1,
            trial,
            canopen::Filtering::Firmware,
        )?);
    }
    let single = trials::Trials::new("bench fleet, one network", singles)?;
    let single_rtf = single.best().real_time_factor();
    let ideal = threads as f64 * single_rtf;
    eprintln!(
        "  one network: real-time factor {single_rtf:.0} (median {:.0}); {threads} threads could \
         hold {ideal:.0}; trials of {trial} …",
        single.median().real_time_factor()
    );
    let (best, trials) = if let Some(n) = args.buses {
        eprintln!("bench fleet: {n} networks on {threads} threads, {trial} of bus time …");
        let r = canopen::run_networks_threaded(n, threads, trial, canopen::Filtering::Firmware)?;
        progress(&r);
        ((r.real_time_factor() >= 1.0).then_some(r), vec![r])
    } else {
        canopen::find_fleet(
            single_rtf,
            threads,
            trial,
            canopen::Filtering::Firmware,
            progress,
        )?
    };
    let mut table = format!(
        "| figure | value |\n|---|---|\n\
         | one network alone: real-time factor (best of {count}, same run) | {single_rtf:.0} (median {median:.0}) |\n\
         | threads × that: networks the threads could hold if nothing were lost | {ideal:.0} |\n\
         | machine load (1, 5, 15 min) at the start | {load} |\n\n\
         | networks | threads | real-time factor | frames per wall second | networks × real-time factor / (threads × single) |\n\
         |---|---|---|---|---|\n",
        count = trials_count(n),
        median = single.median().real_time_factor(),
    );
    for r in &trials {
        table.push_str(&format!(
            "| {} | {} | {:.2} | {:.0} | {:.0} % |\n",
            r.buses,
            r.threads,
            r.real_time_factor(),
            r.frames as f64 / r.wall_time.as_secs_f64().max(1e-9),
            100.0 * r.buses as f64 * r.real_time_factor() / ideal.max(1e-9),
        ));
    }
    match best {
        Some(b) => {
            let fraction = b.buses as f64 / ideal.max(1e-9);
            table.push_str(&format!(
                "\n**{} networks ({} devices) in real time**: **{:.0} %** of threads × the single \
                 network's real-time factor ({} of 30 %; {} of 50 networks)",
                b.buses,
                b.buses * usize::from(canopen::NETWORK_DEVICES),
                100.0 * fraction,
                verdict(fraction, 0.30, true),
                verdict(b.buses as f64, 50.0, true)
            ))
        }
        None => table.push_str("\n**no trial ran in real time**"),
    }
    let intro = format!(
        "The `network` benchmark's bus (firmware acceptance filters), N times, spread over \
         {threads} threads, each network its own `Simulation`; each thread runs its networks in \
         slices of {slice} of bus time (every network to the end of a slice, one after the \
         other), so every network stays within a slice of the others and runs a whole slice \
         while its devices are in the core's caches. {trial} of bus time per trial; the table \
         lists every trial of the search for the largest N with a real-time factor ≥ 1. The \
         baseline, in the same run: one network alone on one thread. Floors: ≥ 30 % of \
         threads × the single network's real-time factor; ≥ 50 networks.",
        slice = canopen::FLEET_SLICE,
    );
    record(
        args,
        "fleet",
        "networks simulated in real time",
        &intro,
        &table,
    )
}

fn bench_sdo(args: &Args, spinner: &ProgressBar) -> Result<()> {
    let duration = seconds(args, 60.0);
    let bulk = 100_000;
    let n = args.trials;
    eprintln!(
        "bench sdo: expedited uploads for {duration} of bus time, {}, then {bulk}-byte \
         downloads …",
        trials_count(n)
    );
    let load = load_average();
    // Each trial: the round trips through the bus, then the device alone answering as many
    // requests, in turn, so that a burst of load disturbs one trial of each.
    let mut alone_runs = Vec::with_capacity(n);
    let trials = trials::run("bench sdo", n, spinner, |i| {
        let r = canopen::run_sdo_expedited(duration)?;
        let alone = canopen::run_sdo_device_alone(r.round_trips.max(1))?;
        spinner.suspend(|| {
            eprintln!(
                "  trial {i}/{n}: {:.0} expedited round trips per wall second ({:.0} ns); \
                 the device alone {:.1} ns per answer",
                r.round_trips_per_wall_second(),
                1e9 / r.round_trips_per_wall_second().max(1e-9),
                alone.ns_per_answer()
            );
        });
        alone_runs.push(alone);
        Ok(r)
    })?;
    let alone = trials::Trials::new("bench sdo, the device alone", alone_runs)?;
    // The transfers are measured in bus time, the same in every run: once is enough.
    spinner.set_message("bench sdo: segmented and block downloads");
    let t = canopen::run_sdo_transfers(bulk)?;
    let (e, median) = (trials.best(), trials.median());
    let rt = e.round_trips_per_wall_second();
    let rt_ns = 1e9 / rt.max(1e-9);
    let alone_ns = alone.best().ns_per_answer();
    let ratio = rt_ns / alone_ns.max(1e-9);
    let median_ratio = 1e9
        / median.round_trips_per_wall_second().max(1e-9)
        / alone.median().ns_per_answer().max(1e-9);
    let table = format!(
        "| figure | {header} |\n|---|---|\n\
         | expedited upload round trips | {rounds} in {bus:.1} s of bus time |\n\
         | expedited: wall time | {wall} |\n\
         | **expedited round trips per wall second** | **{rt:.0}** (median {mrt:.0}; {v1} of 2 000 000) |\n\
         | wall ns per round trip through the virtual bus (2 frames) | {rt_ns:.0} |\n\
         | wall ns per answer, the device stack alone (same run) | {alone_ns:.1} (median {alone_median:.1}) |\n\
         | **round trip / device alone** (best trials) | **{ratio:.1}×** (medians {median_ratio:.1}×; {v0} of 6×) |\n\
         | machine load (1, 5, 15 min) at the start | {load} |\n\
         | expedited round trips per bus second | {per_bus:.0} |\n\
         | segmented download of {bulk} bytes | {seg_t:.3} s of bus time |\n\
         | **segmented: fraction of the request/response limit** | **{seg:.2} %** ({v2} of 95 %) |\n\
         | block download of {bulk} bytes | {blk_t:.3} s of bus time |\n\
         | **block: fraction of the bus limit** | **{blk:.2} %** ({v3} of 95 %) |",
        header = trials_header(n),
        rounds = e.round_trips,
        bus = e.bus_time.as_secs_f64(),
        wall = trials::best_median(
            e.wall_time.as_secs_f64(),
            median.wall_time.as_secs_f64(),
            3,
            " s"
        ),
        mrt = median.round_trips_per_wall_second(),
        v1 = verdict(rt, 2e6, true),
        v0 = verdict(ratio, 6.0, false),
        alone_median = alone.median().ns_per_answer(),
        per_bus = e.round_trips_per_bus_second(),
        bulk = t.bulk_bytes,
        seg_t = t.segmented_bus_time.as_secs_f64(),
        seg = t.segmented_fraction * 100.0,
        v2 = verdict(t.segmented_fraction, 0.95, true),
        blk_t = t.block_bus_time.as_secs_f64(),
        blk = t.block_fraction * 100.0,
        v3 = verdict(t.block_fraction, 0.95, true),
    );
    let intro = format!(
        "A CiA 301 `Device` (node 5) and a client on a 1 Mbit/s bus. Expedited: the client \
         reads 0x1000 again as soon as each answer arrives. Segmented: a 100 000-byte \
         download to a DOMAIN, limit = every segment request followed at once by its \
         response. Block: the same by block download (CRC on, the server's block size), limit \
         = the data segments back to back. Fractions are in simulated time (bits on the bus), \
         the same in every run, so the transfers run once. Expedited figures in wall time are \
         the best of {trials} of the same deterministic run, which is the code's own cost \
         on a shared machine; the median shows the spread. The baseline of the same run: the same \
         device, wrapped as on the bus, answering as many requests handed straight to its \
         `on_frame` (no bus, no client), each answer checked. Floors (judged on the best \
         trials): a round trip through the virtual bus ≤ 6× the device alone; ≥ 2 000 000 \
         round trips per wall second; ≥ 95 % for both transfers.",
        trials = trials_count(n),
    );
    record(
        args,
        "sdo",
        "SDO round trips and transfer efficiency",
        &intro,
        &table,
    )
}

/// `cantwin sim` starts per `cia301` scenario, and per twin scenario: fewer, so that the
/// eight twin scenarios keep the whole benchmark short.
const CIA301_STARTS: usize = 3;
const TWIN_STARTS: usize = 2;

/// What `bench memory` measured in `cantwin sim`.
struct SimRuns {
    /// One `cia301` device.
    one: process::SimProcessReport,
    /// The 127-device `cia301` scenario.
    full: process::SimProcessReport,
    /// Per twin kind: one twin, and as many as one bus takes.
    twins: Vec<(
        memory_twins::TwinFleet,
        process::SimProcessReport,
        process::SimProcessReport,
    )>,
}

fn measure_sims(dir: &std::path::Path, devices: u8) -> Result<SimRuns> {
    let exe = std::env::current_exe().context("locating the cantwin executable")?;
    eprintln!("  cantwin sim with 1 and {devices} devices, {CIA301_STARTS} starts each …");
    let cia301 = |n: u8| process::best_of(&exe, dir, &canopen::scenario_text(n), n, CIA301_STARTS);
    let one = cia301(1)?;
    let full = cia301(devices)?;
    let mut twins = Vec::new();
    for fleet in memory_twins::FLEETS {
        let n = fleet.devices;
        eprintln!(
            "  cantwin sim with 1 and {n}: {}, {TWIN_STARTS} starts each …",
            fleet.what
        );
        let twin = |count: u8| {
            process::best_of(&exe, dir, &fleet.scenario_text(count), count, TWIN_STARTS)
        };
        twins.push((*fleet, twin(1)?, twin(n)?));
    }
    Ok(SimRuns { one, full, twins })
}

/// KiB of resident memory each device after the first adds.
fn rss_per_further_device(
    one: &process::SimProcessReport,
    full: &process::SimProcessReport,
) -> f64 {
    full.rss_kib.saturating_sub(one.rss_kib) as f64
        / f64::from(full.devices.saturating_sub(1).max(1))
}

fn bench_memory(args: &Args) -> Result<()> {
    eprintln!("bench memory: devices and a 127-device scenario build …");
    let r = canopen::run_memory(127)?;
    let tm3_heap = memory_twins::tm3_device_heap()?;
    let ms = r.scenario_build.as_secs_f64() * 1e3;
    let dir = std::env::temp_dir().join(format!("cantwin-bench-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let runs = measure_sims(&dir, 127);
    let _ = std::fs::remove_dir_all(&dir);
    let SimRuns { one, full, twins } = runs?;
    let mib = |kib: u64| kib as f64 / 1024.0;
    let start_ms = full.startup.as_secs_f64() * 1e3;
    let mut table = format!(
        "| figure | value |\n|---|---|\n\
         | `Device` inline size | {inline} bytes |\n\
         | heap per device, CiA 301 defaults | {default} bytes |\n\
         | heap per device, 4 RPDOs + 4 TPDOs | {pdo} bytes |\n\
         | heap per `network` device (1 TPDO) | {net} bytes |\n\
         | heap of the CiA 301 `Device` in a TM3BCCO with 14 modules (its own description not counted) | {tm3_heap} bytes |\n\
         | parse and build a {n}-device `cia301` scenario, in process | {ms:.1} ms |\n\
         | **start-up of `cantwin sim` with {n} devices** (spawn → socketcand gateway listening, best of {CIA301_STARTS}) | **{start_ms:.1} ms** ({v} of < 100 ms) |\n\
         | start-up of `cantwin sim` with 1 device | {one_ms:.1} ms |\n\
         | **RSS of `cantwin sim` with {n} devices**, running paced with its gateway | **{rss:.1} MiB** (peak {peak:.1} MiB) |\n\
         | RSS of `cantwin sim` with 1 device | {one_rss:.1} MiB |\n\
         | RSS per further device ({n} − 1 devices) | {per:.1} KiB |",
        inline = r.device_inline,
        default = r.default_heap,
        pdo = r.pdo_4_4_heap,
        net = r.network_heap,
        n = r.scenario_devices,
        v = verdict(start_ms, 100.0, false),
        one_ms = one.startup.as_secs_f64() * 1e3,
        rss = mib(full.rss_kib),
        peak = mib(full.peak_kib),
        one_rss = mib(one.rss_kib),
        per = rss_per_further_device(&one, &full),
    );
    table.push_str(&format!(
        "\n\n| twin, N of them on one bus (best of {TWIN_STARTS}) | N | RSS with 1 | RSS with N | **RSS per further twin** | start-up with N |\n\
         |---|---|---|---|---|---|"
    ));
    for (fleet, one, full) in &twins {
        table.push_str(&format!(
            "\n| {what} | {n} | {one_rss:.1} MiB | {rss:.1} MiB | **{per:.1} KiB** | {start:.1} ms |",
            what = fleet.what,
            n = full.devices,
            one_rss = mib(one.rss_kib),
            rss = mib(full.rss_kib),
            per = rss_per_further_device(one, full),
            start = full.startup.as_secs_f64() * 1e3,
        ));
    }
    let intro = format!(
        "`Device::heap_bytes` of a device whose object dictionary description is shared \
         (the description itself is counted once per kind, not per device). The scenario has \
         127 devices of kind `cia301` (each with its 64 KiB DOMAIN, 4 RPDOs and 4 TPDOs, \
         heartbeat 100 ms) on one 1 Mbit/s bus; `cantwin sim` runs it as a child process \
         (`--socketcand 0`), its resident set read from `/proc/PID/status` after 0.6 s of \
         paced running. Floor: start-up < 100 ms. The second table does the same for the \
         twins: N of one kind with node-IDs 1..N (the ADV200's DeviceNet MAC IDs stop at 63) \
         and a listener on one 500 kbit/s bus, set up as `scenarios/tm3-island.toml` and \
         `scenarios/adv200-*.toml` set them up, against 1 of them with the listener; RSS per \
         further twin = (RSS with N − RSS with 1) / (N − 1), best of {TWIN_STARTS} starts \
         rather than {CIA301_STARTS} to keep the whole benchmark short. Each TM3BCCO carries \
         14 modules: {modules}.",
        modules = memory_twins::TM3_MODULES.join(", "),
    );
    record(
        args,
        "memory",
        "bytes per device and start-up time",
        &intro,
        &table,
    )
}

fn bench_twin(args: &Args, name: &str) -> Result<()> {
    let duration = seconds(args, 20.0);
    let what = twins::TWINS
        .iter()
        .find(|(n, _)| *n == name)
        .map_or("", |(_, w)| *w);
    eprintln!("bench {name}: {duration} of bus time, then the bare CiA 301 devices …");
    let r = twins::best_of(name, duration, args.trials)?;
    let us = |run: &twins::TwinRun| run.ns_per_sim_second() / 1e3;
    let ratio = r.twin.ns_per_sim_second() / r.baseline.ns_per_sim_second().max(1.0);
    let table = format!(
        "| figure | value |\n|---|---|\n\
         | bus time measured | {bus:.1} s |\n\
         | frames on the bus per simulated second, twin | {frames:.0} |\n\
         | **CPU per simulated second, twin** (bus, twin and master) | **{twin:.0} µs** ({rt:.0}× real time) |\n\
         | CPU per simulated second, bare CiA 301 devices (same run) | {base:.1} µs ({base_frames:.0} frames/s) |\n\
         | **twin / bare devices** | **{ratio:.1}**{floor} |{reference}",
        bus = duration.as_secs_f64(),
        frames = r.twin.frames_per_sim_second(),
        twin = us(&r.twin),
        rt = 1e9 / r.twin.ns_per_sim_second().max(1.0),
        base = us(&r.baseline),
        base_frames = r.baseline.frames_per_sim_second(),
        floor = match r.floor {
            Some(f) if ratio <= f => format!(" (floor ≤ {f}: met)"),
            Some(f) => format!(" (floor ≤ {f}: **not met**)"),
            None => String::new(),
        },
        reference = match &r.reference {
            Some((run, _)) => format!(
                "\n| CPU per simulated second, second baseline (same run) | {:.1} µs ({:.0} frames/s) |\n\
                 | twin / second baseline | {:.1} |",
                us(run),
                run.frames_per_sim_second(),
                r.twin.ns_per_sim_second() / run.ns_per_sim_second().max(1.0),
            ),
            None => String::new(),
        },
    );
    let intro = format!(
        "{what}. Measured after start-up and configuration, in chunks of {chunk} of bus \
         time, best of {trials} trials (twin and baselines in turn in each): the median chunk's wall time per simulated second (chunks in which the thread \
         lost its core to other processes drop out, so it is the CPU time of one core). \
         Baseline in the same run: {baseline}.{second}",
        chunk = twins::CHUNK,
        trials = args.trials.max(1),
        baseline = r.baseline_what,
        second = r
            .reference
            .as_ref()
            .map_or(String::new(), |(_, what)| format!(
                " Second baseline: {what}."
            )),
    );
    record(args, name, "twin CPU per simulated second", &intro, &table)
}
