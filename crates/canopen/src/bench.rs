//! The nodes of the `cantwin bench` CANopen workloads: a network device as an application
//! runs it, the network's SYNC master, and SDO clients (on [`SdoClient`]) that keep a
//! server busy. The benchmark harness puts them on a simulated bus and measures.

use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};

use crate::ObjectAccess;
use crate::device::Device;
use crate::master::{Mode, SdoClient, SdoEvent};
use crate::sdo::wire::Mux;

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

/// A network device: a CiA 301 [`Device`] whose 0x1017 is set to a producer heartbeat time
/// at power-up, and whose events are drained after every call as an application would.
pub struct NetworkDevice {
    device: Device,
    filtering: Filtering,
    heartbeat_ms: u16,
}

impl NetworkDevice {
    /// `device`, filtering as `filtering` says, producing heartbeats every `heartbeat_ms`.
    pub fn new(device: Device, filtering: Filtering, heartbeat_ms: u16) -> NetworkDevice {
        NetworkDevice {
            device,
            filtering,
            heartbeat_ms,
        }
    }

    fn drain(&mut self) {
        while self.device.poll_event().is_some() {}
    }
}

impl Node for NetworkDevice {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.device.on_power_up(now, out);
        // Through ObjectAccess, as an SDO download would, so the producer starts at once.
        let _ = self
            .device
            .write(0x1017, 0, &self.heartbeat_ms.to_le_bytes());
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

/// A network's master: NMT start of all nodes at power-up (CiA 301 §7.2.8.3.1.1), then a
/// SYNC without counter every period (§7.2.5).
pub struct SyncMaster {
    period: Duration,
    next_sync: Instant,
    syncs: u64,
}

impl SyncMaster {
    /// A master sending SYNC every `period`.
    pub fn new(period: Duration) -> SyncMaster {
        SyncMaster {
            period,
            next_sync: Instant::ZERO,
            syncs: 0,
        }
    }

    /// SYNCs sent.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }
}

impl Node for SyncMaster {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        if let Ok(f) = Frame::std(0x000, &[0x01, 0x00]) {
            out.push(f);
        }
        self.next_sync = now + self.period;
    }
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while self.next_sync <= now {
            if let Ok(f) = Frame::std(0x080, &[]) {
                out.push(f);
            }
            self.syncs += 1;
            self.next_sync += self.period;
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

/// What an [`SdoBenchClient`] does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SdoWork {
    /// Upload `mux` again and again, each request as soon as the previous answer arrives
    /// (CiA 301 §7.2.4.3.6 for an expedited answer).
    UploadLoop {
        /// The object read.
        mux: Mux,
    },
    /// Download `data` to `mux` once, in `mode`.
    Download {
        /// The object written.
        mux: Mux,
        /// The bytes.
        data: Vec<u8>,
        /// Segmented or block.
        mode: Mode,
    },
}

/// An SDO client node on [`SdoClient`] that keeps one server busy with [`SdoWork`].
pub struct SdoBenchClient {
    client: SdoClient,
    work: SdoWork,
    completed: u64,
    failures: u64,
}

impl SdoBenchClient {
    /// A client of the server with node-ID `node` (pre-defined connection set), with the
    /// client's defaults.
    pub fn new(node: u8, work: SdoWork) -> Result<SdoBenchClient, crate::master::ClientError> {
        Ok(SdoBenchClient {
            client: SdoClient::for_node(node)?,
            work,
            completed: 0,
            failures: 0,
        })
    }

    /// Transfers completed.
    pub fn completed(&self) -> u64 {
        self.completed
    }

    /// Transfers aborted or refused to start.
    pub fn failures(&self) -> u64 {
        self.failures
    }

    fn start(&mut self, now: Instant, out: &mut Outbox) {
        let r = match &self.work {
            SdoWork::UploadLoop { mux } => {
                self.client
                    .start_upload(mux.index, mux.sub, Mode::Expedited, now, out)
            }
            SdoWork::Download { mux, data, mode } => {
                self.client
                    .start_download(mux.index, mux.sub, data.clone(), *mode, now, out)
            }
        };
        if r.is_err() {
            self.failures += 1;
        }
    }

    fn settle(&mut self, now: Instant, out: &mut Outbox) {
        while let Some(ev) = self.client.poll_event() {
            match ev {
                SdoEvent::Completed { data, .. } => {
                    self.completed += 1;
                    // The next upload fills the same buffer rather than a new one.
                    self.client.recycle(data);
                    if matches!(self.work, SdoWork::UploadLoop { .. }) {
                        self.start(now, out);
                    }
                }
                SdoEvent::Aborted { .. } => self.failures += 1,
                SdoEvent::Progress { .. } | SdoEvent::FellBack { .. } => {}
            }
        }
    }
}

impl Node for SdoBenchClient {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.start(now, out);
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if self.client.on_frame(frame, now, out) {
            self.settle(now, out);
        }
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.client.on_tick(now, out);
        self.settle(now, out);
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.client.next_deadline()
    }
    fn accepts(&self, id: Id) -> bool {
        id == self.client.rx_id()
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}
