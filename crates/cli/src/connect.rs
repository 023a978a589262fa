//! How client commands reach a bus: every one connects the same way, to a socketcand server
//! (`cantwin sim`'s or a real socketcand daemon in front of real hardware) or to a scenario
//! run in-process, and drives a sans-IO client node with the wall clock.

use std::net::{SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, bail};
use cantwin_bus::{PacedConfig, PacedSimulation, PortConfig};
use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_gateway::paced::PacedBus;
use cantwin_gateway::socketcand::Remote;
use cantwin_gateway::{BusConnector, BusPort};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

/// Where a client command's bus is.
#[derive(Debug, Clone, clap::Args)]
pub struct Target {
    /// A socketcand server to connect to, HOST:PORT: `cantwin sim --socketcand`, or a
    /// socketcand daemon in front of real CAN hardware.
    #[arg(
        long,
        value_name = "HOST:PORT",
        conflicts_with = "scenario",
        global = true
    )]
    pub socketcand: Option<String>,
    /// The bus (socketcand channel) to use: default the scenario's only bus, or can0.
    #[arg(long, value_name = "NAME", global = true)]
    pub bus: Option<String>,
    /// Run this scenario in-process, paced to the wall clock, and talk to its bus.
    #[arg(long, value_name = "FILE", global = true)]
    pub scenario: Option<PathBuf>,
}

/// An open attachment to a bus.
pub struct Link {
    port: Box<dyn BusPort>,
    // Keeps an in-process simulation running for as long as the link lives.
    _sim: Option<PacedSimulation>,
    start: WallInstant,
    out: Outbox,
}

fn resolve(spec: &str) -> Result<SocketAddr> {
    spec.to_socket_addrs()
        .with_context(|| format!("--socketcand {spec:?}: expected HOST:PORT"))?
        .next()
        .with_context(|| format!("--socketcand {spec:?}: the name resolves to no address"))
}

impl Link {
    /// Connect as `target` says.
    pub fn open(target: &Target) -> Result<Link> {
        let (port, sim): (Box<dyn BusPort>, Option<PacedSimulation>) =
            match (&target.socketcand, &target.scenario) {
                (Some(spec), _) => {
                    let addr = resolve(spec)?;
                    let bus = target.bus.clone().unwrap_or_else(|| "can0".into());
                    let remote = Remote {
                        addr,
                        timeout: WallDuration::from_secs(5),
                    };
                    let port = remote.open(&bus, 4096).with_context(|| {
                        format!("opening bus {bus:?} on the socketcand server {addr}")
                    })?;
                    (port, None)
                }
                (None, Some(file)) => {
                    let scenario = Scenario::load(file)?;
                    let bus = match &target.bus {
                        Some(b) => b.clone(),
                        None if scenario.buses.len() == 1 => scenario.buses[0].name.clone(),
                        None => bail!(
                            "{} has several buses ({}): choose one with --bus NAME",
                            file.display(),
                            scenario
                                .buses
                                .iter()
                                .map(|b| b.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    };
                    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
                    let paced = PacedSimulation::start(built.sim, PacedConfig::default());
                    // A block download puts up to 127 segments on the bus in one go (CiA 301
                    // §7.2.4.3.13): the transmit queue holds a whole block.
                    let port = PacedBus::new(paced.handle())
                        .with_port_config(PortConfig::DEFAULT.with_queue_depth(128))
                        .open(&bus, 4096)
                        .with_context(|| format!("opening bus {bus:?} of {}", file.display()))?;
                    (port, Some(paced))
                }
                (None, None) => bail!(
                    "say which bus to use: --socketcand HOST:PORT [--bus NAME], or --scenario FILE"
                ),
            };
        Ok(Link {
            port,
            _sim: sim,
            start: WallInstant::now(),
            out: Outbox::new(),
        })
    }

    /// The client's clock: time since the link opened.
    pub fn now(&self) -> Instant {
        Instant::from_nanos(u64::try_from(self.start.elapsed().as_nanos()).unwrap_or(u64::MAX))
    }

    /// Send a frame directly (for commands that need no client state machine).
    pub fn send(&self, frame: Frame) -> Result<()> {
        self.port.send(frame).context("sending a frame")
    }

    /// Drive `node` until `done` says so or `limit` of wall time passes; frames it queues
    /// go out through the port, frames the bus carries come in through its acceptance
    /// filter. Returns whether `done` became true.
    pub fn run<N: Node>(
        &mut self,
        node: &mut N,
        mut done: impl FnMut(&mut N) -> bool,
        limit: WallDuration,
    ) -> Result<bool> {
        let until = WallInstant::now() + limit;
        loop {
            self.flush(node)?;
            if done(node) {
                return Ok(true);
            }
            let wall = WallInstant::now();
            if wall >= until {
                return Ok(false);
            }
            let now = self.now();
            if let Some(deadline) = node.next_deadline()
                && deadline <= now
            {
                node.on_tick(now, &mut self.out);
                continue;
            }
            let mut wait = (until - wall).min(WallDuration::from_millis(50));
            if let Some(deadline) = node.next_deadline() {
                wait = wait.min(WallDuration::from_nanos((deadline - now).as_nanos()));
            }
            if let Some(rx) = self
                .port
                .recv_timeout(wait)
                .context("receiving from the bus")?
                && node.accepts(rx.frame.id())
            {
                let now = self.now();
                node.on_frame(&rx.frame, now, &mut self.out);
            }
        }
    }

    fn flush<N: Node>(&mut self, node: &mut N) -> Result<()> {
        while !self.out.is_empty() {
            let frames: Vec<Frame> = self.out.drain().collect();
            for f in frames {
                self.port.send(f).context("sending a frame")?;
                let now = self.now();
                node.on_sent(&f, now, &mut self.out);
            }
        }
        Ok(())
    }

    /// The next frame on the bus, waiting up to `wait` for it.
    pub fn recv(&mut self, wait: WallDuration) -> Result<Option<Frame>> {
        Ok(self
            .port
            .recv_timeout(wait)
            .context("receiving from the bus")?
            .map(|rx| rx.frame))
    }

    /// Receive frames for up to `limit` (or until Ctrl-C ends the process), handing each with
    /// its wall-clock time to `f` until it returns false.
    pub fn watch(
        &mut self,
        limit: Option<WallDuration>,
        mut f: impl FnMut(&Frame, std::time::SystemTime) -> bool,
    ) -> Result<()> {
        let until = limit.map(|l| WallInstant::now() + l);
        loop {
            let wait = match until {
                Some(u) => {
                    let now = WallInstant::now();
                    if now >= u {
                        return Ok(());
                    }
                    (u - now).min(WallDuration::from_millis(100))
                }
                None => WallDuration::from_millis(100),
            };
            if let Some(rx) = self
                .port
                .recv_timeout(wait)
                .context("receiving from the bus")?
                && !f(&rx.frame, rx.timestamp)
            {
                return Ok(());
            }
        }
    }
}
