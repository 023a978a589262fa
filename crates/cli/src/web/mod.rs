//! `cantwin sim --web ADDR:PORT`: a live dashboard of the running network in the browser.
//!
//! The simulation runs paced to the wall clock on its own thread; the web server runs on
//! another thread with its own runtime. They meet only through channels: requests go in
//! through an unbounded queue the sim loop drains without waiting, and the sim loop publishes
//! each snapshot (JSON) into a watch channel that keeps only the newest. Neither side ever
//! waits for the other.
//!
//! What the page shows is the monitor's dashboard model ([`cantwin_monitor::dashboard`]):
//! this module reads the simulation for it, encodes its snapshots as JSON, and carries out the
//! page's commands. The page draws the charts itself (with the vendored uPlot) from the
//! snapshots' signal samples, after reading the window so far from `/api/history`.
//!
//! The dashboard owns one port per bus: a CANopen master ([`Master`]) from which NMT commands
//! and SDO downloads go out on the wire, and from which the fault vocabulary's `send` action
//! sends. Writing an object is an SDO download through the bus rather than a write into the
//! twin's dictionary: the twin's SDO server then applies its access rights, value ranges and
//! side effects, and answers with the abort code a real device would (CiA 301 §7.2.4.3.17).

mod guard;
mod listen;
mod server;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::Result;
use cantwin_bus::{BusId, PortConfig, PortId, SimHandle, Simulation, TapId};
use cantwin_can::{ErrorState, Frame};
use cantwin_canopen::master::sdo_client::{Mode, SdoEvent};
use cantwin_canopen::master::{Master, MasterEvent, TransferId};
use cantwin_canopen::od::{DataType, ObjectCode, OdDescription, Value as OdValue};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;
use cantwin_monitor::Led;
use cantwin_monitor::dashboard::{
    self, BusSample, DashboardTap, Device, DeviceSample, Model, RowKind, Sample, SignalSource,
    Snapshot,
};
use cantwin_scenario::script::{ActionKind, apply_action, parse_action};
use cantwin_scenario::{BuiltDevice, Role, Scenario};
use cantwin_twin::SignalId;
use serde_json::{Value, json};

pub use server::Server;

/// Where `--help` lists the options below.
const HEADING: &str = "Web dashboard";

/// The dashboard's options beside `--web` and `--allow-remote`.
#[derive(Debug, Clone, clap::Args)]
pub struct Options {
    /// With --allow-remote, a further name the dashboard answers to in the Host header,
    /// besides 127.0.0.1, localhost, ::1 and the bound address; repeatable. NAME takes the
    /// served port, NAME:PORT its own (behind a proxy). Requests naming any other host are
    /// refused, which defeats DNS rebinding. E.g. `--web 0.0.0.0:8080 --allow-remote
    /// --allow-host plant.lan`.
    #[arg(long = "allow-host", value_name = "NAME[:PORT]", help_heading = HEADING)]
    pub allow_host: Vec<String>,
    /// Web connections served at once; one more is answered 503 and closed, so the
    /// gateways of the process keep their descriptors.
    #[arg(long, value_name = "N", default_value_t = 64, help_heading = HEADING)]
    pub web_max_connections: usize,
    /// Event streams (open pages) served at once; one more is answered 503.
    #[arg(long, value_name = "N", default_value_t = 16, help_heading = HEADING)]
    pub web_max_streams: usize,
    /// Seconds a request's head may take to arrive (from the connection's opening or the end
    /// of the previous answer), then the connection is closed; and a control's body after
    /// it, then it is answered 408.
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0, help_heading = HEADING)]
    pub web_header_timeout: f64,
    /// Seconds a web connection may see no byte move either way (a stalled request body, an
    /// event stream nobody reads); then it is closed.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0, help_heading = HEADING)]
    pub web_idle_timeout: f64,
}

/// How often the dashboard takes a snapshot and publishes it.
const PERIOD: WallDuration = cantwin_monitor::dashboard::SAMPLE_PERIOD;
/// How long a power cycle keeps the device off.
const POWER_CYCLE_OFF: WallDuration = WallDuration::from_millis(500);

/// What the page asks the simulation to do.
#[derive(Debug)]
pub enum Command {
    /// An NMT command (CiA 301 §7.2.8.3.1) to one device or, with `None`, to all nodes
    /// of every bus (node-ID 0).
    Nmt {
        /// The device, or all.
        device: Option<String>,
        /// The command.
        cs: NmtCs,
    },
    /// Set an input of a device's model.
    SetInput {
        /// The device.
        device: String,
        /// The input's name: one of the device's live values, set through the kind's signal of
        /// that name ([`cantwin_scenario::DeviceKind::set_signal`]).
        input: String,
        /// The value.
        value: f64,
    },
    /// An SDO download of `data` to `index`/`sub` of a device (CiA 301 §7.2.4.3.3).
    SdoDownload {
        /// The device.
        device: String,
        /// The object.
        index: u16,
        /// The sub-index.
        sub: u8,
        /// What to write.
        data: SdoData,
    },
    /// An SDO upload of `index`/`sub` of a device (CiA 301 §7.2.4.3.6), shown as `ty`, else
    /// as the type the device's dictionary gives the object, else as hex bytes.
    SdoUpload {
        /// The device.
        device: String,
        /// The object.
        index: u16,
        /// The sub-index.
        sub: u8,
        /// The type to read the bytes as.
        ty: Option<DataType>,
    },
    /// Every chart signal's samples over the window, as JSON.
    History,
    /// Power a device off and on again.
    PowerCycle {
        /// The device.
        device: String,
    },
    /// An action in the vocabulary of the scenarios' `[[at]]` tables (faults and repairs).
    Fault(toml::Table),
}

