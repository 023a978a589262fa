//! CANopen macro benchmarks: a realistic CiA 301 network, a fleet of such networks, SDO
//! round trips and transfer efficiency, and the memory a device takes.
//!
//! The figures are computed here rather than in the bus crate because the bus crate must not
//! depend on the CANopen stack.

use std::sync::Arc;

use anyhow::{Context, Result, anyhow, bail};
use cantwin_bus::{BusConfig, BusId, PortConfig, Recorder, Simulation, TxOrder};
use cantwin_can::{BitRate, Duration, Instant, Node};
use cantwin_canopen::bench::{NetworkDevice, SdoBenchClient, SdoWork, SyncMaster};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::master::Mode;
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, OdDescription, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_canopen::sdo::wire::Mux;

pub use cantwin_canopen::bench::Filtering;

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

/// A `network` device with node-ID `node` that the bus asks for its own acceptance filter
/// ([`Filtering::Device`]), for other benchmarks' baselines.
pub fn network_device(desc: &Arc<OdDescription>, node: u8) -> Result<impl Node + Send + 'static> {
    Ok(NetworkDevice::new(
        Device::new(Arc::clone(desc), DeviceConfig::new(node))?,
        Filtering::Device,
        HEARTBEAT_MS,
    ))
}

/// Build `buses` networks into `sim`, each of [`NETWORK_DEVICES`] devices and a master.
fn add_networks(
    sim: &mut Simulation,
    desc: &Arc<OdDescription>,
    buses: usize,
    filtering: Filtering,
) -> Result<Vec<BusId>> {
    add_networks_of(sim, desc, buses, NETWORK_DEVICES, SYNC_PERIOD, filtering)
}

/// The SYNC period at which a network of `devices` devices offers `load_percent` of a
/// 1 Mbit/s bus: per period a SYNC and a TPDO per device, and each device's heartbeat every
/// [`HEARTBEAT_MS`] (its share subtracted first). `None` when the heartbeats alone exceed it.
pub fn sync_period_for_load(devices: u8, load_percent: f64) -> Option<Duration> {
    let bits = |id: u16, data: &[u8]| {
        cantwin_can::Frame::std(id, data).map_or(0.0, |f| f64::from(f.bit_length()))
    };
    let n = f64::from(devices);
    let per_sync: f64 = bits(0x080, &[])
        + (1..=devices)
            .map(|d| bits(0x180 + u16::from(d), &[0; 8]))
            .sum::<f64>();
    let heartbeats_per_s = n * bits(0x700 + 1, &[5]) * 1000.0 / f64::from(HEARTBEAT_MS);
    let budget = load_percent / 100.0 * 1e6 - heartbeats_per_s;
    (budget > 0.0).then(|| Duration::from_nanos((per_sync / budget * 1e9).round() as u64))
}

/// Simulate one network of `devices` devices with SYNC every `sync_period` for `duration`,
/// firmware acceptance filters.
pub fn run_network_of(
    devices: u8,
    sync_period: Duration,
    duration: Duration,
) -> Result<NetworkReport> {
    let desc = Arc::new(network_description()?);
    let started = std::time::Instant::now();
    let mut sim = Simulation::new();
    let ids = add_networks_of(
        &mut sim,
        &desc,
        1,
        devices,
        sync_period,
        Filtering::Firmware,
    )?;
    let build_time = started.elapsed();
    let end = Instant::ZERO + duration;
    let started = std::time::Instant::now();
    sim.run_until(end);
    let wall_time = started.elapsed();
    let bus = ids.first().and_then(|&b| sim.bus(b));
    Ok(NetworkReport {
        buses: 1,
        threads: 1,
        bus_time: duration,
        wall_time,
        build_time,
        frames: bus.map_or(0, |b| b.stats().frames()),
        bus_load_percent: bus.map_or(0.0, |b| b.stats().load_percent(end)),
    })
}

