//! CANopen macro benchmarks: a realistic CiA 301 network, a fleet of such networks, SDO
//! round trips and transfer efficiency, and the memory a device takes.
//!
//! The figures are computed here rather than in the bus crate because the bus crate must not
//! depend on the CANopen stack.

use std::sync::Arc;

use anyhow::{Context, Result, anyhow, bail};
use cantwin_bus::{BusConfig, BusId, PortConfig, Recorder, Simulation, TxOrder};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, OdDescription, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_canopen::sdo::wire::{BlockSegment, Initiate, Mux, Request, Response};

use super::trials::Trial;

/// Devices on one network of the `network` and `fleet` benchmarks.
pub const NETWORK_DEVICES: u8 = 64;
/// The SYNC period (0x1006) of the network.
pub const SYNC_PERIOD: Duration = Duration::from_millis(10);
/// The producer heartbeat time (0x1017) of every device, in ms.
pub const HEARTBEAT_MS: u16 = 100;

/// The application object mapped into the TPDO: four UNSIGNED16 inputs.
const INPUTS: u16 = 0x6000;

/// The dictionary of a network device: the CiA 301 defaults, four mappable UNSIGNED16
/// inputs, and TPDO 1 mapping all four (8 bytes) with transmission type 1, sent at every
/// SYNC (CiA 301 §7.2.2.2).
pub fn network_description() -> Result<OdDescription> {
    let word = SubObject::new("Input", DataType::Unsigned16, Access::Ro).mappable();
    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .array_of(INPUTS, "Inputs", 4, word);
    let mapping: Vec<u32> = (1..=4u32)
        .map(|k| (u32::from(INPUTS) << 16) | (k << 8) | 0x10)
        .collect();
    let pdos = PdoObjects::new(0, 1).max_entries(4).tpdo(0, 1, &mapping);
    pdos.add_to(b)
        .build()
        .map_err(|e| anyhow!("network device dictionary: {e}"))
}

/// The dictionary of a device with 4 RPDOs and 4 TPDOs of four UNSIGNED16 entries each.
pub fn pdo_4_4_description() -> Result<OdDescription> {
    let word = SubObject::new("Word", DataType::Unsigned16, Access::Rw).mappable();
    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .array_of(0x6000, "Inputs", 16, word.clone())
        .array_of(0x6200, "Outputs", 16, word);
    let mut pdos = PdoObjects::new(4, 4).max_entries(4);
    for n in 0..4u16 {
        let entry = |index: u16, k: u32| {
            (u32::from(index) << 16) | ((u32::from(n) * 4 + k + 1) << 8) | 0x10
        };
        let tx: Vec<u32> = (0..4).map(|k| entry(0x6000, k)).collect();
        let rx: Vec<u32> = (0..4).map(|k| entry(0x6200, k)).collect();
        pdos = pdos.tpdo(n, 1, &tx).rpdo(n, 255, &rx);
    }
    pdos.add_to(b)
        .build()
        .map_err(|e| anyhow!("4+4 PDO dictionary: {e}"))
}

/// Which frames reach a network device's `on_frame`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filtering {
    /// Only the identifiers this device consumes, listed by hand as firmware would program
    /// the controller's acceptance filter: NMT (0x000), SYNC (0x080), TIME (0x100), its SDO
    /// request (0x600 + node) and node guarding remote request (0x700 + node). The network
    /// devices have no RPDO, no heartbeat consumer and no EMCY consumer, so nothing else is
    /// for them.
    Firmware,
    /// The bus asks the `Device` itself ([`Node::accepts`]), which derives its filter from
    /// its COB-IDs.
    Device,
    /// Every frame is handed to every device (a driver that never asks `accepts`); the
    /// device skips the frames its filter does not pass.
    Everything,
    /// Every frame is handed to every device, whose own filter is off: each frame goes
    /// through the whole stack (the behaviour before devices filtered).
    Unfiltered,
}

/// A network device: a CiA 301 [`Device`] whose 0x1017 is set to [`HEARTBEAT_MS`] at
/// power-up, and whose events are drained after every call as an application would.
struct NetDevice {
    device: Device,
    filtering: Filtering,
}

impl NetDevice {
    fn drain(&mut self) {
        while self.device.poll_event().is_some() {}
    }
}

