//! The data model behind a live dashboard of a simulated network (`cantwin sim --web`),
//! free of I/O like the rest of the crate: the front end drains each bus's
//! [`DashboardTap`], reads the bus statistics and the twins' live values, and hands them to
//! [`Model::update`] with the bus time and the wall time; the model answers with a
//! [`Snapshot`] for the front end to encode and draw.
//!
//! The model keeps, between snapshots:
//!
//! * one [`NetworkView`] per bus, fed with the frames of CANopen senders, for the NMT
//!   state, heartbeat, EMCY and LED columns of the node table;
//! * each device's CANopen node-ID, learned from the COB-IDs of the boot-up, heartbeat and
//!   EMCY messages its port sends, or from what its twin says;
//! * per bus, the fixed trace ([`Model::fixed_trace`]) of every frame, CANopen or not;
//! * the frame stream: every frame, error frame and controller event of every bus, with who
//!   sent it, numbered ([`StreamRow::seq`]) so that a page sees where rows are missing; a
//!   snapshot carries the rows since the previous one, at most [`STREAM_LEN`] (the rest are
//!   left out, and their numbers with them);
//! * the charts' signals ([`Signal`]): each bus's load and frames per second, every live
//!   value of every device, every PDO value the bus views decoded, each with a sliding
//!   [`WINDOW_S`] window of its samples ([`History`]), which [`Model::history`] hands out
//!   whole for a page that opens late.
//!
//! The wall time is a [`std::time::Duration`] since the dashboard started, given by the
//! caller: the charts run on it, so they move at the pace the viewer sees even when the
//! simulation runs faster or slower than real time.

pub mod tap;

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration as WallDuration;

use cantwin_bus::{ErrorKind, PortId, PortStatus};
use cantwin_can::{BitRate, ControllerEvent, Duration, ErrorCounters, ErrorState, Frame, Instant};
use cantwin_canopen::wire::{self, ErrorControl, Message};
use cantwin_twin::{LiveValue, Role, SignalValue};

use crate::kind::{Field, Format};
use crate::{Config, DeviceKind, FixedTrace, FrameEntry, Led, Leds, NetworkView, Service};

pub use tap::{DashboardTap, Seen};

/// The window the series keep, in seconds.
pub const WINDOW_S: f64 = 300.0;
/// Rows a snapshot carries at most (and frames kept by each bus's view): 2048 rows in a
/// quarter of a second is 8192 frames/s, most of a 1 Mbit/s bus; beyond it rows are left
/// out and their numbers show the gap.
pub const STREAM_LEN: usize = 2048;
/// How often the front end samples the simulation for a snapshot: the charts' sampling
/// period.
pub const SAMPLE_PERIOD: WallDuration = WallDuration::from_millis(250);

/// A sliding window of samples over wall time.
#[derive(Debug, Default, Clone)]
pub struct History(VecDeque<(WallDuration, f64)>);

impl History {
    /// Adds `v` sampled at `t` and forgets the samples older than [`WINDOW_S`] before it.
    pub fn push(&mut self, t: WallDuration, v: f64) {
        self.0.push_back((t, v));
        while self
            .0
            .front()
            .is_some_and(|(s, _)| t.saturating_sub(*s).as_secs_f64() > WINDOW_S)
        {
            self.0.pop_front();
        }
    }

    /// The samples as (seconds since the dashboard started, value), oldest first.
    pub fn points(&self) -> Vec<(f64, f64)> {
        self.0.iter().map(|(t, v)| (t.as_secs_f64(), *v)).collect()
    }
}