/// What an SDO download writes.
#[derive(Debug, Clone, PartialEq)]
pub enum SdoData {
    /// A value already encoded, as type `ty` (`None`: raw bytes).
    Encoded {
        /// The type it was encoded as.
        ty: Option<DataType>,
        /// Little-endian bytes.
        bytes: Vec<u8>,
    },
    /// A value as text, to encode as the type the device's dictionary gives the object.
    Text(String),
}

/// How a command ended: `Ok` with a message for the page, or `Err`.
pub type Outcome = Result<String, Refusal>;

/// Why a command did not succeed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// The request names something that does not exist or a value out of range (HTTP 400).
    BadRequest(String),
    /// The device answered with an error (an SDO abort) or could not carry it out (HTTP 422).
    Failed(String),
}

/// A command with the channel its outcome goes back on.
#[derive(Debug)]
pub struct Request {
    /// What to do.
    pub command: Command,
    /// Where the outcome goes.
    pub reply: tokio::sync::oneshot::Sender<Outcome>,
}

struct PendingSdo {
    bus: BusId,
    id: TransferId,
    /// The device, node and object, for the answer.
    what: String,
    /// For an upload, the type its bytes are read as (`None`: hex bytes).
    upload: Option<Option<DataType>>,
    /// For a download, the value written as the page should read it.
    written: String,
    reply: tokio::sync::oneshot::Sender<Outcome>,
}

struct Scheduled {
    at: WallInstant,
    device: String,
}

/// The simulation's side of the dashboard.
pub struct Dashboard {
    scenario: Scenario,
    buses: Vec<(String, BusId)>,
    /// The devices, in the model's order.
    devices: Vec<BuiltDevice>,
    taps: Vec<(BusId, TapId)>,
    /// What the page shows, fed from the taps and the twins at each snapshot.
    model: Model,
    masters: BTreeMap<String, PortId>,
    requests: mpsc::Receiver<Request>,
    sender: mpsc::Sender<Request>,
    publish: tokio::sync::watch::Sender<Arc<String>>,
    pending: Vec<PendingSdo>,
    scheduled: Vec<Scheduled>,
    next_snapshot: WallInstant,
    started: WallInstant,
    /// The last `/api/history` answer and the snapshot count it was made at: pages asking
    /// between two snapshots get the same text, so no number of them makes the simulation's
    /// thread encode the window more than once per snapshot.
    history: Option<(u64, Arc<String>)>,
    snapshots: u64,
}

impl Dashboard {
    /// Attaches the dashboard's taps and master ports to `sim` (before it is paced).
    pub fn attach(
        sim: &mut Simulation,
        scenario: &Scenario,
        buses: &[(String, BusId)],
        devices: &[BuiltDevice],
    ) -> Dashboard {
        let mut taps = Vec::new();
        let mut masters = BTreeMap::new();
        let mut model_buses = Vec::new();
        for (name, id) in buses {
            if let Some(bus) = sim.bus_mut(*id) {
                model_buses.push((name.clone(), bus.bit_rate()));
                taps.push((*id, bus.add_tap(DashboardTap::default())));
                let port = bus.attach(Master::new(), PortConfig::default().with_queue_depth(64));
                masters.insert(name.clone(), port);
            }
        }
        let model_devices = devices
            .iter()
            .map(|d| {
                let bus = buses
                    .iter()
                    .position(|(_, id)| *id == d.port.bus())
                    .unwrap_or(0);
                Device {
                    name: d.name.clone(),
                    kind: d.kind.clone(),
                    port: d.port,
                    bus,
                    bus_name: buses.get(bus).map(|b| b.0.clone()).unwrap_or_default(),
                    node_id: None,
                    canopen: sim
                        .twin(d.port)
                        .is_some_and(|t| t.canopen_node_id().is_some() || t.lss_slave()),
                    monitor_kind: crate::monitor::declared_kind(sim, d).and_then(|(_, k)| k),
                }
            })
            .collect();
        let model = Model::new(
            scenario.name.clone(),
            model_buses,
            model_devices,
            masters.values().copied().collect(),
        );
        let (sender, requests) = mpsc::channel();
        let (publish, _) = tokio::sync::watch::channel(Arc::new(String::from("{}")));
        let now = WallInstant::now();
        Dashboard {
            scenario: scenario.clone(),
            buses: buses.to_vec(),
            devices: devices.to_vec(),
            taps,
            model,
            masters,
            requests,
            sender,
            publish,
            pending: Vec::new(),
            scheduled: Vec::new(),
            next_snapshot: now,
            started: now,
            history: None,
            snapshots: 0,
        }
    }