impl Node for NetDevice {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.device.on_power_up(now, out);
        // Through ObjectAccess, as an SDO download would, so the producer starts at once.
        let _ = self.device.write(0x1017, 0, &HEARTBEAT_MS.to_le_bytes());
        self.drain();
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.device.on_frame(frame, now, out);
        self.drain();
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.device.on_tick(now, out);
        self.drain();
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.device.next_deadline()
    }
    fn accepts(&self, id: Id) -> bool {
        match self.filtering {
            Filtering::Device => self.device.accepts(id),
            Filtering::Everything | Filtering::Unfiltered => true,
            Filtering::Firmware => {
                let Id::Standard(id) = id else {
                    return false;
                };
                let node = u16::from(self.device.node_id());
                let raw = id.as_raw();
                matches!(raw, 0x000 | 0x080 | 0x100) || raw == 0x600 + node || raw == 0x700 + node
            }
        }
    }
    fn acceptance_version(&self) -> Option<u64> {
        match self.filtering {
            Filtering::Device => self.device.acceptance_version(),
            // Fixed filters.
            Filtering::Firmware | Filtering::Everything | Filtering::Unfiltered => Some(0),
        }
    }
}

/// A `network` device with node-ID `node` that the bus asks for its own acceptance filter
/// ([`Filtering::Device`]), for other benchmarks' baselines.
pub fn network_device(desc: &Arc<OdDescription>, node: u8) -> Result<impl Node + Send + 'static> {
    Ok(NetDevice {
        device: Device::new(Arc::clone(desc), DeviceConfig::new(node))?,
        filtering: Filtering::Device,
    })
}

/// The network's master: NMT start of all nodes at power-up (CiA 301 §7.2.8.3.1.1), then a
/// SYNC without counter every [`SYNC_PERIOD`] (§7.2.5).
struct SyncMaster {
    next_sync: Instant,
    syncs: u64,
}

impl Node for SyncMaster {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        if let Ok(f) = Frame::std(0x000, &[0x01, 0x00]) {
            out.push(f);
        }
        self.next_sync = now + SYNC_PERIOD;
    }
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while self.next_sync <= now {
            if let Ok(f) = Frame::std(0x080, &[]) {
                out.push(f);
            }
            self.syncs += 1;
            self.next_sync += SYNC_PERIOD;
        }
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(self.next_sync)
    }
    fn accepts(&self, _: Id) -> bool {
        false
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// Build `buses` networks into `sim`, each of [`NETWORK_DEVICES`] devices and a master.
fn add_networks(
    sim: &mut Simulation,
    desc: &Arc<OdDescription>,
    buses: usize,
    filtering: Filtering,
) -> Result<Vec<BusId>> {
    let mut ids = Vec::with_capacity(buses);
    for b in 0..buses {
        let bus = sim.add_bus(BusConfig::new(format!("can{b}"), BitRate::R1M));
        sim.attach(
            bus,
            SyncMaster {
                next_sync: Instant::ZERO,
                syncs: 0,
            },
            PortConfig::default(),
        )?;
        for node in 1..=NETWORK_DEVICES {
            let config = DeviceConfig {
                acceptance_filter: filtering != Filtering::Unfiltered,
                ..DeviceConfig::new(node)
            };
            let device = Device::new(Arc::clone(desc), config)?;
            sim.attach(bus, NetDevice { device, filtering }, PortConfig::default())?;
        }
        ids.push(bus);
    }
    Ok(ids)
}

/// What a run of one or more networks measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkReport {
    /// Networks (buses) simulated.
    pub buses: usize,
    /// Threads they were spread over.
    pub threads: usize,
    /// Bus time simulated.
    pub bus_time: Duration,
    /// Wall time of the run (the slowest thread), without building.
    pub wall_time: std::time::Duration,
    /// Wall time to build the networks.
    pub build_time: std::time::Duration,
    /// Frames delivered on all buses.
    pub frames: u64,
    /// Bus load of the first bus over the run, percent.
    pub bus_load_percent: f64,
}

impl NetworkReport {
    /// Bus time over wall time.
    pub fn real_time_factor(&self) -> f64 {
        self.bus_time.as_secs_f64() / self.wall_time.as_secs_f64().max(1e-9)
    }

    /// Wall nanoseconds per delivered frame.
    pub fn ns_per_frame(&self) -> f64 {
        self.wall_time.as_nanos() as f64 / self.frames.max(1) as f64
    }
}

