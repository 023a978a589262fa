//! A live model of a CANopen network, fed with timestamped frames and free of I/O, for
//! monitors (`cantwin monitor`, a web dashboard): whatever reads the bus calls
//! [`NetworkView::push`] with each frame and its bus time, and [`NetworkView::advance`] when
//! time passes without frames; whatever draws reads the model.
//!
//! The model keeps:
//!
//! * a node table ([`NodeInfo`]): name and kind (given by the front end, e.g. from a
//!   scenario, or learned from SDO answers about 0x1000/0x1008/0x1018 seen on the bus), NMT
//!   state from boot-up/heartbeat/guarding, heartbeat age, error register, the last EMCY
//!   with its meaning, and the CiA 303-3 LED states ([`NodeInfo::leds`]);
//! * a bounded ring of decoded frames ([`FrameEntry`], decoded as `cantwin trace` does),
//!   read through a [`Filter`] by node, service and identifier range;
//! * the fixed trace ([`FixedTrace`]): one row per identifier with its count, cycle times,
//!   changed bytes and last frame decoded;
//! * the bus load and frames per second per time window ([`LoadSeries`]);
//! * per-device live values from PDOs, where the device's [`DeviceKind`] tells how its PDOs
//!   read.
//!
//! [`dashboard`] is the model behind the web dashboard of a simulated network: one view per
//! bus beside what only the simulator knows (power, controller state, the twins' live
//! values), the frame stream and the charts' series.
//!
//! ```
//! use cantwin_can::{Frame, Id, Instant};
//! use cantwin_canopen::wire::NmtState;
//! use cantwin_monitor::{Config, NetworkView, kind::DeviceKind, node::Led};
//!
//! let mut view = NetworkView::new(Config::default());
//! view.declare(12, Some("drive".into()), Some(DeviceKind::adv200_example()));
//! let f = |id: u16, data: &[u8]| Frame::data(Id::standard(id).unwrap(), data).unwrap();
//! let ms = |v: u64| Instant::from_nanos(v * 1_000_000);
//! view.push(ms(0), &f(0x70C, &[0x00]));                       // boot-up
//! view.push(ms(10), &f(0x000, &[0x01, 12]));                  // NMT start node 12
//! view.push(ms(100), &f(0x70C, &[0x05]));                     // heartbeat: operational
//! view.push(ms(110), &f(0x18C, &[0x03, 0x00, 0xDC, 0x05, 0, 0])); // TPDO1
//! view.push(ms(120), &f(0x08C, &[0x30, 0x81, 0x11, 0, 0, 0, 0, 0])); // EMCY
//!
//! let drive = view.node(12).unwrap();
//! assert_eq!(drive.nmt(), Some(NmtState::Operational));
//! assert_eq!(drive.leds(view.now()).run, Led::On);
//! assert_eq!(drive.last_emcy.as_ref().unwrap().meaning(), "life guard error or heartbeat error");
//! assert_eq!(drive.leds(view.now()).err, Led::DoubleFlash);
//! assert_eq!(drive.value("motor speed").unwrap().text, "1500 rpm");
//! assert_eq!(view.frames().count(), 5);
//! ```
#![forbid(unsafe_code)]

pub mod dashboard;
pub mod filter;
pub mod fixed_trace;
pub mod kind;
pub mod load;
pub mod node;

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use cantwin_can::{BitRate, Duration, Frame, Instant};
use cantwin_canopen::master::pdo::PdoDecoder;
use cantwin_canopen::wire::{self, ErrorControl, Message, NmtCs, NmtState};
use cantwin_report::canopen::{describe, describe_pdo};
use cantwin_report::sdo::{Outcome, Tracker, Transfer};

pub use filter::{Filter, Service};
pub use fixed_trace::FixedTrace;
pub use kind::{DeviceKind, LiveValue};
pub use load::{LoadSeries, Window};
pub use node::{EmcyEvent, Identity, Led, Leds, NodeInfo};

