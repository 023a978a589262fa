//! `cantwin monitor`: a live view of a CANopen bus in the terminal. The model is
//! `cantwin_monitor::NetworkView`; this module reads the bus and the keyboard and draws
//! [`crate::monitor_ui`] on the terminal.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, bail};
use cantwin_bus::Simulation;
use cantwin_can::{BitRate, Duration};
use cantwin_canopen::od::{ObjectDictionary, Value};
use cantwin_monitor::{Config, DeviceKind, NetworkView};
use cantwin_scenario::{BuildEnv, Built, BuiltDevice, Registry, Scenario};
use ratatui::crossterm::event::{self, Event, KeyEventKind};

use crate::connect::{Link, Target};
use crate::monitor_ui::{Flow, Ui, draw};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    target: Target,
    /// Name the nodes after the devices of this scenario file (when attached with
    /// --socketcand to `cantwin sim FILE`); --scenario does it by itself.
    #[arg(long, value_name = "FILE", conflicts_with = "scenario")]
    names: Option<PathBuf>,
    /// The bus bit rate for the load: default the scenario bus's, else 500k (as `cantwin
    /// report` assumes; the load panel then says "assumed").
    #[arg(long, value_name = "RATE")]
    bit_rate: Option<BitRate>,
    /// Width of a bus load window, in milliseconds.
    #[arg(long, default_value_t = 100, value_name = "MS")]
    window_ms: u64,
    /// Decoded frames kept for scrolling.
    #[arg(long, default_value_t = 10_000, value_name = "FRAMES")]
    keep: usize,
    /// Name PDO values from a node's EDS or DCF in the frame stream: NODE=FILE (repeatable).
    #[arg(long = "eds", value_name = "NODE=FILE")]
    eds: Vec<String>,
}

/// A node a scenario places on the bus: its node-ID, device name and kind.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Declared {
    /// The node-ID.
    pub node: u8,
    /// The scenario's device name.
    pub name: String,
    /// Its kind, if the monitor knows how its PDOs read.
    pub kind: Option<DeviceKind>,
    /// Its device type (0x1000) at power-up, which names its profile.
    pub device_type: Option<u32>,
}

fn od_device_type(od: &ObjectDictionary) -> Option<u32> {
    match od.get(0x1000, 0) {
        Ok(Value::Unsigned32(v)) => Some(v),
        _ => None,
    }
}

fn od_identity(od: &ObjectDictionary) -> Option<DeviceKind> {
    let device_type = od_device_type(od);
    let name = match od.get(0x1008, 0) {
        Ok(Value::VisibleString(s)) => Some(s),
        _ => None,
    };
    DeviceKind::identify(device_type, name.as_deref())
}

/// The CANopen nodes of a built scenario, in file order: the twins' node-IDs and kinds as
/// they are at power-up (DeviceNet and CAL devices, generators and masters have none).
pub fn declared_nodes(built: &Built) -> Vec<Declared> {
    built
        .devices
        .iter()
        .filter_map(|d| {
            let (node, kind) = declared_kind(&built.sim, d)?;
            let device_type = built
                .sim
                .twin(d.port)
                .and_then(|t| t.dictionary())
                .and_then(od_device_type);
            Some(Declared {
                node,
                name: d.name.clone(),
                kind,
                device_type,
            })
        })
        .collect()
}

/// The node-ID of a CANopen twin and the monitor kind its PDOs read as, from the twin
/// itself (so an ADV200 reads as its active personality), or `None` for a device that is
/// not a CANopen node.
pub fn declared_kind(sim: &Simulation, d: &BuiltDevice) -> Option<(u8, Option<DeviceKind>)> {
    let twin = sim.twin(d.port)?;
    // An ADV200 names its active personality in its dictionary: the CiA 402 one has
    // profile 402 in 0x1000.
    let od = twin.dictionary()?;
    Some((twin.canopen_node_id()?, od_identity(od)))
}

/// The dictionary of the CANopen twin on `port`.
fn generic_od(built: &Built, port: cantwin_bus::PortId) -> Option<&ObjectDictionary> {
    built.sim.twin(port)?.dictionary()
}

/// The bus a scenario file's command means: `--bus`, else its only bus.
fn scenario_bus<'a>(
    scenario: &'a Scenario,
    bus: Option<&str>,
) -> Result<&'a cantwin_scenario::BusSpec> {
    match bus {
        Some(name) => scenario
            .bus(name)
            .with_context(|| format!("{} has no bus {name:?}", scenario.file.display())),
        None if scenario.buses.len() == 1 => Ok(&scenario.buses[0]),
        None => bail!(
            "{} has several buses: choose one with --bus NAME",
            scenario.file.display()
        ),
    }
}

/// A view configured for `scenario`'s bus `bus`, with its CANopen nodes declared and the
/// PDOs of its generic twins named from their dictionaries (`--eds` files in `eds` win).
pub fn view_for_scenario(
    scenario: &Scenario,
    bus: Option<&str>,
    mut config: Config,
    bit_rate: Option<BitRate>,
    eds: &[String],
) -> Result<(NetworkView, Built)> {
    let spec = scenario_bus(scenario, bus)?;
    config.bit_rate = bit_rate.unwrap_or(spec.bit_rate);
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let bus_id = built.bus(&spec.name);
    let declared: Vec<(Declared, cantwin_bus::PortId)> = declared_nodes(&built)
        .into_iter()
        .filter_map(|d| {
            let port = built.device(&d.name)?.port;
            (Some(port.bus()) == bus_id).then_some((d, port))
        })
        .collect();
    // Twins of no known kind: their dictionaries at power-up name their PDO values.
    for (d, port) in &declared {
        if d.kind.is_none()
            && let Some(od) = generic_od(&built, *port)
        {
            cantwin_report::canopen::add_od_pdos(&mut config.pdos, od);
        }
    }
    crate::canopen::add_eds_pdos(&mut config.pdos, eds)?;
    let mut view = NetworkView::new(config);
    for (d, _) in declared {
        view.declare(d.node, Some(d.name), d.kind);
        if let Some(t) = d.device_type {
            view.declare_device_type(d.node, t);
        }
    }
    Ok((view, built))
}