/// A device of the simulation as the dashboard shows it.
#[derive(Debug, Clone)]
pub struct Device {
    /// Its name in the scenario.
    pub name: String,
    /// Its kind in the scenario (`"tm3"`, `"adv200"` …).
    pub kind: String,
    /// Its port.
    pub port: PortId,
    /// The index of its bus among the model's buses.
    pub bus: usize,
    /// The name of its bus.
    pub bus_name: String,
    /// Its CANopen node-ID once known (see [`Model::update`]).
    pub node_id: Option<u8>,
    /// Whether its twin is a CANopen node at power-up (it has a node-ID,
    /// `Twin::canopen_node_id`, or is an LSS slave waiting for one): a bus with one carries
    /// CANopen.
    pub canopen: bool,
    /// How the bus view reads its PDOs, from the twin itself (an ADV200 in its active
    /// personality), when it is a CANopen node; without it the view takes the built-in
    /// reading of its kind ([`DeviceKind::builtin`]).
    pub monitor_kind: Option<DeviceKind>,
}

/// A bus of the simulation as the model keeps it.
#[derive(Debug)]
struct Bus {
    name: String,
    /// Whether the bus carries CANopen: every frame on it is decoded as CANopen, whoever
    /// sent it (a gateway's client, a generator, the dashboard).
    canopen: bool,
    /// The CANopen model of the bus, fed with the frames of CANopen senders.
    view: NetworkView,
    /// The fixed trace of every frame that reached the receivers, whatever its protocol
    /// (the view's own sees CANopen senders only).
    fixed: FixedTrace,
}

/// What a row of the frame stream is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// A frame that reached the receivers.
    Frame,
    /// A frame an injected fault kept from every receiver.
    Dropped,
    /// A transmission that ended in an error frame.
    Error,
    /// A controller event (no frame).
    Controller,
}

/// One row of the frame stream.
#[derive(Debug, Clone)]
pub struct StreamRow {
    /// Its number since the dashboard started, over all buses (0 for the first row).
    pub seq: u64,
    /// Bus time.
    pub at: Instant,
    /// The index of its bus.
    pub bus: usize,
    /// The frame; `None` for controller events.
    pub frame: Option<Frame>,
    /// Who sent it: a device's name, `"dashboard"` for the dashboard's own ports, a gateway
    /// client's name (`socketcand 127.0.0.1:54012`), else `port N`.
    pub from: String,
    /// A one-line decoding (CANopen frames), or what happened.
    pub text: String,
    /// What the row is.
    pub kind: RowKind,
}

/// What the front end reads of one bus for a snapshot.
#[derive(Debug, Clone)]
pub struct BusSample {
    /// Frames completed since the bus started.
    pub frames: u64,
    /// Error frames since the bus started.
    pub error_frames: u64,
    /// The bus load over the statistics' window, in percent.
    pub load_percent: f64,
    /// The bus time `load_percent` was measured over: the statistics' window, or less
    /// while the bus has run for less than it.
    pub load_span: Duration,
    /// The bus's bit rate.
    pub bit_rate: BitRate,
}

/// What the front end reads of one device for a snapshot.
#[derive(Debug, Clone, Default)]
pub struct DeviceSample {
    /// Its port's state, where the bus still has the port.
    pub status: Option<PortStatus>,
    /// Its twin's live values.
    pub values: Vec<LiveValue>,
    /// Its error register (0x1001) as its twin holds it, where it has a dictionary.
    pub error_register: Option<u8>,
    /// Its CANopen node-ID as its twin knows it.
    pub node_id: Option<u8>,
}

/// Everything read from the simulation for one snapshot.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Bus time.
    pub now: Instant,
    /// Wall time since the dashboard started.
    pub wall: WallDuration,
    /// Per bus, in the model's order: the events its tap drained and how many it missed.
    pub events: Vec<(Vec<Seen>, u64)>,
    /// Per bus, in the model's order.
    pub buses: Vec<BusSample>,
    /// Per device, in the model's order.
    pub devices: Vec<DeviceSample>,
    /// Names of ports that are no device and no port of the dashboard, as the buses give
    /// them ([`cantwin_bus::Bus::port_labels`]): a gateway's clients.
    pub labels: Vec<(PortId, String)>,
}

