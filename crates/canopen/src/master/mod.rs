//! The CANopen master role: SDO clients, NMT master, heartbeat consumer, node guarding
//! master, SYNC and TIME producers, network scan and remote PDO configuration.
//!
//! * [`SdoClient`]: one SDO client channel as a sans-IO state machine (all transfer
//!   modes, fallback from block to segmented, timeouts, progress);
//! * [`Master`]: a [`Node`] that runs one SDO client per target node (transfers to
//!   different nodes run concurrently, transfers to the same node queue), the NMT master
//!   services and the producers, and reports everything as timestamped [`MasterEvent`]s;
//! * [`pdo`]: reading and writing another node's PDO parameters and decoding its PDOs;
//! * [`cia402`]: a CiA 402 drive master (power states, modes, profile moves, homing,
//!   cyclic set-points on SYNC) over a [`Master`];
//! * [`drive()`]: a loop that runs a [`Master`] over any [`Port`] with a clock.
//!
//! ```
//! use cantwin_can::{Instant, Node, Outbox};
//! use cantwin_canopen::master::{Master, Mode, Mux};
//! use cantwin_canopen::wire::NmtCs;
//!
//! let mut master = Master::new();
//! let mut out = Outbox::new();
//! master.nmt(NmtCs::Start, 0, &mut out)?;
//! let id = master.upload(5, Mux::new(0x1000, 0), Mode::Auto, Instant::ZERO, &mut out)?;
//! let sent: Vec<String> = out.drain().map(|f| f.to_string()).collect();
//! assert_eq!(sent, ["000#0100", "605#4000100000000000"]);
//! assert_eq!(master.next_deadline(), Some(Instant::from_nanos(1_000_000_000)));
//! # let _ = id;
//! # Ok::<(), cantwin_canopen::master::MasterError>(())
//! ```

pub mod cia402;
pub mod drive;
pub mod pdo;
pub mod sdo_client;

use std::collections::VecDeque;

pub use drive::{Port, drive};
pub use sdo_client::{ClientConfig, ClientError, Mode, SdoClient, SdoEvent};

use crate::od::TimeOfDay;
pub use crate::sdo::wire::Mux;
use crate::wire::{self, Emcy, ErrorControl, NmtCommand, NmtCs, NmtState};
use cantwin_can::{ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};

/// The identifier of a transfer started on a [`Master`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TransferId(pub u64);

/// A node that answered a network scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanHit {
    /// Its node-ID.
    pub node: u8,
    /// Its device type (0x1000), or the abort code it answered with instead.
    pub device_type: Result<u32, crate::AbortCode>,
}

/// Something that happened on the network, as the master saw it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterEvent {
    /// A user transfer progressed, completed or was aborted.
    Sdo {
        /// The transfer.
        id: TransferId,
        /// The server's node-ID.
        node: u8,
        /// What happened.
        event: SdoEvent,
    },
    /// A boot-up message (CiA 301 §7.2.8.3.2.4).
    BootUp {
        /// The node.
        node: u8,
    },
    /// A heartbeat or guarding response reported a state different from the last one.
    StateChanged {
        /// The node.
        node: u8,
        /// The previous state, if one was known.
        from: Option<NmtState>,
        /// The new state.
        to: NmtState,
    },
    /// No heartbeat within the consumer time (CiA 301 §7.2.8.3.2.2).
    HeartbeatTimeout {
        /// The node.
        node: u8,
    },
    /// No valid guarding response within the node life time (CiA 301 §7.2.8.3.2.1).
    GuardingTimeout {
        /// The node.
        node: u8,
    },
    /// A guarding response whose toggle bit did not alternate (ignored as a response).
    GuardingToggleError {
        /// The node.
        node: u8,
    },
    /// An emergency message (CiA 301 §7.2.7).
    Emcy {
        /// The producer (from its default COB-ID 0x80 + node-ID).
        node: u8,
        /// The message.
        emcy: Emcy,
    },
    /// A network scan finished: the nodes that answered, in node-ID order.
    ScanFinished {
        /// Who answered.
        found: Vec<ScanHit>,
    },
    /// A remote PDO job finished (see [`pdo`]).
    Pdo {
        /// The job (its id is that of the transfers it ran).
        id: TransferId,
        /// The node.
        node: u8,
        /// The outcome.
        result: Result<pdo::PdoOutcome, pdo::PdoError>,
    },
}

