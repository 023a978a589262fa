//! The DeviceNet slave (server): a UCMM-capable device of the Predefined Master/Slave
//! Connection Set, driven through [`cantwin_can::Node`].
//!
//! Frames are routed by identifier: the duplicate MAC ID check (group 2 message 7), the
//! group 2 only unconnected port (message 6: Allocate/Release), the predefined explicit
//! connection (message 4), the poll command (message 5), the UCMM (group 3 message 6) and
//! the explicit connections the UCMM opened (group 3, the client's message ID). Nothing
//! but the duplicate MAC ID check is answered before the node is on-line.

use crate::fragment::{RxOutcome, TxProgress};
use crate::link::{DupMacCheck, LinkState};
use crate::objects::connection::{
    self as conn, ConnKind, ConnState, Connection, WATCHDOG_AUTO_DELETE, WATCHDOG_AUTO_RESET,
};
use crate::objects::devicenet::{self as dnobj, DeviceNetObject};
use crate::objects::identity::{self, IdentityAction};
use crate::objects::parameter::{self, ParameterObject};
use crate::objects::{Application, CipError, Identity, Reply, SlaveEvent, message_router};
use crate::ucmm;
use crate::wire::{
    self, Allocate, BodyFormat, DnId, DupMac, ExplicitFrame, Header, MacId, Request, RequestError,
    alloc_error, choice, group1, group2, group3, service, status,
};
use cantwin_can::{BitRate, ControllerEvent, Frame, Id, Instant, Node, Outbox};

/// Configuration of a slave: address, bit rate, identity and the limits of the device.
#[derive(Debug, Clone)]
pub struct SlaveConfig {
    /// MAC ID (the card accepts 1–63).
    pub mac: MacId,
    /// Bit rate (DeviceNet: 125, 250 or 500 kbit/s).
    pub bit_rate: BitRate,
    /// Identity object values.
    pub identity: Identity,
    /// Largest explicit message body in either direction (the EXP-CAN/DN-ADV card: 32
    /// bytes, manual §3.2).
    pub max_explicit: u16,
    /// Explicit connections the UCMM may open at once (the card: 3 explicit connections
    /// in all, manual §3.3.1, so 2 besides the predefined one).
    pub ucmm_connections: usize,
    /// First Connection instance ID used for UCMM connections.
    pub ucmm_first_instance: u16,
    /// The body format answered to an Allocate (8/8 unless the device needs 16-bit
    /// class or instance IDs on the predefined connection).
    pub allocate_format: BodyFormat,
    /// Timer resolution in ms: expected packet rates are rounded up to it.
    pub epr_resolution_ms: u16,
    /// Expected packet rate of a new explicit connection in ms (2500 ms by default).
    pub explicit_epr_ms: u16,
}

impl SlaveConfig {
    /// A configuration with the defaults described on each field.
    pub fn new(mac: MacId, bit_rate: BitRate, identity: Identity) -> Self {
        SlaveConfig {
            mac,
            bit_rate,
            identity,
            max_explicit: 32,
            ucmm_connections: 2,
            ucmm_first_instance: 6,
            allocate_format: BodyFormat::F8_8,
            epr_resolution_ms: 10,
            explicit_epr_ms: 2500,
        }
    }
}

/// A slave configuration DeviceNet cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// DeviceNet runs at 125, 250 or 500 kbit/s only.
    #[error("DeviceNet runs at 125, 250 or 500 kbit/s, not {0} bit/s")]
    BitRate(u32),
    /// Group 3 offers 5 connection message IDs (0–4) per server.
    #[error("at most 5 UCMM connections (group 3 message IDs 0-4), not {0}")]
    TooManyUcmmConnections(usize),
    /// The product name is a SHORT_STRING of at most 32 characters.
    #[error("product name longer than 32 bytes")]
    ProductName,
    /// The timer resolution must be at least 1 ms.
    #[error("expected packet rate resolution of 0 ms")]
    Resolution,
}

/// The DeviceNet object's baud rate code for a bit rate (0 = 125, 1 = 250, 2 = 500
/// kbit/s); `None` for a rate DeviceNet does not define.
pub fn baud_code(rate: BitRate) -> Option<u8> {
    match rate {
        BitRate::R125K => Some(0),
        BitRate::R250K => Some(1),
        BitRate::R500K => Some(2),
        _ => None,
    }
}