/// A bus in a snapshot.
#[derive(Debug, Clone)]
pub struct BusSnapshot {
    /// Its name.
    pub name: String,
    /// Its bit rate.
    pub bit_rate: BitRate,
    /// Frames since the bus started.
    pub frames: u64,
    /// Error frames since the bus started.
    pub error_frames: u64,
    /// The bus load, in percent.
    pub load: f64,
    /// Whether `load` was measured over at least [`SAMPLE_PERIOD`] of bus time: a shorter
    /// window (the first milliseconds after start) is a start-up artefact, shown in the
    /// table but not charted.
    pub load_settled: bool,
    /// Frames per second of wall time since the previous snapshot (0 for the first).
    pub fps: f64,
}

/// The last EMCY of a node in a snapshot.
#[derive(Debug, Clone)]
pub struct EmcySnapshot {
    /// The error code.
    pub code: u16,
    /// What the code means (empty when unknown).
    pub meaning: String,
    /// The error register sent with it.
    pub register: u8,
    /// Bus time since it was sent.
    pub age: Duration,
    /// Whether the error is still active (no error-reset EMCY since).
    pub active: bool,
}

/// A row of the node table in a snapshot.
#[derive(Debug, Clone)]
pub struct NodeSnapshot {
    /// The device's name.
    pub device: String,
    /// Its kind.
    pub kind: String,
    /// Its bus's name.
    pub bus: String,
    /// Its CANopen node-ID, once known.
    pub node_id: Option<u8>,
    /// Its NMT state's name, once seen on the bus.
    pub nmt: Option<&'static str>,
    /// Bus time since its last heartbeat.
    pub heartbeat_age: Option<Duration>,
    /// Its error register: the twin's, else the last one seen on the bus.
    pub error_register: Option<u8>,
    /// Its last EMCY.
    pub emcy: Option<EmcySnapshot>,
    /// Whether it is powered.
    pub powered: bool,
    /// Whether it is connected to the bus.
    pub connected: bool,
    /// Its controller's error counters and state.
    pub counters: ErrorCounters,
    /// Its indicators ([`leds`]).
    pub leds: Leds,
}

/// A device's panel of live values in a snapshot.
#[derive(Debug, Clone)]
pub struct DevicePanel {
    /// The device's name.
    pub name: String,
    /// Its kind.
    pub kind: String,
    /// Its live values, in the twin's order.
    pub values: Vec<LiveValue>,
}

/// Where a chartable signal comes from, for the page's picker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalSource {
    /// The bus's statistics.
    Bus,
    /// A twin's live value, read from its model.
    Device,
    /// A value the bus view decoded from a PDO on the wire.
    Pdo,
}

/// A value the page can chart, sampled at each snapshot.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// Its key, unique and stable over the run: `bus/can0/load`, `device/drive/speed`,
    /// `pdo/can0/5/TPDO1/statusword`.
    pub key: String,
    /// What the page calls it.
    pub label: String,
    /// Its unit (may be empty).
    pub unit: String,
    /// The group the picker lists it under (a bus or a device).
    pub group: String,
    /// Where it comes from.
    pub source: SignalSource,
    /// Whether it cannot be negative (a load, a rate, a count, an on/off signal, an input
    /// whose range starts at zero or above): its axis starts at zero.
    pub non_negative: bool,
    /// The value at this snapshot.
    pub value: f64,
}

