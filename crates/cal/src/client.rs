//! The client role (the CAL master): requests, confirmations, timeouts and event
//! notifications, sans-IO.
//!
//! Each object has at most one confirmed request outstanding, as a CMS client waits for the
//! confirmation of a confirmed service before it requests again (DS 202-1). A request is
//! encoded into the caller's [`Outbox`]; what comes back is read with
//! [`CmsClient::poll_event`]. The client is a [`Node`], so it can sit on the virtual bus as
//! it is, or be driven by a CLI over a gateway with the wall clock.

use std::collections::VecDeque;

use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};

use crate::server::ObjectIndex;
use crate::wire::{
    BasicRequest, BasicResponse, EventControl, EventMessage, Mux, MuxRequest, MuxResponse, Payload,
};
use crate::{CobPair, ObjectKind};

/// How long the client waits for a confirmation by default.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);

/// One CMS object the client talks to: the server's object, seen from the other side
/// (`cobs.request` is what the client sends on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientObject {
    /// What it is.
    pub kind: ObjectKind,
    /// Its COBs.
    pub cobs: CobPair,
    /// The DLC of a remote read ([`Request::ReadBasicRemote`]): the length of the
    /// variable's response frame.
    pub remote_dlc: u8,
}

impl ClientObject {
    /// An object of `kind` on `cobs`, with a remote read DLC of 8.
    pub const fn new(kind: ObjectKind, cobs: CobPair) -> Self {
        ClientObject {
            kind,
            cobs,
            remote_dlc: 8,
        }
    }
}

/// A confirmed request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Read a basic variable with a data frame (`c` = 1) on the request COB.
    ReadBasic,
    /// Read a basic variable with a remote frame on the response COB.
    ReadBasicRemote,
    /// Write a basic variable.
    WriteBasic(Payload),
    /// Read a multiplexed variable.
    ReadMux(Mux),
    /// Write a multiplexed variable.
    WriteMux(Mux, Payload),
    /// Enable (`true`) or disable a controlled event.
    ControlEvent(bool),
}

/// What the client reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClientEvent {
    /// A request was confirmed with `r` = 0; `data` is what the server answered (the value
    /// read, or written; empty for an event control).
    Confirmed {
        /// The object.
        object: ObjectIndex,
        /// The request.
        request: Request,
        /// The response data.
        data: Payload,
        /// When the confirmation arrived.
        at: Instant,
    },
    /// A request was answered with `r` = 1.
    Failed {
        /// The object.
        object: ObjectIndex,
        /// The request.
        request: Request,
        /// The error data.
        error: Payload,
        /// When the error response arrived.
        at: Instant,
    },
    /// An event's control confirmation: the server's actual state (`as`).
    EventState {
        /// The object.
        object: ObjectIndex,
        /// Whether the event is now enabled.
        enabled: bool,
        /// When.
        at: Instant,
    },
    /// A notification of a controlled event.
    Notified {
        /// The object.
        object: ObjectIndex,
        /// The event data.
        data: Payload,
        /// When it arrived.
        at: Instant,
    },
    /// No confirmation within the timeout.
    TimedOut {
        /// The object.
        object: ObjectIndex,
        /// The request that got no answer.
        request: Request,
        /// When the client gave up.
        at: Instant,
    },
}

/// Why a request cannot be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ClientError {
    /// No object with that index.
    #[error("no CMS object {0}")]
    NoSuchObject(usize),
    /// The request does not apply to that kind of object.
    #[error("{request:?} does not apply to a {kind:?}")]
    WrongKind {
        /// The request.
        request: Request,
        /// The object's kind.
        kind: ObjectKind,
    },
    /// A request on the object is still waiting for its confirmation.
    #[error("object {0} still waits for a confirmation")]
    Busy(usize),
    /// More data than fits in one frame.
    #[error("{0} bytes do not fit into one CMS frame (at most 7)")]
    TooLong(usize),
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    request: Request,
    deadline: Instant,
}

/// A CAL master for a set of CMS objects.
#[derive(Debug, Clone)]
pub struct CmsClient {
    objects: Vec<ClientObject>,
    pending: Vec<Option<Pending>>,
    events: VecDeque<ClientEvent>,
    timeout: Duration,
}

impl CmsClient {
    /// A client for `objects`, with [`DEFAULT_TIMEOUT`].
    pub fn new(objects: Vec<ClientObject>) -> CmsClient {
        let pending = vec![None; objects.len()];
        CmsClient {
            objects,
            pending,
            events: VecDeque::new(),
            timeout: DEFAULT_TIMEOUT,
        }
    }

    /// With another confirmation timeout.
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// The objects.
    pub fn objects(&self) -> &[ClientObject] {
        &self.objects
    }

    /// Whether `object` waits for a confirmation.
    pub fn is_pending(&self, object: ObjectIndex) -> bool {
        self.pending.get(object.0).is_some_and(Option::is_some)
    }

    /// The next report, oldest first.
    pub fn poll_event(&mut self) -> Option<ClientEvent> {
        self.events.pop_front()
    }