impl Trial for NetworkReport {
    fn wall(&self) -> std::time::Duration {
        self.wall_time
    }
    fn with_wall(&self, wall: std::time::Duration) -> Self {
        NetworkReport {
            wall_time: wall,
            ..*self
        }
    }
    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![("delivered frames", self.frames)]
    }
}

/// Simulate `buses` networks in one [`Simulation`] for `duration`.
pub fn run_networks(
    buses: usize,
    duration: Duration,
    filtering: Filtering,
) -> Result<NetworkReport> {
    let desc = Arc::new(network_description()?);
    let started = std::time::Instant::now();
    let mut sim = Simulation::new();
    let ids = add_networks(&mut sim, &desc, buses, filtering)?;
    let build_time = started.elapsed();
    let end = Instant::ZERO + duration;
    let started = std::time::Instant::now();
    sim.run_until(end);
    let wall_time = started.elapsed();
    let frames = ids
        .iter()
        .filter_map(|&b| sim.bus(b))
        .map(|b| b.stats().frames())
        .sum();
    let bus_load_percent = ids
        .first()
        .and_then(|&b| sim.bus(b))
        .map_or(0.0, |b| b.stats().load_percent(end));
    Ok(NetworkReport {
        buses,
        threads: 1,
        bus_time: duration,
        wall_time,
        build_time,
        frames,
        bus_load_percent,
    })
}

/// Simulate `buses` networks spread over `threads` threads, one [`Simulation`] each.
pub fn run_networks_threaded(
    buses: usize,
    threads: usize,
    duration: Duration,
    filtering: Filtering,
) -> Result<NetworkReport> {
    let threads = threads.clamp(1, buses.max(1));
    let shares: Vec<usize> = (0..threads)
        .map(|t| buses / threads + usize::from(t < buses % threads))
        .collect();
    let reports: Vec<Result<NetworkReport>> = std::thread::scope(|s| {
        let handles: Vec<_> = shares
            .iter()
            .map(|&n| s.spawn(move || run_networks(n, duration, filtering)))
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(anyhow!("a benchmark thread panicked")))
            })
            .collect()
    });
    let mut total = NetworkReport {
        buses,
        threads,
        bus_time: duration,
        wall_time: std::time::Duration::ZERO,
        build_time: std::time::Duration::ZERO,
        frames: 0,
        bus_load_percent: 0.0,
    };
    for (i, r) in reports.into_iter().enumerate() {
        let r = r?;
        total.wall_time = total.wall_time.max(r.wall_time);
        total.build_time = total.build_time.max(r.build_time);
        total.frames += r.frames;
        if i == 0 {
            total.bus_load_percent = r.bus_load_percent;
        }
    }
    Ok(total)
}

/// The largest number of networks that runs at a real-time factor of at least 1, found by
/// trials of `duration` each, starting from an estimate from `single` (one network's
/// real-time factor). Returns the best passing trial and every trial made.
pub fn find_fleet(
    single_rtf: f64,
    threads: usize,
    duration: Duration,
    filtering: Filtering,
    mut progress: impl FnMut(&NetworkReport),
) -> Result<(Option<NetworkReport>, Vec<NetworkReport>)> {
    let mut trials = Vec::new();
    let mut best: Option<NetworkReport> = None;
    let mut lowest_fail: Option<usize> = None;
    // A little below the linear estimate: more buses mean more cache misses.
    let mut n = ((single_rtf * threads as f64 * 0.9) as usize).max(1);
    for _ in 0..10 {
        let r = run_networks_threaded(n, threads, duration, filtering)?;
        progress(&r);
        trials.push(r);
        let rtf = r.real_time_factor();
        if rtf >= 1.0 {
            if best.is_none_or(|b| b.buses < n) {
                best = Some(r);
            }
        } else if lowest_fail.is_none_or(|f| n < f) {
            lowest_fail = Some(n);
        }
        let low = best.map_or(0, |b| b.buses);
        // The cost per network grows with their number (caches), so a linear rescale
        // overshoots: rescale until both a passing and a failing count are known, then
        // bisect between them.
        let next = match lowest_fail {
            Some(f) if low > 0 => low + (f - low) / 2,
            Some(f) => (((n as f64) * rtf * 0.9) as usize).clamp(1, f.saturating_sub(1).max(1)),
            None => (((n as f64) * rtf * 0.98) as usize).max(n + 1),
        };
        // Done: within 2 % (or 1) of a failing count, or nothing left to try.
        if let Some(f) = lowest_fail
            && (next <= low || next >= f || (f - low) * 50 <= f || f - low <= 1)
        {
            break;
        }
        n = next;
    }
    Ok((best, trials))
}