/// The network status as the module/network status LEDs show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NetworkStatus {
    /// Not powered.
    Off,
    /// Duplicate MAC ID check in progress.
    SelfTest,
    /// On-line, waiting for the master or polled I/O not active.
    WaitingForMaster,
    /// Polled I/O established: operational.
    IoActive,
    /// Recoverable fault: duplicate MAC ID, bus-off, or a timed-out connection.
    RecoverableFault,
}

/// A LED's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Led {
    /// Off.
    Off,
    /// On.
    On,
    /// Blinking.
    Blink,
}

impl NetworkStatus {
    /// The (OP green, AL red) LEDs of the EXP-CAN/DN-ADV card (manual, "LEDs" table).
    pub fn leds(self) -> (Led, Led) {
        match self {
            NetworkStatus::Off => (Led::Off, Led::Off),
            NetworkStatus::SelfTest => (Led::Blink, Led::Blink),
            NetworkStatus::WaitingForMaster => (Led::Blink, Led::Off),
            NetworkStatus::IoActive => (Led::On, Led::Off),
            NetworkStatus::RecoverableFault => (Led::Off, Led::Blink),
        }
    }
}

/// Which explicit connection a message belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    /// The predefined explicit connection (instance 1).
    Predefined,
    /// A UCMM connection (index into `ucmm`).
    Ucmm(usize),
}

/// A DeviceNet slave serving `A`'s device.
#[derive(Debug)]
pub struct Slave<A> {
    app: A,
    config: SlaveConfig,
    link: DupMacCheck,
    dn: DeviceNetObject,
    explicit: Option<Connection>,
    poll: Option<Connection>,
    ucmm: Vec<Connection>,
    bus_off: bool,
    powered: bool,
    pending_reset: Option<u8>,
    parameters: Option<ParameterObject>,
}

impl<A: Application> Slave<A> {
    /// A slave; it stays silent until [`Node::on_power_up`].
    pub fn new(config: SlaveConfig, app: A) -> Result<Self, ConfigError> {
        let baud = baud_code(config.bit_rate)
            .ok_or(ConfigError::BitRate(config.bit_rate.bits_per_second()))?;
        if config.ucmm_connections > 5 {
            return Err(ConfigError::TooManyUcmmConnections(config.ucmm_connections));
        }
        if config.identity.product_name.len() > 32 {
            return Err(ConfigError::ProductName);
        }
        if config.epr_resolution_ms == 0 {
            return Err(ConfigError::Resolution);
        }
        let link = DupMacCheck::new(config.mac, config.identity.vendor, config.identity.serial);
        let dn = DeviceNetObject {
            mac: config.mac,
            baud,
            boi: false,
            bus_off_count: 0,
            choice: 0,
            master: None,
        };
        Ok(Slave {
            app,
            config,
            link,
            dn,
            explicit: None,
            poll: None,
            ucmm: Vec::new(),
            bus_off: false,
            powered: false,
            pending_reset: None,
            parameters: None,
        })
    }

    /// Serve class 0x0F from a table-driven Parameter object (unless the application
    /// answers class 0x0F itself).
    pub fn with_parameters(mut self, parameters: ParameterObject) -> Self {
        self.parameters = Some(parameters);
        self
    }

    /// The table-driven Parameter object, if any.
    pub fn parameters(&self) -> Option<&ParameterObject> {
        self.parameters.as_ref()
    }

    /// The application.
    pub fn app(&self) -> &A {
        &self.app
    }

    /// The application, mutably.
    pub fn app_mut(&mut self) -> &mut A {
        &mut self.app
    }

    /// The configuration.
    pub fn config(&self) -> &SlaveConfig {
        &self.config
    }

    /// The network access state.
    pub fn link_state(&self) -> LinkState {
        self.link.state()
    }

    /// The DeviceNet object's attributes.
    pub fn devicenet_object(&self) -> &DeviceNetObject {
        &self.dn
    }

    /// The predefined explicit connection (instance 1), if allocated.
    pub fn explicit_connection(&self) -> Option<&Connection> {
        self.explicit.as_ref()
    }

    /// The polled I/O connection (instance 2), if allocated.
    pub fn poll_connection(&self) -> Option<&Connection> {
        self.poll.as_ref()
    }