/// What the dashboard shows at one moment.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The scenario's name.
    pub scenario: String,
    /// Bus time.
    pub now: Instant,
    /// Wall time since the dashboard started.
    pub uptime: WallDuration,
    /// The buses.
    pub buses: Vec<BusSnapshot>,
    /// The node table, one row per device.
    pub nodes: Vec<NodeSnapshot>,
    /// The devices' panels, one per device.
    pub devices: Vec<DevicePanel>,
    /// The charts' signals at this snapshot's wall time ([`Snapshot::uptime`]).
    pub signals: Vec<Signal>,
    /// The rows of the frame stream since the previous snapshot, oldest first, at most
    /// [`STREAM_LEN`]: when more came, the oldest are left out (their `seq` numbers with
    /// them, so the gap shows).
    pub frames: Vec<StreamRow>,
    /// The `seq` the next row will have: rows up to it have been numbered.
    pub next_seq: u64,
    /// Events the taps could not keep since the previous snapshot (they got no number).
    pub missed: u64,
    /// Events the taps could not keep since the dashboard started.
    pub missed_total: u64,
}

/// The dashboard's model of a running simulation.
#[derive(Debug)]
pub struct Model {
    scenario: String,
    buses: Vec<Bus>,
    devices: Vec<Device>,
    /// The dashboard's own ports (its CANopen masters).
    masters: Vec<PortId>,
    /// The rows since the previous snapshot, at most [`STREAM_LEN`].
    stream: VecDeque<StreamRow>,
    seq: u64,
    missed: u64,
    missed_total: u64,
    /// Each signal's samples, by key.
    series: BTreeMap<String, History>,
    /// The wall time and frame counts of the previous snapshot.
    last: Option<(WallDuration, Vec<u64>)>,
    /// Names of other ports (gateway clients), kept after they leave: port numbers are
    /// never reused.
    labels: BTreeMap<PortId, String>,
}

impl Model {
    /// A model of scenario `scenario` with `buses` (name and bit rate), `devices` (their
    /// `bus` indices into `buses`) and the dashboard's own ports `masters`.
    ///
    /// A bus carries CANopen when it has no device or one of its devices is a CANopen node
    /// ([`Device::canopen`]), the judgement `cantwin dump --scenario` makes of a recording.
    pub fn new(
        scenario: String,
        buses: Vec<(String, BitRate)>,
        devices: Vec<Device>,
        masters: Vec<PortId>,
    ) -> Model {
        let buses = buses
            .into_iter()
            .enumerate()
            .map(|(i, (name, bit_rate))| Bus {
                name,
                canopen: devices.iter().all(|d| d.bus != i)
                    || devices.iter().any(|d| d.bus == i && d.canopen),
                view: NetworkView::new(Config {
                    bit_rate,
                    ring: STREAM_LEN,
                    ..Config::default()
                }),
                fixed: FixedTrace::new(FixedTrace::DEFAULT_CAPACITY),
            })
            .collect();
        Model {
            scenario,
            buses,
            devices,
            masters,
            stream: VecDeque::new(),
            seq: 0,
            missed: 0,
            missed_total: 0,
            series: BTreeMap::new(),
            last: None,
            labels: BTreeMap::new(),
        }
    }

    /// The devices, in the order they were given.
    pub fn devices(&self) -> &[Device] {
        &self.devices
    }

    /// The name of bus `bus`.
    pub fn bus_name(&self, bus: usize) -> Option<&str> {
        self.buses.get(bus).map(|b| b.name.as_str())
    }

    /// The view of bus `bus`.
    pub fn view(&self, bus: usize) -> Option<&NetworkView> {
        self.buses.get(bus).map(|b| &b.view)
    }

    /// The fixed trace of bus `bus`: one row per identifier of every frame that reached the
    /// receivers, from any sender.
    pub fn fixed_trace(&self, bus: usize) -> Option<&FixedTrace> {
        self.buses.get(bus).map(|b| &b.fixed)
    }