/// What the expedited part of the `sdo` benchmark measured: one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpeditedReport {
    /// Expedited upload round trips completed.
    pub round_trips: u64,
    /// Their wall time.
    pub wall_time: std::time::Duration,
    /// Bus time they took.
    pub bus_time: Duration,
}

impl ExpeditedReport {
    /// Round trips per wall second.
    pub fn round_trips_per_wall_second(&self) -> f64 {
        self.round_trips as f64 / self.wall_time.as_secs_f64().max(1e-9)
    }

    /// Round trips per bus second.
    pub fn round_trips_per_bus_second(&self) -> f64 {
        self.round_trips as f64 / self.bus_time.as_secs_f64().max(1e-9)
    }
}

impl Trial for ExpeditedReport {
    fn wall(&self) -> std::time::Duration {
        self.wall_time
    }
    fn with_wall(&self, wall: std::time::Duration) -> Self {
        ExpeditedReport {
            wall_time: wall,
            ..*self
        }
    }
    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![("round trips", self.round_trips)]
    }
}

/// What the bulk transfers of the `sdo` benchmark measured, all in simulated time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferReport {
    /// Bytes moved by each of the transfers.
    pub bulk_bytes: usize,
    /// Segmented download: data-segment bits over all bits on the bus.
    pub segmented_fraction: f64,
    /// Segmented download: bus time, from the first frame to the last one's end.
    pub segmented_bus_time: Duration,
    /// Block download: data-segment bits over all bits on the bus.
    pub block_fraction: f64,
    /// Block download: bus time.
    pub block_bus_time: Duration,
}

/// The SDO server of the `sdo` benchmark is node 5.
const SDO_NODE: u8 = 5;
/// The DOMAIN the bulk transfers write.
const DOMAIN: Mux = Mux::new(0x2000, 0);

fn sdo_description(size: usize) -> Result<OdDescription> {
    cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .var(
            0x2000,
            SubObject::new("Domain", DataType::Domain, Access::Rw)
                .default(Value::Domain(Vec::new()))
                .max_len(size),
        )
        .build()
        .map_err(|e| anyhow!("SDO dictionary: {e}"))
}

fn request(b: [u8; 8]) -> Option<Frame> {
    Id::standard(0x600 + u16::from(SDO_NODE))
        .ok()
        .map(|id| Frame::data_array(id, b))
}

fn response_of(frame: &Frame) -> Option<Response> {
    let b = <[u8; 8]>::try_from(frame.data_bytes()).ok()?;
    Response::decode(&b).ok()
}

/// A client reading 0x1000 (device type) by expedited upload, again as soon as each answer
/// arrives (CiA 301 §7.2.4.3.6).
struct ExpeditedClient {
    round_trips: u64,
    failures: u64,
}

impl ExpeditedClient {
    fn ask(out: &mut Outbox) {
        let r = Request::InitiateUpload {
            mux: Mux::new(0x1000, 0),
        };
        if let Some(f) = request(r.encode()) {
            out.push(f);
        }
    }
}

impl Node for ExpeditedClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        Self::ask(out);
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        match response_of(frame) {
            Some(Response::InitiateUpload {
                init: Initiate::Expedited { .. },
                ..
            }) => self.round_trips += 1,
            _ => self.failures += 1,
        }
        Self::ask(out);
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        id.as_raw() == 0x580 + u32::from(SDO_NODE)
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// A client downloading `data` by segmented transfer (§7.2.4.3.3, §7.2.4.3.4).
struct SegmentedClient {
    data: Vec<u8>,
    next: usize,
    toggle: bool,
    done: bool,
    failed: bool,
}

