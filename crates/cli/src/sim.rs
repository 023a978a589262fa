//! `cantwin sim SCENARIO.toml`: run a scenario paced to the wall clock, with gateways for
//! external tools, until SIGINT (Ctrl-C), SIGTERM or SIGHUP, or `--duration`.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, bail};
use cantwin_bus::{PacedConfig, PacedSimulation};
use cantwin_gateway::paced::PacedBus;
use cantwin_gateway::{Limits, slcan, socketcand};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

use cantwin_capture::Format;

use crate::capture_tap::Captures;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scenario file (TOML).
    scenario: PathBuf,
    /// Serve every bus over the socketcand protocol on [ADDR:]PORT (ADDR defaults to
    /// 127.0.0.1; port 0 picks a free port). Channel names are the scenario's bus names.
    #[arg(long, value_name = "[ADDR:]PORT")]
    socketcand: Option<String>,
    /// Serve one bus as an slcan (Lawicel) adapter over TCP on [ADDR:]PORT, for tools that
    /// need remote frames (python-can `slcan` with `socket://ADDR:PORT`).
    #[arg(long, value_name = "[ADDR:]PORT")]
    slcan: Option<String>,
    /// The bus the slcan gateway serves (needed when the scenario has several).
    #[arg(long, value_name = "NAME")]
    slcan_bus: Option<String>,
    /// Serve a live dashboard (node table, frame stream, bus load, device values and
    /// charts, controls) for a web browser on [ADDR:]PORT (ADDR defaults to 127.0.0.1; port
    /// 0 picks a free port).
    #[arg(long, value_name = "[ADDR:]PORT")]
    web: Option<String>,
    /// Allow gateways to listen on addresses other than loopback. Anyone who can reach the
    /// address can then put frames on the simulated buses.
    #[arg(long)]
    allow_remote: bool,
    #[command(flatten)]
    web_options: crate::web::Options,
    /// Stop after this many seconds of wall time (default: run until Ctrl-C, SIGTERM or
    /// SIGHUP).
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
    /// Record every frame of every bus, with bus timestamps mapped to wall time, into a pcap
    /// file (one file per bus, `STEM-BUS.pcap`, when there are several) or a pcapng file (one
    /// interface per bus), by extension.
    #[arg(long, value_name = "FILE")]
    pcap: Option<PathBuf>,
    /// Record every frame of every bus into a can-utils candump log.
    #[arg(long, value_name = "FILE")]
    candump: Option<PathBuf>,
    /// Directory where devices keep what they store (CANopen 0x1010) between runs; without
    /// it they keep it in memory, across their power cycles, until the run ends.
    #[arg(long, value_name = "DIR")]
    state_dir: Option<PathBuf>,
    /// Run the scenario's script in virtual time instead, print each expectation's verdict
    /// and exit non-zero on a failure.
    #[arg(long, conflicts_with_all = ["socketcand", "slcan", "duration", "pcap", "candump", "web", "silkit"])]
    check: bool,
    /// Join a Vector SIL Kit simulation through the registry at REGISTRY_URI (e.g.
    /// silkit://127.0.0.1:8500): each bus is the SIL Kit CAN network of its name. Needs
    /// libSilKit.so (CANTWIN_SILKIT_LIB, CANTWIN_SILKIT_DIR or the library path).
    #[arg(long, value_name = "REGISTRY_URI")]
    silkit: Option<String>,
    /// The SIL Kit participant name [default: cantwin].
    #[arg(long, value_name = "NAME", requires = "silkit")]
    participant: Option<String>,
    /// Run synchronised with SIL Kit's virtual time, in steps of this many microseconds, as a
    /// coordinated participant (a system controller must list it); without it cantwin joins
    /// unsynchronised, paced to the wall clock.
    #[arg(long, value_name = "MICROSECONDS", requires = "silkit",
          conflicts_with_all = ["socketcand", "slcan", "pcap", "candump", "web"])]
    silkit_step: Option<u64>,
    /// Give up when the synchronised SIL Kit simulation has not started within this many
    /// seconds (a required participant that never joins keeps the system controller from
    /// starting it): an error naming who did not run, and a non-zero exit. Without it cantwin
    /// waits until Ctrl-C or SIGTERM, as SIL Kit participants do.
    #[arg(long, value_name = "SECONDS", requires = "silkit_step",
          value_parser = crate::silkit::parse_join_timeout)]
    silkit_join_timeout: Option<std::time::Duration>,
    /// A participant the system controller waits for, named in the --silkit-join-timeout
    /// error when it never joined or never ran (repeat for several; SIL Kit does not tell a
    /// participant whom the system controller requires).
    #[arg(long, value_name = "NAME", requires = "silkit_join_timeout")]
    silkit_expect: Vec<String>,
}