    /// Starts the web server on `addr` (refusing non-loopback addresses unless
    /// `allow_remote`).
    pub fn serve(&self, addr: SocketAddr, allow_remote: bool, options: &Options) -> Result<Server> {
        server::Server::start(
            addr,
            allow_remote,
            options,
            self.sender.clone(),
            self.publish.subscribe(),
        )
    }

    /// Handles what arrived and publishes a snapshot when one is due. Never waits for the
    /// web server.
    pub fn poll(&mut self, handle: &SimHandle) {
        let now = WallInstant::now();
        let mut due: Vec<Scheduled> = Vec::new();
        self.scheduled.retain_mut(|s| {
            if s.at <= now {
                due.push(Scheduled {
                    at: s.at,
                    device: std::mem::take(&mut s.device),
                });
                false
            } else {
                true
            }
        });
        for s in due {
            let action = ActionKind::Power {
                device: s.device,
                on: true,
            };
            let _ = self.apply(handle, &action);
        }
        while let Ok(req) = self.requests.try_recv() {
            self.handle(handle, req);
        }
        self.sdo_results(handle);
        if now >= self.next_snapshot {
            self.next_snapshot = now + PERIOD;
            self.snapshot(handle, now);
        }
    }

    fn device(&self, name: &str) -> Result<usize, Refusal> {
        self.devices
            .iter()
            .position(|d| d.name == name)
            .ok_or_else(|| {
                let known: Vec<&str> = self.devices.iter().map(|d| d.name.as_str()).collect();
                Refusal::BadRequest(format!(
                    "no device {name:?} (devices: {})",
                    known.join(", ")
                ))
            })
    }

    fn apply(&self, handle: &SimHandle, action: &ActionKind) -> Result<(), String> {
        handle
            .with(|sim| apply_action(sim, &self.buses, &self.devices, &self.masters, action))
            .map_err(|e| e.to_string())?
    }

    fn handle(&mut self, handle: &SimHandle, req: Request) {
        let Request { command, reply } = req;
        let outcome = match command {
            Command::Nmt { device, cs } => self.nmt(handle, device.as_deref(), cs),
            Command::SetInput {
                device,
                input,
                value,
            } => self.set_input(handle, &device, &input, value),
            Command::PowerCycle { device } => self.power_cycle(handle, &device),
            Command::Fault(table) => self.fault(handle, table),
            Command::History => Ok(self.history().as_str().to_owned()),
            Command::SdoDownload {
                device,
                index,
                sub,
                data,
            } => match self.sdo(handle, &device, Mux::new(index, sub), Some(data), None) {
                Ok(p) => {
                    self.pending.push(PendingSdo { reply, ..p });
                    return;
                }
                Err(e) => Err(e),
            },
            Command::SdoUpload {
                device,
                index,
                sub,
                ty,
            } => match self.sdo(handle, &device, Mux::new(index, sub), None, ty) {
                Ok(p) => {
                    self.pending.push(PendingSdo { reply, ..p });
                    return;
                }
                Err(e) => Err(e),
            },
        };
        // The page may have gone; nobody else waits for the outcome.
        let _ = reply.send(outcome);
    }

    fn nmt(&mut self, handle: &SimHandle, device: Option<&str>, cs: NmtCs) -> Outcome {
        let targets: Vec<(PortId, u8, String)> = match device {
            None => self
                .masters
                .iter()
                .map(|(bus, p)| (*p, 0, format!("all nodes on {bus}")))
                .collect(),
            Some(name) => {
                let d = &self.model.devices()[self.device(name)?];
                let node = d.node_id.ok_or_else(|| {
                    Refusal::BadRequest(format!(
                        "{name} has sent no boot-up or heartbeat message: its CANopen node-ID is unknown"
                    ))
                })?;
                let port = *self.masters.get(&d.bus_name).ok_or_else(|| {
                    Refusal::Failed(format!("no dashboard port on bus {}", d.bus_name))
                })?;
                vec![(port, node, format!("{name} (node {node})"))]
            }
        };
        let mut done = Vec::new();
        for (port, node, who) in targets {
            let r = handle
                .with(|sim| {
                    let bus = sim.bus_mut(port.bus())?;
                    bus.with_node::<Master, _>(port, |m, _now, out| m.nmt(cs, node, out))
                })
                .map_err(|e| Refusal::Failed(e.to_string()))?;
            match r {
                Some(Ok(())) => done.push(who),
                Some(Err(e)) => return Err(Refusal::BadRequest(e.to_string())),
                None => return Err(Refusal::Failed("the dashboard's port is gone".into())),
            }
        }
        Ok(format!("NMT {} sent to {}", cs_name(cs), done.join(", ")))
    }