/// How a [`NetworkView`] measures and how much it keeps.
#[derive(Debug, Clone)]
pub struct Config {
    /// The bus bit rate, for the load.
    pub bit_rate: BitRate,
    /// Width of a load window.
    pub window: Duration,
    /// Load windows kept (the chart's history).
    pub windows: usize,
    /// Decoded frames kept; older ones are dropped and counted.
    pub ring: usize,
    /// Identifiers the fixed trace keeps rows for (see [`FixedTrace`]).
    pub fixed_rows: usize,
    /// PDO mappings from EDS files, to name PDO values in the frame text (see
    /// `cantwin_report::canopen::add_eds_pdos`); a node's [`DeviceKind`] names the rest.
    pub pdos: PdoDecoder,
}

impl Default for Config {
    /// 500 kbit/s, 100 ms windows, one minute of them, 10 000 frames, 4096 identifiers.
    fn default() -> Self {
        Config {
            // One default with the capture report: captures and sockets do not say the rate.
            bit_rate: cantwin_report::DEFAULT_BIT_RATE,
            window: Duration::from_millis(100),
            windows: 600,
            ring: 10_000,
            fixed_rows: FixedTrace::DEFAULT_CAPACITY,
            pdos: PdoDecoder::new(),
        }
    }
}

/// One frame of the ring, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameEntry {
    /// Its number since the view started (0 for the first frame).
    pub seq: u64,
    /// Bus time.
    pub at: Instant,
    /// The frame.
    pub frame: Frame,
    /// Its service.
    pub service: Service,
    /// The node it is about, if any (see [`filter::node_of`]).
    pub node: Option<u8>,
    /// A one-line decoding.
    pub text: String,
}

impl FrameEntry {
    /// Whether it passes `filter`.
    pub fn matches(&self, filter: &Filter) -> bool {
        filter.matches(self.frame.id().as_raw(), self.service, self.node)
    }
}

/// The live model of one bus.
#[derive(Debug)]
pub struct NetworkView {
    config: Config,
    nodes: BTreeMap<u8, NodeInfo>,
    ring: VecDeque<FrameEntry>,
    fixed: FixedTrace,
    seq: u64,
    load: LoadSeries,
    now: Instant,
    sdo: BTreeMap<u8, Tracker>,
    /// Nodes a guard request was sent to that have not answered yet.
    guard_pending: BTreeSet<u8>,
}

/// The values of a PDO that `pdos` maps, named from the dictionary description.
fn mapped_values(frame: &Frame, pdo: wire::PdoKind, pdos: &PdoDecoder) -> Vec<LiveValue> {
    let Some(Ok(values)) = pdos.decode(frame) else {
        return Vec::new();
    };
    values
        .into_iter()
        .map(|v| {
            use cantwin_canopen::od::Value as V;
            let raw = match v.value {
                V::Boolean(b) => Some(u64::from(b)),
                V::Unsigned8(n) => Some(u64::from(n)),
                V::Unsigned16(n) => Some(u64::from(n)),
                V::Unsigned24(n) | V::Unsigned32(n) => Some(u64::from(n)),
                V::Unsigned40(n) | V::Unsigned48(n) | V::Unsigned56(n) | V::Unsigned64(n) => {
                    Some(n)
                }
                // Two's complement bits of the type's width, as on the wire.
                V::Integer8(n) => Some(u64::from(n as u8)),
                V::Integer16(n) => Some(u64::from(n as u16)),
                V::Integer24(n) => Some(u64::from(n as u32 & 0xFF_FFFF)),
                V::Integer32(n) => Some(u64::from(n as u32)),
                V::Integer40(n) => Some(n as u64 & 0xFF_FFFF_FFFF),
                V::Integer48(n) => Some(n as u64 & 0xFFFF_FFFF_FFFF),
                V::Integer56(n) => Some(n as u64 & 0xFF_FFFF_FFFF_FFFF),
                V::Integer64(n) => Some(n as u64),
                _ => None,
            };
            LiveValue {
                name: v.name,
                pdo,
                raw,
                text: v.value.to_string(),
            }
        })
        .collect()
}

