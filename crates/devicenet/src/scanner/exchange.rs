//! The scanner's explicit message exchange: starting queued operations one per slave,
//! matching responses (whole or fragmented, with acknowledges) to the request in flight,
//! timeouts, and poll responses.

use super::{InFlight, Op, Peer, Route, Scanner, ScannerEvent, UcmmLink, parse_identity};
use crate::fragment::{ExplicitSender, RxOutcome, TxProgress};
use crate::wire::{
    self, Allocate, BodyFormat, DnId, ExplicitFrame, Header, MacId, Request, Response, UcmmOpen,
    UcmmOpenReply, choice, group2, group3, service,
};
use cantwin_can::{Instant, Outbox};

impl Scanner {
    /// Start queued operations where nothing is in flight.
    pub(super) fn pump(&mut self, now: Instant, out: &mut Outbox) {
        if !self.link.is_online() {
            return;
        }
        let own = self.config.mac;
        let timeout = self.config.response_timeout;
        let slaves: Vec<MacId> = self.peers.keys().copied().collect();
        for slave in slaves {
            while let Some(p) = self.peers.get_mut(&slave) {
                if p.in_flight.is_some() {
                    break;
                }
                let Some((op, browse)) = p.queue.pop_front() else {
                    break;
                };
                let (route, svc, body) = match &op {
                    Op::Allocate(c) => (
                        Route::Unconnected,
                        service::ALLOCATE,
                        Request {
                            service: service::ALLOCATE,
                            class: 3,
                            instance: 1,
                            data: &Allocate {
                                choice: *c,
                                allocator: own,
                            }
                            .encode(),
                        }
                        .encode(BodyFormat::F8_8),
                    ),
                    Op::Release(c) => (
                        Route::Unconnected,
                        service::RELEASE,
                        Request {
                            service: service::RELEASE,
                            class: 3,
                            instance: 1,
                            data: &[*c],
                        }
                        .encode(BodyFormat::F8_8),
                    ),
                    Op::UcmmOpen(f) => {
                        let o = UcmmOpen {
                            format: *f,
                            group: UcmmOpen::GROUP3,
                            source_msg: 0,
                        };
                        let mut b = vec![service::ALLOCATE];
                        b.extend_from_slice(&o.encode());
                        (Route::Ucmm, service::ALLOCATE, b)
                    }
                    Op::UcmmClose => {
                        let Some(u) = p.ucmm else {
                            self.events.push_back(ScannerEvent::NotConnected {
                                slave,
                                service: service::RELEASE,
                            });
                            continue;
                        };
                        let mut b = vec![service::RELEASE];
                        b.extend_from_slice(&u.instance.to_le_bytes());
                        (Route::Ucmm, service::RELEASE, b)
                    }
                    Op::Request {
                        service,
                        class,
                        instance,
                        data,
                    } => {
                        let (route, format) = match (p.explicit, p.ucmm) {
                            (Some(f), _) => (Route::Predefined, f),
                            (None, Some(u)) => (Route::UcmmConnection, u.format),
                            (None, None) => {
                                self.events.push_back(ScannerEvent::NotConnected {
                                    slave,
                                    service: *service,
                                });
                                if browse {
                                    self.drop_browse_ops(slave);
                                }
                                continue;
                            }
                        };
                        let req = Request {
                            service: *service,
                            class: *class,
                            instance: *instance,
                            data,
                        };
                        (route, *service, req.encode(format))
                    }
                };
                p.xid = !p.xid;
                let (header_mac, id) = match route {
                    Route::Unconnected => (own, DnId::g2(slave, group2::UNCONNECTED_REQUEST)),
                    Route::Predefined => (own, DnId::g2(slave, group2::EXPLICIT_REQUEST)),
                    Route::Ucmm => (
                        slave,
                        DnId::Group3 {
                            msg: group3::UNCONNECTED_REQUEST,
                            mac: own,
                        },
                    ),
                    Route::UcmmConnection => (
                        slave,
                        DnId::Group3 {
                            msg: p.ucmm.map_or(0, |u| u.client_msg),
                            mac: own,
                        },
                    ),
                };
                let frames = wire::explicit_frames(Header::new(p.xid, header_mac), &body);
                p.rx.reset();
                if frames.len() > 1 {
                    let (s, first) = ExplicitSender::start(frames, now);
                    out.push(id.frame(&first));
                    p.tx = Some(s);
                } else if let Some(f) = frames.first() {
                    out.push(id.frame(f));
                    p.tx = None;
                }
                p.in_flight = Some(InFlight {
                    op,
                    service: svc,
                    xid: p.xid,
                    route,
                    deadline: now + timeout,
                    browse,
                });
            }
        }
    }

    pub(super) fn request_id(&self, slave: MacId, route: Route, p: &Peer) -> DnId {
        match route {
            Route::Predefined | Route::Unconnected => DnId::g2(slave, group2::EXPLICIT_REQUEST),
            _ => DnId::Group3 {
                msg: p.ucmm.map_or(0, |u| u.client_msg),
                mac: self.config.mac,
            },
        }
    }