/// Build `buses` networks into `sim`, each of `devices` devices (node-IDs 1..=devices) and a
/// master sending SYNC every `sync_period`.
fn add_networks_of(
    sim: &mut Simulation,
    desc: &Arc<OdDescription>,
    buses: usize,
    devices: u8,
    sync_period: Duration,
    filtering: Filtering,
) -> Result<Vec<BusId>> {
    let mut ids = Vec::with_capacity(buses);
    for b in 0..buses {
        let bus = sim.add_bus(BusConfig::new(format!("can{b}"), BitRate::R1M));
        sim.attach(bus, SyncMaster::new(sync_period), PortConfig::default())?;
        for node in 1..=devices.min(127) {
            let config = DeviceConfig {
                acceptance_filter: filtering != Filtering::Unfiltered,
                ..DeviceConfig::new(node)
            };
            let device = Device::new(Arc::clone(desc), config)?;
            sim.attach(
                bus,
                NetworkDevice::new(device, filtering, HEARTBEAT_MS),
                PortConfig::default(),
            )?;
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

/// How far a fleet thread runs each of its networks before it moves on to the next: every
/// network stays within one slice of bus time of every other, and each runs a whole slice
/// while its devices are in the core's caches.
pub const FLEET_SLICE: Duration = Duration::from_millis(100);

/// Simulate `networks` networks, each its own [`Simulation`], in slices of [`FLEET_SLICE`]:
/// all networks to the end of a slice, one after the other, then the next slice.
fn run_networks_sliced(
    networks: usize,
    duration: Duration,
    filtering: Filtering,
) -> Result<NetworkReport> {
    let desc = Arc::new(network_description()?);
    let started = std::time::Instant::now();
    let mut sims = Vec::with_capacity(networks);
    for _ in 0..networks {
        let mut sim = Simulation::new();
        let ids = add_networks(&mut sim, &desc, 1, filtering)?;
        sims.push((sim, ids));
    }
    let build_time = started.elapsed();
    let end = Instant::ZERO + duration;
    let started = std::time::Instant::now();
    let mut t = Instant::ZERO;
    while t < end {
        t = (t + FLEET_SLICE).min(end);
        for (sim, _) in &mut sims {
            sim.run_until(t);
        }
    }
    let wall_time = started.elapsed();
    let stats = |(sim, ids): &(Simulation, Vec<BusId>)| {
        ids.iter()
            .filter_map(|&b| sim.bus(b))
            .map(|b| (b.stats().frames(), b.stats().load_percent(end)))
            .collect::<Vec<_>>()
    };
    let all: Vec<(u64, f64)> = sims.iter().flat_map(stats).collect();
    Ok(NetworkReport {
        buses: networks,
        threads: 1,
        bus_time: duration,
        wall_time,
        build_time,
        frames: all.iter().map(|&(f, _)| f).sum(),
        bus_load_percent: all.first().map_or(0.0, |&(_, l)| l),
    })
}

/// Simulate `buses` networks spread over `threads` threads, each network its own
/// [`Simulation`], each thread running its networks in slices ([`FLEET_SLICE`]).
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
            .map(|&n| s.spawn(move || run_networks_sliced(n, duration, filtering)))
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
        NetworkDevice::new(device, Filtering::Device, HEARTBEAT_MS),
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
    let client = SdoBenchClient::new(
        SDO_NODE,
        SdoWork::UploadLoop {
            mux: Mux::new(0x1000, 0),
        },
    )?;
    let (mut sim, _, _, port) = sdo_bus(16, client, false)?;
    let started = std::time::Instant::now();
    sim.run_until(Instant::ZERO + duration);
    let wall_time = started.elapsed();
    let c = sim
        .node::<SdoBenchClient>(port)
        .context("the client is gone")?;
    if c.failures() > 0 {
        bail!("{} expedited uploads failed", c.failures());
    }
    Ok(ExpeditedReport {
        round_trips: c.completed(),
        wall_time,
        bus_time: duration,
    })
}

/// What the device stack alone measured: the SDO server answering the expedited benchmark's
/// request, called directly, with no bus and no client.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceAloneReport {
    /// Requests answered (each with exactly one expedited upload response).
    pub answers: u64,
    /// Their wall time.
    pub wall_time: std::time::Duration,
}

impl DeviceAloneReport {
    /// Wall nanoseconds per answered request.
    pub fn ns_per_answer(&self) -> f64 {
        self.wall_time.as_nanos() as f64 / self.answers.max(1) as f64
    }
}

impl Trial for DeviceAloneReport {
    fn wall(&self) -> std::time::Duration {
        self.wall_time
    }
    fn with_wall(&self, wall: std::time::Duration) -> Self {
        DeviceAloneReport {
            wall_time: wall,
            ..*self
        }
    }
    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![("answers", self.answers)]
    }
}

/// The expedited benchmark's server (the same device, wrapped as on the bus) answering
/// `requests` initiate-upload requests of 0x1000 handed straight to `on_frame`, 1 µs apart,
/// the way the bus hands it each request; every call is checked to answer with one expedited
/// upload response (CiA 301 §7.2.4.3) of the server's COB-ID.
pub fn run_sdo_device_alone(requests: u64) -> Result<DeviceAloneReport> {
    let desc = Arc::new(sdo_description(16)?);
    let device = Device::new(desc, DeviceConfig::new(SDO_NODE))?;
    let mut node = NetworkDevice::new(device, Filtering::Device, HEARTBEAT_MS);
    let mut out = cantwin_can::Outbox::new();
    node.on_power_up(Instant::ZERO, &mut out);
    out.clear();
    let request = cantwin_can::Frame::std(
        0x600 + u16::from(SDO_NODE),
        &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0],
    )?;
    let response = 0x580 + u32::from(SDO_NODE);
    let mut answers = 0u64;
    let started = std::time::Instant::now();
    for k in 0..requests {
        let now = Instant::from_nanos(1_000 * (k + 1));
        node.on_frame(std::hint::black_box(&request), now, &mut out);
        // Its heartbeat (0x1017) may go out in the same call, as on the bus.
        let expedited = |f: &&cantwin_can::Frame| {
            f.id().as_raw() == response && f.data_bytes().first().is_some_and(|b| b & 0xE3 == 0x43)
        };
        if out.frames().iter().filter(expedited).count() == 1 {
            answers += 1;
        }
        out.clear();
    }
    let wall_time = started.elapsed();
    if answers != requests {
        bail!("the device alone answered {answers} of {requests} expedited upload requests");
    }
    Ok(DeviceAloneReport { answers, wall_time })
}

