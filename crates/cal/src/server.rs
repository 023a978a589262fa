//! The server role of CMS objects (DS 202-1 "server", the device side).
//!
//! A [`CmsServer`] owns the COB-ID table of its objects and the state of its controlled
//! events; the values behind the objects belong to the application, which the server calls
//! through [`Application`] for every indication and which answers with the response data.
//! The server holds no reference to the application, so a device can keep both side by side
//! and borrow them independently.

use cantwin_can::{Frame, Id, Instant, Outbox};

use crate::wire::{
    BasicRequest, BasicResponse, EventControl, EventMessage, Mux, MuxRequest, MuxResponse, Payload,
    is_remote_read,
};
use crate::{CobPair, ObjectKind};

/// The index of an object in a server's or client's table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ObjectIndex(pub usize);

/// One CMS object a server serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServerObject {
    /// What it is.
    pub kind: ObjectKind,
    /// Its COBs.
    pub cobs: CobPair,
}

/// The data behind a server's objects. Each method answers `Ok(response data)` or
/// `Err(error data)`; the server puts them into the response with `r` = 0 or 1.
pub trait Application {
    /// Read indication on a basic variable.
    fn read_basic(&mut self, object: ObjectIndex, now: Instant) -> Result<Payload, Payload>;
    /// Write indication on a basic variable; the answer is the confirmation's data.
    fn write_basic(
        &mut self,
        object: ObjectIndex,
        data: &[u8],
        now: Instant,
    ) -> Result<Payload, Payload>;
    /// Read indication on a multiplexed variable.
    fn read_mux(&mut self, object: ObjectIndex, mux: Mux, now: Instant)
    -> Result<Payload, Payload>;
    /// Write indication on a multiplexed variable.
    fn write_mux(
        &mut self,
        object: ObjectIndex,
        mux: Mux,
        data: &[u8],
        now: Instant,
    ) -> Result<Payload, Payload>;
    /// A client asks to enable or disable a controlled event. `Ok(())` accepts; `Err` refuses
    /// with error data and leaves the state as it was. The default accepts.
    fn control_event(
        &mut self,
        object: ObjectIndex,
        enable: bool,
        now: Instant,
    ) -> Result<(), Payload> {
        let _ = (object, enable, now);
        Ok(())
    }
    /// The error data for a request that does not decode (wrong control byte or length).
    /// The default is empty.
    fn malformed(&mut self, object: ObjectIndex) -> Payload {
        let _ = object;
        Payload::EMPTY
    }
}

/// Two objects listen on the same request COB, or a COB-ID is used twice as a response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("COB-ID {0:#X} is used by two objects of the server")]
pub struct DuplicateCob(pub u32);

/// The server side of a set of CMS objects.
#[derive(Debug, Clone)]
pub struct CmsServer {
    objects: Vec<ServerObject>,
    enabled: Vec<bool>,
    answer_remote_reads: bool,
}

impl CmsServer {
    /// A server for `objects`; request COBs must be distinct. Controlled events start
    /// disabled (DS 202-2: notification only after a client enabled it).
    pub fn new(objects: Vec<ServerObject>) -> Result<CmsServer, DuplicateCob> {
        for (i, a) in objects.iter().enumerate() {
            for b in &objects[i + 1..] {
                if a.cobs.request == b.cobs.request {
                    return Err(DuplicateCob(a.cobs.request.as_raw()));
                }
                if a.cobs.response == b.cobs.response {
                    return Err(DuplicateCob(a.cobs.response.as_raw()));
                }
            }
        }
        let enabled = vec![false; objects.len()];
        Ok(CmsServer {
            objects,
            enabled,
            answer_remote_reads: true,
        })
    }

    /// Whether a remote frame on a basic variable's response COB is answered as a read
    /// (the DS 202-2 "one remote COB" read). On by default.
    pub fn with_remote_reads(mut self, on: bool) -> Self {
        self.answer_remote_reads = on;
        self
    }

    /// The objects.
    pub fn objects(&self) -> &[ServerObject] {
        &self.objects
    }

    /// Whether the controlled event `object` is enabled.
    pub fn event_enabled(&self, object: ObjectIndex) -> bool {
        self.enabled.get(object.0).copied().unwrap_or(false)
    }

