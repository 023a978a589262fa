//! The scanner (master, client) side: allocates slaves' Predefined Master/Slave
//! Connection Sets, sends explicit requests (fragmenting and reassembling as needed),
//! polls cyclically, opens UCMM connections and browses the network by MAC ID.
//!
//! The API queues operations and never blocks; one explicit transaction per slave is in
//! flight at a time. Results come back as [`ScannerEvent`]s from [`Scanner::poll_event`].

mod exchange;
pub mod explicit;

use crate::fragment::{ExplicitReassembler, ExplicitSender, IoReassembler, TxProgress};
use crate::link::{DupMacCheck, LinkState};
use crate::objects::Identity;
use crate::wire::{
    self, BodyFormat, DnId, DupMac, MacId, UcmmOpenReply, choice, group1, group2, group3, service,
};
use cantwin_can::{Duration, Frame, Instant, Node, Outbox};
use std::collections::{BTreeMap, VecDeque};

/// Scanner configuration.
#[derive(Debug, Clone)]
pub struct ScannerConfig {
    /// The scanner's own MAC ID.
    pub mac: MacId,
    /// Vendor ID used in the duplicate MAC ID check.
    pub vendor: u16,
    /// Serial number used in the duplicate MAC ID check.
    pub serial: u32,
    /// How long to wait for an explicit response.
    pub response_timeout: Duration,
    /// Largest explicit response body accepted.
    pub max_explicit: usize,
}

impl ScannerConfig {
    /// Defaults: 1 s response timeout, 240-byte responses.
    pub fn new(mac: MacId, vendor: u16, serial: u32) -> Self {
        ScannerConfig {
            mac,
            vendor,
            serial,
            response_timeout: Duration::from_secs(1),
            max_explicit: 240,
        }
    }
}

/// A request the scanner cannot queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ScannerError {
    /// The slave's address is the scanner's own.
    #[error("MAC ID {0} is the scanner's own")]
    OwnMac(MacId),
}

