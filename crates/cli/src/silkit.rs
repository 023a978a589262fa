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
use cantwin_silkit::{BridgeConfig, Deadlines, PacedBridge, SilKit};

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
    /// `--silkit-join-timeout`: how long the synchronised simulation may take to start.
    pub join_timeout: Option<WallDuration>,
    /// `--silkit-expect`: the participants named when it did not start in time.
    pub expect: Vec<String>,
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

/// `--join-timeout` and `--silkit-join-timeout`: seconds, positive and finite.
pub fn parse_join_timeout(text: &str) -> Result<WallDuration, String> {
    let seconds: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a number of seconds"))?;
    if !seconds.is_finite() || seconds <= 0.0 {
        return Err(format!(
            "{text:?}: the join timeout must be a positive, finite number of seconds"
        ));
    }
    WallDuration::try_from_secs_f64(seconds)
        .map_err(|_| format!("{text:?}: too many seconds for a join timeout"))
}

/// The bounds of a coordinated run: at most `join` until it starts (naming `expect` when
/// it did not), no bound on how long it then runs.
fn deadlines(join: Option<WallDuration>, expect: &[String]) -> Deadlines {
    Deadlines {
        join,
        run: None,
        peers: expect.to_vec(),
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
/// simulation stops, `stop` is set (Ctrl-C, SIGTERM) or `duration` of wall time has passed;
/// an error when it has not started within `--silkit-join-timeout`.
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
    let outcome = cantwin_silkit::run_synchronized_within(
        &kit,
        built.sim,
        &built.buses,
        &config,
        Duration::from_micros(step_us),
        &stop,
        &deadlines(options.join_timeout, &options.expect),
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
    /// arbitration, exact frame times, ACK, error counters, error-passive and bus-off. Runs
    /// as a coordinated, synchronised participant until the SIL Kit simulation stops (or, with
    /// --join-timeout, fails when it has not started in time).
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
    /// Apply this scenario's bus-level `[[at]]` actions (drop, corrupt, clear_faults, send)
    /// to the simulated networks of their buses' names, at their times in SIL Kit's
    /// simulated time.
    #[arg(long, value_name = "SCENARIO.toml")]
    faults: Option<std::path::PathBuf>,
    /// Give up when the simulation has not started within this many seconds (a required
    /// participant that never joins keeps the system controller from starting it): an error
    /// naming who did not run, and a non-zero exit. Without it the simulator waits until
    /// Ctrl-C or SIGTERM, as SIL Kit participants do.
    #[arg(long, value_name = "SECONDS", value_parser = parse_join_timeout)]
    join_timeout: Option<WallDuration>,
    /// A participant the system controller waits for, named in the --join-timeout error when
    /// it never joined or never ran (repeat for several; SIL Kit does not tell a participant
    /// whom the system controller requires).
    #[arg(long, value_name = "NAME", requires = "join_timeout")]
    expect: Vec<String>,
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
        &deadlines(args.join_timeout, &args.expect),
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
