//! Vector SIL Kit for `cantwin sim --silkit`: the scenario's twins join a SIL Kit
//! co-simulation, each bus as the SIL Kit CAN network of its name (the engine is
//! `cantwin_silkit::bridge`; this module only wires it to the command line).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, bail};
use cantwin_bus::{BusId, SimHandle};
use cantwin_can::Duration;
use cantwin_scenario::Built;
use cantwin_silkit::bridge::QUIET_CONFIGURATION;
use cantwin_silkit::{BridgeConfig, PacedBridge, SilKit};

/// The participant name when `--participant` is not given.
pub const DEFAULT_PARTICIPANT: &str = "cantwin";

/// What `cantwin sim` was asked for.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// `--silkit`.
    pub registry_uri: String,
    /// `--participant`.
    pub participant: Option<String>,
    /// `--silkit-step` in microseconds: synchronised when given.
    pub step_us: Option<u64>,
}

impl SimOptions {
    fn config(&self) -> BridgeConfig {
        BridgeConfig {
            registry_uri: self.registry_uri.clone(),
            participant: self
                .participant
                .clone()
                .unwrap_or_else(|| DEFAULT_PARTICIPANT.to_string()),
            configuration: QUIET_CONFIGURATION.to_string(),
        }
    }
}

fn load(what: &str) -> Result<SilKit> {
    SilKit::load().with_context(|| format!("{what} needs Vector SIL Kit"))
}

fn announce(options: &SimOptions, mode: &str, buses: &[(String, BusId)]) -> Result<()> {
    let config = options.config();
    let names: Vec<&str> = buses.iter().map(|(n, _)| n.as_str()).collect();
    crate::output::result(
        format_args!(
            "silkit {} at {} ({mode}), networks {}",
            config.participant,
            config.registry_uri,
            names.join(", ")
        ),
        || {
            serde_json::json!({
                "silkit": {
                    "participant": config.participant,
                    "registry": config.registry_uri,
                    "mode": mode,
                    "networks": names,
                }
            })
        },
    )?;
    Ok(())
}

/// Join SIL Kit unsynchronised, beside a simulation paced to the wall clock.
pub fn join_paced(
    options: &SimOptions,
    handle: &SimHandle,
    buses: &[(String, BusId)],
) -> Result<PacedBridge> {
    let kit = load("cantwin sim --silkit")?;
    let bridge = PacedBridge::start(&kit, handle, buses, &options.config()).with_context(|| {
        format!(
            "joining the SIL Kit simulation at {} as {}",
            options.registry_uri,
            options.config().participant
        )
    })?;
    announce(options, "unsynchronised, paced to the wall clock", buses)?;
    Ok(bridge)
}

/// Leave the SIL Kit simulation joined by [`join_paced`], and report its counters.
pub fn leave_paced(bridge: PacedBridge) -> Result<()> {
    let c = bridge.stop().context("leaving the SIL Kit simulation")?;
    eprintln!(
        "  SIL Kit: {} frames in, {} frames out, {} refused",
        c.frames_in, c.frames_out, c.frames_refused
    );
    Ok(())
}

/// Run the scenario as a coordinated, synchronised SIL Kit participant until the SIL Kit
/// simulation stops, `stop` is set (Ctrl-C, SIGTERM) or `duration` of wall time has passed.
pub fn run_synchronized(
    options: &SimOptions,
    built: Built,
    stop: Arc<AtomicBool>,
    duration: Option<f64>,
) -> Result<()> {
    let Some(step_us) = options.step_us else {
        bail!("synchronised SIL Kit mode needs --silkit-step");
    };
    if step_us == 0 {
        bail!("--silkit-step must be at least 1 microsecond");
    }
    let kit = load("cantwin sim --silkit")?;
    let config = options.config();
    announce(
        options,
        &format!("synchronised, steps of {step_us} µs"),
        &built.buses,
    )?;
    if let Some(d) = duration {
        let stop = Arc::clone(&stop);
        let until = WallInstant::now() + WallDuration::from_secs_f64(d);
        std::thread::spawn(move || {
            while WallInstant::now() < until && !stop.load(Ordering::SeqCst) {
                std::thread::sleep(WallDuration::from_millis(20));
            }
            stop.store(true, Ordering::SeqCst);
        });
    }
    let started = WallInstant::now();
    let outcome = cantwin_silkit::run_synchronized(
        &kit,
        built.sim,
        &built.buses,
        &config,
        Duration::from_micros(step_us),
        &stop,
    )
    .with_context(|| {
        format!(
            "running as SIL Kit participant {} at {}",
            config.participant, config.registry_uri
        )
    })?;
    for name in &outcome.left {
        eprintln!(
            "cantwin sim: SIL Kit participant {name} left mid-run; the simulation was stopped"
        );
    }
    let sim = outcome.sim;
    let c = outcome.counters;
    eprintln!(
        "cantwin sim: SIL Kit simulation ended ({:?}) after {:.1} s: {} of virtual time in {} steps",
        outcome.final_state,
        started.elapsed().as_secs_f64(),
        sim.now(),
        c.steps
    );
    eprintln!(
        "  SIL Kit: {} frames in, {} frames out, {} refused",
        c.frames_in, c.frames_out, c.frames_refused
    );
    for bus in sim.buses() {
        let s = bus.stats();
        eprintln!(
            "  {}: {} frames, {} error frames, bus load {:.1} %",
            bus.name(),
            s.frames(),
            s.error_frames(),
            s.load_percent(sim.now())
        );
    }
    Ok(())
}