/// Feed `view` the frames `link` receives for `budget` of wall time, each at the link's
/// clock when it arrived, then let the view's time catch up with the clock.
pub fn pump(link: &mut Link, view: &mut NetworkView, budget: WallDuration) -> Result<()> {
    let until = WallInstant::now() + budget;
    loop {
        let left = until.saturating_duration_since(WallInstant::now());
        match link.recv(left)? {
            Some(frame) => view.push(link.now(), &frame),
            None => break,
        }
        if left.is_zero() {
            break;
        }
    }
    view.advance(link.now());
    Ok(())
}

/// Restores the terminal however the monitor ends: return, error or panic (ratatui's
/// `init` installs the panic hook, this guard covers the rest).
struct TerminalGuard;

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

pub fn run(args: &Args) -> Result<()> {
    if !std::io::stdout().is_terminal() {
        bail!(
            "cantwin monitor draws on a terminal: run it with standard output on one (use `cantwin trace` for a pipe)"
        );
    }
    let mut config = Config {
        bit_rate: args.bit_rate.unwrap_or(cantwin_report::DEFAULT_BIT_RATE),
        window: Duration::from_millis(args.window_ms.max(1)),
        ring: args.keep.max(1),
        ..Config::default()
    };
    let bus = args.target.bus.as_deref();
    let names = args.target.scenario.as_ref().or(args.names.as_ref());
    let mut view = match names {
        Some(file) => {
            let scenario = Scenario::load(file)?;
            view_for_scenario(&scenario, bus, config, args.bit_rate, &args.eds)?.0
        }
        None => {
            crate::canopen::add_eds_pdos(&mut config.pdos, &args.eds)?;
            NetworkView::new(config)
        }
    };
    let source = match (&args.target.socketcand, &args.target.scenario) {
        (Some(addr), _) => format!("socketcand {addr} {}", bus.unwrap_or("can0")),
        (None, Some(file)) => format!("scenario {}", file.display()),
        (None, None) => String::new(),
    };
    // Connect before taking over the terminal, so that errors print as usual.
    let mut link = Link::open(&args.target)?;
    let mut ui = Ui::new(source);
    ui.bit_rate_assumed = args.bit_rate.is_none() && names.is_none();
    let mut terminal = ratatui::init();
    let _guard = TerminalGuard;
    let mut last_draw: Option<WallInstant> = None;
    loop {
        // Frames for up to 20 ms, then the keyboard, then (at most 10 times a second) the
        // screen: a busy bus must not starve the keys or the other way round.
        pump(&mut link, &mut view, WallDuration::from_millis(20))?;
        let mut pressed = false;
        while event::poll(WallDuration::ZERO).context("reading the keyboard")? {
            if let Event::Key(key) = event::read().context("reading the keyboard")?
                && key.kind == KeyEventKind::Press
            {
                if ui.on_key(key, &view) == Flow::Quit {
                    return Ok(());
                }
                pressed = true;
            }
        }
        // A key shows at once; otherwise ten frames a second are plenty for a person.
        if pressed || last_draw.is_none_or(|t| t.elapsed() >= WallDuration::from_millis(100)) {
            terminal
                .draw(|f| draw(f, &view, &ui))
                .context("drawing on the terminal")?;
            last_draw = Some(WallInstant::now());
        }
    }
}

#[cfg(test)]
mod tests {
    use cantwin_canopen::wire::NmtState;

    use super::*;

    #[test]
    fn pump_feeds_a_paced_scenario_into_the_view() {
        let file = PathBuf::from(format!(
            "{}/../../scenarios/monitor-network.toml",
            env!("CARGO_MANIFEST_DIR")
        ));
        let scenario = Scenario::load(&file).unwrap();
        let (mut view, _) =
            view_for_scenario(&scenario, None, Config::default(), None, &[]).unwrap();
        let target = Target {
            socketcand: None,
            bus: None,
            scenario: Some(file),
        };
        let mut link = Link::open(&target).unwrap();
        // The scenario starts the nodes at 300 ms and commands the drive from 350 ms of its
        // paced time; a loaded machine gets a few seconds.
        let ready = |v: &NetworkView| {
            v.node(5).and_then(|n| n.nmt()) == Some(NmtState::Operational)
                && v.node(12).and_then(|n| n.value("ramp ref 1")).is_some()
        };
        let start = WallInstant::now();
        while !ready(&view) && start.elapsed() < WallDuration::from_secs(10) {
            pump(&mut link, &mut view, WallDuration::from_millis(50)).unwrap();
        }
        assert!(ready(&view), "{:?}", view.nodes().collect::<Vec<_>>());
        assert_eq!(
            view.node(12).unwrap().value("ramp ref 1").unwrap().text,
            "1500 rpm"
        );
        assert!(view.total_frames() > 0);
        assert!(view.now() > cantwin_can::Instant::ZERO);
        assert!(view.load().windows().map(|w| w.frames).sum::<u64>() > 0);
    }
}