    /// Disable every event (power-up, reset).
    pub fn reset(&mut self) {
        self.enabled.iter_mut().for_each(|e| *e = false);
    }

    /// Whether a frame with this identifier concerns the server.
    pub fn accepts(&self, id: Id) -> bool {
        self.objects.iter().any(|o| {
            o.cobs.request == id
                || (self.answer_remote_reads
                    && o.kind == ObjectKind::BasicVariable
                    && o.cobs.response == id)
        })
    }

    /// Serve a frame: the response, if any, goes into `out`. Returns whether the frame was
    /// for one of the server's objects.
    pub fn handle<A: Application + ?Sized>(
        &mut self,
        frame: &Frame,
        app: &mut A,
        now: Instant,
        out: &mut Outbox,
    ) -> bool {
        let Some((i, obj)) = self.find(frame) else {
            return false;
        };
        let index = ObjectIndex(i);
        let tx = obj.cobs.response;
        match obj.kind {
            ObjectKind::BasicVariable => {
                if is_remote_read(frame, tx) {
                    if self.answer_remote_reads {
                        out.push(basic(app.read_basic(index, now)).encode(tx));
                    }
                    return self.answer_remote_reads;
                }
                let resp = match BasicRequest::decode(frame) {
                    Ok(BasicRequest::Read) => app.read_basic(index, now),
                    Ok(BasicRequest::Write(d)) => app.write_basic(index, d.as_slice(), now),
                    Err(_) => Err(app.malformed(index)),
                };
                out.push(basic(resp).encode(tx));
            }
            ObjectKind::MultiplexedVariable => {
                let (mux, result) = match MuxRequest::decode(frame) {
                    Ok(MuxRequest { mux, write: None }) => (mux, app.read_mux(index, mux, now)),
                    Ok(MuxRequest {
                        mux,
                        write: Some(d),
                    }) => (mux, app.write_mux(index, mux, d.as_slice(), now)),
                    Err(_) => {
                        // A read with data, or a frame without a control byte (answered
                        // for multiplexor 0).
                        let mux =
                            Mux::from_control(frame.data_bytes().first().copied().unwrap_or(0));
                        (mux, Err(app.malformed(index)))
                    }
                };
                out.push(MuxResponse { mux, result }.encode(tx));
            }
            ObjectKind::ControlledEvent => {
                let before = self.enabled[i];
                let msg = match EventControl::decode(frame) {
                    Ok(EventControl { enable }) => match app.control_event(index, enable, now) {
                        Ok(()) => {
                            self.enabled[i] = enable;
                            EventMessage::Control {
                                enabled: enable,
                                result: Ok(()),
                            }
                        }
                        Err(e) => EventMessage::Control {
                            enabled: before,
                            result: Err(e),
                        },
                    },
                    Err(_) => EventMessage::Control {
                        enabled: before,
                        result: Err(app.malformed(index)),
                    },
                };
                out.push(msg.encode(tx));
            }
        }
        true
    }

    /// Notify the controlled event `object` with `data`, if a client enabled it. Returns
    /// whether a notification was queued.
    pub fn notify(&self, object: ObjectIndex, data: &[u8], out: &mut Outbox) -> bool {
        let Some(obj) = self.objects.get(object.0) else {
            return false;
        };
        if obj.kind != ObjectKind::ControlledEvent || !self.event_enabled(object) {
            return false;
        }
        let Some(p) = Payload::new(data) else {
            return false;
        };
        out.push(EventMessage::Notify(p).encode(obj.cobs.response));
        true
    }

    fn find(&self, frame: &Frame) -> Option<(usize, ServerObject)> {
        let id = frame.id();
        self.objects.iter().copied().enumerate().find(|(_, o)| {
            if frame.is_remote() {
                o.kind == ObjectKind::BasicVariable && o.cobs.response == id
            } else {
                o.cobs.request == id
            }
        })
    }
}

fn basic(r: Result<Payload, Payload>) -> BasicResponse {
    match r {
        Ok(d) => BasicResponse::Success(d),
        Err(e) => BasicResponse::Failure(e),
    }
}