/// `cantwin silkit …`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: SilkitCommand,
}

#[derive(Debug, clap::Subcommand)]
enum SilkitCommand {
    /// Be SIL Kit's network simulator for CAN networks (SIL Kit's experimental network
    /// simulator API): every controller on them sends through cantwin's bus model, with
    /// arbitration, exact frame times, ACK, error counters and error states. Runs as a
    /// coordinated, synchronised participant until the SIL Kit simulation stops.
    Netsim(NetsimArgs),
}

#[derive(Debug, clap::Args)]
struct NetsimArgs {
    /// The registry, e.g. silkit://127.0.0.1:8500.
    #[arg(long, value_name = "URI")]
    registry: String,
    /// A CAN network to simulate (repeat for several).
    #[arg(long = "network", value_name = "NAME", required = true)]
    networks: Vec<String>,
    /// The participant name (list it in the system controller's required participants).
    #[arg(long, value_name = "NAME", default_value = "cantwin-netsim")]
    participant: String,
    /// The bit rate of every simulated bus (10k … 1M).
    #[arg(long, default_value = "500k")]
    bit_rate: cantwin_can::BitRate,
    /// The simulator's step in microseconds.
    #[arg(long, value_name = "MICROSECONDS", default_value_t = 1000)]
    step: u64,
    /// Each controller's transmit queue depth.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..=4096))]
    queue_depth: u64,
    /// Apply this scenario's bus-level `[[at]]` actions (drop, corrupt, clear_faults) to the
    /// simulated networks of their buses' names, at their times in SIL Kit's simulated time.
    #[arg(long, value_name = "SCENARIO.toml")]
    faults: Option<std::path::PathBuf>,
}

/// Run `cantwin silkit …`.
pub fn run(args: &Args) -> Result<()> {
    match &args.command {
        SilkitCommand::Netsim(a) => netsim(a),
    }
}