    /// The explicit connections opened through the UCMM.
    pub fn ucmm_connections(&self) -> &[Connection] {
        &self.ucmm
    }

    /// The status the LEDs show.
    pub fn network_status(&self) -> NetworkStatus {
        if !self.powered {
            return NetworkStatus::Off;
        }
        match self.link.state() {
            LinkState::Offline => NetworkStatus::Off,
            LinkState::Checking { .. } => NetworkStatus::SelfTest,
            LinkState::CommFaulted => NetworkStatus::RecoverableFault,
            LinkState::Online => match self.poll.as_ref().map(|c| c.state) {
                Some(ConnState::Established) => NetworkStatus::IoActive,
                Some(ConnState::TimedOut) => NetworkStatus::RecoverableFault,
                _ => NetworkStatus::WaitingForMaster,
            },
        }
    }

    /// Identity attribute 5: owned bit and extended device status.
    pub fn status_word(&self) -> u16 {
        let owned = if self.dn.master.is_some() {
            identity::STATUS_OWNED
        } else {
            0
        };
        let ext = match &self.poll {
            Some(c) if c.state == ConnState::TimedOut => identity::EXT_IO_FAULTED,
            Some(c) if c.state == ConnState::Established && c.idle => identity::EXT_IO_IDLE,
            Some(c) if c.state == ConnState::Established => identity::EXT_IO_RUN,
            _ => identity::EXT_NO_IO,
        };
        owned | ext
    }

    fn response_id(&self) -> DnId {
        DnId::g2(self.config.mac, group2::EXPLICIT_RESPONSE)
    }

    fn drop_connections(&mut self) {
        self.explicit = None;
        self.poll = None;
        self.ucmm.clear();
        self.dn.choice = 0;
        self.dn.master = None;
    }

    fn restart(&mut self, now: Instant, out: &mut Outbox) {
        self.drop_connections();
        self.bus_off = false;
        out.push(self.link.start(now));
    }

    // ----- explicit message transport -----

    fn channel_conn(&mut self, ch: Channel) -> Option<&mut Connection> {
        match ch {
            Channel::Predefined => self.explicit.as_mut(),
            Channel::Ucmm(i) => self.ucmm.get_mut(i),
        }
    }

    /// Send a response body on a channel, fragmenting it if needed.
    fn send_body(
        &mut self,
        ch: Channel,
        id: DnId,
        header: Header,
        body: &[u8],
        now: Instant,
        out: &mut Outbox,
    ) {
        let frames = wire::explicit_frames(header, body);
        if frames.len() == 1 {
            if let Some(f) = frames.first() {
                out.push(id.frame(f));
            }
            return;
        }
        let (sender, first) = crate::fragment::ExplicitSender::start(frames, now);
        out.push(id.frame(&first));
        if let Some(c) = self.channel_conn(ch) {
            c.tx = Some(sender);
        }
    }

    /// A frame on an explicit connection.
    fn on_explicit(&mut self, ch: Channel, data: &[u8], now: Instant, out: &mut Outbox) {
        let Ok(frame) = ExplicitFrame::decode(data) else {
            return;
        };
        let own = self.config.mac;
        let Some(c) = self.channel_conn(ch) else {
            return;
        };
        let (peer, id, format) = (c.peer, c.produced_id, c.format);
        // Predefined: the header carries the master (source). UCMM: the identifier carries
        // the client, the header our own MAC ID (destination).
        let expected = match ch {
            Channel::Predefined => peer,
            Channel::Ucmm(_) => own,
        };
        if frame.header().mac != expected {
            return;
        }
        c.kick(now);
        let xid = frame.header().xid;
        let reply_header = Header::new(xid, peer);
        let body = match frame {
            ExplicitFrame::Whole { body, .. } => {
                c.rx.reset();
                c.tx = None;
                body.to_vec()
            }
            ExplicitFrame::Ack { count, status, .. } => {
                let Some(tx) = c.tx.as_mut() else { return };
                match tx.on_ack(count, status, now) {
                    TxProgress::Send(f) => out.push(id.frame(&f)),
                    TxProgress::Done | TxProgress::Aborted => c.tx = None,
                    TxProgress::Ignored => {}
                }
                return;
            }
            ExplicitFrame::Fragment { frag, data, .. } => {
                c.tx = None;
                let ack = |count, st| id.frame(&wire::encode_ack(xid, peer, count, st));
                match c.rx.on_fragment(frag, data) {
                    RxOutcome::Ack { count, status } => {
                        out.push(ack(count, status));
                        return;
                    }
                    RxOutcome::Discard => return,
                    RxOutcome::Complete { count, body } => {
                        out.push(ack(count, wire::ack_status::SUCCESS));
                        body
                    }
                }
            }
        };
        let reply = match Request::decode(&body, format) {
            Ok(req) => self.dispatch(ch, &req, now),
            Err(RequestError::NoPath(_)) => CipError::new(status::NOT_ENOUGH_DATA).into(),
            Err(_) => return,
        };
        let service = body.first().copied().unwrap_or(0);
        self.reply(ch, id, reply_header, service, reply, now, out);
        self.after_dispatch(now, out);
    }