/// `[ADDR:]PORT` with ADDR defaulting to loopback.
fn parse_listen(spec: &str, flag: &str) -> Result<SocketAddr> {
    if let Ok(port) = spec.parse::<u16>() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
    }
    spec.parse::<SocketAddr>().with_context(|| {
        format!("{flag} {spec:?}: expected PORT or ADDR:PORT, e.g. 29536 or 127.0.0.1:29536")
    })
}

/// How often a running simulation's captures are flushed to their files.
const CAPTURE_FLUSH: WallDuration = WallDuration::from_millis(500);

pub fn run(args: &Args) -> Result<()> {
    if args.check {
        return crate::check::run(
            &args.scenario,
            &BuildEnv {
                state_dir: args.state_dir.clone(),
            },
        );
    }
    let scenario = Scenario::load(&args.scenario)?;
    if let Some(dir) = &args.state_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the state directory {}", dir.display()))?;
    }
    let env = BuildEnv {
        state_dir: args.state_dir.clone(),
    };
    let mut built = scenario.build(&Registry::builtin(), &env)?;
    for w in &built.warnings {
        eprintln!("cantwin sim: warning: {w}");
    }
    // SIGINT, SIGTERM and SIGHUP (ctrlc's termination feature) all end the run below, with
    // captures flushed and closed; installed before any capture exists, so that no signal
    // finds a capture it would leave cut short.
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    let silkit = args.silkit.as_ref().map(|uri| crate::silkit::SimOptions {
        registry_uri: uri.clone(),
        participant: args.participant.clone(),
        step_us: args.silkit_step,
        join_timeout: args.silkit_join_timeout,
        expect: args.silkit_expect.clone(),
    });
    if let Some(options) = silkit.as_ref().filter(|o| o.step_us.is_some()) {
        return crate::silkit::run_synchronized(options, built, stop, args.duration);
    }
    let mut captures = Captures::new();
    let pcap = args.pcap.as_ref().map(|p| {
        let ng = p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("pcapng"));
        (p, if ng { Format::Pcapng } else { Format::Pcap })
    });
    let candump = args.candump.as_ref().map(|p| (p, Format::Candump));
    for (path, format) in [pcap, candump].into_iter().flatten() {
        for file in captures.add(&mut built.sim, path, format)? {
            eprintln!("recording {}", file.display());
        }
    }
    // The file headers reach the files at once: a capture is readable from the start.
    captures.finish()?;
    let bus_names: Vec<String> = built.buses.iter().map(|(n, _)| n.clone()).collect();
    let slcan_bus = match (&args.slcan, &args.slcan_bus) {
        (None, Some(_)) => bail!("--slcan-bus needs --slcan"),
        (None, None) => None,
        (Some(_), Some(name)) => {
            if !bus_names.contains(name) {
                bail!(
                    "--slcan-bus {name:?}: no such bus in {} (buses: {})",
                    args.scenario.display(),
                    bus_names.join(", ")
                );
            }
            Some(name.clone())
        }
        (Some(_), None) if bus_names.len() == 1 => Some(bus_names[0].clone()),
        (Some(_), None) => bail!(
            "the scenario has several buses ({}): choose the one slcan serves with --slcan-bus NAME",
            bus_names.join(", ")
        ),
    };
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration must be a positive number of seconds, not {d}");
    }
    let limits = Limits {
        allow_remote: args.allow_remote,
        ..Limits::default()
    };

    let mut dashboard = args.web.as_ref().map(|_| {
        crate::web::Dashboard::attach(&mut built.sim, &scenario, &built.buses, &built.devices)
    });

    let paced = PacedSimulation::start(built.sim, PacedConfig::default());
    let handle = paced.handle();
    let connector = Arc::new(PacedBus::new(handle.clone()));
    let silkit_bridge = match &silkit {
        Some(options) => Some(crate::silkit::join_paced(options, &handle, &built.buses)?),
        None => None,
    };

    eprintln!(
        "cantwin sim: {} ({}, {}), paced to the wall clock",
        scenario.name,
        crate::report::count(bus_names.len() as u64, "bus", "buses"),
        crate::report::count(built.devices.len() as u64, "device", "devices")
    );
    for d in &built.devices {
        let bus = built
            .buses
            .iter()
            .find(|(_, id)| *id == d.port.bus())
            .map(|(n, _)| n.as_str())
            .unwrap_or("?");
        eprintln!("  {} ({}) on {bus}", d.name, d.kind);
    }
    let mut socketcand_server = None;
    if let Some(spec) = &args.socketcand {
        let addr = parse_listen(spec, "--socketcand")?;
        let server = socketcand::Server::bind(addr, connector.clone(), limits.clone())
            .with_context(|| format!("starting the socketcand gateway on {addr}"))?;
        for name in &bus_names {
            crate::output::gateway("socketcand", server.local_addr(), name)?;
        }
        socketcand_server = Some(server);
    }
    let mut slcan_server = None;
    if let (Some(spec), Some(bus)) = (&args.slcan, &slcan_bus) {
        let addr = parse_listen(spec, "--slcan")?;
        let server = slcan::Server::bind(addr, connector.clone(), bus, limits.clone())
            .with_context(|| format!("starting the slcan gateway on {addr}"))?;
        crate::output::gateway("slcan", server.local_addr(), bus)?;
        slcan_server = Some(server);
    }
    let mut web_server = None;
    if let (Some(spec), Some(d)) = (&args.web, &dashboard) {
        let addr = parse_listen(spec, "--web")?;
        let server = d.serve(addr, args.allow_remote, &args.web_options)?;
        let url = server.url().to_string();
        crate::output::result(
            format_args!("web {url}"),
            || serde_json::json!({ "web": url }),
        )?;
        web_server = Some(server);
    }
    use std::io::Write as _;
    std::io::stdout().flush().ok();

    let started = WallInstant::now();
    let deadline = args
        .duration
        .map(|d| started + WallDuration::from_secs_f64(d));
    let mut flushed = WallInstant::now();
    let mut capture_error = None;
    while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| WallInstant::now() < d) {
        if let Some(d) = dashboard.as_mut() {
            d.poll(&handle);
        }
        // Captures reach their files this often, whole records only (each writer writes a
        // record in one piece), so that a SIGKILL loses at most the last second.
        if flushed.elapsed() >= CAPTURE_FLUSH {
            flushed = WallInstant::now();
            if let Err(e) = captures.finish() {
                capture_error = Some(e);
                break;
            }
        }
        std::thread::sleep(WallDuration::from_millis(20));
    }

    if let Some(s) = web_server {
        s.shutdown();
    }
    if let Some(s) = socketcand_server {
        s.shutdown();
    }
    if let Some(s) = slcan_server {
        s.shutdown();
    }
    if let Some(bridge) = silkit_bridge {
        crate::silkit::leave_paced(bridge)?;
    }
    let slips = handle.slips();
    let sim = paced
        .stop()
        .context("the simulation thread stopped unexpectedly")?;
    if let Some(e) = capture_error {
        return Err(e);
    }
    captures.finish()?;
    eprintln!(
        "cantwin sim: stopped after {:.1} s ({} of bus time{})",
        started.elapsed().as_secs_f64(),
        sim.now(),
        if slips > 0 {
            format!(", fell behind the wall clock {slips} times")
        } else {
            String::new()
        }
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