    /// An explicit frame from `slave` on a response identifier of `route`.
    pub(super) fn on_response_frame(
        &mut self,
        slave: MacId,
        routes: &[Route],
        data: &[u8],
        now: Instant,
        out: &mut Outbox,
    ) {
        let own = self.config.mac;
        let Ok(frame) = ExplicitFrame::decode(data) else {
            return;
        };
        if frame.header().mac != own {
            return;
        }
        let Some(p) = self.peers.get(&slave) else {
            return;
        };
        let Some(f) = p.in_flight.as_ref() else {
            return;
        };
        if !routes.contains(&f.route) || frame.header().xid != f.xid {
            return;
        }
        let route = f.route;
        let ack_id = self.request_id(slave, route, p);
        let Some(p) = self.peers.get_mut(&slave) else {
            return;
        };
        let body = match frame {
            ExplicitFrame::Whole { body, .. } => body.to_vec(),
            ExplicitFrame::Ack { count, status, .. } => {
                if let Some(tx) = p.tx.as_mut() {
                    match tx.on_ack(count, status, now) {
                        TxProgress::Send(f) => out.push(ack_id.frame(&f)),
                        TxProgress::Done => {
                            // The response timeout runs from the last fragment on.
                            p.tx = None;
                            if let Some(f) = p.in_flight.as_mut() {
                                f.deadline = now + self.config.response_timeout;
                            }
                        }
                        TxProgress::Aborted => {
                            p.tx = None;
                            self.finish_timeout(slave, now);
                        }
                        TxProgress::Ignored => {}
                    }
                }
                return;
            }
            ExplicitFrame::Fragment { header, frag, data } => {
                // The acknowledge travels like a request: on group 2 the header carries the
                // source (us), on group 3 the destination (the slave).
                let hdr_mac = match route {
                    Route::Unconnected | Route::Predefined => own,
                    Route::Ucmm | Route::UcmmConnection => slave,
                };
                let ack =
                    |count, st| ack_id.frame(&wire::encode_ack(header.xid, hdr_mac, count, st));
                match p.rx.on_fragment(frag, data) {
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
        let Some(resp) = Response::decode(&body) else {
            return;
        };
        let Some(f) = p.in_flight.take() else { return };
        p.tx = None;
        self.complete(slave, f, resp, now);
    }

    pub(super) fn complete(&mut self, slave: MacId, f: InFlight, resp: Response<'_>, now: Instant) {
        let _ = now;
        let svc = f.service;
        let data = match resp {
            Response::Error {
                general,
                additional,
            } => {
                if f.browse {
                    match f.op {
                        Op::Allocate(_) => {
                            // Someone answered: a device is there, owned by another master.
                            self.browse_found.push(slave);
                            self.events.push_back(ScannerEvent::DeviceFound {
                                slave,
                                identity: None,
                            });
                            self.drop_browse_ops(slave);
                        }
                        // The device is allocated but refused the Identity read (e.g. a
                        // reply over its explicit size limit, status 0x11): its identity
                        // stays unknown, and the queued Release still frees the connection.
                        Op::Request { .. } => {}
                        _ => self.browse_device_done(slave),
                    }
                    return;
                }
                self.events.push_back(ScannerEvent::Error {
                    slave,
                    service: svc,
                    general,
                    additional,
                });
                return;
            }
            Response::Success { service, data } if service == svc => data.to_vec(),
            Response::Success { .. } => return,
        };
        let Some(p) = self.peers.get_mut(&slave) else {
            return;
        };
        let ev = match f.op {
            Op::Allocate(c) => {
                let format = data
                    .first()
                    .and_then(|b| BodyFormat::from_code(b & 0x0F))
                    .unwrap_or_default();
                if c & choice::EXPLICIT != 0 {
                    p.explicit = Some(format);
                }
                ScannerEvent::Allocated {
                    slave,
                    choice: c,
                    format,
                }
            }
            Op::Release(c) => {
                if c & choice::EXPLICIT != 0 {
                    p.explicit = None;
                }
                ScannerEvent::Released { slave, choice: c }
            }
            Op::UcmmOpen(_) => match UcmmOpenReply::decode(&data) {
                Some(reply) => {
                    p.ucmm = Some(UcmmLink {
                        client_msg: 0,
                        server_msg: reply.source_msg,
                        instance: reply.instance,
                        format: reply.format,
                    });
                    ScannerEvent::Opened { slave, reply }
                }
                None => return,
            },
            Op::UcmmClose => {
                p.ucmm = None;
                ScannerEvent::Closed { slave }
            }
            Op::Request { .. } if f.browse => {
                p.browse_identity = parse_identity(&data);
                return;
            }
            Op::Request { .. } => ScannerEvent::Response {
                slave,
                service: svc,
                data,
            },
        };
        if f.browse {
            if let Op::Release(_) = f.op {
                self.browse_device_done(slave);
            }
            return;
        }
        self.events.push_back(ev);
    }

    pub(super) fn finish_timeout(&mut self, slave: MacId, _now: Instant) {
        let Some(p) = self.peers.get_mut(&slave) else {
            return;
        };
        let Some(f) = p.in_flight.take() else { return };
        p.tx = None;
        p.rx.reset();
        if f.browse {
            match f.op {
                // Allocated, but no Identity answer: release all the same.
                Op::Request { .. } => {}
                // Allocated and read; the device is there even if the Release got lost.
                Op::Release(_) => self.browse_device_done(slave),
                _ => self.drop_browse_ops(slave),
            }
        } else {
            self.events.push_back(ScannerEvent::Timeout {
                slave,
                service: f.service,
            });
        }
    }

    pub(super) fn on_poll_response(&mut self, slave: MacId, data: &[u8]) {
        let Some(p) = self.peers.get_mut(&slave) else {
            return;
        };
        let data = if p.input_size > 8 {
            match p.io_rx.on_frame(data) {
                Some(d) => d,
                None => return,
            }
        } else {
            data.to_vec()
        };
        self.events
            .push_back(ScannerEvent::PollResponse { slave, data });
    }
}