    #[allow(clippy::too_many_arguments)]
    fn reply(
        &mut self,
        ch: Channel,
        id: DnId,
        header: Header,
        service: u8,
        reply: Reply,
        now: Instant,
        out: &mut Outbox,
    ) {
        let body = match reply {
            Reply::Silent => return,
            Reply::Data(d) if d.len() + 1 > usize::from(self.config.max_explicit) => {
                wire::encode_error(status::REPLY_TOO_LARGE, status::NO_ADDITIONAL).to_vec()
            }
            Reply::Data(d) => wire::encode_success(service, &d),
            Reply::Error(e) => wire::encode_error(e.general, e.additional).to_vec(),
        };
        self.send_body(ch, id, header, &body, now, out);
    }

    // ----- deferred effects of a request -----

    fn after_dispatch(&mut self, now: Instant, out: &mut Outbox) {
        if let Some(kind) = self.pending_reset.take() {
            self.app.event(SlaveEvent::Reset(kind), now);
            self.restart(now, out);
        }
    }

    // ----- the message router -----

    fn dispatch(&mut self, ch: Channel, req: &Request<'_>, now: Instant) -> Reply {
        if let Some(r) = self.app.request(req, now) {
            return r;
        }
        match req.class {
            identity::CLASS => {
                let (reply, action) =
                    identity::serve(&self.config.identity, self.status_word(), req);
                if let IdentityAction::Reset(kind) = action {
                    self.pending_reset = Some(kind);
                }
                reply
            }
            0x02 => message_router(req),
            dnobj::CLASS if req.instance == 1 && req.service == service::ALLOCATE => {
                let peer = self.channel_conn(ch).map(|c| c.peer);
                self.allocate(req, peer, now)
            }
            dnobj::CLASS if req.instance == 1 && req.service == service::RELEASE => {
                let peer = self.channel_conn(ch).map(|c| c.peer);
                self.release(req, peer, now)
            }
            dnobj::CLASS => self.dn.serve(req),
            conn::CLASS => self.serve_connection(req, now),
            parameter::CLASS if self.parameters.is_some() => match self.parameters.as_mut() {
                Some(p) => p.serve(req),
                None => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
            },
            _ => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
        }
    }

    fn serve_connection(&mut self, req: &Request<'_>, now: Instant) -> Reply {
        let res = self.config.epr_resolution_ms;
        if req.instance == 0 {
            return crate::objects::attribute_service(
                req,
                &[crate::objects::get(1)],
                |_| 1u16.to_le_bytes().to_vec(),
                |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
            );
        }
        let c = match req.instance {
            1 => self.explicit.as_mut(),
            2 => self.poll.as_mut(),
            i => self.ucmm.iter_mut().find(|c| c.instance == i),
        };
        let Some(c) = c else {
            return CipError::new(status::OBJECT_DOES_NOT_EXIST).into();
        };
        let was = c.state;
        let reply = c.serve(req, res, now);
        let established = was != ConnState::Established && c.state == ConnState::Established;
        if established && c.kind == ConnKind::Polled {
            self.app.event(SlaveEvent::IoEstablished, now);
        }
        reply
    }

    // ----- Predefined Master/Slave Connection Set -----

