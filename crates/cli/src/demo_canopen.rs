//! `cantwin demo`, CANopen part: a generic CiA 301 device twin and cantwin's CANopen master on
//! a 500 kbit/s bus, in virtual time.

use anyhow::{Context, Result, bail};
use cantwin_bus::{BusEvent, BusId, PortConfig, PortId, Recorder, Simulation, TapId, TxOrder};
use cantwin_can::{Duration, Instant, Outbox};
use cantwin_canopen::master::pdo::PdoDecoder;
use cantwin_canopen::master::{Master, MasterEvent, Mode, SdoEvent};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;
use cantwin_scenario::{BuildEnv, Registry, Scenario};

use crate::canopen::{describe, emcy_meaning};

/// The embedded scenario: the device of `scenarios/cia301-device.toml`, without the listener
/// (the master acknowledges its frames).
const SCENARIO: &str = r#"
name = "demo: CiA 301"
seed = 301

[[bus]]
name = "canopen"
bit_rate = "500k"

[[device]]
name = "node5"
kind = "cia301"
bus = "canopen"
node_id = 5
heartbeat_ms = 100
device_name = "cantwin generic CiA 301 device"
vendor_id = 0x00000CA7
product_code = 301
domain_size = 65536
"#;

/// A simulation with cantwin's CANopen master on one bus, and helpers to drive it and print
/// what happens, shared by the demo's CANopen parts.
pub(crate) struct Net {
    pub(crate) sim: Simulation,
    pub(crate) bus: BusId,
    master: PortId,
    tap: TapId,
    shown: usize,
    /// Master events seen while waiting for something else, kept for the next `events()`.
    pending: Vec<(Instant, MasterEvent)>,
}

impl Net {
    /// Attach the master to `bus` of `sim` and record the bus.
    pub(crate) fn new(mut sim: Simulation, bus: BusId) -> Result<Net> {
        let tap = sim.bus_mut(bus).context("bus")?.add_tap(Recorder::new());
        let master = sim.attach(
            bus,
            Master::new(),
            PortConfig::default()
                .with_queue_depth(256)
                .with_order(TxOrder::Fifo),
        )?;
        Ok(Net {
            sim,
            bus,
            master,
            tap,
            shown: 0,
            pending: Vec::new(),
        })
    }

    /// Call the master with the current time; the frames it queues are transmitted.
    pub(crate) fn master<R>(
        &mut self,
        f: impl FnOnce(&mut Master, Instant, &mut Outbox) -> R,
    ) -> Result<R> {
        let now = self.sim.now();
        let mut out = Outbox::new();
        let m = self
            .sim
            .node_mut::<Master>(self.master)
            .context("the master")?;
        let r = f(m, now, &mut out);
        for frame in out.drain() {
            self.sim.transmit(self.master, frame)?;
        }
        Ok(r)
    }

    /// The master's port, for frames sent outside the master (RPDOs).
    pub(crate) fn master_port(&self) -> Option<PortId> {
        Some(self.master)
    }

    /// The master's events since the last call.
    pub(crate) fn events(&mut self) -> Result<Vec<(Instant, MasterEvent)>> {
        let m = self
            .sim
            .node_mut::<Master>(self.master)
            .context("the master")?;
        let mut all = std::mem::take(&mut self.pending);
        all.extend(std::iter::from_fn(|| m.poll_event()));
        Ok(all)
    }

    /// Print the frames since the last call, decoded, at most `limit` of them.
    pub(crate) fn frames(&mut self, limit: usize) -> Result<()> {
        self.frames_with(limit, |_| None)
    }