/// The bulk part of the `sdo` benchmark: a segmented and a block download of `bulk_bytes`,
/// measured in bus time.
pub fn run_sdo_transfers(bulk_bytes: usize) -> Result<TransferReport> {
    let data: Vec<u8> = (0..bulk_bytes).map(|i| (i % 251) as u8).collect();
    // Enough bus time for either transfer: 2 frames of at most 135 bits per 7 bytes.
    let limit = Instant::ZERO + BitRate::R1M.bit_time() * ((bulk_bytes as u64 / 7 + 10) * 300);

    let seg = SdoBenchClient::new(
        SDO_NODE,
        SdoWork::Download {
            mux: DOMAIN,
            data: data.clone(),
            mode: Mode::Segmented,
        },
    )?;
    let (mut sim, bus, tap, port) = sdo_bus(bulk_bytes, seg, true)?;
    sim.run_until(limit);
    let c = sim
        .node::<SdoBenchClient>(port)
        .context("the client is gone")?;
    if c.completed() != 1 || c.failures() > 0 {
        bail!("the segmented download did not complete");
    }
    let (segmented_fraction, segmented_bus_time) = efficiency(
        &sim,
        bus,
        tap.context("no recorder")?,
        Limit::RequestResponse,
    )?;

    let block = SdoBenchClient::new(
        SDO_NODE,
        SdoWork::Download {
            mux: DOMAIN,
            data,
            mode: Mode::Block { blksize: 127 },
        },
    )?;
    let (mut sim, bus, tap, port) = sdo_bus(bulk_bytes, block, true)?;
    sim.run_until(limit);
    let c = sim
        .node::<SdoBenchClient>(port)
        .context("the client is gone")?;
    if c.completed() != 1 || c.failures() > 0 {
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
        let alone = run_sdo_device_alone(1000).unwrap();
        assert_eq!(alone.answers, 1000);
        let r = run_sdo_transfers(7000).unwrap();
        assert!(r.segmented_fraction > 0.95 && r.segmented_fraction < 1.0);
        assert!(r.block_fraction > 0.95 && r.block_fraction < 1.0);
    }

    /// In virtual time the device answers with no reaction time: its expedited upload
    /// response starts arbitrating at the first idle bit after the request, the end of the
    /// request's intermission (ISO 11898-1 §10.4.6.2), every time.
    #[test]
    fn cia301_sdo_answer_arbitrates_at_the_first_idle_bit_after_the_request() {
        let client = SdoBenchClient::new(
            SDO_NODE,
            SdoWork::UploadLoop {
                mux: Mux::new(0x1000, 0),
            },
        )
        .unwrap();
        let (mut sim, bus, tap, _) = sdo_bus(16, client, true).unwrap();
        sim.run_until(Instant::ZERO + Duration::from_millis(5));
        let rec = sim
            .bus(bus)
            .and_then(|b| b.tap::<Recorder>(tap.unwrap()))
            .unwrap();
        let frames: Vec<_> = rec.frames().collect();
        let request = 0x600 + u32::from(SDO_NODE);
        let response = 0x580 + u32::from(SDO_NODE);
        // The boot-up message (0x700 + node) was queued at power-up, before the first request
        // arrived, and the device's queue is FIFO: it goes first. From then on nothing else
        // is due in these 5 ms.
        let boot_up = frames
            .iter()
            .position(|f| f.frame.id().as_raw() == 0x700 + u32::from(SDO_NODE))
            .unwrap();
        let mut answered = 0;
        for pair in frames[boot_up..].windows(2) {
            if pair[0].frame.id().as_raw() == request {
                assert_eq!(pair[1].frame.id().as_raw(), response);
                assert_eq!(pair[1].start, pair[0].idle_at);
                answered += 1;
            }
        }
        assert!(answered > 10, "{answered} round trips in 5 ms");
    }

    #[test]
    fn memory_report_counts_a_127_device_scenario() {
        let r = run_memory(127).unwrap();
        assert_eq!(r.scenario_devices, 127);
        assert!(r.pdo_4_4_heap > r.network_heap);
    }
}