    /// Allocate_Master/Slave_Connection_Set. `via` is the master of the explicit
    /// connection the request came on (`None` on the unconnected port).
    fn allocate(&mut self, req: &Request<'_>, via: Option<MacId>, now: Instant) -> Reply {
        let Some(a) = Allocate::decode(req.data) else {
            return CipError::new(status::NOT_ENOUGH_DATA).into();
        };
        if req.data.len() > 2 {
            return CipError::new(status::TOO_MUCH_DATA).into();
        }
        let invalid = CipError::with(status::INVALID_PARAMETER, alloc_error::INVALID_CHOICE);
        let supported = choice::EXPLICIT | choice::POLLED;
        if a.choice == 0 || a.choice & !supported != 0 {
            return invalid.into();
        }
        if let Some(owner) = self.dn.master {
            if owner != a.allocator || via.is_some_and(|v| v != owner) {
                return CipError::with(
                    status::OBJECT_STATE_CONFLICT,
                    alloc_error::ALLOCATION_CONFLICT,
                )
                .into();
            }
        }
        if a.choice & self.dn.choice != 0 {
            return CipError::with(status::ALREADY_IN_STATE, alloc_error::INVALID_CHOICE).into();
        }
        if (a.choice | self.dn.choice) & choice::EXPLICIT == 0 {
            return invalid.into();
        }
        let mac = self.config.mac;
        let master = a.allocator;
        if a.choice & choice::EXPLICIT != 0 {
            let max = self.config.max_explicit;
            let mut c = Connection::new(
                1,
                ConnKind::Explicit,
                master,
                DnId::g2(mac, group2::EXPLICIT_RESPONSE),
                DnId::g2(mac, group2::EXPLICIT_REQUEST),
                0x21,
                (max, max),
                self.config.explicit_epr_ms,
                now,
            );
            c.format = self.config.allocate_format;
            self.explicit = Some(c);
        }
        if a.choice & choice::POLLED != 0 {
            let (produced, consumed) = self.app.poll_sizes();
            self.poll = Some(Connection::new(
                2,
                ConnKind::Polled,
                master,
                DnId::Group1 {
                    msg: group1::POLL_RESPONSE,
                    mac,
                },
                DnId::g2(mac, group2::POLL_COMMAND),
                0x01,
                (produced, consumed),
                0,
                now,
            ));
        }
        self.dn.choice |= a.choice;
        self.dn.master = Some(master);
        self.app.event(
            SlaveEvent::Allocated {
                master,
                choice: self.dn.choice,
            },
            now,
        );
        Reply::Data(vec![self.config.allocate_format.code()])
    }

    /// Release_Master/Slave_Connection_Set. `via` as for [`Slave::allocate`]; on the
    /// unconnected port the requester is the header's MAC ID, checked by the caller.
    fn release(&mut self, req: &Request<'_>, via: Option<MacId>, now: Instant) -> Reply {
        let Some(&c) = req.data.first() else {
            return CipError::new(status::NOT_ENOUGH_DATA).into();
        };
        if req.data.len() > 1 {
            return CipError::new(status::TOO_MUCH_DATA).into();
        }
        if let (Some(owner), Some(v)) = (self.dn.master, via) {
            if owner != v {
                return CipError::with(
                    status::OBJECT_STATE_CONFLICT,
                    alloc_error::ALLOCATION_CONFLICT,
                )
                .into();
            }
        }
        let supported = choice::EXPLICIT | choice::POLLED;
        if c == 0 || c & !supported != 0 {
            return CipError::with(status::INVALID_PARAMETER, alloc_error::INVALID_CHOICE).into();
        }
        if c & !self.dn.choice != 0 {
            return CipError::with(status::ALREADY_IN_STATE, alloc_error::INVALID_CHOICE).into();
        }
        self.release_bits(c, now);
        Reply::Data(Vec::new())
    }

    fn release_bits(&mut self, c: u8, now: Instant) {
        if c & choice::EXPLICIT != 0 {
            self.explicit = None;
        }
        if c & choice::POLLED != 0 {
            self.poll = None;
        }
        self.dn.choice &= !c;
        if self.dn.choice == 0 {
            self.dn.master = None;
        }
        self.app.event(
            SlaveEvent::Released {
                choice: self.dn.choice,
            },
            now,
        );
    }