    /// Print the frames since the last call, decoded, at most `limit` of them, and the
    /// master's events `line` has a line for, all in bus time order (an event right after
    /// the frame that caused it); the other events stay for the next `events()`.
    pub(crate) fn frames_with(
        &mut self,
        limit: usize,
        mut line: impl FnMut(&MasterEvent) -> Option<String>,
    ) -> Result<()> {
        let mut printed: Vec<(Instant, u8, String)> = Vec::new();
        let mut kept = Vec::new();
        for (at, ev) in self.events()? {
            match line(&ev) {
                Some(text) => printed.push((at, 1, format!("  {:>12}  {text}", at.to_string()))),
                None => kept.push((at, ev)),
            }
        }
        self.pending = kept;
        let bus = self.sim.bus(self.bus).context("bus")?;
        let rec = bus.tap::<Recorder>(self.tap).context("recorder")?;
        let new: Vec<_> = rec.events[self.shown..]
            .iter()
            .filter_map(|e| match e {
                BusEvent::Frame(f) => Some(*f),
                _ => None,
            })
            .collect();
        self.shown = rec.events.len();
        let none = PdoDecoder::new();
        for f in new.iter().take(limit) {
            let text = format!(
                "  {:>12}  {:<22} {}",
                f.end.to_string(),
                f.frame.to_string(),
                describe(&f.frame, &none)
            );
            printed.push((f.end, 0, text));
        }
        // Stable: frames keep their bus order, an event follows the frame of its instant.
        printed.sort_by_key(|(at, kind, _)| (*at, *kind));
        for (_, _, text) in printed {
            println!("{text}");
        }
        if new.len() > limit {
            println!("  {:>12}  … {} more frames", "", new.len() - limit);
        }
        Ok(())
    }

    /// Run until the transfer ends; returns its data, or the abort in words.
    pub(crate) fn sdo(
        &mut self,
        give_up: Duration,
    ) -> Result<std::result::Result<Vec<u8>, String>> {
        let until = self.sim.now() + give_up;
        while self.sim.now() < until {
            let step = self.sim.now() + Duration::from_millis(1);
            self.sim.run_until(step);
            let mut outcome = None;
            for (at, ev) in self.events()? {
                match ev {
                    MasterEvent::Sdo {
                        event: SdoEvent::Completed { data, .. },
                        ..
                    } => outcome = Some(Ok(data)),
                    MasterEvent::Sdo {
                        event: SdoEvent::Aborted { code, .. },
                        ..
                    } => outcome = Some(Err(code.to_string())),
                    MasterEvent::Sdo { .. } => {}
                    other => self.pending.push((at, other)),
                }
            }
            if let Some(o) = outcome {
                return Ok(o);
            }
        }
        bail!("the transfer did not end within {give_up}")
    }
}