/// What the scanner reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScannerEvent {
    /// The scanner's duplicate MAC ID check passed.
    Online,
    /// Another node answered the scanner's duplicate MAC ID check.
    DuplicateMac,
    /// A slave accepted an Allocate; explicit requests use `format`.
    Allocated {
        /// The slave.
        slave: MacId,
        /// The allocated choice.
        choice: u8,
        /// Message body format of the explicit connection.
        format: BodyFormat,
    },
    /// A slave accepted a Release.
    Released {
        /// The slave.
        slave: MacId,
        /// The released choice.
        choice: u8,
    },
    /// A UCMM explicit connection was opened.
    Opened {
        /// The slave.
        slave: MacId,
        /// The answer: format, message IDs, instance.
        reply: UcmmOpenReply,
    },
    /// A UCMM explicit connection was closed.
    Closed {
        /// The slave.
        slave: MacId,
    },
    /// Success response to an explicit request.
    Response {
        /// The slave.
        slave: MacId,
        /// The request's service.
        service: u8,
        /// Reply data.
        data: Vec<u8>,
    },
    /// Error response (to any request, Allocate and Release included).
    Error {
        /// The slave.
        slave: MacId,
        /// The request's service.
        service: u8,
        /// General status.
        general: u8,
        /// Additional code.
        additional: u8,
    },
    /// The request could not be sent: no explicit connection to the slave when its turn
    /// came (allocate or open one first).
    NotConnected {
        /// The slave.
        slave: MacId,
        /// The request's service.
        service: u8,
    },
    /// No response (or the fragmented transfer was abandoned).
    Timeout {
        /// The slave.
        slave: MacId,
        /// The request's service.
        service: u8,
    },
    /// A poll response.
    PollResponse {
        /// The slave.
        slave: MacId,
        /// Input data.
        data: Vec<u8>,
    },
    /// Browse found a device (identity `None` if it refused the allocation).
    DeviceFound {
        /// The device's MAC ID.
        slave: MacId,
        /// Its Identity attributes 1–7.
        identity: Option<Identity>,
    },
    /// Browse finished.
    BrowseDone {
        /// The MAC IDs that answered.
        found: Vec<MacId>,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Op {
    Allocate(u8),
    Release(u8),
    Request {
        service: u8,
        class: u16,
        instance: u16,
        data: Vec<u8>,
    },
    UcmmOpen(u8),
    UcmmClose,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    Unconnected,
    Predefined,
    Ucmm,
    UcmmConnection,
}

#[derive(Debug)]
struct InFlight {
    op: Op,
    service: u8,
    /// The transaction ID sent; the server echoes it, so stale answers are told apart.
    xid: bool,
    route: Route,
    deadline: Instant,
    browse: bool,
}

#[derive(Debug, Clone, Copy)]
struct UcmmLink {
    client_msg: u8,
    server_msg: u8,
    instance: u16,
    format: BodyFormat,
}

#[derive(Debug)]
struct PollCycle {
    period: Duration,
    next: Instant,
    output: Vec<u8>,
}

#[derive(Debug)]
struct Peer {
    explicit: Option<BodyFormat>,
    ucmm: Option<UcmmLink>,
    queue: VecDeque<(Op, bool)>,
    in_flight: Option<InFlight>,
    rx: ExplicitReassembler,
    tx: Option<ExplicitSender>,
    xid: bool,
    input_size: u16,
    io_rx: IoReassembler,
    cycle: Option<PollCycle>,
    browse_identity: Option<Identity>,
}

impl Peer {
    fn new(max: usize) -> Self {
        Peer {
            explicit: None,
            ucmm: None,
            queue: VecDeque::new(),
            in_flight: None,
            rx: ExplicitReassembler::new(max),
            tx: None,
            xid: false,
            input_size: 0,
            io_rx: IoReassembler::new(256),
            cycle: None,
            browse_identity: None,
        }
    }
}

/// A DeviceNet scanner.
#[derive(Debug)]
pub struct Scanner {
    config: ScannerConfig,
    link: DupMacCheck,
    peers: BTreeMap<MacId, Peer>,
    events: VecDeque<ScannerEvent>,
    browse_pending: Vec<MacId>,
    browse_found: Vec<MacId>,
    browsing: bool,
}

impl Scanner {
    /// A scanner; it checks its MAC ID at [`Node::on_power_up`].
    pub fn new(config: ScannerConfig) -> Self {
        let link = DupMacCheck::new(config.mac, config.vendor, config.serial);
        Scanner {
            config,
            link,
            peers: BTreeMap::new(),
            events: VecDeque::new(),
            browse_pending: Vec::new(),
            browse_found: Vec::new(),
            browsing: false,
        }
    }

    /// The scanner's network access state.
    pub fn link_state(&self) -> LinkState {
        self.link.state()
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<ScannerEvent> {
        self.events.pop_front()
    }

    fn peer(&mut self, slave: MacId) -> &mut Peer {
        let max = self.config.max_explicit;
        self.peers.entry(slave).or_insert_with(|| Peer::new(max))
    }

    fn queue(&mut self, slave: MacId, op: Op, browse: bool) -> Result<(), ScannerError> {
        if slave == self.config.mac {
            return Err(ScannerError::OwnMac(slave));
        }
        self.peer(slave).queue.push_back((op, browse));
        Ok(())
    }

    /// Allocate connections (`choice` bits) of the slave's Predefined Master/Slave
    /// Connection Set through its group 2 only unconnected port.
    pub fn allocate(&mut self, slave: MacId, choice: u8) -> Result<(), ScannerError> {
        self.queue(slave, Op::Allocate(choice), false)
    }

    /// Release connections (`choice` bits).
    pub fn release(&mut self, slave: MacId, choice: u8) -> Result<(), ScannerError> {
        self.queue(slave, Op::Release(choice), false)
    }

    /// Open an explicit connection through the slave's UCMM, asking for a body format.
    pub fn open_ucmm(&mut self, slave: MacId, format: BodyFormat) -> Result<(), ScannerError> {
        self.queue(slave, Op::UcmmOpen(format.code()), false)
    }

    /// Close the UCMM connection to the slave.
    pub fn close_ucmm(&mut self, slave: MacId) -> Result<(), ScannerError> {
        self.queue(slave, Op::UcmmClose, false)
    }

    /// Send an explicit request on the slave's explicit connection (predefined if
    /// allocated or queued for allocation, else UCMM).
    pub fn request(
        &mut self,
        slave: MacId,
        service: u8,
        class: u16,
        instance: u16,
        data: &[u8],
    ) -> Result<(), ScannerError> {
        self.queue(
            slave,
            Op::Request {
                service,
                class,
                instance,
                data: data.to_vec(),
            },
            false,
        )
    }

    /// Get_Attribute_Single.
    pub fn get_attribute_single(
        &mut self,
        slave: MacId,
        class: u16,
        instance: u16,
        attribute: u8,
    ) -> Result<(), ScannerError> {
        self.request(
            slave,
            service::GET_ATTRIBUTE_SINGLE,
            class,
            instance,
            &[attribute],
        )
    }

    /// Set_Attribute_Single.
    pub fn set_attribute_single(
        &mut self,
        slave: MacId,
        class: u16,
        instance: u16,
        attribute: u8,
        value: &[u8],
    ) -> Result<(), ScannerError> {
        let mut data = vec![attribute];
        data.extend_from_slice(value);
        self.request(slave, service::SET_ATTRIBUTE_SINGLE, class, instance, &data)
    }

    /// Set a connection's expected packet rate (Connection attribute 9), which moves an
    /// allocated I/O connection to Established.
    pub fn set_expected_packet_rate(
        &mut self,
        slave: MacId,
        instance: u16,
        ms: u16,
    ) -> Result<(), ScannerError> {
        self.set_attribute_single(slave, 5, instance, 9, &ms.to_le_bytes())
    }

    /// Send one poll command now; `input_size` is the slave's produced size (I/O
    /// fragmented above 8 bytes).
    pub fn poll(&mut self, slave: MacId, output: &[u8], input_size: u16, out: &mut Outbox) {
        self.peer(slave).input_size = input_size;
        for f in poll_frames(slave, output) {
            out.push(f);
        }
    }

    /// Poll the slave every `period` from `start` on with `output`.
    pub fn start_polling(
        &mut self,
        slave: MacId,
        period: Duration,
        output: &[u8],
        input_size: u16,
        start: Instant,
    ) {
        let p = self.peer(slave);
        p.input_size = input_size;
        p.cycle = Some(PollCycle {
            period,
            next: start,
            output: output.to_vec(),
        });
    }

    /// Change the cyclic poll output data.
    pub fn set_output(&mut self, slave: MacId, output: &[u8]) {
        if let Some(c) = self.peer(slave).cycle.as_mut() {
            c.output = output.to_vec();
        }
    }

    /// Stop polling the slave (a silent master, as far as the slave is concerned).
    pub fn stop_polling(&mut self, slave: MacId) {
        self.peer(slave).cycle = None;
    }

    /// Browse `macs`: allocate explicit messaging, read the Identity with
    /// Get_Attributes_All, release. Reports [`ScannerEvent::DeviceFound`] per device and
    /// [`ScannerEvent::BrowseDone`] at the end.
    pub fn browse(&mut self, macs: impl IntoIterator<Item = MacId>) {
        self.browsing = true;
        self.browse_found.clear();
        for m in macs {
            if m == self.config.mac {
                continue;
            }
            self.browse_pending.push(m);
            let p = self.peer(m);
            p.queue.push_back((Op::Allocate(choice::EXPLICIT), true));
            p.queue.push_back((
                Op::Request {
                    service: service::GET_ATTRIBUTES_ALL,
                    class: 1,
                    instance: 1,
                    data: Vec::new(),
                },
                true,
            ));
            p.queue.push_back((Op::Release(choice::EXPLICIT), true));
        }
    }

    fn browse_finished(&mut self, slave: MacId) {
        self.browse_pending.retain(|&m| m != slave);
        if self.browsing && self.browse_pending.is_empty() {
            self.browsing = false;
            self.events.push_back(ScannerEvent::BrowseDone {
                found: core::mem::take(&mut self.browse_found),
            });
        }
    }

    /// Browse of `slave` ended after its allocation: report it with what was read.
    fn browse_device_done(&mut self, slave: MacId) {
        let identity = self
            .peers
            .get_mut(&slave)
            .and_then(|p| p.browse_identity.take());
        self.browse_found.push(slave);
        self.events
            .push_back(ScannerEvent::DeviceFound { slave, identity });
        self.drop_browse_ops(slave);
    }

    fn drop_browse_ops(&mut self, slave: MacId) {
        if let Some(p) = self.peers.get_mut(&slave) {
            p.queue.retain(|(_, b)| !b);
        }
        self.browse_finished(slave);
    }
}

fn poll_frames(slave: MacId, output: &[u8]) -> Vec<Frame> {
    let id = DnId::g2(slave, group2::POLL_COMMAND);
    if output.len() > 8 {
        wire::io_fragments(output)
            .iter()
            .map(|f| id.frame(f))
            .collect()
    } else {
        vec![id.frame(output)]
    }
}

/// Parse an Identity Get_Attributes_All reply (attributes 1–7).
pub fn parse_identity(d: &[u8]) -> Option<Identity> {
    if d.len() < 15 {
        return None;
    }
    let u16at = |i: usize| u16::from_le_bytes([d[i], d[i + 1]]);
    let n = usize::from(d[14]);
    let name = d.get(15..15 + n)?;
    Some(Identity {
        vendor: u16at(0),
        device_type: u16at(2),
        product_code: u16at(4),
        revision: (d[6], d[7]),
        serial: u32::from_le_bytes([d[10], d[11], d[12], d[13]]),
        product_name: String::from_utf8_lossy(name).into_owned(),
    })
}

impl Node for Scanner {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        out.push(self.link.start(now));
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if frame.is_remote() {
            return;
        }
        let Ok(dn) = DnId::decode(frame.id()) else {
            return;
        };
        let data = frame.data_bytes();
        let own = self.config.mac;
        match dn {
            DnId::Group2 {
                mac,
                msg: group2::DUP_MAC_CHECK,
            } if mac == own => {
                if let Some(m) = DupMac::decode(data) {
                    let was = self.link.state();
                    if let Some(f) = self.link.on_message(&m) {
                        out.push(f);
                    } else if was != LinkState::CommFaulted
                        && self.link.state() == LinkState::CommFaulted
                    {
                        self.events.push_back(ScannerEvent::DuplicateMac);
                    }
                }
            }
            DnId::Group2 {
                mac,
                msg: group2::EXPLICIT_RESPONSE,
            } => self.on_response_frame(
                mac,
                &[Route::Unconnected, Route::Predefined],
                data,
                now,
                out,
            ),
            DnId::Group3 {
                msg: group3::UNCONNECTED_RESPONSE,
                mac,
            } => self.on_response_frame(mac, &[Route::Ucmm], data, now, out),
            DnId::Group3 { msg, mac } => {
                let matches = self
                    .peers
                    .get(&mac)
                    .and_then(|p| p.ucmm)
                    .is_some_and(|u| u.server_msg == msg);
                if matches {
                    self.on_response_frame(mac, &[Route::UcmmConnection], data, now, out);
                }
            }
            DnId::Group1 {
                msg: group1::POLL_RESPONSE,
                mac,
            } => self.on_poll_response(mac, data),
            _ => {}
        }
        self.pump(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let was_online = self.link.is_online();
        if let Some(f) = self.link.on_tick(now) {
            out.push(f);
        }
        if !was_online && self.link.is_online() {
            self.events.push_back(ScannerEvent::Online);
        }
        let slaves: Vec<MacId> = self.peers.keys().copied().collect();
        for slave in slaves {
            let Some(p) = self.peers.get_mut(&slave) else {
                continue;
            };
            if let Some(tx) = p.tx.as_mut() {
                let route = p.in_flight.as_ref().map_or(Route::Predefined, |f| f.route);
                match tx.on_tick(now) {
                    Some(TxProgress::Send(f)) => {
                        let id = match route {
                            Route::Predefined | Route::Unconnected => {
                                DnId::g2(slave, group2::EXPLICIT_REQUEST)
                            }
                            _ => DnId::Group3 {
                                msg: p.ucmm.map_or(0, |u| u.client_msg),
                                mac: self.config.mac,
                            },
                        };
                        out.push(id.frame(&f));
                    }
                    Some(TxProgress::Aborted) => {
                        self.finish_timeout(slave, now);
                        continue;
                    }
                    _ => {}
                }
            }
            let Some(p) = self.peers.get_mut(&slave) else {
                continue;
            };
            if p.tx.is_none() && p.in_flight.as_ref().is_some_and(|f| now >= f.deadline) {
                self.finish_timeout(slave, now);
            }
            let Some(p) = self.peers.get_mut(&slave) else {
                continue;
            };
            if let Some(c) = p.cycle.as_mut() {
                if now >= c.next && self.link.is_online() {
                    for f in poll_frames(slave, &c.output) {
                        out.push(f);
                    }
                    c.next = now + c.period;
                }
            }
        }
        self.pump(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let mut d = self.link.deadline();
        let mut min = |t: Instant| d = Some(d.map_or(t, |x: Instant| x.min(t)));
        for p in self.peers.values() {
            // Queued work with nothing in flight: wake at once (the API has no clock).
            if self.link.is_online() && p.in_flight.is_none() && !p.queue.is_empty() {
                min(Instant::ZERO);
            }
            if let Some(tx) = &p.tx {
                min(tx.deadline());
            } else if let Some(f) = &p.in_flight {
                min(f.deadline);
            }
            if let Some(c) = &p.cycle {
                min(c.next);
            }
        }
        d
    }
}