    /// The group 2 only unconnected port (group 2 message 6): Allocate and Release only,
    /// unfragmented, 8/8 body, answered on group 2 message 3.
    fn on_unconnected(&mut self, data: &[u8], now: Instant, out: &mut Outbox) {
        let Ok(ExplicitFrame::Whole { header, body }) = ExplicitFrame::decode(data) else {
            return;
        };
        let requester = header.mac;
        let reply = match Request::decode(body, BodyFormat::F8_8) {
            Ok(req) if req.class == dnobj::CLASS && req.instance == 1 => match req.service {
                service::ALLOCATE => {
                    match Allocate::decode(req.data) {
                        // The allocator's MAC ID must be the sender's.
                        Some(a) if a.allocator != requester => {
                            CipError::with(status::INVALID_PARAMETER, alloc_error::INVALID_CHOICE)
                                .into()
                        }
                        _ => self.allocate(&req, None, now),
                    }
                }
                service::RELEASE => match self.dn.master {
                    Some(owner) if owner != requester => CipError::with(
                        status::OBJECT_STATE_CONFLICT,
                        alloc_error::ALLOCATION_CONFLICT,
                    )
                    .into(),
                    _ => self.release(&req, None, now),
                },
                _ => CipError::with(
                    status::SERVICE_NOT_SUPPORTED,
                    alloc_error::GROUP2_ONLY_SERVICE,
                )
                .into(),
            },
            Ok(req) if req.service == service::ALLOCATE || req.service == service::RELEASE => {
                CipError::new(status::OBJECT_DOES_NOT_EXIST).into()
            }
            Ok(_) => CipError::with(
                status::SERVICE_NOT_SUPPORTED,
                alloc_error::GROUP2_ONLY_SERVICE,
            )
            .into(),
            Err(RequestError::NoPath(_)) => CipError::new(status::NOT_ENOUGH_DATA).into(),
            Err(_) => return,
        };
        let service = body.first().copied().unwrap_or(0);
        let id = self.response_id();
        // The response header carries the requester, whatever it was allocated to.
        self.reply(
            Channel::Predefined,
            id,
            Header::new(header.xid, requester),
            service,
            reply,
            now,
            out,
        );
    }

    // ----- polled I/O -----

    fn on_poll(&mut self, data: &[u8], now: Instant, out: &mut Outbox) {
        let Some(c) = self.poll.as_mut() else { return };
        if c.state != ConnState::Established {
            return;
        }
        c.kick(now);
        let command = if c.consumed_size > 8 && !data.is_empty() {
            match c.io_rx.on_frame(data) {
                Some(d) => d,
                None => return,
            }
        } else {
            data.to_vec()
        };
        if command.len() > usize::from(c.consumed_size) {
            return;
        }
        c.idle = command.is_empty();
        let (produced_size, id) = (usize::from(c.produced_size), c.produced_id);
        self.app.consume(&command, now);
        let mut input = self.app.produce(now);
        input.resize(produced_size, 0);
        if produced_size > 8 {
            for f in wire::io_fragments(&input) {
                out.push(id.frame(&f));
            }
        } else {
            out.push(id.frame(&input));
        }
    }

    // ----- watchdogs -----

    fn watchdogs(&mut self, now: Instant) {
        if self
            .explicit
            .as_ref()
            .and_then(Connection::watchdog_deadline)
            .is_some_and(|d| now >= d)
        {
            self.app
                .event(SlaveEvent::ExplicitTimedOut { instance: 1 }, now);
            self.release_bits(choice::EXPLICIT, now);
        }
        if let Some(c) = self.poll.as_mut() {
            if c.watchdog_deadline().is_some_and(|d| now >= d) {
                match c.watchdog_action {
                    WATCHDOG_AUTO_DELETE => {
                        self.app.event(SlaveEvent::IoTimedOut, now);
                        self.release_bits(choice::POLLED, now);
                    }
                    WATCHDOG_AUTO_RESET => c.kick(now),
                    _ => {
                        c.state = ConnState::TimedOut;
                        self.app.event(SlaveEvent::IoTimedOut, now);
                    }
                }
            }
        }
        let mut i = 0;
        while i < self.ucmm.len() {
            if self.ucmm[i].watchdog_deadline().is_some_and(|d| now >= d) {
                let instance = self.ucmm.remove(i).instance;
                self.app
                    .event(SlaveEvent::ExplicitTimedOut { instance }, now);
            } else {
                i += 1;
            }
        }
    }