fn netsim(args: &NetsimArgs) -> Result<()> {
    if args.step == 0 {
        bail!("--step must be at least 1 microsecond");
    }
    // Before joining: a fault the simulator cannot apply is an error of the command line.
    let faults = match &args.faults {
        Some(path) => {
            let scenario = cantwin_scenario::Scenario::load(path)
                .with_context(|| format!("--faults {}", path.display()))?;
            let faults = cantwin_silkit::faults_from_scenario(&scenario, &args.networks)
                .map_err(anyhow::Error::msg)
                .with_context(|| format!("--faults {}", path.display()))?;
            cantwin_silkit::NetsimFaults {
                seed: scenario.seed,
                faults,
            }
        }
        None => cantwin_silkit::NetsimFaults::default(),
    };
    let kit = load("cantwin silkit netsim")?;
    if !kit.has_network_simulator() {
        bail!(
            "{} (SIL Kit {}) has no network simulator API (SIL Kit 4.0.50 or later has it)",
            kit.path().display(),
            kit.version().unwrap_or_default()
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    let bridge = BridgeConfig {
        registry_uri: args.registry.clone(),
        participant: args.participant.clone(),
        configuration: QUIET_CONFIGURATION.to_string(),
    };
    let config = cantwin_silkit::NetsimConfig {
        bit_rate: args.bit_rate,
        step: Duration::from_micros(args.step),
        queue_depth: args.queue_depth as usize,
    };
    crate::output::result(
        format_args!(
            "silkit netsim {} at {} for {} ({}, steps of {} µs; experimental SIL Kit API)",
            args.participant,
            args.registry,
            args.networks.join(", "),
            args.bit_rate,
            args.step
        ),
        || {
            serde_json::json!({
                "silkit_netsim": {
                    "participant": args.participant,
                    "registry": args.registry,
                    "networks": args.networks,
                    "step_us": args.step,
                    "faults": faults.faults.len(),
                }
            })
        },
    )?;
    let started = WallInstant::now();
    let out = cantwin_silkit::run_network_simulator_with_faults(
        &kit,
        &bridge,
        &args.networks,
        config,
        &faults,
        &stop,
        &cantwin_silkit::Deadlines::default(),
    )
    .with_context(|| {
        format!(
            "simulating {} at {}",
            args.networks.join(", "),
            args.registry
        )
    })?;
    for name in &out.left {
        eprintln!(
            "cantwin silkit netsim: participant {name} left mid-run; the simulation was stopped"
        );
    }
    eprintln!(
        "cantwin silkit netsim: SIL Kit simulation ended ({:?}) after {:.1} s",
        out.final_state,
        started.elapsed().as_secs_f64()
    );
    for net in &out.networks {
        let c = net.counters();
        let load = net.with_simulation(|sim, bus| {
            sim.bus(bus)
                .map(|b| (b.stats().error_frames(), b.stats().load_percent(sim.now())))
        });
        let (errors, load) = load.unwrap_or((0, 0.0));
        eprintln!(
            "  {}: {} frames, {} error frames, bus load {load:.1} %, {} requests refused, {} queue full",
            net.name(),
            c.frames,
            errors,
            c.refused,
            c.queue_full
        );
        for (at, fault) in net.applied_faults() {
            eprintln!("    at {at} s: {fault}");
        }
    }
    Ok(())
}

/// Steps of 1 ms each participant sends a frame in, per measurement.
const BENCH_STEPS: u64 = 2000;

/// One configuration's trials: the best trial's figures (the floors are judged on them)
/// and the median ones, each figure's best and median taken over the trials separately.
#[derive(Debug, Clone, Copy)]
struct BenchFigures {
    frames_per_second: (f64, f64),
    latency_us: (f64, f64),
    step_us: (f64, f64),
    latency_steps: (f64, f64),
}

impl BenchFigures {
    /// The figures of `trials` (never empty): the highest frames/s and the lowest times are
    /// the best, the trial least disturbed by other processes' load.
    fn of(trials: &[cantwin_silkit::bench::BenchReport]) -> BenchFigures {
        let figure = |f: &dyn Fn(&cantwin_silkit::bench::BenchReport) -> f64, higher: bool| {
            let mut v: Vec<f64> = trials.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            let best = if higher { v[v.len() - 1] } else { v[0] };
            (best, median(&v))
        };
        BenchFigures {
            frames_per_second: figure(&|r| r.frames_per_second, true),
            latency_us: figure(&|r| r.latency_us, false),
            step_us: figure(&|r| r.step_us(), false),
            latency_steps: figure(&|r| r.latency_steps(), false),
        }
    }
}

/// The median of sorted, non-empty `v` (of an even count, the mean of the middle two).
fn median(v: &[f64]) -> f64 {
    let n = v.len();
    (v[(n - 1) / 2] + v[n / 2]) / 2.0
}

/// `best (median m)`, with `decimals` decimals and `unit`.
fn best_median((best, median): (f64, f64), decimals: usize, unit: &str) -> String {
    format!("{best:.decimals$}{unit} (median {median:.decimals$}{unit})")
}

/// `cantwin bench silkit`: frames per second and latency through cantwin as network
/// simulator with 2 and 8 participants, each against SIL Kit without a network simulator in
/// the same run, best of `trials` trials of each (the two in turn in every trial, so that a
/// burst of load disturbs one trial of each rather than every trial of one); with `write`,
/// recorded in `file`. When it was not named and SIL Kit is not there, it is skipped with the
/// reason.
pub fn bench(write: bool, file: &std::path::Path, named: bool, trials: usize) -> Result<()> {
    let kit = match SilKit::load() {
        Ok(kit) => kit,
        Err(e) if !named => {
            eprintln!("bench silkit: skipped: {e}");
            return Ok(());
        }
        Err(e) => return Err(e).context("bench silkit needs Vector SIL Kit"),
    };
    let registry_exe = std::env::var_os("CANTWIN_SILKIT_REGISTRY")
        .map(std::path::PathBuf::from)
        .or_else(|| kit.path().parent().map(|d| d.join("sil-kit-registry")))
        .filter(|p| p.exists())
        .context(
            "bench silkit needs sil-kit-registry beside libSilKit.so or named by CANTWIN_SILKIT_REGISTRY",
        )?;
    let trials = trials.max(1);
    let load_before = crate::bench::load_average();
    let mut rows = Vec::new();
    for participants in [2usize, 8] {
        let mut runs: [Vec<cantwin_silkit::bench::BenchReport>; 2] = [Vec::new(), Vec::new()];
        for trial in 1..=trials {
            for (k, netsim) in [false, true].into_iter().enumerate() {
                let registry = BenchRegistry::start(&registry_exe)?;
                let r = cantwin_silkit::bench::run(
                    &kit,
                    &registry.uri,
                    cantwin_silkit::bench::BenchConfig {
                        participants,
                        steps: BENCH_STEPS,
                        netsim,
                    },
                )
                .with_context(|| {
                    format!("bench silkit: {participants} participants, trial {trial}/{trials}")
                })?;
                let expected = participants as u64 * BENCH_STEPS;
                if r.frames != expected {
                    bail!(
                        "bench silkit: {} of {expected} frames acknowledged with {participants} participants{}, trial {trial}/{trials}",
                        r.frames,
                        if netsim { " through cantwin" } else { "" }
                    );
                }
                runs[k].push(r);
            }
        }
        rows.push((
            participants,
            BenchFigures::of(&runs[0]),
            BenchFigures::of(&runs[1]),
        ));
    }
    let load_after = crate::bench::load_average();
    let mut table = String::from(
        "| participants | SIL Kit alone: frames/s | through cantwin: frames/s | ratio (floor ≥ 0.5 at 8) | SIL Kit alone: latency | through cantwin: latency | ratio (floor ≤ 2 at 8) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for (n, alone, net) in &rows {
        table.push_str(&format!(
            "| {n} | {} | {} | {:.2} (medians {:.2}) | {} | {} | {:.2} (medians {:.2}) |\n",
            best_median(alone.frames_per_second, 0, ""),
            best_median(net.frames_per_second, 0, ""),
            net.frames_per_second.0 / alone.frames_per_second.0,
            net.frames_per_second.1 / alone.frames_per_second.1,
            best_median(alone.latency_us, 0, " µs"),
            best_median(net.latency_us, 0, " µs"),
            net.latency_us.0 / alone.latency_us.0,
            net.latency_us.1 / alone.latency_us.1,
        ));
    }
    let mut steps = String::from(
        "| participants | SIL Kit alone: wall time per step | through cantwin: wall time per step | SIL Kit alone: latency in steps | through cantwin: latency in steps |\n\
         |---|---|---|---|---|\n",
    );
    for (n, alone, net) in &rows {
        steps.push_str(&format!(
            "| {n} | {} | {} | {} | {} |\n",
            best_median(
                (alone.step_us.0 / 1000.0, alone.step_us.1 / 1000.0),
                2,
                " ms"
            ),
            best_median((net.step_us.0 / 1000.0, net.step_us.1 / 1000.0), 2, " ms"),
            best_median(alone.latency_steps, 2, ""),
            best_median(net.latency_steps, 2, ""),
        ));
    }
    let verdict = rows
        .iter()
        .find(|(n, _, _)| *n == 8)
        .map(|(_, alone, net)| {
            let fps = net.frames_per_second.0 / alone.frames_per_second.0;
            let lat = net.latency_us.0 / alone.latency_us.0;
            let met = |ok: bool| if ok { "met" } else { "not met" };
            format!(
                "Floors with 8 participants, best trials: frames/s {fps:.2}× SIL Kit alone \
                 (floor ≥ 0.5×: {}), latency {lat:.2}× (floor ≤ 2×: {}).",
                met(fps >= 0.5),
                met(lat <= 2.0)
            )
        })
        .unwrap_or_default();
    let load = format!("Load average (1, 5, 15 min) before: {load_before}; after: {load_after}.");
    // The latency floor in steps, for the record: what a step costs and how many a frame
    // waits, through cantwin and alone, with 8 participants (best trials).
    let in_steps = rows
        .iter()
        .find(|(n, _, _)| *n == 8)
        .map(|(_, alone, net)| {
            format!(
                "With 8 participants a step takes {:.2} ms of wall time through cantwin against \
                 {:.2} ms alone, and a frame arrives {:.1} steps after it was sent through cantwin \
                 against {:.1} alone: the latency ratio is about the product of the two ratios.",
                net.step_us.0 / 1000.0,
                alone.step_us.0 / 1000.0,
                net.latency_steps.0,
                alone.latency_steps.0
            )
        })
        .unwrap_or_default();
    if crate::output::json() {
        let pair = |(best, median): (f64, f64)| serde_json::json!({"best": best, "median": median});
        crate::output::emit(&serde_json::json!({
            "bench": "silkit",
            "trials": trials,
            "load_before": load_before,
            "load_after": load_after,
            "rows": rows.iter().map(|(n, a, b)| serde_json::json!({
                "participants": n,
                "alone_frames_per_second": pair(a.frames_per_second),
                "netsim_frames_per_second": pair(b.frames_per_second),
                "alone_latency_us": pair(a.latency_us),
                "netsim_latency_us": pair(b.latency_us),
                "alone_step_us": pair(a.step_us),
                "netsim_step_us": pair(b.step_us),
                "alone_latency_steps": pair(a.latency_steps),
                "netsim_latency_steps": pair(b.latency_steps),
            })).collect::<Vec<_>>(),
        }))?;
    } else {
        println!("{table}\n{steps}\n{verdict}\n{load}");
    }
    if write {
        let count = if trials == 1 {
            "1 trial".to_string()
        } else {
            format!("{trials} trials")
        };
        let body = format!(
            "## silkit — CAN frames through SIL Kit, with cantwin as network simulator\n\n\
             Best of {count} of each configuration (SIL Kit alone and through cantwin in turn \
             in every trial), the median in brackets; ratios of the best trials, of the medians \
             in brackets. The floors are judged on the best trials.\n\n\
             {table}\n{verdict}\n\n\
             The same runs in synchronisation steps: wall time per 1 ms step, and the latency \
             as that many steps' wall time.\n\n\
             {steps}\n\
             Each participant (a SIL Kit participant of its own, all in one process, on loopback) \
             sends one 5-byte frame in each of {BENCH_STEPS} synchronised 1 ms steps at 1 Mbit/s; \
             the first also measures, for every frame of the others, the wall time from \
             `SendFrame` to its reception. frames/s counts frames acknowledged `Transmitted` per \
             wall second. \"Through cantwin\" adds `cantwin silkit netsim` (steps of 1 ms) as the \
             network's simulator: arbitration, bit timing and ACK on cantwin's bus, one more \
             synchronised participant, and a frame reaches the others in the simulator's step \
             after it was sent. That step is what the latency measures: without a simulator a \
             frame goes straight from sender to receivers, within the step it was sent in, \
             through cantwin it waits until every participant has finished the step it was sent \
             in, since the simulator puts the frames of one step on the bus together to \
             arbitrate them by identifier, and each step takes longer with one more \
             participant to synchronise; the floor on latency would need the simulator to take \
             each request alone as it comes, in wall-clock order, which gives up arbitration \
             between participants and the reproducible frame times. {in_steps} {load} SIL Kit \
             {}; {}; {}.\n\n\
             Reproduce: `scripts/fetch-silkit.sh`, then \
             `CANTWIN_SILKIT_DIR=target/silkit/silkit-py-1.0.5 cargo run --release --bin cantwin -- bench silkit --write`.\n",
            kit.version().unwrap_or_default(),
            crate::benchmarks_md::machine_description(),
            crate::benchmarks_md::today()
        );
        crate::benchmarks_md::write_section(file, "silkit", &body)?;
    }
    Ok(())
}

/// A registry on 127.0.0.1 with a port the system picks, for the bench; killed when dropped.
struct BenchRegistry {
    uri: String,
    child: std::process::Child,
    dir: std::path::PathBuf,
}

impl BenchRegistry {
    fn start(exe: &std::path::Path) -> Result<BenchRegistry> {
        let dir = std::env::temp_dir().join(format!(
            "cantwin-bench-silkit-{}-{}",
            std::process::id(),
            WallInstant::now().elapsed().as_nanos()
        ));
        std::fs::create_dir_all(&dir).context("creating a temporary directory")?;
        let cfg = dir.join("registry.yaml");
        let child = std::process::Command::new(exe)
            .args(["-u", "silkit://127.0.0.1:0", "-g"])
            .arg(&cfg)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        let mut reg = BenchRegistry {
            uri: String::new(),
            child,
            dir,
        };
        // The registry writes the file, naming the port it listens on, once it listens.
        let until = WallInstant::now() + WallDuration::from_secs(20);
        loop {
            if let Ok(text) = std::fs::read_to_string(&cfg)
                && let Some(uri) = text
                    .lines()
                    .find_map(|l| l.trim().strip_prefix("RegistryUri:"))
            {
                reg.uri = uri.trim().trim_matches(['\'', '"']).to_string();
                return Ok(reg);
            }
            if WallInstant::now() >= until {
                bail!("{} did not start in 20 s", exe.display());
            }
            std::thread::sleep(WallDuration::from_millis(10));
        }
    }
}

impl Drop for BenchRegistry {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
