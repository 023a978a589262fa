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

fn load() -> Result<SilKit> {
    SilKit::load().context("--silkit needs Vector SIL Kit")
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
    let kit = load()?;
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
    let kit = load()?;
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