    fn fragment_timers(&mut self, now: Instant, out: &mut Outbox) {
        let conns = self.explicit.iter_mut().chain(self.ucmm.iter_mut());
        for c in conns {
            if let Some(tx) = c.tx.as_mut() {
                match tx.on_tick(now) {
                    Some(TxProgress::Send(f)) => out.push(c.produced_id.frame(&f)),
                    Some(TxProgress::Aborted) => c.tx = None,
                    _ => {}
                }
            }
        }
    }

    fn frame_inner(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if !self.powered || frame.is_remote() || self.bus_off {
            return;
        }
        let Ok(dn) = DnId::decode(frame.id()) else {
            return;
        };
        let data = frame.data_bytes();
        let mac = self.config.mac;
        if dn == DnId::g2(mac, group2::DUP_MAC_CHECK) {
            if let Some(msg) = DupMac::decode(data) {
                let was_faulted = self.link.state() == LinkState::CommFaulted;
                if let Some(resp) = self.link.on_message(&msg) {
                    out.push(resp);
                } else if !was_faulted && self.link.state() == LinkState::CommFaulted {
                    self.drop_connections();
                    self.app.event(SlaveEvent::DuplicateMac, now);
                }
            }
            return;
        }
        if !self.link.is_online() {
            return;
        }
        match dn {
            DnId::Group2 { mac: m, msg } if m == mac => match msg {
                group2::UNCONNECTED_REQUEST => self.on_unconnected(data, now, out),
                group2::EXPLICIT_REQUEST => self.on_explicit(Channel::Predefined, data, now, out),
                group2::POLL_COMMAND => self.on_poll(data, now, out),
                _ => {}
            },
            DnId::Group3 {
                msg: group3::UNCONNECTED_REQUEST,
                mac: client,
            } => {
                let r = ucmm::on_request(self, client, data, now);
                if let Some(f) = r {
                    out.push(f);
                }
            }
            DnId::Group3 { msg, mac: client } => {
                if let Some(i) = self
                    .ucmm
                    .iter()
                    .position(|c| c.consumed_id == DnId::Group3 { msg, mac: client })
                {
                    self.on_explicit(Channel::Ucmm(i), data, now, out);
                }
            }
            _ => {}
        }
    }
}

impl<A> Slave<A> {
    pub(crate) fn ucmm_parts(&mut self) -> ucmm::Parts<'_> {
        ucmm::Parts {
            config: &self.config,
            conns: &mut self.ucmm,
        }
    }
}

impl<A: Application> Node for Slave<A> {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.powered = true;
        self.dn.bus_off_count = 0;
        self.restart(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.frame_inner(frame, now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if !self.powered {
            return;
        }
        let was_online = self.link.is_online();
        if let Some(f) = self.link.on_tick(now) {
            out.push(f);
        }
        if !was_online && self.link.is_online() {
            self.app.event(SlaveEvent::Online, now);
        }
        self.watchdogs(now);
        self.fragment_timers(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        if !self.powered {
            return None;
        }
        let conns = self.explicit.iter().chain(&self.poll).chain(&self.ucmm);
        let mut d = self.link.deadline();
        for c in conns {
            for t in [c.watchdog_deadline(), c.tx.as_ref().map(|t| t.deadline())]
                .into_iter()
                .flatten()
            {
                d = Some(d.map_or(t, |x| x.min(t)));
            }
        }
        d
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        match event {
            ControllerEvent::BusOff => {
                self.dn.bus_off_count = self.dn.bus_off_count.saturating_add(1);
                self.bus_off = true;
                self.drop_connections();
                self.link.fault();
                self.app.event(SlaveEvent::BusOff, now);
            }
            // BOI = 1: reset the controller and come back, re-checking the MAC ID. BOI = 0:
            // hold, until a reset or power cycle.
            ControllerEvent::BusOffRecovered if self.bus_off && self.dn.boi => {
                self.restart(now, out);
            }
            _ => {}
        }
    }

    fn accepts(&self, id: Id) -> bool {
        match DnId::decode(id) {
            Ok(DnId::Group2 { mac, .. }) => mac == self.config.mac,
            Ok(DnId::Group3 { .. }) => true,
            _ => false,
        }
    }
}