    /// Takes in what was read from the simulation and answers what the dashboard shows.
    pub fn update(&mut self, sample: Sample) -> Snapshot {
        let Sample {
            now,
            wall,
            events,
            buses: bus_stats,
            devices: live,
            labels,
        } = sample;
        self.labels.extend(labels);
        // The node-IDs the twins know (before any boot-up is seen, and for nodes that send
        // no heartbeat).
        for (k, l) in live.iter().enumerate() {
            if let (Some(node), Some(d)) = (l.node_id, self.devices.get(k))
                && d.node_id.is_none()
            {
                self.name_node(k, node);
            }
        }
        self.missed = 0;
        for (i, (seen, missed)) in events.into_iter().enumerate() {
            self.missed += missed;
            self.missed_total += missed;
            self.absorb(i, seen);
            if let Some(b) = self.buses.get_mut(i) {
                b.view.advance(now);
            }
        }
        let buses = self.sample_buses(wall, &bus_stats);
        let mut signals = Vec::new();
        for b in &buses {
            if b.load_settled {
                signals.push(Signal {
                    key: format!("bus/{}/load", b.name),
                    label: format!("{} bus load", b.name),
                    unit: "%".into(),
                    group: format!("bus {}", b.name),
                    source: SignalSource::Bus,
                    non_negative: true,
                    value: b.load,
                });
            }
            signals.push(Signal {
                key: format!("bus/{}/fps", b.name),
                label: format!("{} frames per second", b.name),
                unit: "1/s".into(),
                group: format!("bus {}", b.name),
                source: SignalSource::Bus,
                non_negative: true,
                value: b.fps,
            });
        }
        let mut nodes = Vec::new();
        let mut panels = Vec::new();
        for (d, l) in self.devices.iter().zip(live) {
            let powered = l.status.as_ref().is_none_or(|s| s.powered);
            let counters = l.status.as_ref().map(|s| s.counters).unwrap_or_default();
            let info = d
                .node_id
                .and_then(|n| self.buses.get(d.bus).and_then(|b| b.view.node(n)));
            let emcy = info.and_then(|i| {
                let e = i.last_emcy.as_ref()?;
                Some(EmcySnapshot {
                    code: e.code,
                    meaning: i.emcy_meaning().unwrap_or("").to_string(),
                    register: e.register,
                    age: Duration::from_nanos(now.as_nanos().saturating_sub(e.at.as_nanos())),
                    active: i.emcy_active,
                })
            });
            nodes.push(NodeSnapshot {
                device: d.name.clone(),
                kind: d.kind.clone(),
                bus: d.bus_name.clone(),
                node_id: d.node_id,
                nmt: info.filter(|i| i.state.is_some()).map(|i| i.state_name()),
                heartbeat_age: info.and_then(|i| i.heartbeat_age(now)),
                error_register: l.error_register.or(info.and_then(|i| i.error_register)),
                emcy,
                powered,
                connected: l.status.as_ref().is_none_or(|s| s.connected),
                counters,
                leds: leds(powered, info.map(|i| i.leds(now)), &counters),
            });
            for v in &l.values {
                signals.push(Signal {
                    key: format!("device/{}/{}", d.name, v.name),
                    label: format!("{} {}", d.name, v.name),
                    unit: v.unit.to_string(),
                    group: format!("device {}", d.name),
                    source: SignalSource::Device,
                    non_negative: match v.role {
                        Role::DigitalInput | Role::DigitalOutput => true,
                        Role::AnalogInput { min, .. } => min >= 0.0,
                        Role::Measured | Role::AnalogOutput => false,
                    },
                    value: v.value,
                });
            }
            panels.push(DevicePanel {
                name: d.name.clone(),
                kind: d.kind.clone(),
                values: l.values,
            });
        }
        for (i, b) in self.buses.iter().enumerate() {
            for n in b.view.nodes() {
                let who = self
                    .devices
                    .iter()
                    .find(|d| d.bus == i && d.node_id == Some(n.id))
                    .map_or_else(|| format!("node {}", n.id), |d| d.name.clone());
                for (v, _) in &n.values {
                    let Some(value) = pdo_number(n.kind.as_ref(), v) else {
                        continue;
                    };
                    let pdo = crate::kind::pdo_label(v.pdo);
                    signals.push(Signal {
                        key: format!("pdo/{}/{}/{pdo}/{}", b.name, n.id, v.name),
                        label: format!("{who} {pdo} {}", v.name),
                        unit: pdo_unit(n.kind.as_ref(), v),
                        group: format!("PDOs of {who} on {}", b.name),
                        source: SignalSource::Pdo,
                        non_negative: value >= 0.0 && pdo_unsigned(n.kind.as_ref(), v),
                        value,
                    });
                }
            }
        }
        for s in &signals {
            self.series
                .entry(s.key.clone())
                .or_default()
                .push(wall, s.value);
        }
        let frames: Vec<StreamRow> = self.stream.drain(..).collect();
        Snapshot {
            scenario: self.scenario.clone(),
            now,
            uptime: wall,
            buses,
            nodes,
            devices: panels,
            signals,
            frames,
            next_seq: self.seq,
            missed: self.missed,
            missed_total: self.missed_total,
        }
    }