    /// Sets an input among the device's live values through its kind's signal of the same
    /// name (`[[at]] action = "set"` in scripts): a digital input takes 0 or 1, an analog
    /// input a number within its range.
    fn set_input(&mut self, handle: &SimHandle, device: &str, input: &str, value: f64) -> Outcome {
        let port = self.devices[self.device(device)?].port;
        handle
            .with(|sim| {
                let values = sim.twin(port).map(|t| t.live_values()).unwrap_or_default();
                let signal = dashboard::input_signal(&values, device, input, value)?;
                sim.with_twin(port, |t, cx| {
                    t.set_signal(&SignalId::new(input), &signal, cx)
                })
                .ok_or_else(|| format!("{device} has no inputs"))?
                .map_err(|e| format!("{device}: {e}"))
            })
            .map_err(|e| Refusal::Failed(e.to_string()))?
            .map_err(Refusal::BadRequest)?;
        Ok(format!("{device}: {input} = {value}"))
    }

    fn power_cycle(&mut self, handle: &SimHandle, device: &str) -> Outcome {
        self.device(device)?;
        if self.scheduled.iter().any(|s| s.device == device) {
            return Err(Refusal::BadRequest(format!(
                "{device} is already being power-cycled"
            )));
        }
        let off = ActionKind::Power {
            device: device.to_string(),
            on: false,
        };
        self.apply(handle, &off).map_err(Refusal::Failed)?;
        self.scheduled.push(Scheduled {
            at: WallInstant::now() + POWER_CYCLE_OFF,
            device: device.to_string(),
        });
        Ok(format!(
            "{device} powered off; power returns in {} ms",
            POWER_CYCLE_OFF.as_millis()
        ))
    }

    fn fault(&mut self, handle: &SimHandle, table: toml::Table) -> Outcome {
        let what = table
            .get("action")
            .and_then(|v| v.as_str())
            .unwrap_or("?")
            .to_string();
        let action = parse_action(&self.scenario, table).map_err(Refusal::BadRequest)?;
        self.apply(handle, &action).map_err(Refusal::Failed)?;
        Ok(format!("{what}: applied ({})", describe_action(&action)))
    }

    /// Starts an SDO download of `data` (or, without it, an upload read as `ty`) of `mux`
    /// of `device`, through the dashboard's master on the device's bus.
    fn sdo(
        &mut self,
        handle: &SimHandle,
        device: &str,
        mux: Mux,
        data: Option<SdoData>,
        ty: Option<DataType>,
    ) -> Result<PendingSdo, Refusal> {
        let k = self.device(device)?;
        let d = &self.model.devices()[k];
        let node = d.node_id.ok_or_else(|| {
            Refusal::BadRequest(format!(
                "{device} has sent no boot-up or heartbeat message: its CANopen node-ID is unknown"
            ))
        })?;
        let port = *self
            .masters
            .get(&d.bus_name)
            .ok_or_else(|| Refusal::Failed(format!("no dashboard port on bus {}", d.bus_name)))?;
        // The object's name and type, as the device's dictionary (its EDS) gives them.
        let twin_port = self.devices[k].port;
        let entry = handle
            .with(|sim| {
                sim.twin(twin_port)
                    .and_then(|t| t.dictionary())
                    .and_then(|od| object_entry(od.description(), mux))
            })
            .map_err(|e| Refusal::Failed(e.to_string()))?;
        let name = entry
            .as_ref()
            .map(|(n, _)| format!(" \"{n}\""))
            .unwrap_or_default();
        let what = format!(
            "{device} (node {node}) {:04X}sub{}{name}",
            mux.index, mux.sub
        );
        let dictionary_type = entry.map(|(_, t)| t);
        let (bytes, written, upload) = match data {
            Some(SdoData::Encoded { ty, bytes }) => {
                let shown = show_value(ty, &bytes);
                (Some(bytes), shown, None)
            }
            Some(SdoData::Text(text)) => {
                let ty = dictionary_type.ok_or_else(|| {
                    Refusal::BadRequest(format!(
                        "{device}'s dictionary has no {:04X}sub{}: give the value's type",
                        mux.index, mux.sub
                    ))
                })?;
                let v = OdValue::parse(ty, text.trim())
                    .map_err(|e| Refusal::BadRequest(format!("{text:?} as {ty}: {e}")))?;
                let bytes = v.to_le_bytes();
                let shown = show_value(Some(ty), &bytes);
                (Some(bytes), shown, None)
            }
            None => (None, String::new(), Some(ty.or(dictionary_type))),
        };
        let r = handle
            .with(|sim| {
                let bus = sim.bus_mut(port.bus())?;
                bus.with_node::<Master, _>(port, |m, now, out| match bytes {
                    Some(b) => m.download(node, mux, b, Mode::Auto, now, out),
                    None => m.upload(node, mux, Mode::Auto, now, out),
                })
            })
            .map_err(|e| Refusal::Failed(e.to_string()))?;
        let id = match r {
            Some(Ok(id)) => id,
            Some(Err(e)) => return Err(Refusal::BadRequest(e.to_string())),
            None => return Err(Refusal::Failed("the dashboard's port is gone".into())),
        };
        let (reply, _) = tokio::sync::oneshot::channel();
        Ok(PendingSdo {
            bus: port.bus(),
            id,
            what,
            upload,
            written,
            reply,
        })
    }