impl SegmentedClient {
    fn send_segment(&mut self, out: &mut Outbox) {
        let end = (self.next + 7).min(self.data.len());
        let mut d = [0u8; 7];
        d[..end - self.next].copy_from_slice(&self.data[self.next..end]);
        let len = (end - self.next) as u8;
        self.next = end;
        let r = Request::DownloadSegment {
            toggle: self.toggle,
            last: self.next == self.data.len(),
            len,
            data: d,
        };
        if let Some(f) = request(r.encode()) {
            out.push(f);
        }
    }
}

impl Node for SegmentedClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        let init = Initiate::Segmented {
            size: Some(self.data.len() as u32),
        };
        if let Some(f) = request(Request::InitiateDownload { mux: DOMAIN, init }.encode()) {
            out.push(f);
        }
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        match response_of(frame) {
            Some(Response::InitiateDownload { .. }) => self.send_segment(out),
            Some(Response::DownloadSegment { toggle }) if toggle == self.toggle => {
                self.toggle = !self.toggle;
                if self.next < self.data.len() {
                    self.send_segment(out);
                } else {
                    self.done = true;
                }
            }
            _ => self.failed = true,
        }
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        id.as_raw() == 0x580 + u32::from(SDO_NODE)
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// A client downloading `data` by block transfer, each block as soon as the previous one is
/// acknowledged (§7.2.4.3.9 to §7.2.4.3.11).
struct BlockClient {
    data: Vec<u8>,
    next: usize,
    blksize: u8,
    done: bool,
    failed: bool,
}

impl BlockClient {
    fn segments(&self) -> usize {
        self.data.len().div_ceil(7).max(1)
    }

    fn send_block(&mut self, out: &mut Outbox) {
        let n = usize::from(self.blksize).min(self.segments() - self.next);
        for k in 0..n {
            let i = self.next + k;
            let lo = (i * 7).min(self.data.len());
            let hi = ((i + 1) * 7).min(self.data.len());
            let mut d = [0u8; 7];
            d[..hi - lo].copy_from_slice(&self.data[lo..hi]);
            let seg = BlockSegment {
                last: i + 1 == self.segments(),
                seqno: k as u8 + 1,
                data: d,
            };
            if let Some(f) = request(seg.encode()) {
                out.push(f);
            }
        }
    }
}

impl Node for BlockClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        let r = Request::BlockDownloadInitiate {
            mux: DOMAIN,
            crc: true,
            size: Some(self.data.len() as u32),
        };
        if let Some(f) = request(r.encode()) {
            out.push(f);
        }
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        match response_of(frame) {
            Some(Response::BlockDownloadInitiate { blksize, .. }) => {
                self.blksize = blksize;
                self.send_block(out);
            }
            Some(Response::BlockDownloadAck { ackseq, blksize }) => {
                self.next += usize::from(ackseq);
                self.blksize = blksize;
                if self.next >= self.segments() {
                    let unused = (self.segments() * 7 - self.data.len()) as u8;
                    let crc = Crc16::of(&self.data);
                    if let Some(f) = request(Request::BlockDownloadEnd { unused, crc }.encode()) {
                        out.push(f);
                    }
                } else {
                    self.send_block(out);
                }
            }
            Some(Response::BlockDownloadEnd) => self.done = true,
            _ => self.failed = true,
        }
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        id.as_raw() == 0x580 + u32::from(SDO_NODE)
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// A bus with the SDO server device and `client`; both queues deep enough for a whole block,
/// in FIFO order so that a block's segments keep their sequence.
fn sdo_bus<C: Node + Send + 'static>(
    size: usize,
    client: C,
    record: bool,
) -> Result<(
    Simulation,
    BusId,
    Option<cantwin_bus::TapId>,
    cantwin_bus::PortId,
)> {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let desc = Arc::new(sdo_description(size)?);
    let port = PortConfig::default()
        .with_queue_depth(256)
        .with_order(TxOrder::Fifo);
    let device = Device::new(desc, DeviceConfig::new(SDO_NODE))?;
    sim.attach(
        bus,
        NetDevice {
            device,
            filtering: Filtering::Device,
        },
        port,
    )?;
    let client = sim.attach(bus, client, port)?;
    let tap = if record {
        sim.bus_mut(bus).map(|b| b.add_tap(Recorder::new()))
    } else {
        None
    };
    Ok((sim, bus, tap, client))
}

/// How a transfer's bus limit is counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Limit {
    /// Every request followed at once by its response: all SDO frames but the initiate
    /// exchange (the first two).
    RequestResponse,
    /// Nothing but the data segments back to back: the requests between the initiate
    /// request and the end request.
    DataSegments,
}

