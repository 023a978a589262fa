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
//! * the frame stream: the last [`STREAM_LEN`] frames, error frames and controller events of
//!   every bus, with who sent them;
//! * a sliding [`WINDOW_S`] window ([`History`]) of each bus's load and frames per second
//!   and of each device's analog live values.
//!
//! The wall time is a [`std::time::Duration`] since the dashboard started, given by the
//! caller: the charts run on it, so they move at the pace the viewer sees even when the
//! simulation runs faster or slower than real time.

pub mod tap;

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration as WallDuration;

use cantwin_bus::{PortId, PortStatus};
use cantwin_can::{BitRate, Duration, ErrorCounters, ErrorState, Frame, Instant};
use cantwin_canopen::wire::{self, ErrorControl, Message};
use cantwin_twin::{LiveValue, Role, SignalValue};

use crate::{Config, DeviceKind, Led, Leds, NetworkView};

pub use tap::{DashboardTap, Seen};

/// The window the series keep, in seconds.
pub const WINDOW_S: f64 = 60.0;
/// Rows kept for the frame stream (and frames kept by each bus's view).
pub const STREAM_LEN: usize = 200;

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

    /// The samples as (seconds before `now`, value), oldest first.
    pub fn points(&self, now: WallDuration) -> Vec<(f64, f64)> {
        self.0
            .iter()
            .map(|(t, v)| (now.saturating_sub(*t).as_secs_f64(), *v))
            .collect()
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
    /// How the bus view reads its PDOs, from the twin itself (an ADV200 in its active
    /// personality), when it is a CANopen node; without it the view takes the built-in
    /// reading of its kind ([`DeviceKind::builtin`]).
    pub monitor_kind: Option<DeviceKind>,
}