    /// Answers the SDO transfers that completed or were aborted.
    fn sdo_results(&mut self, handle: &SimHandle) {
        if self.pending.is_empty() {
            return;
        }
        let ports: Vec<PortId> = self.masters.values().copied().collect();
        let events: Vec<(BusId, MasterEvent)> = handle
            .with(|sim| {
                let mut v = Vec::new();
                for p in &ports {
                    if let Some(m) = sim.node_mut::<Master>(*p) {
                        while let Some((_, e)) = m.poll_event() {
                            v.push((p.bus(), e));
                        }
                    }
                }
                v
            })
            .unwrap_or_default();
        for (bus, e) in events {
            let MasterEvent::Sdo { id, event, .. } = e else {
                continue;
            };
            let outcome = match event {
                SdoEvent::Completed { data, .. } => Ok(data),
                SdoEvent::Aborted {
                    code, by_server, ..
                } => Err((code, by_server)),
                _ => continue,
            };
            if let Some(i) = self.pending.iter().position(|p| p.bus == bus && p.id == id) {
                let p = self.pending.swap_remove(i);
                let service = if p.upload.is_some() {
                    "upload"
                } else {
                    "download"
                };
                let msg = match (outcome, p.upload) {
                    (Ok(data), Some(ty)) => {
                        Ok(format!("SDO upload {} = {}", p.what, show_value(ty, &data)))
                    }
                    (Ok(_), None) => Ok(format!("SDO download {} = {}: done", p.what, p.written)),
                    (Err((code, by_server)), _) => Err(Refusal::Failed(format!(
                        "SDO {service} {}: aborted by the {} with {code}",
                        p.what,
                        if by_server { "device" } else { "dashboard" },
                    ))),
                };
                let _ = p.reply.send(msg);
            }
        }
    }

    fn snapshot(&mut self, handle: &SimHandle, wall: WallInstant) {
        let taps = self.taps.clone();
        let devices = &self.devices;
        let since_start = wall.duration_since(self.started);
        let grabbed = handle.with(|sim| {
            let now = sim.now();
            let events = taps
                .iter()
                .map(|(bus, tap)| {
                    sim.bus_mut(*bus)
                        .and_then(|b| b.tap_mut::<DashboardTap>(*tap))
                        .map(DashboardTap::drain)
                        .unwrap_or_default()
                })
                .collect();
            let buses = sim
                .buses()
                .iter()
                .map(|b| {
                    let s = b.stats();
                    BusSample {
                        frames: s.frames(),
                        error_frames: s.error_frames(),
                        load_percent: s.window_load_percent(now),
                        load_span: now.saturating_duration_since(s.since()).min(s.window()),
                        bit_rate: b.bit_rate(),
                    }
                })
                .collect();
            let live = devices
                .iter()
                .map(|d| {
                    let twin = sim.twin(d.port);
                    DeviceSample {
                        status: sim
                            .bus(d.port.bus())
                            .and_then(|b| b.port_status(d.port).ok()),
                        values: twin.map(|t| t.live_values()).unwrap_or_default(),
                        error_register: twin
                            .and_then(|t| t.read_object(0x1001, 0).ok())
                            .and_then(|b| b.first().copied()),
                        node_id: twin.and_then(|t| t.canopen_node_id()),
                    }
                })
                .collect();
            let labels = sim
                .buses()
                .iter()
                .flat_map(|b| b.port_labels().map(|(p, l)| (p, l.to_string())))
                .collect();
            Sample {
                now,
                wall: since_start,
                events,
                buses,
                devices: live,
                labels,
            }
        });
        let Ok(sample) = grabbed else {
            return;
        };
        let snapshot = self.model.update(sample);
        self.snapshots += 1;
        let json = self.encode(&snapshot);
        self.publish.send_replace(Arc::new(json.to_string()));
    }

    /// [`Dashboard::history_json`] as text, encoded at most once per snapshot.
    fn history(&mut self) -> Arc<String> {
        match &self.history {
            Some((at, text)) if *at == self.snapshots => Arc::clone(text),
            _ => {
                let text = Arc::new(self.history_json().to_string());
                self.history = Some((self.snapshots, Arc::clone(&text)));
                text
            }
        }
    }