/// The limit's bits over all bits from the first SDO frame to the end of the last one, and
/// that bus time.
fn efficiency(
    sim: &Simulation,
    bus: BusId,
    tap: cantwin_bus::TapId,
    limit: Limit,
) -> Result<(f64, Duration)> {
    let rec = sim
        .bus(bus)
        .and_then(|b| b.tap::<Recorder>(tap))
        .context("the recorder is gone")?;
    let rx = 0x600 + u32::from(SDO_NODE);
    let tx = 0x580 + u32::from(SDO_NODE);
    let sdo: Vec<_> = rec
        .frames()
        .filter(|f| {
            let id = f.frame.id().as_raw();
            !f.dropped && (id == rx || id == tx)
        })
        .collect();
    let (Some(first), Some(last)) = (sdo.first(), sdo.last()) else {
        bail!("no SDO frames on the bus");
    };
    let limit_bits: u64 = match limit {
        Limit::RequestResponse => sdo.iter().skip(2).map(|f| u64::from(f.bits)).sum(),
        Limit::DataSegments => {
            let requests: Vec<_> = sdo.iter().filter(|f| f.frame.id().as_raw() == rx).collect();
            let n = requests.len().saturating_sub(1);
            requests
                .iter()
                .take(n)
                .skip(1)
                .map(|f| u64::from(f.bits))
                .sum()
        }
    };
    let elapsed = last.idle_at - first.start;
    let elapsed_bits = elapsed.as_nanos() / BitRate::R1M.bit_time().as_nanos();
    Ok((limit_bits as f64 / elapsed_bits.max(1) as f64, elapsed))
}

/// The expedited part of the `sdo` benchmark: a client reading 0x1000 for `duration` of bus
/// time, each request as soon as the previous answer arrives.
pub fn run_sdo_expedited(duration: Duration) -> Result<ExpeditedReport> {
    let client = ExpeditedClient {
        round_trips: 0,
        failures: 0,
    };
    let (mut sim, _, _, port) = sdo_bus(16, client, false)?;
    let started = std::time::Instant::now();
    sim.run_until(Instant::ZERO + duration);
    let wall_time = started.elapsed();
    let c = sim
        .node::<ExpeditedClient>(port)
        .context("the client is gone")?;
    if c.failures > 0 {
        bail!("{} expedited uploads failed", c.failures);
    }
    Ok(ExpeditedReport {
        round_trips: c.round_trips,
        wall_time,
        bus_time: duration,
    })
}

/// The bulk part of the `sdo` benchmark: a segmented and a block download of `bulk_bytes`,
/// measured in bus time.
pub fn run_sdo_transfers(bulk_bytes: usize) -> Result<TransferReport> {
    let data: Vec<u8> = (0..bulk_bytes).map(|i| (i % 251) as u8).collect();
    // Enough bus time for either transfer: 2 frames of at most 135 bits per 7 bytes.
    let limit = Instant::ZERO + BitRate::R1M.bit_time() * ((bulk_bytes as u64 / 7 + 10) * 300);

    let seg = SegmentedClient {
        data: data.clone(),
        next: 0,
        toggle: false,
        done: false,
        failed: false,
    };
    let (mut sim, bus, tap, port) = sdo_bus(bulk_bytes, seg, true)?;
    sim.run_until(limit);
    let c = sim
        .node::<SegmentedClient>(port)
        .context("the client is gone")?;
    if !c.done || c.failed {
        bail!("the segmented download did not complete");
    }
    let (segmented_fraction, segmented_bus_time) = efficiency(
        &sim,
        bus,
        tap.context("no recorder")?,
        Limit::RequestResponse,
    )?;

    let block = BlockClient {
        data,
        next: 0,
        blksize: 0,
        done: false,
        failed: false,
    };
    let (mut sim, bus, tap, port) = sdo_bus(bulk_bytes, block, true)?;
    sim.run_until(limit);
    let c = sim
        .node::<BlockClient>(port)
        .context("the client is gone")?;
    if !c.done || c.failed {
        bail!("the block download did not complete");
    }
    let (block_fraction, block_bus_time) =
        efficiency(&sim, bus, tap.context("no recorder")?, Limit::DataSegments)?;

    Ok(TransferReport {
        bulk_bytes,
        segmented_fraction,
        segmented_bus_time,
        block_fraction,
        block_bus_time,
    })
}