/// A request the master cannot carry out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum MasterError {
    /// A node-ID outside 1..=127 (0..=127 for NMT commands).
    #[error("node-ID {0} is out of range")]
    NodeId(u8),
    /// The transfer cannot start.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// A scan is already running.
    #[error("a network scan is already running")]
    ScanRunning,
    /// Zero guard time, life time factor or period.
    #[error("a zero time or factor")]
    ZeroTime,
}

/// Settings of a [`Master`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MasterConfig {
    /// SDO client settings of every transfer.
    pub sdo: ClientConfig,
    /// At most this many of the master's frames are handed to the driver and not yet
    /// confirmed by [`Node::on_sent`] (a block of 127 segments or a scan of 127 requests
    /// does not overflow a transmit queue). `None`: no limit.
    pub tx_window: Option<usize>,
    /// The response timeout of each scan request.
    pub scan_timeout: Duration,
}

impl Default for MasterConfig {
    fn default() -> Self {
        MasterConfig {
            sdo: ClientConfig::default(),
            tx_window: Some(16),
            scan_timeout: Duration::from_millis(300),
        }
    }
}

/// The age and state of a node, from its last heartbeat or guarding response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodeStatus {
    /// The last reported state.
    pub state: Option<NmtState>,
    /// When the node was last heard (boot-up, heartbeat or guarding response).
    pub last_seen: Option<Instant>,
    /// The heartbeat consumer or guarding master has reported it lost and it has not been
    /// heard since.
    pub lost: bool,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Op {
    Upload { mux: Mux, mode: Mode },
    Download { mux: Mux, data: Vec<u8>, mode: Mode },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Purpose {
    User,
    Scan,
    Pdo,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Queued {
    id: TransferId,
    op: Op,
    purpose: Purpose,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct HeartbeatWatch {
    time: Duration,
    deadline: Option<Instant>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct GuardWatch {
    guard_time: Duration,
    life_time: Duration,
    next_poll: Instant,
    life_deadline: Option<Instant>,
    expected_toggle: Option<bool>,
}

#[derive(Debug, Clone)]
struct Peer {
    client: SdoClient,
    current: Option<(TransferId, Purpose)>,
    queue: VecDeque<Queued>,
    job: Option<(TransferId, pdo::Job)>,
    heartbeat: Option<HeartbeatWatch>,
    guard: Option<GuardWatch>,
    status: NodeStatus,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SyncProducer {
    id: Id,
    period: Duration,
    overflow: u8,
    counter: u8,
    next: Instant,
}

/// The NMT master and SDO client node.
#[derive(Debug, Clone)]
pub struct Master {
    config: MasterConfig,
    /// Index = node-ID; 0 is unused.
    peers: Vec<Option<Box<Peer>>>,
    next_id: u64,
    events: VecDeque<(Instant, MasterEvent)>,
    txq: VecDeque<Frame>,
    in_flight: usize,
    sync: Option<SyncProducer>,
    time_id: Id,
    scan: Option<(usize, Vec<ScanHit>)>,
}

impl Default for Master {
    fn default() -> Self {
        Master::new()
    }
}

fn check_node(node: u8) -> Result<usize, MasterError> {
    if (1..=127).contains(&node) {
        Ok(usize::from(node))
    } else {
        Err(MasterError::NodeId(node))
    }
}

impl Master {
    /// A master with the default settings.
    pub fn new() -> Self {
        Master::with_config(MasterConfig::default())
    }

    /// A master with these settings.
    pub fn with_config(config: MasterConfig) -> Self {
        Master {
            config,
            peers: vec![None; 128],
            next_id: 0,
            events: VecDeque::new(),
            txq: VecDeque::new(),
            in_flight: 0,
            sync: None,
            time_id: Id::Standard(
                cantwin_can::StandardId::new(wire::TIME_COB_ID)
                    .unwrap_or(cantwin_can::StandardId::MAX),
            ),
            scan: None,
        }
    }

    /// The settings.
    pub fn config(&self) -> &MasterConfig {
        &self.config
    }

    /// Changes the settings (SDO settings apply to transfers started afterwards).
    pub fn config_mut(&mut self) -> &mut MasterConfig {
        &mut self.config
    }

    /// The next event, oldest first, with the time it happened.
    pub fn poll_event(&mut self) -> Option<(Instant, MasterEvent)> {
        self.events.pop_front()
    }

    /// What the master knows about `node`.
    pub fn status(&self, node: u8) -> Option<NodeStatus> {
        self.peers
            .get(usize::from(node))
            .and_then(|p| p.as_ref())
            .map(|p| p.status)
    }

    /// How long ago `node` was last heard, if ever.
    pub fn age(&self, node: u8, now: Instant) -> Option<Duration> {
        self.status(node)?
            .last_seen
            .map(|t| now.saturating_duration_since(t))
    }

    fn peer(&mut self, node: usize) -> &mut Peer {
        let slot = &mut self.peers[node & 0x7F];
        slot.get_or_insert_with(|| {
            let client = u8::try_from(node)
                .ok()
                .and_then(|n| SdoClient::for_node(n).ok())
                .unwrap_or_else(|| {
                    SdoClient::new(
                        Id::Standard(cantwin_can::StandardId::MAX),
                        Id::Standard(cantwin_can::StandardId::MAX),
                    )
                });
            Box::new(Peer {
                client,
                current: None,
                queue: VecDeque::new(),
                job: None,
                heartbeat: None,
                guard: None,
                status: NodeStatus {
                    state: None,
                    last_seen: None,
                    lost: false,
                },
            })
        })
    }

    fn new_id(&mut self) -> TransferId {
        self.next_id += 1;
        TransferId(self.next_id)
    }

    /// Reads `index`/`sub` of `node`. Starts now if the node's channel is free, else
    /// after the transfers queued before it.
    pub fn upload(
        &mut self,
        node: u8,
        mux: Mux,
        mode: Mode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<TransferId, MasterError> {
        let n = check_node(node)?;
        let id = self.new_id();
        let op = Op::Upload { mux, mode };
        self.enqueue(n, id, op, Purpose::User, now, out)?;
        Ok(id)
    }

    /// Writes `data` to `index`/`sub` of `node` (queued like [`Self::upload`]).
    pub fn download(
        &mut self,
        node: u8,
        mux: Mux,
        data: Vec<u8>,
        mode: Mode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<TransferId, MasterError> {
        let n = check_node(node)?;
        match mode {
            Mode::Expedited if !(1..=4).contains(&data.len()) => {
                return Err(ClientError::ExpeditedLength(data.len()).into());
            }
            Mode::Block { blksize } if !(1..=127).contains(&blksize) => {
                return Err(ClientError::BlockSize(blksize).into());
            }
            _ => {}
        }
        let id = self.new_id();
        let op = Op::Download { mux, data, mode };
        self.enqueue(n, id, op, Purpose::User, now, out)?;
        Ok(id)
    }

    /// Aborts transfer `id` (running: abort `code` on the bus; queued: dropped). Returns
    /// whether it was found.
    pub fn abort(
        &mut self,
        id: TransferId,
        code: crate::AbortCode,
        now: Instant,
        out: &mut Outbox,
    ) -> bool {
        let mut local = Outbox::new();
        let mut found = false;
        for n in 1..128 {
            let Some(p) = self.peers[n].as_mut() else {
                continue;
            };
            if p.current.is_some_and(|(c, _)| c == id) {
                p.client.abort(code, &mut local);
                found = true;
            } else if let Some(pos) = p.queue.iter().position(|q| q.id == id) {
                p.queue.remove(pos);
                found = true;
            }
            if found {
                self.pump(n, now, &mut local);
                break;
            }
        }
        self.flush(local, out);
        found
    }

    fn enqueue(
        &mut self,
        n: usize,
        id: TransferId,
        op: Op,
        purpose: Purpose,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), MasterError> {
        self.peer(n).queue.push_back(Queued { id, op, purpose });
        let mut local = Outbox::new();
        self.pump(n, now, &mut local);
        self.flush(local, out);
        Ok(())
    }

    /// Moves events out of node `n`'s client and starts its next queued transfer.
    fn pump(&mut self, n: usize, now: Instant, out: &mut Outbox) {
        loop {
            let Some(p) = self.peers[n].as_mut() else {
                return;
            };
            let Some(event) = p.client.poll_event() else {
                if p.client.is_idle() {
                    p.current = None;
                    if !self.start_next(n, now, out) {
                        return;
                    }
                    continue;
                }
                return;
            };
            let Some((id, purpose)) = p.current else {
                continue;
            };
            let terminal = matches!(event, SdoEvent::Completed { .. } | SdoEvent::Aborted { .. });
            if terminal {
                p.current = None;
            }
            // n ≤ 127.
            let node = u8::try_from(n).unwrap_or(0);
            match purpose {
                Purpose::User => self
                    .events
                    .push_back((now, MasterEvent::Sdo { id, node, event })),
                Purpose::Scan => self.scan_result(node, event, now),
                Purpose::Pdo => self.pdo_result(n, id, event, now, out),
            }
        }
    }

    /// Starts node `n`'s next queued transfer; false if there is none.
    fn start_next(&mut self, n: usize, now: Instant, out: &mut Outbox) -> bool {
        let sdo = self.config.sdo;
        let scan_timeout = self.config.scan_timeout;
        let Some(p) = self.peers[n].as_mut() else {
            return false;
        };
        let Some(q) = p.queue.pop_front() else {
            return false;
        };
        let cfg = p.client.config_mut();
        *cfg = sdo;
        if q.purpose == Purpose::Scan {
            // A scan asks everyone: silence is the expected answer of an absent node, so
            // it ends without an abort frame and with a short timeout.
            cfg.timeout = scan_timeout;
            cfg.abort_on_timeout = false;
        }
        let r = match q.op {
            Op::Upload { mux, mode } => p.client.start_upload(mux.index, mux.sub, mode, now, out),
            Op::Download { mux, data, mode } => p
                .client
                .start_download(mux.index, mux.sub, data, mode, now, out),
        };
        p.current = Some((q.id, q.purpose));
        if let Err(e) = r {
            // Checked when queued; a refused start ends the transfer as a local abort.
            let _ = e;
            p.current = None;
            let node = u8::try_from(n).unwrap_or(0);
            self.events.push_back((
                now,
                MasterEvent::Sdo {
                    id: q.id,
                    node,
                    event: SdoEvent::Aborted {
                        mux: Mux::default(),
                        code: crate::AbortCode::GENERAL_ERROR,
                        by_server: false,
                    },
                },
            ));
        }
        true
    }

    /// Hands queued frames to the driver within the transmit window.
    fn flush(&mut self, mut local: Outbox, out: &mut Outbox) {
        self.txq.extend(local.drain());
        self.release(out);
    }

    fn release(&mut self, out: &mut Outbox) {
        while let Some(f) = self.txq.front() {
            if self
                .config
                .tx_window
                .is_some_and(|w| self.in_flight >= w.max(1))
            {
                break;
            }
            out.push(*f);
            self.txq.pop_front();
            self.in_flight += 1;
        }
    }

    // ---- NMT (CiA 301 §7.2.8.3.1) ----

    /// Sends NMT command `cs` to `node` (0: all nodes).
    pub fn nmt(&mut self, cs: NmtCs, node: u8, out: &mut Outbox) -> Result<(), MasterError> {
        if node > 127 {
            return Err(MasterError::NodeId(node));
        }
        let mut local = Outbox::new();
        local.push(NmtCommand { cs, node }.encode());
        self.flush(local, out);
        Ok(())
    }

    // ---- heartbeat consumer (CiA 301 §7.2.8.3.2.2) ----

    /// Watches `node`'s heartbeat with consumer time `time`: monitoring starts with the
    /// first heartbeat received (as a 0x1016 entry does), and a heartbeat not followed by
    /// the next within `time` is a [`MasterEvent::HeartbeatTimeout`]. `None` stops.
    pub fn watch_heartbeat(&mut self, node: u8, time: Option<Duration>) -> Result<(), MasterError> {
        let n = check_node(node)?;
        if time.is_some_and(|t| t.is_zero()) {
            return Err(MasterError::ZeroTime);
        }
        self.peer(n).heartbeat = time.map(|time| HeartbeatWatch {
            time,
            deadline: None,
        });
        Ok(())
    }

    // ---- node guarding master (CiA 301 §7.2.8.3.2.1) ----

    /// Guards `node`: a remote frame on 0x700 + node every `guard_time` from `now`, and a
    /// [`MasterEvent::GuardingTimeout`] when no valid response arrives within the node
    /// life time (`guard_time` × `life_time_factor`) of the last one (or of the start).
    /// The first response sets the toggle bit expected next; then it must alternate.
    /// `None` stops guarding.
    pub fn guard(
        &mut self,
        node: u8,
        times: Option<(Duration, u8)>,
        now: Instant,
    ) -> Result<(), MasterError> {
        let n = check_node(node)?;
        let watch = match times {
            None => None,
            Some((g, f)) if g.is_zero() || f == 0 => return Err(MasterError::ZeroTime),
            Some((guard_time, factor)) => {
                let life_time = guard_time.saturating_mul(u64::from(factor));
                Some(GuardWatch {
                    guard_time,
                    life_time,
                    next_poll: now,
                    life_deadline: now.checked_add(life_time),
                    expected_toggle: None,
                })
            }
        };
        self.peer(n).guard = watch;
        Ok(())
    }

    // ---- SYNC and TIME producers (CiA 301 §7.2.5, §7.2.6) ----

    /// Produces SYNC on 0x080 every `period`, the first one `period` after `now`. With
    /// `overflow` in 2..=240 each SYNC carries a counter running 1..=overflow
    /// (0x1019, §7.5.2.22); 0 or 1 sends SYNC without data. `None` stops.
    pub fn set_sync(
        &mut self,
        producer: Option<(Duration, u8)>,
        now: Instant,
    ) -> Result<(), MasterError> {
        self.sync = match producer {
            None => None,
            Some((p, _)) if p.is_zero() => return Err(MasterError::ZeroTime),
            Some((period, overflow)) => Some(SyncProducer {
                id: Id::Standard(
                    cantwin_can::StandardId::new(wire::SYNC_COB_ID)
                        .unwrap_or(cantwin_can::StandardId::MAX),
                ),
                period,
                overflow: if overflow >= 2 { overflow.min(240) } else { 0 },
                counter: 1,
                next: now.checked_add(period).unwrap_or(Instant::MAX),
            }),
        };
        Ok(())
    }

    /// Sends a TIME message with `time` on 0x100.
    pub fn send_time(&mut self, time: TimeOfDay, out: &mut Outbox) {
        let mut local = Outbox::new();
        local.push(wire::Time(time).encode(self.time_id));
        self.flush(local, out);
    }

    // ---- network scan ----

    /// Asks every node-ID 1..=127 for its device type (0x1000) at once, each with
    /// [`MasterConfig::scan_timeout`]; [`MasterEvent::ScanFinished`] lists who answered
    /// (with the value, or with an abort, which also proves the node is there).
    pub fn scan(&mut self, now: Instant, out: &mut Outbox) -> Result<(), MasterError> {
        if self.scan.is_some() {
            return Err(MasterError::ScanRunning);
        }
        self.scan = Some((127, Vec::new()));
        let mut local = Outbox::new();
        for n in 1..=127usize {
            let id = self.new_id();
            let op = Op::Upload {
                mux: Mux::new(0x1000, 0),
                mode: Mode::Segmented,
            };
            self.peer(n).queue.push_back(Queued {
                id,
                op,
                purpose: Purpose::Scan,
            });
            self.pump(n, now, &mut local);
        }
        self.flush(local, out);
        Ok(())
    }

    fn scan_result(&mut self, node: u8, event: SdoEvent, now: Instant) {
        let Some((pending, found)) = self.scan.as_mut() else {
            return;
        };
        let hit = match event {
            SdoEvent::Completed { data, .. } => Some(Ok(data
                .get(..4)
                .and_then(|b| <[u8; 4]>::try_from(b).ok())
                .map(u32::from_le_bytes)
                .unwrap_or(0))),
            SdoEvent::Aborted {
                code,
                by_server: true,
                ..
            } => Some(Err(code)),
            SdoEvent::Aborted { .. } => None,
            _ => return,
        };
        if let Some(device_type) = hit {
            found.push(ScanHit { node, device_type });
        }
        *pending -= 1;
        if *pending == 0 {
            let mut found = std::mem::take(found);
            found.sort_by_key(|h| h.node);
            self.scan = None;
            self.events
                .push_back((now, MasterEvent::ScanFinished { found }));
        }
    }

    // ---- remote PDO configuration (see [`pdo`]) ----

    /// Reads `node`'s PDO parameters (communication and mapping), reported as
    /// [`MasterEvent::Pdo`] with [`pdo::PdoOutcome::Read`].
    pub fn read_pdo(
        &mut self,
        node: u8,
        pdo: pdo::PdoRef,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<TransferId, MasterError> {
        self.start_job(node, pdo::Job::read(pdo), now, out)
    }

    /// Writes `node`'s PDO parameters with the CiA 301 §7.4.8.2 sequence (see
    /// [`pdo::Job::write`]), reported as [`MasterEvent::Pdo`] with
    /// [`pdo::PdoOutcome::Written`].
    pub fn write_pdo(
        &mut self,
        node: u8,
        pdo: pdo::PdoRef,
        params: &pdo::PdoParams,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<TransferId, MasterError> {
        self.start_job(node, pdo::Job::write(pdo, params), now, out)
    }

    fn start_job(
        &mut self,
        node: u8,
        mut job: pdo::Job,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<TransferId, MasterError> {
        let n = check_node(node)?;
        let id = self.new_id();
        let first = job.next_op();
        self.peer(n).job = Some((id, job));
        let mut local = Outbox::new();
        self.queue_job_op(n, id, first, now, &mut local);
        self.flush(local, out);
        Ok(id)
    }

    fn queue_job_op(
        &mut self,
        n: usize,
        id: TransferId,
        op: Option<pdo::JobOp>,
        now: Instant,
        out: &mut Outbox,
    ) {
        match op {
            Some(op) => {
                let op = match op {
                    pdo::JobOp::Read(index, sub) => Op::Upload {
                        mux: Mux::new(index, sub),
                        mode: Mode::Auto,
                    },
                    pdo::JobOp::Write(index, sub, data) => Op::Download {
                        mux: Mux::new(index, sub),
                        data,
                        mode: Mode::Auto,
                    },
                };
                self.peer(n).queue.push_back(Queued {
                    id,
                    op,
                    purpose: Purpose::Pdo,
                });
                self.pump(n, now, out);
            }
            None => {
                if let Some((id, job)) = self.peer(n).job.take() {
                    let node = u8::try_from(n).unwrap_or(0);
                    let result = job.finish();
                    self.events
                        .push_back((now, MasterEvent::Pdo { id, node, result }));
                }
            }
        }
    }

    fn pdo_result(
        &mut self,
        n: usize,
        id: TransferId,
        event: SdoEvent,
        now: Instant,
        out: &mut Outbox,
    ) {
        let data = match event {
            SdoEvent::Completed { data, .. } => Ok(data),
            SdoEvent::Aborted { mux, code, .. } => Err((mux, code)),
            _ => return,
        };
        let Some((_, job)) = self.peer(n).job.as_mut() else {
            return;
        };
        job.on_result(data);
        let next = job.next_op();
        self.queue_job_op(n, id, next, now, out);
    }

    // ---- frames and timers ----

    fn on_error_control(&mut self, node: u8, byte: u8, now: Instant) {
        let n = usize::from(node);
        let p = self.peer(n);
        p.status.last_seen = Some(now);
        let mut events = Vec::new();
        if byte == 0 {
            // Boot-up: the node enters pre-operational by itself (§7.3.2.2.1); heartbeat
            // monitoring pauses until its next heartbeat, and its first guarding
            // response after the reset carries toggle 0.
            events.push(MasterEvent::BootUp { node });
            if let Some(h) = p.heartbeat.as_mut() {
                h.deadline = None;
            }
            if let Some(g) = p.guard.as_mut() {
                g.expected_toggle = Some(false);
            }
            p.status.lost = false;
            let from = p.status.state;
            p.status.state = Some(NmtState::PreOperational);
            if from != p.status.state {
                events.push(MasterEvent::StateChanged {
                    node,
                    from,
                    to: NmtState::PreOperational,
                });
            }
        } else {
            let toggle = byte & 0x80 != 0;
            let state = NmtState::from_u8(byte & 0x7F);
            let mut valid = true;
            if let Some(g) = p.guard.as_mut() {
                // Guarding response (§7.2.8.3.2.1): the toggle bit alternates.
                if g.expected_toggle.is_some_and(|e| e != toggle) {
                    events.push(MasterEvent::GuardingToggleError { node });
                    valid = false;
                } else {
                    g.expected_toggle = Some(!toggle);
                    g.life_deadline = now.checked_add(g.life_time);
                }
            } else if let Some(h) = p.heartbeat.as_mut() {
                h.deadline = now.checked_add(h.time);
            }
            if valid {
                p.status.lost = false;
                if let Some(to) = state
                    && p.status.state != Some(to)
                {
                    events.push(MasterEvent::StateChanged {
                        node,
                        from: p.status.state,
                        to,
                    });
                    p.status.state = Some(to);
                }
            }
        }
        self.events.extend(events.into_iter().map(|e| (now, e)));
    }

    fn timers(&mut self, now: Instant, out: &mut Outbox) {
        for n in 1..128 {
            let Some(p) = self.peers[n].as_mut() else {
                continue;
            };
            let node = u8::try_from(n).unwrap_or(0);
            p.client.on_tick(now, out);
            if let Some(h) = p.heartbeat.as_mut()
                && h.deadline.is_some_and(|d| now >= d)
            {
                h.deadline = None;
                p.status.lost = true;
                self.events
                    .push_back((now, MasterEvent::HeartbeatTimeout { node }));
            }
            if let Some(g) = p.guard.as_mut() {
                if g.life_deadline.is_some_and(|d| now >= d) {
                    g.life_deadline = None;
                    p.status.lost = true;
                    self.events
                        .push_back((now, MasterEvent::GuardingTimeout { node }));
                }
                if now >= g.next_poll {
                    out.push(ErrorControl::GuardRequest { node }.encode());
                    g.next_poll = g
                        .next_poll
                        .checked_add(g.guard_time)
                        .unwrap_or(Instant::MAX);
                }
            }
            self.pump(n, now, out);
        }
        if let Some(s) = self.sync.as_mut()
            && now >= s.next
        {
            let counter = (s.overflow >= 2).then_some(s.counter);
            out.push(wire::Sync { counter }.encode(s.id));
            s.counter = if s.counter >= s.overflow {
                1
            } else {
                s.counter + 1
            };
            s.next = s.next.checked_add(s.period).unwrap_or(Instant::MAX);
        }
    }
}

impl Node for Master {
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let Id::Standard(sid) = frame.id() else {
            return;
        };
        let raw = sid.as_raw();
        let mut local = Outbox::new();
        match raw {
            0x581..=0x5FF => {
                let n = usize::from(raw - wire::SDO_TX_BASE);
                if let Some(p) = self.peers[n].as_mut()
                    && p.client.on_frame(frame, now, &mut local)
                {
                    self.pump(n, now, &mut local);
                }
            }
            0x701..=0x77F if !frame.is_remote() => {
                if let [b] = frame.data_bytes() {
                    // raw - 0x700 is 1..=127.
                    let node = u8::try_from(raw - wire::ERROR_CONTROL_BASE).unwrap_or(0);
                    self.on_error_control(node, *b, now);
                }
            }
            0x081..=0x0FF => {
                if let Ok(emcy) = Emcy::decode(frame) {
                    let node = u8::try_from(raw - wire::EMCY_BASE).unwrap_or(0);
                    self.events
                        .push_back((now, MasterEvent::Emcy { node, emcy }));
                }
            }
            _ => {}
        }
        self.flush(local, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.timers(now, &mut local);
        self.flush(local, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let mut next: Option<Instant> = self.sync.map(|s| s.next);
        let mut consider = |t: Option<Instant>| {
            if let Some(t) = t {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        };
        for p in self.peers.iter().flatten() {
            consider(p.client.next_deadline());
            consider(p.heartbeat.and_then(|h| h.deadline));
            if let Some(g) = p.guard {
                consider(Some(g.next_poll));
                consider(g.life_deadline);
            }
        }
        next
    }

    fn on_sent(&mut self, _frame: &Frame, _now: Instant, out: &mut Outbox) {
        self.in_flight = self.in_flight.saturating_sub(1);
        self.release(out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, _now: Instant, out: &mut Outbox) {
        if event == ControllerEvent::TxDropped {
            // A frame that will never be confirmed frees its place in the window.
            self.in_flight = self.in_flight.saturating_sub(1);
            self.release(out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn cia301_7_2_8_3_1_node_ids_are_checked() {
        let mut m = Master::new();
        let mut out = Outbox::new();
        let mux = Mux::new(0x1000, 0);
        assert_eq!(
            m.upload(0, mux, Mode::Auto, Instant::ZERO, &mut out),
            Err(MasterError::NodeId(0))
        );
        assert_eq!(
            m.upload(128, mux, Mode::Auto, Instant::ZERO, &mut out),
            Err(MasterError::NodeId(128))
        );
        assert_eq!(
            m.guard(5, Some((Duration::ZERO, 3)), Instant::ZERO),
            Err(MasterError::ZeroTime)
        );
        assert_eq!(
            m.download(5, mux, vec![0; 5], Mode::Expedited, Instant::ZERO, &mut out),
            Err(MasterError::Client(ClientError::ExpeditedLength(5)))
        );
        assert!(out.is_empty());
    }

    #[test]
    fn tx_window_holds_frames_until_they_are_sent() {
        let cfg = MasterConfig {
            tx_window: Some(2),
            ..MasterConfig::default()
        };
        let mut m = Master::with_config(cfg);
        let mut out = Outbox::new();
        for cs in [NmtCs::Start, NmtCs::Stop, NmtCs::ResetNode] {
            m.nmt(cs, 0, &mut out).unwrap();
        }
        let sent: Vec<Frame> = out.drain().collect();
        assert_eq!(sent.len(), 2);
        m.on_sent(&sent[0], Instant::ZERO, &mut out);
        let more: Vec<String> = out.drain().map(|f| f.to_string()).collect();
        assert_eq!(more, ["000#8100"]);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Any traffic, during a scan with guarding and a SYNC producer running: no panic,
        /// and the scan still ends at its timeout.
        #[test]
        fn any_traffic_is_handled(
            frames in proptest::collection::vec(
                (0u16..0x800, proptest::collection::vec(any::<u8>(), 0..=8), any::<bool>()),
                0..200,
            ),
        ) {
            let mut m = Master::new();
            let mut out = Outbox::new();
            m.scan(Instant::ZERO, &mut out).unwrap();
            m.guard(7, Some((Duration::from_millis(10), 3)), Instant::ZERO).unwrap();
            m.watch_heartbeat(9, Some(Duration::from_millis(20))).unwrap();
            m.set_sync(Some((Duration::from_millis(1), 5)), Instant::ZERO).unwrap();
            let mut now = Instant::ZERO;
            for (id, data, remote) in frames {
                now += Duration::from_micros(100);
                let f = if remote {
                    Frame::remote(Id::standard(id).unwrap(), 1).unwrap()
                } else {
                    Frame::std(id, &data).unwrap()
                };
                m.on_frame(&f, now, &mut out);
                for f in out.drain().collect::<Vec<_>>() {
                    m.on_sent(&f, now, &mut out);
                }
                if m.next_deadline().is_some_and(|d| d <= now) {
                    m.on_tick(now, &mut out);
                }
            }
            let end = Instant::from_nanos(2_000_000_000);
            while let Some(d) = m.next_deadline().filter(|d| *d <= end) {
                m.on_tick(d, &mut out);
                for f in out.drain().collect::<Vec<_>>() {
                    m.on_sent(&f, d, &mut out);
                }
            }
            let finished = std::iter::from_fn(|| m.poll_event())
                .filter(|(_, e)| matches!(e, MasterEvent::ScanFinished { .. }))
                .count();
            prop_assert_eq!(finished, 1);
        }
    }
}