    /// Every signal's samples over the window: `{"series": {key: [[t, v], …]}}` with `t` in
    /// seconds since the dashboard started.
    fn history_json(&self) -> Value {
        let series: serde_json::Map<String, Value> = self
            .model
            .history()
            .into_iter()
            .map(|(k, points)| {
                let points: Vec<Value> = points
                    .into_iter()
                    .map(|(t, v)| json!([round3(t), round3(v)]))
                    .collect();
                (k.to_string(), Value::Array(points))
            })
            .collect();
        json!({ "series": series })
    }

    /// The snapshot as the page reads it.
    fn encode(&self, snap: &Snapshot) -> Value {
        let bus_json: Vec<Value> = snap
            .buses
            .iter()
            .map(|b| {
                json!({
                    "name": b.name,
                    "bit_rate": b.bit_rate.to_string(),
                    "frames": b.frames,
                    "error_frames": b.error_frames,
                    "load": round2(b.load),
                    "fps": round2(b.fps),
                })
            })
            .collect();
        let nodes: Vec<Value> = snap
            .nodes
            .iter()
            .map(|n| {
                let emcy = n.emcy.as_ref().map(|e| {
                    json!({
                        "code": format!("0x{:04X}", e.code),
                        "meaning": e.meaning,
                        "register": format!("0x{:02X}", e.register),
                        "age_ms": (e.age.as_nanos() as f64 / 1e6).round(),
                        "active": e.active,
                    })
                });
                json!({
                    "device": n.device,
                    "kind": n.kind,
                    "bus": n.bus,
                    "node_id": n.node_id,
                    "nmt": n.nmt,
                    "heartbeat_age_ms": n
                        .heartbeat_age
                        .map(|a| (a.as_nanos() as f64 / 1e6).round()),
                    "error_register": n.error_register.map(|r| format!("0x{r:02X}")),
                    "emcy": emcy,
                    "powered": n.powered,
                    "connected": n.connected,
                    "controller": state_name(n.counters.state()),
                    "tec": n.counters.tec(),
                    "rec": n.counters.rec(),
                    "leds": { "run": led_name(n.leds.run), "err": led_name(n.leds.err) },
                })
            })
            .collect();
        let panels: Vec<Value> = snap
            .devices
            .iter()
            .map(|p| {
                let vals: Vec<Value> = p
                    .values
                    .iter()
                    .map(|v| {
                        let (min, max) = match v.role {
                            Role::AnalogInput { min, max } => (Some(min), Some(max)),
                            _ => (None, None),
                        };
                        json!({
                            "name": v.name,
                            "value": round3(v.value),
                            "unit": v.unit,
                            "role": role_name(v.role),
                            "min": min,
                            "max": max,
                        })
                    })
                    .collect();
                json!({ "name": p.name, "kind": p.kind, "values": vals })
            })
            .collect();
        let signals: Vec<Value> = snap
            .signals
            .iter()
            .map(|s| {
                json!({
                    "key": s.key,
                    "label": s.label,
                    "unit": s.unit,
                    "group": s.group,
                    "source": match s.source {
                        SignalSource::Bus => "bus",
                        SignalSource::Device => "device",
                        SignalSource::Pdo => "pdo",
                    },
                    "non_negative": s.non_negative,
                    "value": round3(s.value),
                })
            })
            .collect();
        let stream: Vec<Value> = snap
            .frames
            .iter()
            .map(|r| {
                json!({
                    "seq": r.seq,
                    "t_ms": round3(r.at.as_nanos() as f64 / 1e6),
                    "bus": self.model.bus_name(r.bus).unwrap_or("?"),
                    "id": r.frame.as_ref().map(id_text).unwrap_or_default(),
                    "data": match &r.frame {
                        Some(f) if f.is_remote() => format!("R{}", f.dlc()),
                        Some(f) => hex_spaced(f.data_bytes()),
                        None => String::new(),
                    },
                    "from": r.from,
                    "text": r.text,
                    "flag": flag_name(r.kind),
                })
            })
            .collect();
        let mut fixed = Vec::new();
        let mut fixed_overflow = 0;
        for (i, b) in snap.buses.iter().enumerate() {
            let Some(trace) = self.model.fixed_trace(i) else {
                continue;
            };
            fixed_overflow += trace.overflow();
            for r in trace.rows() {
                let f = &r.last.frame;
                fixed.push(json!({
                    "bus": b.name,
                    "id": id_text(f),
                    "count": r.count,
                    "cycle_ms": r.cycle.last.map(ms),
                    "min_ms": r.cycle.min.map(ms),
                    "max_ms": r.cycle.max.map(ms),
                    "age_ms": ms(r.age(snap.now)),
                    "data": if f.is_remote() { format!("R{}", f.dlc()) } else { hex_spaced(f.data_bytes()) },
                    "changed": r.changed,
                    "text": r.last.text,
                }));
            }
        }
        json!({
            "scenario": snap.scenario,
            "time_ms": round3(snap.now.as_nanos() as f64 / 1e6),
            "uptime_s": round2(snap.uptime.as_secs_f64()),
            "buses": bus_json,
            "nodes": nodes,
            "devices": panels,
            "signals": signals,
            "frames": stream,
            "next_seq": snap.next_seq,
            "missed": snap.missed,
            "missed_total": snap.missed_total,
            "fixed": fixed,
            "fixed_overflow": fixed_overflow,
        })
    }
}