/// A bus of the simulation as the model keeps it.
#[derive(Debug)]
struct Bus {
    name: String,
    /// The CANopen model of the bus, fed with the frames of CANopen senders.
    view: NetworkView,
    load: History,
    fps: History,
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
    /// Bus time.
    pub at: Instant,
    /// The index of its bus.
    pub bus: usize,
    /// The frame; `None` for controller events.
    pub frame: Option<Frame>,
    /// Who sent it: a device's name, `"dashboard"` for the dashboard's own ports.
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
    /// Frames per second of wall time since the previous snapshot (0 for the first).
    pub fps: f64,
    /// The load over the window, as (seconds ago, percent), oldest first.
    pub load_history: Vec<(f64, f64)>,
    /// The frames per second over the window, as (seconds ago, 1/s), oldest first.
    pub fps_history: Vec<(f64, f64)>,
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

/// A live value of a device in a snapshot.
#[derive(Debug, Clone)]
pub struct PanelValue {
    /// The value now.
    pub value: LiveValue,
    /// For analog values, the value over the window as (seconds ago, value), oldest first.
    pub history: Option<Vec<(f64, f64)>>,
}

/// A device's panel of live values in a snapshot.
#[derive(Debug, Clone)]
pub struct DevicePanel {
    /// The device's name.
    pub name: String,
    /// Its kind.
    pub kind: String,
    /// Its live values, in the twin's order.
    pub values: Vec<PanelValue>,
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
    /// The frame stream, newest first.
    pub frames: Vec<StreamRow>,
    /// Events the taps could not keep since the dashboard started.
    pub missed: u64,
}

/// The dashboard's model of a running simulation.
#[derive(Debug)]
pub struct Model {
    scenario: String,
    buses: Vec<Bus>,
    devices: Vec<Device>,
    /// The dashboard's own ports (its CANopen masters).
    masters: Vec<PortId>,
    stream: VecDeque<StreamRow>,
    missed: u64,
    values: BTreeMap<(usize, String), History>,
    /// The wall time and frame counts of the previous snapshot.
    last: Option<(WallDuration, Vec<u64>)>,
}

impl Model {
    /// A model of scenario `scenario` with `buses` (name and bit rate), `devices` (their
    /// `bus` indices into `buses`) and the dashboard's own ports `masters`.
    pub fn new(
        scenario: String,
        buses: Vec<(String, BitRate)>,
        devices: Vec<Device>,
        masters: Vec<PortId>,
    ) -> Model {
        let buses = buses
            .into_iter()
            .map(|(name, bit_rate)| Bus {
                name,
                view: NetworkView::new(Config {
                    bit_rate,
                    ring: STREAM_LEN,
                    ..Config::default()
                }),
                load: History::default(),
                fps: History::default(),
            })
            .collect();
        Model {
            scenario,
            buses,
            devices,
            masters,
            stream: VecDeque::new(),
            missed: 0,
            values: BTreeMap::new(),
            last: None,
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

    /// Takes in what was read from the simulation and answers what the dashboard shows.
    pub fn update(&mut self, sample: Sample) -> Snapshot {
        let Sample {
            now,
            wall,
            events,
            buses: bus_stats,
            devices: live,
        } = sample;
        // The node-IDs the twins know (before any boot-up is seen, and for nodes that send
        // no heartbeat).
        for (k, l) in live.iter().enumerate() {
            if let (Some(node), Some(d)) = (l.node_id, self.devices.get(k))
                && d.node_id.is_none()
            {
                self.name_node(k, node);
            }
        }
        for (i, (seen, missed)) in events.into_iter().enumerate() {
            self.missed += missed;
            self.absorb(i, seen);
            if let Some(b) = self.buses.get_mut(i) {
                b.view.advance(now);
            }
        }
        let buses = self.sample_buses(wall, &bus_stats);
        let mut nodes = Vec::new();
        let mut panels = Vec::new();
        for (k, (d, l)) in self.devices.iter().zip(live).enumerate() {
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
            let values = l
                .values
                .into_iter()
                .map(|v| {
                    let history = v.role.is_analog().then(|| {
                        let h = self.values.entry((k, v.name.clone())).or_default();
                        h.push(wall, v.value);
                        h.points(wall)
                    });
                    PanelValue { value: v, history }
                })
                .collect();
            panels.push(DevicePanel {
                name: d.name.clone(),
                kind: d.kind.clone(),
                values,
            });
        }
        Snapshot {
            scenario: self.scenario.clone(),
            now,
            uptime: wall,
            buses,
            nodes,
            devices: panels,
            frames: self.stream.iter().rev().cloned().collect(),
            missed: self.missed,
        }
    }

    /// The buses' rows of a snapshot at `wall`: frames per second since the previous one,
    /// and the series extended.
    fn sample_buses(&mut self, wall: WallDuration, stats: &[BusSample]) -> Vec<BusSnapshot> {
        let elapsed = self
            .last
            .as_ref()
            .map(|(t, _)| wall.saturating_sub(*t).as_secs_f64());
        let mut rows = Vec::new();
        for (i, (bus, s)) in self.buses.iter_mut().zip(stats).enumerate() {
            let fps = match (&self.last, elapsed) {
                (Some((_, before)), Some(dt)) if dt > 0.0 => {
                    s.frames.saturating_sub(before.get(i).copied().unwrap_or(0)) as f64 / dt
                }
                _ => 0.0,
            };
            bus.load.push(wall, s.load_percent);
            bus.fps.push(wall, fps);
            rows.push(BusSnapshot {
                name: bus.name.clone(),
                bit_rate: s.bit_rate,
                frames: s.frames,
                error_frames: s.error_frames,
                load: s.load_percent,
                fps,
                load_history: bus.load.points(wall),
                fps_history: bus.fps.points(wall),
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
        } else {
            format!("{port:?}")
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
                    let canopen = self.speaks_canopen(sender);
                    let mut text = String::new();
                    if canopen && !dropped {
                        self.learn(&frame, sender);
                        if let Some(b) = self.buses.get_mut(bus) {
                            b.view.push(at, &frame);
                            text = b
                                .view
                                .frames()
                                .next_back()
                                .map(|e| e.text.clone())
                                .unwrap_or_default();
                        }
                    }
                    self.push_row(StreamRow {
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
                    at,
                    bus,
                    frame: Some(frame),
                    from: self.name_of(sender),
                    text: format!("error frame: {kind:?}"),
                    kind: RowKind::Error,
                }),
                Seen::Controller { at, port, event } => {
                    let from = self.name_of(port);
                    self.push_row(StreamRow {
                        at,
                        bus,
                        frame: None,
                        from,
                        text: format!("controller: {event:?}"),
                        kind: RowKind::Controller,
                    });
                }
            }
        }
    }

    fn push_row(&mut self, row: StreamRow) {
        self.stream.push_back(row);
        while self.stream.len() > STREAM_LEN {
            self.stream.pop_front();
        }
    }

    /// Whether frames from `port` are CANopen (the dashboard's master, or a device of a
    /// CANopen kind): other protocols on the same identifiers mean other things.
    fn speaks_canopen(&self, port: PortId) -> bool {
        if self.masters.contains(&port) {
            return true;
        }
        self.devices
            .iter()
            .find(|d| d.port == port)
            .is_some_and(|d| {
                matches!(
                    d.kind.as_str(),
                    "cia301" | "eds" | "tm3" | "adv200" | "master"
                )
            })
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