    /// Every signal's samples over the window, as (seconds since the dashboard started,
    /// value), oldest first, by key: what a page that opens late draws first.
    pub fn history(&self) -> Vec<(&str, Vec<(f64, f64)>)> {
        self.series
            .iter()
            .map(|(k, h)| (k.as_str(), h.points()))
            .collect()
    }

    /// The buses' rows of a snapshot at `wall`: frames per second since the previous one,
    /// and the series extended.
    fn sample_buses(&mut self, wall: WallDuration, stats: &[BusSample]) -> Vec<BusSnapshot> {
        let elapsed = self
            .last
            .as_ref()
            .map(|(t, _)| wall.saturating_sub(*t).as_secs_f64());
        let mut rows = Vec::new();
        for (i, (bus, s)) in self.buses.iter().zip(stats).enumerate() {
            let fps = match (&self.last, elapsed) {
                (Some((_, before)), Some(dt)) if dt > 0.0 => {
                    s.frames.saturating_sub(before.get(i).copied().unwrap_or(0)) as f64 / dt
                }
                _ => 0.0,
            };
            rows.push(BusSnapshot {
                name: bus.name.clone(),
                bit_rate: s.bit_rate,
                frames: s.frames,
                error_frames: s.error_frames,
                load: s.load_percent,
                load_settled: s.load_span.as_nanos() >= SAMPLE_PERIOD.as_nanos() as u64,
                fps,
            });
        }
        self.last = Some((wall, stats.iter().map(|s| s.frames).collect()));
        rows
    }

    fn name_of(&self, port: PortId) -> String {
        if let Some(d) = self.devices.iter().find(|d| d.port == port) {
            d.name.clone()
        } else if self.masters.contains(&port) {
            "dashboard".to_string()
        } else if let Some(label) = self.labels.get(&port) {
            label.clone()
        } else {
            format!("port {}", port.index())
        }
    }

    fn absorb(&mut self, bus: usize, events: Vec<Seen>) {
        for e in events {
            match e {
                Seen::Frame {
                    at,
                    frame,
                    sender,
                    dropped,
                } => {
                    let canopen = self.buses.get(bus).is_some_and(|b| b.canopen);
                    let mut text = String::new();
                    if canopen && !dropped {
                        self.learn(&frame, sender);
                    }
                    if let Some(b) = self.buses.get_mut(bus)
                        && !dropped
                    {
                        let entry = if canopen {
                            b.view.push(at, &frame);
                            b.view.frames().next_back().cloned()
                        } else {
                            None
                        };
                        // Other protocols on the same identifiers mean other things: their
                        // rows carry the frame undecoded.
                        let entry = entry.unwrap_or(FrameEntry {
                            seq: self.seq,
                            at,
                            frame,
                            service: Service::Other,
                            node: None,
                            text: String::new(),
                        });
                        b.fixed.record(&entry);
                        text = entry.text;
                    }
                    self.push_row(StreamRow {
                        seq: 0,
                        at,
                        bus,
                        frame: Some(frame),
                        from: self.name_of(sender),
                        text,
                        kind: if dropped {
                            RowKind::Dropped
                        } else {
                            RowKind::Frame
                        },
                    });
                }
                Seen::Error {
                    at,
                    frame,
                    sender,
                    kind,
                } => self.push_row(StreamRow {
                    seq: 0,
                    at,
                    bus,
                    frame: Some(frame),
                    from: self.name_of(sender),
                    text: format!("error frame: {}", error_words(kind)),
                    kind: RowKind::Error,
                }),
                Seen::Controller { at, port, event } => {
                    let from = self.name_of(port);
                    self.push_row(StreamRow {
                        seq: 0,
                        at,
                        bus,
                        frame: None,
                        from,
                        text: format!("controller: {}", controller_words(event)),
                        kind: RowKind::Controller,
                    });
                }
            }
        }
    }