pub fn run() -> Result<()> {
    let scenario = Scenario::parse(SCENARIO, "demo (embedded)")?;
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let bus = built.bus("canopen").context("bus")?;
    let device = built.device("node5").context("device")?.port;
    let mut net = Net::new(built.sim, bus)?;
    let ms = |v: u64| Instant::ZERO + Duration::from_millis(v);

    println!("CANopen: a CiA 301 device twin (node 5) and cantwin's master on a 500 kbit/s bus.\n");
    println!("Power-up: the device sends its boot-up message and enters PRE-OPERATIONAL:");
    net.sim.run_until(ms(5));
    net.frames(5)?;

    println!(
        "\nThe master starts node 5 (NMT) and watches its heartbeat (100 ms, timeout 250 ms):"
    );
    net.master(|m, _, out| m.nmt(NmtCs::Start, 5, out))??;
    net.master(|m, _, _| m.watch_heartbeat(5, Some(Duration::from_millis(250))))??;
    net.sim.run_until(ms(120));
    net.frames(6)?;

    println!("\nSDO upload of 0x1008 (device name), segmented:");
    let start = net.sim.now();
    net.master(|m, now, out| m.upload(5, Mux::new(0x1008, 0), Mode::Segmented, now, out))??;
    let name = net.sdo(Duration::from_secs(1))?;
    match name {
        Ok(data) => println!(
            "  \"{}\" ({} bytes in {})",
            String::from_utf8_lossy(&data),
            data.len(),
            net.sim.now() - start
        ),
        Err(e) => println!("  aborted: {e}"),
    }
    net.frames(4)?;

    println!(
        "\nSYNC every 10 ms from the master: the device answers with its TPDOs (transmission type 1):"
    );
    net.master(|m, now, _| m.set_sync(Some((Duration::from_millis(10), 0)), now))??;
    let t = net.sim.now() + Duration::from_millis(21);
    net.sim.run_until(t);
    net.master(|m, now, _| m.set_sync(None, now))??;
    net.frames(10)?;

    println!("\nSDO download of 150 to the set point 0x2002 (limited to 0..100):");
    net.master(|m, now, out| {
        m.download(5, Mux::new(0x2002, 0), vec![150], Mode::Expedited, now, out)
    })??;
    match net.sdo(Duration::from_secs(1))? {
        Ok(_) => println!("  accepted"),
        Err(e) => println!("  the device refuses it: {e}"),
    }
    net.frames(2)?;

    println!("\nWriting 0x5000 to the EMCY trigger 0x2001 makes the device report an error:");
    net.master(|m, now, out| {
        m.download(
            5,
            Mux::new(0x2001, 0),
            0x5000u16.to_le_bytes().to_vec(),
            Mode::Expedited,
            now,
            out,
        )
    })??;
    net.sdo(Duration::from_secs(1))?
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let t = net.sim.now() + Duration::from_millis(2);
    net.sim.run_until(t);
    net.frames_with(3, |ev| match ev {
        MasterEvent::Emcy { node, emcy } => Some(format!(
            "EMCY from node {node}: 0x{:04X} {} (error register 0x{:02X})",
            emcy.code,
            emcy_meaning(emcy.code),
            emcy.register
        )),
        _ => None,
    })?;

    println!("\nBlock upload of the 64 KiB DOMAIN 0x2000:");
    let start = net.sim.now();
    net.master(|m, now, out| {
        m.upload(
            5,
            Mux::new(0x2000, 0),
            Mode::Block { blksize: 127 },
            now,
            out,
        )
    })??;
    let data = net
        .sdo(Duration::from_secs(5))?
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let took = net.sim.now() - start;
    println!(
        "  {} bytes in {} of bus time: {:.0} kbit/s of data on a 500 kbit/s bus",
        data.len(),
        took,
        data.len() as f64 * 8.0 / took.as_secs_f64() / 1e3
    );
    net.frames(0)?;

    println!("\nThe device's cable is cut for 400 ms: the master's heartbeat watch times out, and");
    println!(
        "after the reconnection the device, which lost its bus, is power-cycled and boots again:"
    );
    net.events()?;
    net.sim
        .bus_mut(bus)
        .context("bus")?
        .set_connected(device, false)?;
    let t = net.sim.now() + Duration::from_millis(400);
    net.sim.run_until(t);
    net.sim
        .bus_mut(bus)
        .context("bus")?
        .set_connected(device, true)?;
    net.sim
        .bus_mut(bus)
        .context("bus")?
        .set_powered(device, false)?;
    let t = net.sim.now() + Duration::from_millis(10);
    net.sim.run_until(t);
    net.sim
        .bus_mut(bus)
        .context("bus")?
        .set_powered(device, true)?;
    let t = net.sim.now() + Duration::from_millis(50);
    net.sim.run_until(t);
    for (at, ev) in net.events()? {
        match ev {
            MasterEvent::HeartbeatTimeout { node } => {
                println!("  {:>12}  heartbeat of node {node} lost", at.to_string())
            }
            MasterEvent::BootUp { node } => {
                println!("  {:>12}  node {node} booted", at.to_string())
            }
            MasterEvent::StateChanged { node, from, to } => println!(
                "  {:>12}  node {node}: {} -> {to:?}",
                at.to_string(),
                from.map(|s| format!("{s:?}")).unwrap_or_else(|| "?".into())
            ),
            _ => {}
        }
    }
    net.frames(0)?;
    let stats = net.sim.bus(bus).context("bus")?.stats();
    println!(
        "\n  {} frames on the CANopen bus in {} of bus time.",
        stats.frames(),
        net.sim.now()
    );
    Ok(())
}
