//! The DeviceNet slave (server): a UCMM-capable device of the Predefined Master/Slave
//! Connection Set, driven through [`cantwin_can::Node`].
//!
//! Frames are routed by identifier: the duplicate MAC ID check (group 2 message 7), the
//! group 2 only unconnected port (message 6: Allocate/Release), the predefined explicit
//! connection (message 4), the poll command (message 5), the UCMM (group 3 message 6) and
//! the explicit connections the UCMM opened (group 3, the client's message ID). Nothing
//! but the duplicate MAC ID check is answered before the node is on-line.

mod config;
mod io;
mod predefined;

pub use config::{ConfigError, Led, NetworkStatus, SlaveConfig, baud_code};

use crate::fragment::{RxOutcome, TxProgress};
use crate::link::{DupMacCheck, LinkState};
use crate::objects::connection::{self as conn, ConnKind, ConnState, Connection};
use crate::objects::devicenet::{self as dnobj, DeviceNetObject};
use crate::objects::identity::{self, IdentityAction};
use crate::objects::parameter::{self, ParameterObject};
use crate::objects::{Application, CipError, Reply, SlaveEvent, message_router};
use crate::ucmm;
use crate::wire::{
    self, DnId, DupMac, ExplicitFrame, Header, Request, RequestError, group2, group3, service,
    status,
};
use cantwin_can::{ControllerEvent, Frame, Id, Instant, Node, Outbox};

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
                let r = ucmm::on_request(self.ucmm_parts(), client, data, now);
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
            config: ucmm::Limits {
                mac: self.config.mac,
                connections: self.config.ucmm_connections,
                first_instance: self.config.ucmm_first_instance,
                max_explicit: self.config.max_explicit,
                explicit_epr_ms: self.config.explicit_epr_ms,
            },
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