    /// Numbers `row` and keeps it for the next snapshot; past [`STREAM_LEN`] rows the
    /// oldest is left out (its number is not given again, so the page sees the gap).
    fn push_row(&mut self, mut row: StreamRow) {
        row.seq = self.seq;
        self.seq += 1;
        self.stream.push_back(row);
        while self.stream.len() > STREAM_LEN {
            self.stream.pop_front();
        }
    }

    /// Learns which node-ID a device has from the COB-IDs of what its port sends (CiA 301
    /// §7.2.8.3.2 boot-up and heartbeat, §7.2.7 EMCY), and names the node in its bus's view.
    fn learn(&mut self, frame: &Frame, sender: PortId) {
        let Some(k) = self.devices.iter().position(|d| d.port == sender) else {
            return;
        };
        let node = match wire::decode(frame) {
            Message::ErrorControl(ErrorControl::State { node, .. }) => node,
            Message::Emcy { node, .. } => node,
            _ => return,
        };
        if self.devices[k].node_id != Some(node) {
            self.name_node(k, node);
        }
    }

    /// Records that device `k` is CANopen node `node` and names it in its bus's view.
    fn name_node(&mut self, k: usize, node: u8) {
        let Some(d) = self.devices.get_mut(k) else {
            return;
        };
        d.node_id = Some(node);
        if let Some(b) = self.buses.get_mut(d.bus) {
            b.view.declare(
                node,
                Some(d.name.clone()),
                d.monitor_kind
                    .clone()
                    .or_else(|| DeviceKind::builtin(&d.kind)),
            );
        }
    }
}

/// Why a transmission ended in an error frame, in words (ISO 11898-1 §10.11 names the
/// errors receivers flag).
fn error_words(kind: ErrorKind) -> &'static str {
    match kind {
        ErrorKind::Ack => "acknowledgement error",
        ErrorKind::Corrupted => "bit error (corrupted)",
        ErrorKind::BitRateMismatch => "stuff error (bit-rate mismatch)",
        ErrorKind::Aborted => "form error (transmitter stopped)",
    }
}

/// A controller event in words (ISO 11898-1 §12.1.4 fault confinement states).
fn controller_words(event: ControllerEvent) -> &'static str {
    match event {
        ControllerEvent::ErrorPassive => "error passive",
        ControllerEvent::ErrorActive => "error active",
        ControllerEvent::BusOff => "bus-off",
        ControllerEvent::BusOffRecovered => "bus-off recovered",
        ControllerEvent::RxOverrun => "receive overrun",
        ControllerEvent::TxDropped => "transmit frame dropped",
    }
}

/// The field of `kind` that carries PDO value `v`.
fn pdo_field<'a>(kind: Option<&'a DeviceKind>, v: &crate::LiveValue) -> Option<&'a Field> {
    kind?
        .pdos
        .iter()
        .filter(|l| l.pdo == v.pdo)
        .flat_map(|l| l.fields.iter())
        .find(|f| f.name == v.name)
}

