//! The Predefined Master/Slave Connection Set (DeviceNet Vol. 1, "Predefined Master/Slave
//! Connection Set"): Allocate and Release, on the group 2 only unconnected port or on the
//! explicit connection, with their error responses.

use super::{Channel, Slave};
use crate::objects::connection::{ConnKind, Connection};
use crate::objects::devicenet as dnobj;
use crate::objects::{Application, CipError, Reply, SlaveEvent};
use crate::wire::{
    Allocate, BodyFormat, DnId, ExplicitFrame, Header, MacId, Request, RequestError, alloc_error,
    choice, group1, group2, service, status,
};
use cantwin_can::{Instant, Outbox};

impl<A: Application> Slave<A> {
    // ----- Predefined Master/Slave Connection Set -----

    /// Allocate_Master/Slave_Connection_Set. `via` is the master of the explicit
    /// connection the request came on (`None` on the unconnected port).
    pub(super) fn allocate(
        &mut self,
        req: &Request<'_>,
        via: Option<MacId>,
        now: Instant,
    ) -> Reply {
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
    pub(super) fn release(&mut self, req: &Request<'_>, via: Option<MacId>, now: Instant) -> Reply {
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

    pub(super) fn release_bits(&mut self, c: u8, now: Instant) {
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
    pub(super) fn on_unconnected(&mut self, data: &[u8], now: Instant, out: &mut Outbox) {
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
}