/// What the `memory` benchmark measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryReport {
    /// `size_of::<Device>()`.
    pub device_inline: usize,
    /// Heap of a device with the CiA 301 defaults only (description shared, not counted).
    pub default_heap: usize,
    /// Heap of a device with 4 RPDOs and 4 TPDOs.
    pub pdo_4_4_heap: usize,
    /// Heap of a network device (one TPDO).
    pub network_heap: usize,
    /// Devices in the scenario build.
    pub scenario_devices: usize,
    /// Wall time to parse and build that scenario.
    pub scenario_build: std::time::Duration,
}

/// The text of a scenario of `devices` `cia301` devices on one 1 Mbit/s bus.
pub fn scenario_text(devices: u8) -> String {
    let mut s = String::from("name = \"bench\"\n\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n");
    for n in 1..=devices {
        s.push_str(&format!(
            "\n[[device]]\nname = \"node{n}\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = {n}\nheartbeat_ms = 100\n"
        ));
    }
    s
}

/// Run the `memory` benchmark.
pub fn run_memory(scenario_devices: u8) -> Result<MemoryReport> {
    let default_desc = Arc::new(
        cia301_defaults(OdBuilder::new(), &Cia301Options::default())
            .build()
            .map_err(|e| anyhow!("default dictionary: {e}"))?,
    );
    let default_heap = Device::new(default_desc, DeviceConfig::new(1))?.heap_bytes();
    let pdo_desc = Arc::new(pdo_4_4_description()?);
    let pdo_4_4_heap = Device::new(pdo_desc, DeviceConfig::new(1))?.heap_bytes();
    let net_desc = Arc::new(network_description()?);
    let network_heap = Device::new(net_desc, DeviceConfig::new(1))?.heap_bytes();

    let text = scenario_text(scenario_devices);
    let started = std::time::Instant::now();
    let scenario = cantwin_scenario::Scenario::parse(&text, "bench.toml")?;
    let built = scenario.build(
        &cantwin_scenario::Registry::builtin(),
        &cantwin_scenario::BuildEnv::default(),
    )?;
    let scenario_build = started.elapsed();
    if built.devices.len() != usize::from(scenario_devices) {
        bail!(
            "the scenario built {} devices, not {scenario_devices}",
            built.devices.len()
        );
    }
    Ok(MemoryReport {
        device_inline: core::mem::size_of::<Device>(),
        default_heap,
        pdo_4_4_heap,
        network_heap,
        scenario_devices: usize::from(scenario_devices),
        scenario_build,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn network_devices_send_a_tpdo_per_sync_and_heartbeats() {
        for filtering in [
            Filtering::Firmware,
            Filtering::Device,
            Filtering::Everything,
            Filtering::Unfiltered,
        ] {
            let r = run_networks(1, Duration::from_millis(1000), filtering).unwrap();
            // One NMT, 64 boot-ups, then SYNCs at 10..990 ms with 64 TPDOs each and heartbeats
            // at 100..900 ms: what falls due at 1000 ms is not on the bus yet when the run ends.
            assert_eq!(r.frames, 1 + 64 + 99 * 65 + 9 * 64);
            assert!(r.bus_load_percent > 70.0 && r.bus_load_percent < 95.0);
        }
    }

    #[test]
    fn sdo_transfers_complete_near_the_bus_limit() {
        let e = run_sdo_expedited(Duration::from_millis(100)).unwrap();
        assert!(e.round_trips > 400);
        // Deterministic: a second run makes exactly as many round trips.
        assert_eq!(
            run_sdo_expedited(Duration::from_millis(100))
                .unwrap()
                .round_trips,
            e.round_trips
        );
        let r = run_sdo_transfers(7000).unwrap();
        assert!(r.segmented_fraction > 0.95 && r.segmented_fraction < 1.0);
        assert!(r.block_fraction > 0.95 && r.block_fraction < 1.0);
    }

    #[test]
    fn memory_report_counts_a_127_device_scenario() {
        let r = run_memory(127).unwrap();
        assert_eq!(r.scenario_devices, 127);
        assert!(r.pdo_4_4_heap > r.network_heap);
    }
}