/// The name and type of `mux` in dictionary `od`: a VAR's own name, a record's or array's
/// name with its sub-object's (CiA 306 §4.6.3 ParameterName).
fn object_entry(od: &OdDescription, mux: Mux) -> Option<(String, DataType)> {
    let object = od.object(mux.index)?;
    let (_, sub) = object.subs().find(|(s, _)| *s == mux.sub)?;
    let name = if object.code() == ObjectCode::Var || sub.name == object.name() {
        object.name().to_string()
    } else {
        format!("{}: {}", object.name(), sub.name)
    };
    Some((name, sub.data_type))
}

/// The most bytes an answer shows of an upload read as hex bytes.
const SHOWN_BYTES: usize = 64;
/// The most characters an answer shows of an upload read as a string: a whole device name
/// or version (0x1008–0x100A) fits, a segmented upload of a megabyte does not flood the page.
const SHOWN_CHARS: usize = 1024;

/// `bytes` read as `ty` (CiA 301 §7.1), with the bytes beside numbers; as hex bytes without a
/// type or when they do not fit it.
fn show_value(ty: Option<DataType>, bytes: &[u8]) -> String {
    let raw = || {
        let shown = hex_spaced(&bytes[..bytes.len().min(SHOWN_BYTES)]);
        if bytes.len() > SHOWN_BYTES {
            format!("{shown} … ({} bytes)", bytes.len())
        } else if bytes.is_empty() {
            "(0 bytes)".to_string()
        } else {
            shown
        }
    };
    let Some(ty) = ty else { return raw() };
    match OdValue::from_le_bytes(ty, bytes) {
        Ok(OdValue::OctetString(_) | OdValue::Domain(_)) => format!("{} ({ty})", raw()),
        Ok(v @ (OdValue::VisibleString(_) | OdValue::UnicodeString(_))) => {
            let whole = v.to_string();
            let text: String = whole.chars().take(SHOWN_CHARS).collect();
            if text.len() < whole.len() {
                format!("{text:?} … ({} bytes) ({ty})", bytes.len())
            } else {
                format!("{text:?} ({ty})")
            }
        }
        Ok(v) if v.as_i128().is_some() => format!("{v} (0x{}, {ty})", hex_le(bytes)),
        Ok(v) => format!("{v} ({ty})"),
        Err(e) => format!("{} (not a {ty}: {e})", raw()),
    }
}

/// Little-endian bytes as one hexadecimal number, most significant digit first.
fn hex_le(b: &[u8]) -> String {
    b.iter().rev().map(|b| format!("{b:02X}")).collect()
}

/// A bus time span in milliseconds, to the microsecond.
fn ms(d: cantwin_can::Duration) -> f64 {
    round3(d.as_nanos() as f64 / 1e6)
}

fn round2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn hex_spaced(b: &[u8]) -> String {
    b.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn id_text(f: &Frame) -> String {
    match f.id() {
        cantwin_can::Id::Standard(s) => format!("{:03X}", s.as_raw()),
        cantwin_can::Id::Extended(e) => format!("{:08X}", e.as_raw()),
    }
}

fn role_name(r: Role) -> &'static str {
    match r {
        Role::Measured => "measured",
        Role::DigitalInput => "digital-input",
        Role::AnalogInput { .. } => "analog-input",
        Role::DigitalOutput => "digital-output",
        Role::AnalogOutput => "analog-output",
    }
}

fn state_name(s: ErrorState) -> &'static str {
    match s {
        ErrorState::Active => "error-active",
        ErrorState::Passive => "error-passive",
        ErrorState::BusOff => "bus-off",
    }
}

fn cs_name(cs: NmtCs) -> &'static str {
    match cs {
        NmtCs::Start => "start",
        NmtCs::Stop => "stop",
        NmtCs::EnterPreOperational => "enter pre-operational",
        NmtCs::ResetNode => "reset node",
        NmtCs::ResetCommunication => "reset communication",
    }
}