/// The little-endian unsigned value of up to 4 bytes of SDO data.
fn le_u32(data: &[u8]) -> Option<u32> {
    (!data.is_empty() && data.len() <= 4).then(|| {
        data.iter()
            .rev()
            .fold(0u32, |acc, b| (acc << 8) | u32::from(*b))
    })
}

impl NetworkView {
    /// An empty view.
    pub fn new(config: Config) -> NetworkView {
        let load = LoadSeries::new(config.bit_rate, config.window, config.windows);
        let fixed = FixedTrace::new(config.fixed_rows);
        NetworkView {
            fixed,
            config,
            nodes: BTreeMap::new(),
            ring: VecDeque::new(),
            seq: 0,
            load,
            now: Instant::ZERO,
            sdo: BTreeMap::new(),
            guard_pending: BTreeSet::new(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Tell the view about node `id` before (or after) it is heard: a name to show and its
    /// kind. A given kind is kept even if the bus suggests another.
    pub fn declare(&mut self, id: u8, name: Option<String>, kind: Option<DeviceKind>) {
        let node = self.node_entry(id);
        if name.is_some() {
            node.name = name;
        }
        if let Some(k) = kind {
            node.kind = Some(k);
            node.kind_given = true;
        }
    }

    /// Tell the view node `id`'s device type (0x1000) when the front end knows it (a
    /// scenario's twin): its kind column shows the device profile until the bus says more.
    pub fn declare_device_type(&mut self, id: u8, device_type: u32) {
        let node = self.node_entry(id);
        node.device_type = Some(device_type);
        if !node.kind_given
            && node.kind.is_none()
            && let Some(k) = DeviceKind::identify(Some(device_type), node.device_name.as_deref())
        {
            node.kind = Some(k);
        }
    }

    fn node_entry(&mut self, id: u8) -> &mut NodeInfo {
        self.nodes.entry(id).or_insert_with(|| NodeInfo::new(id))
    }

    /// The latest bus time seen.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// Let bus time pass without frames (heartbeat ages grow, load windows close).
    pub fn advance(&mut self, now: Instant) {
        if now > self.now {
            self.now = now;
        }
        self.load.advance(self.now);
    }

    /// A frame that ended on the bus at `at`.
    pub fn push(&mut self, at: Instant, frame: &Frame) {
        self.advance(at);
        self.load.record(at, frame);
        let msg = wire::decode(frame);
        let service = Service::of(&msg);
        let node = filter::node_of(&msg);
        // Nodes come into the table by what only a node sends: error control, EMCY and
        // SDO responses; other frames about a node count only once it is there.
        let producer = matches!(
            msg,
            Message::ErrorControl(ErrorControl::State { .. })
                | Message::Emcy { .. }
                | Message::SdoResponse { .. }
        );
        if let Some(n) = node {
            if producer {
                self.node_entry(n);
            }
            if let Some(info) = self.nodes.get_mut(&n) {
                info.frames += 1;
            }
        }
        let mut text = None;
        match msg {
            Message::Nmt(cmd) => {
                // CiA 301 §7.3.2.2.1: the state a command puts an addressed node in; a
                // reset ends in a boot-up, which the node reports itself.
                let state = match cmd.cs {
                    NmtCs::Start => Some(NmtState::Operational as u8),
                    NmtCs::Stop => Some(NmtState::Stopped as u8),
                    NmtCs::EnterPreOperational => Some(NmtState::PreOperational as u8),
                    NmtCs::ResetNode | NmtCs::ResetCommunication => None,
                };
                for info in self.nodes.values_mut().filter(|i| cmd.addresses(i.id)) {
                    info.state = state;
                    info.state_commanded = true;
                }
            }
            Message::ErrorControl(ErrorControl::GuardRequest { node }) => {
                self.guard_pending.insert(node);
            }
            Message::ErrorControl(ErrorControl::State {
                node,
                state,
                toggle,
            }) => {
                // CiA 301 §7.2.8.3.2.1: the answer to a guard request; its first toggle is 0,
                // so only the request tells it from a heartbeat then.
                let guarded = self.guard_pending.remove(&node) || toggle;
                let info = self.node_entry(node);
                if state != 0 {
                    info.guarded = guarded;
                    text = Some(cantwin_report::canopen::error_control(
                        node, state, toggle, guarded,
                    ));
                }
                if state == 0 {
                    info.boot_ups += 1;
                    // A boot-up restarts the heartbeat: the gap before it is no period.
                    info.heartbeat_period = None;
                } else if let Some(last) = info.last_heartbeat
                    && !info.state_commanded
                    && info.state.is_some_and(|s| s != 0)
                {
                    info.heartbeat_period = Some(Duration::from_nanos(
                        at.as_nanos().saturating_sub(last.as_nanos()),
                    ));
                }
                info.state = Some(state);
                info.state_commanded = false;
                info.last_heartbeat = Some(at);
            }
            Message::Emcy { node, emcy } => {
                let info = self.node_entry(node);
                info.emcy_count += 1;
                info.error_register = Some(emcy.register);
                // CiA 301 §7.2.7.1: code 0x0000 ("error reset or no error") ends the
                // error; so does a cleared error register.
                if emcy.code == 0 || emcy.register == 0 {
                    info.emcy_active = false;
                }
                if emcy.code != 0 {
                    info.last_emcy = Some(EmcyEvent {
                        at,
                        code: emcy.code,
                        register: emcy.register,
                        manufacturer: emcy.manufacturer,
                    });
                    info.emcy_active = emcy.register != 0;
                }
            }
            Message::SdoRequest { node, data, len: 8 } => {
                let done =
                    self.sdo
                        .entry(node)
                        .or_default()
                        .on_request(at.as_nanos(), "", node, &data);
                self.learn(&done);
            }
            Message::SdoResponse { node, data, len: 8 } => {
                let done =
                    self.sdo
                        .entry(node)
                        .or_default()
                        .on_response(at.as_nanos(), "", node, &data);
                self.learn(&done);
            }
            Message::Pdo { kind, node, .. } => {
                let pdos = &self.config.pdos;
                if let Some(info) = self.nodes.get_mut(&node) {
                    let values = match info.kind.as_ref().and_then(|k| k.decode(frame, node)) {
                        Some(values) => {
                            let parts: Vec<String> = values
                                .iter()
                                .map(|v| format!("{}={}", v.name, v.text))
                                .collect();
                            text = Some(format!(
                                "{} node {node}: {}",
                                kind::pdo_label(kind),
                                parts.join(" ")
                            ));
                            values
                        }
                        // No layout of the kind: the mappings the front end gave (an EDS, a
                        // twin's dictionary) name the values.
                        None => mapped_values(frame, kind, pdos),
                    };
                    for v in values {
                        match info.values.iter_mut().find(|(old, _)| old.name == v.name) {
                            Some(slot) => *slot = (v, at),
                            None => info.values.push((v, at)),
                        }
                    }
                    if let Some(k) = &info.kind {
                        // Keep the kind's field order, whatever order the PDOs came in.
                        let order = |name: &str| {
                            k.pdos
                                .iter()
                                .flat_map(|l| l.fields.iter())
                                .position(|f| f.name == name)
                        };
                        info.values.sort_by_key(|(v, _)| order(&v.name));
                    }
                }
            }
            _ => {}
        }
        let mut text = match text {
            // An EDS mapping the front end gave wins over the kind's defaults (only PDO
            // texts can be shadowed by one).
            Some(t) if describe_pdo(frame, &self.config.pdos).is_none() => t,
            _ => describe(frame, &self.config.pdos),
        };
        if let Message::Emcy { node, emcy } = msg
            && let Some(own) = self
                .nodes
                .get(&node)
                .and_then(|n| n.kind.as_ref())
                .and_then(|k| k.emcy_meaning(emcy.code))
        {
            // The device's manual says more than CiA 301 table 21.
            let generic = format!("({})", cantwin_report::canopen::emcy_meaning(emcy.code));
            text = text.replacen(&generic, &format!("({own})"), 1);
        }
        let entry = FrameEntry {
            seq: self.seq,
            at,
            frame: *frame,
            service,
            node,
            text,
        };
        self.fixed.record(&entry);
        self.ring.push_back(entry);
        self.seq += 1;
        while self.ring.len() > self.config.ring.max(1) {
            self.ring.pop_front();
        }
    }

    /// What completed SDO transfers tell about the nodes (CiA 301 §7.5.2: 0x1000 device
    /// type, 0x1001 error register, 0x1008 device name, 0x1018 identity).
    fn learn(&mut self, done: &[Transfer]) {
        for t in done {
            if t.outcome != Outcome::Done || t.direction.is_none() {
                continue;
            }
            let info = self.node_entry(t.node);
            match (t.index, t.sub) {
                (0x1000, 0) => info.device_type = le_u32(&t.data).or(info.device_type),
                (0x1001, 0) => info.error_register = t.data.first().copied(),
                (0x1008, 0) => {
                    let name = String::from_utf8_lossy(&t.data);
                    let name = name.trim_end_matches('\0').trim();
                    if !name.is_empty() {
                        info.device_name = Some(name.to_string());
                    }
                }
                (0x1018, 1) => info.identity.vendor_id = le_u32(&t.data),
                (0x1018, 2) => info.identity.product_code = le_u32(&t.data),
                (0x1018, 3) => info.identity.revision = le_u32(&t.data),
                (0x1018, 4) => info.identity.serial = le_u32(&t.data),
                _ => continue,
            }
            if !info.kind_given
                && let Some(k) = DeviceKind::identify(info.device_type, info.device_name.as_deref())
            {
                info.kind = Some(k);
            }
        }
    }

    /// The nodes, by node-ID.
    pub fn nodes(&self) -> impl DoubleEndedIterator<Item = &NodeInfo> + ExactSizeIterator {
        self.nodes.values()
    }

    /// Node `id`, if known.
    pub fn node(&self, id: u8) -> Option<&NodeInfo> {
        self.nodes.get(&id)
    }

    /// The frames kept, oldest first.
    pub fn frames(&self) -> impl DoubleEndedIterator<Item = &FrameEntry> + ExactSizeIterator {
        self.ring.iter()
    }

    /// The frames kept that pass `filter`, oldest first.
    pub fn filtered<'a>(
        &'a self,
        filter: &'a Filter,
    ) -> impl DoubleEndedIterator<Item = &'a FrameEntry> + 'a {
        self.ring.iter().filter(move |e| e.matches(filter))
    }

    /// Frames seen since the view started.
    pub fn total_frames(&self) -> u64 {
        self.seq
    }

    /// Frames dropped from the ring to keep it bounded.
    pub fn dropped_frames(&self) -> u64 {
        self.seq - self.ring.len() as u64
    }

    /// The fixed trace: one row per identifier seen.
    pub fn fixed_trace(&self) -> &FixedTrace {
        &self.fixed
    }

    /// Forget the fixed trace's rows (counts and cycle times start again).
    pub fn clear_fixed_trace(&mut self) {
        self.fixed.clear();
    }

    /// Bus load and frames per window.
    pub fn load(&self) -> &LoadSeries {
        &self.load
    }
}

#[cfg(test)]
mod tests;