    /// Send a confirmed request.
    pub fn request(
        &mut self,
        object: ObjectIndex,
        request: Request,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        let obj = *self
            .objects
            .get(object.0)
            .ok_or(ClientError::NoSuchObject(object.0))?;
        let kind_ok = match request {
            Request::ReadBasic | Request::ReadBasicRemote | Request::WriteBasic(_) => {
                obj.kind == ObjectKind::BasicVariable
            }
            Request::ReadMux(_) | Request::WriteMux(..) => {
                obj.kind == ObjectKind::MultiplexedVariable
            }
            Request::ControlEvent(_) => obj.kind == ObjectKind::ControlledEvent,
        };
        if !kind_ok {
            return Err(ClientError::WrongKind {
                request,
                kind: obj.kind,
            });
        }
        if self.is_pending(object) {
            return Err(ClientError::Busy(object.0));
        }
        let tx = obj.cobs.request;
        let frame = match request {
            Request::ReadBasic => BasicRequest::Read.encode(tx),
            // The remote frame asks for as many bytes as a response of the variable carries;
            // the manual's message 0 response is 4 bytes long.
            Request::ReadBasicRemote => Frame::remote(obj.cobs.response, obj.remote_dlc)
                .map_err(|_| ClientError::TooLong(usize::from(obj.remote_dlc)))?,
            Request::WriteBasic(d) => BasicRequest::Write(d).encode(tx),
            Request::ReadMux(mux) => MuxRequest { mux, write: None }.encode(tx),
            Request::WriteMux(mux, d) => MuxRequest {
                mux,
                write: Some(d),
            }
            .encode(tx),
            Request::ControlEvent(enable) => EventControl { enable }.encode(tx),
        };
        out.push(frame);
        self.pending[object.0] = Some(Pending {
            request,
            deadline: now + self.timeout,
        });
        Ok(())
    }

    /// Read a basic variable (data-frame request, `c` = 1).
    pub fn read_basic(
        &mut self,
        object: ObjectIndex,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        self.request(object, Request::ReadBasic, now, out)
    }

    /// Write a basic variable.
    pub fn write_basic(
        &mut self,
        object: ObjectIndex,
        data: &[u8],
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        let p = Payload::new(data).ok_or(ClientError::TooLong(data.len()))?;
        self.request(object, Request::WriteBasic(p), now, out)
    }

    /// Read a multiplexed variable.
    pub fn read_mux(
        &mut self,
        object: ObjectIndex,
        mux: Mux,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        self.request(object, Request::ReadMux(mux), now, out)
    }

    /// Write a multiplexed variable.
    pub fn write_mux(
        &mut self,
        object: ObjectIndex,
        mux: Mux,
        data: &[u8],
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        let p = Payload::new(data).ok_or(ClientError::TooLong(data.len()))?;
        self.request(object, Request::WriteMux(mux, p), now, out)
    }

    /// Enable or disable a controlled event.
    pub fn control_event(
        &mut self,
        object: ObjectIndex,
        enable: bool,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        self.request(object, Request::ControlEvent(enable), now, out)
    }

    /// Take a received frame. Returns whether it belonged to one of the client's objects.
    pub fn handle(&mut self, frame: &Frame, now: Instant) -> bool {
        if frame.is_remote() {
            return false;
        }
        let Some(i) = self
            .objects
            .iter()
            .position(|o| o.cobs.response == frame.id())
        else {
            return false;
        };
        let object = ObjectIndex(i);
        let pending = self.pending[i];
        match self.objects[i].kind {
            ObjectKind::BasicVariable => {
                let Some(p) = pending else { return true };
                match BasicResponse::decode(frame) {
                    Ok(BasicResponse::Success(data)) => self.confirm(i, p, Ok(data), now),
                    Ok(BasicResponse::Failure(e)) => self.confirm(i, p, Err(e), now),
                    Err(_) => {}
                }
            }
            ObjectKind::MultiplexedVariable => {
                let Some(p) = pending else { return true };
                let want = match p.request {
                    Request::ReadMux(m) | Request::WriteMux(m, _) => m,
                    _ => return true,
                };
                // A response for another multiplexor answers someone else's request.
                if let Ok(MuxResponse { mux, result }) = MuxResponse::decode(frame)
                    && mux == want
                {
                    self.confirm(i, p, result, now);
                }
            }
            ObjectKind::ControlledEvent => match EventMessage::decode(frame) {
                Ok(EventMessage::Notify(data)) => self.events.push_back(ClientEvent::Notified {
                    object,
                    data,
                    at: now,
                }),
                Ok(EventMessage::Control { enabled, result }) => {
                    if let Some(p) = pending {
                        self.events.push_back(ClientEvent::EventState {
                            object,
                            enabled,
                            at: now,
                        });
                        self.confirm(i, p, result.map(|()| Payload::EMPTY), now);
                    }
                }
                Err(_) => {}
            },
        }
        true
    }

    fn confirm(&mut self, i: usize, p: Pending, result: Result<Payload, Payload>, at: Instant) {
        self.pending[i] = None;
        let object = ObjectIndex(i);
        self.events.push_back(match result {
            Ok(data) => ClientEvent::Confirmed {
                object,
                request: p.request,
                data,
                at,
            },
            Err(error) => ClientEvent::Failed {
                object,
                request: p.request,
                error,
                at,
            },
        });
    }

    /// Expire requests whose timeout has passed.
    pub fn poll_timeouts(&mut self, now: Instant) {
        for (i, slot) in self.pending.iter_mut().enumerate() {
            if let Some(p) = slot.filter(|p| p.deadline <= now) {
                *slot = None;
                self.events.push_back(ClientEvent::TimedOut {
                    object: ObjectIndex(i),
                    request: p.request,
                    at: now,
                });
            }
        }
    }

    /// The earliest confirmation deadline.
    pub fn deadline(&self) -> Option<Instant> {
        self.pending.iter().flatten().map(|p| p.deadline).min()
    }
}

impl Node for CmsClient {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.handle(frame, now);
    }

    fn on_tick(&mut self, now: Instant, _out: &mut Outbox) {
        self.poll_timeouts(now);
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.deadline()
    }

    fn accepts(&self, id: Id) -> bool {
        self.objects.iter().any(|o| o.cobs.response == id)
    }
}