fn describe_action(a: &ActionKind) -> String {
    match a {
        ActionKind::Send { bus, frame } => format!("{frame} sent on {bus}"),
        ActionKind::Power { device, on } => {
            format!("{device} powered {}", if *on { "on" } else { "off" })
        }
        ActionKind::Connect { device, connected } => format!(
            "{device} {}",
            if *connected {
                "reconnected"
            } else {
                "disconnected"
            }
        ),
        ActionKind::BusOff { device } => format!("{device} forced bus-off"),
        ActionKind::Babble { device, frame } => match frame {
            Some(f) => format!("{device} babbles {f}"),
            None => format!("{device} stops babbling"),
        },
        ActionKind::BitRateMismatch { device, rate } => match rate {
            Some(r) => format!("{device} misconfigured to {r}"),
            None => format!("{device} back at the bus's bit rate"),
        },
        ActionKind::Fault {
            bus,
            corrupt,
            fraction,
            from,
            count,
        } => format!(
            "{} {:.1} % of the frames on {bus}{}{}",
            if *corrupt { "corrupt" } else { "drop" },
            fraction * 100.0,
            from.as_ref()
                .map(|f| format!(" from {f}"))
                .unwrap_or_default(),
            count.map(|n| format!(", at most {n}")).unwrap_or_default()
        ),
        ActionKind::ClearFaults { bus } => format!("faults on {bus} cleared"),
        ActionKind::Inject { device, fault } => match fault {
            Some(f) => format!("{device}: internal fault {f} injected"),
            None => format!("{device}: internal faults repaired"),
        },
        ActionKind::Set {
            device,
            signal,
            value,
        } => format!("{device}: {signal} set to {value}"),
    }
}

/// The page's word for a row of the frame stream.
fn flag_name(k: RowKind) -> &'static str {
    match k {
        RowKind::Frame => "",
        RowKind::Dropped => "dropped",
        RowKind::Error => "error",
        RowKind::Controller => "controller",
    }
}

/// The page's word for an indicator state.
fn led_name(l: Led) -> &'static str {
    match l {
        Led::Off => "off",
        Led::On => "on",
        Led::Blinking => "blinking",
        Led::SingleFlash => "single-flash",
        Led::DoubleFlash => "double-flash",
        Led::Unknown => "unknown",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::ErrorCounters;

    /// The indicator states as the page names them.
    fn leds(
        powered: bool,
        seen: Option<cantwin_monitor::Leds>,
        c: &ErrorCounters,
    ) -> (&'static str, &'static str) {
        let l = cantwin_monitor::dashboard::leds(powered, seen, c);
        (led_name(l.run), led_name(l.err))
    }

    #[test]
    fn cia301_sdo_answers_are_read_by_type_and_named_as_in_the_dictionary() {
        use cantwin_canopen::od::{Access, OdBuilder, SubObject};
        assert_eq!(
            show_value(Some(DataType::Unsigned16), &[0xE8, 0x03]),
            "1000 (0x03E8, UNSIGNED16)"
        );
        assert_eq!(
            show_value(Some(DataType::Integer8), &[0xFF]),
            "-1 (0xFF, INTEGER8)"
        );
        assert_eq!(
            show_value(Some(DataType::VisibleString), b"ADV2"),
            "\"ADV2\" (VISIBLE_STRING)"
        );
        assert_eq!(show_value(None, &[0xE8, 0x03]), "E8 03");
        assert!(
            show_value(Some(DataType::Unsigned16), &[0xE8]).starts_with("E8 (not a UNSIGNED16"),
            "bytes that do not fit the type are shown as they came"
        );
        assert!(show_value(None, &[0; 100]).ends_with("… (100 bytes)"));
        // A string longer than the old 64-character cut shows whole; one past the bound
        // shows its start and is marked as cut, as raw bytes are.
        let long = "x".repeat(200);
        assert_eq!(
            show_value(Some(DataType::VisibleString), long.as_bytes()),
            format!("{long:?} (VISIBLE_STRING)")
        );
        let huge = "y".repeat(SHOWN_CHARS + 10);
        assert_eq!(
            show_value(Some(DataType::VisibleString), huge.as_bytes()),
            format!(
                "{:?} … ({} bytes) (VISIBLE_STRING)",
                &huge[..SHOWN_CHARS],
                SHOWN_CHARS + 10
            )
        );
        let od = OdBuilder::new()
            .var(
                0x1017,
                SubObject::new("Producer heartbeat time", DataType::Unsigned16, Access::Rw),
            )
            .record(
                0x1018,
                "Identity object",
                [(
                    1,
                    SubObject::new("Vendor-ID", DataType::Unsigned32, Access::Ro),
                )],
            )
            .build()
            .unwrap();
        assert_eq!(
            object_entry(&od, Mux::new(0x1018, 1)),
            Some(("Identity object: Vendor-ID".into(), DataType::Unsigned32))
        );
        assert_eq!(
            object_entry(&od, Mux::new(0x1017, 0)),
            Some(("Producer heartbeat time".into(), DataType::Unsigned16))
        );
        assert_eq!(object_entry(&od, Mux::new(0x1017, 1)), None);
        assert_eq!(object_entry(&od, Mux::new(0x1019, 0)), None);
    }

    #[test]
    fn cia303_3_leds_add_power_and_controller_state_to_what_the_bus_shows() {
        let c = ErrorCounters::new();
        let seen = cantwin_monitor::Leds {
            run: Led::On,
            err: Led::DoubleFlash,
        };
        assert_eq!(leds(true, Some(seen), &c), ("on", "double-flash"));
        assert_eq!(leds(false, Some(seen), &c), ("off", "off"));
        assert_eq!(leds(true, None, &c), ("unknown", "off"));
    }
}