/// PDO value `v` as a number to chart: its field's number (sign-extended where the field is
/// signed); without a field (a value mapped from a dictionary, whose text is the typed value)
/// the number its text reads as, else its raw bits; `None` for values that are no number of
/// at most 64 bits.
fn pdo_number(kind: Option<&DeviceKind>, v: &crate::LiveValue) -> Option<f64> {
    let raw = v.raw?;
    Some(match pdo_field(kind, v) {
        Some(f) => f.number(raw) as f64,
        None => v
            .text
            .parse::<f64>()
            .ok()
            .filter(|n| n.is_finite())
            .unwrap_or(raw as f64),
    })
}

/// The unit of PDO value `v`, where its field names one.
fn pdo_unit(kind: Option<&DeviceKind>, v: &crate::LiveValue) -> String {
    match pdo_field(kind, v).map(|f| &f.format) {
        Some(Format::Unsigned(Some(u)) | Format::Signed(Some(u))) => u.clone(),
        _ => String::new(),
    }
}

/// Whether PDO value `v` can only be zero or more: a field of the kind that is not signed
/// (bits, flags and statuswords are unsigned too). Values without a field (mapped from a
/// dictionary) may be either.
fn pdo_unsigned(kind: Option<&DeviceKind>, v: &crate::LiveValue) -> bool {
    pdo_field(kind, v).is_some_and(|f| !matches!(f.format, Format::Signed(_)))
}

/// The indicator states (CiA 303-3 §3) a dashboard shows: what the bus shows of the node
/// (the view's RUN and ERROR LEDs, `seen`), with what only the simulator knows on top: an
/// unpowered device has both off, a controller that is bus-off lights ERROR, one whose error
/// counters reached the warning limit flashes it once.
pub fn leds(powered: bool, seen: Option<Leds>, c: &ErrorCounters) -> Leds {
    if !powered {
        return Leds {
            run: Led::Off,
            err: Led::Off,
        };
    }
    let run = seen.map_or(Led::Unknown, |l| l.run);
    let err = match c.state() {
        ErrorState::BusOff => Led::On,
        _ if c.tec() >= ErrorCounters::WARNING_LIMIT || c.rec() >= ErrorCounters::WARNING_LIMIT => {
            Led::SingleFlash
        }
        _ => seen.map_or(Led::Off, |l| l.err),
    };
    Leds { run, err }
}

/// The signal value that sets input `input` of `device` to `value` from its live values
/// `values` (the device's signal of the same name): a digital input takes 0 or 1, an analog
/// input a number within its range. The error says why the page's value does not fit.
pub fn input_signal(
    values: &[LiveValue],
    device: &str,
    input: &str,
    value: f64,
) -> Result<SignalValue, String> {
    let role = values.iter().find(|v| v.name == input).map(|v| v.role);
    match role {
        Some(Role::DigitalInput) if value == 0.0 || value == 1.0 => {
            Ok(SignalValue::Bool(value == 1.0))
        }
        Some(Role::DigitalInput) => Err(format!("{input} is a digital input: 0 or 1, not {value}")),
        // Whole numbers go as integers: raw counts (TM3) take nothing else, and the twins
        // that take volts or hertz read integers as numbers too.
        Some(Role::AnalogInput { min, max })
            if (min..=max).contains(&value) && value.fract() == 0.0 =>
        {
            Ok(SignalValue::Integer(value as i64))
        }
        Some(Role::AnalogInput { min, max }) if (min..=max).contains(&value) => {
            Ok(SignalValue::Real(value))
        }
        Some(Role::AnalogInput { min, max }) => Err(format!("{input} is {min}–{max}, not {value}")),
        _ => {
            let inputs: Vec<&str> = values
                .iter()
                .filter(|v| v.role.is_input())
                .map(|v| v.name.as_str())
                .collect();
            if inputs.is_empty() {
                Err(format!("{device} has no inputs"))
            } else {
                Err(format!(
                    "{device} has no input {input:?} (inputs: {})",
                    inputs.join(", ")
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests;
