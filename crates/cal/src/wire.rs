//! Stateless encoding and decoding of CMS frames (DS 202-2 protocol, DS 202-3 encoding).
//!
//! Every CMS frame of this stack starts with one control byte followed by application data,
//! multi-byte values little-endian (DS 202-3 encodes integers least significant octet
//! first; the OPEN DRIVE manual writes the 50.00 Hz reference `0x1388` as `88 H 13 H`).
//!
//! | object | direction | byte 0 | bytes 1… |
//! |---|---|---|---|
//! | basic variable | request | bit 7 `c` (0 write, 1 read), bits 6–0 zero | write: data |
//! | basic variable | response | bit 7 `r` (0 success, 1 failure), bits 6–0 zero | data, or error data |
//! | multiplexed variable | request | bit 7 `c`, bits 6–0 multiplexor | write: data |
//! | multiplexed variable | response | bit 7 `r`, bits 6–0 multiplexor | data, or error data |
//! | controlled event | control request | bits 7–5 `c` = 1, bit 4 `s` (requested state), bits 3–0 zero | — |
//! | controlled event | control response | bits 7–5 `c` = 1, bit 4 `as` (actual state), bit 3 `r`, bits 2–0 zero | error data if `r` = 1 |
//! | controlled event | notify | bits 7–5 `c` = 0, bit 4 `as` = 1, bits 3–0 zero | event data |
//!
//! A read of a basic variable can also be the DS 202-2 "one remote COB" form: a remote
//! frame on the variable's response COB, answered by a data frame on the same COB
//! ([`is_remote_read`]).

use cantwin_can::Frame;
use core::fmt;

/// Up to 7 bytes of application data: what fits after the control byte of a CAN frame.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Payload {
    len: u8,
    buf: [u8; 7],
}

impl Payload {
    /// The most bytes a payload holds.
    pub const MAX: usize = 7;
    /// No data.
    pub const EMPTY: Payload = Payload {
        len: 0,
        buf: [0; 7],
    };

    /// A payload of `data`, or `None` when it is longer than 7 bytes.
    pub fn new(data: &[u8]) -> Option<Payload> {
        if data.len() > Self::MAX {
            return None;
        }
        let mut buf = [0; 7];
        buf[..data.len()].copy_from_slice(data);
        Some(Payload {
            len: data.len() as u8,
            buf,
        })
    }

    /// A 16-bit value, little-endian (the manual's message 2 data and error data).
    pub fn u16(value: u16) -> Payload {
        let [lo, hi] = value.to_le_bytes();
        Payload {
            len: 2,
            buf: [lo, hi, 0, 0, 0, 0, 0],
        }
    }

    /// The bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.buf[..usize::from(self.len)]
    }

    /// How many bytes.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether there are no bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The first two bytes as a little-endian `u16`, if there are at least two.
    pub fn as_u16(&self) -> Option<u16> {
        match self.as_slice() {
            [lo, hi, ..] => Some(u16::from_le_bytes([*lo, *hi])),
            _ => None,
        }
    }
}

impl fmt::Debug for Payload {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Payload[")?;
        for (i, b) in self.as_slice().iter().enumerate() {
            if i > 0 {
                write!(f, " ")?;
            }
            write!(f, "{b:02X}")?;
        }
        write!(f, "]")
    }
}

/// A multiplexor: the index (0–127) of a variable in a multiplexed variable set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Mux(u8);

impl Mux {
    /// A multiplexor, or `None` above 0x7F (bit 7 of the control byte is `c` or `r`).
    pub const fn new(raw: u8) -> Option<Mux> {
        if raw <= 0x7F { Some(Mux(raw)) } else { None }
    }

    /// The multiplexor in the low 7 bits of a control byte.
    pub const fn from_control(byte: u8) -> Mux {
        Mux(byte & 0x7F)
    }

    /// The raw value.
    pub const fn raw(self) -> u8 {
        self.0
    }
}

impl fmt::Display for Mux {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#04X}", self.0)
    }
}

/// Why a frame is not a CMS message of the expected kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// A data frame without the control byte.
    #[error("a CMS frame needs its control byte")]
    Empty,
    /// A remote frame where a data frame was expected.
    #[error("a remote frame is not a CMS request or response on this COB")]
    Remote,
    /// Bits the protocol reserves are set.
    #[error("reserved bits set in control byte {0:#04X}")]
    Reserved(u8),
    /// A read request carries data.
    #[error("a read request carries no data, this one carries {0} bytes")]
    ReadWithData(usize),
    /// A controlled-event frame with a service code other than notify (0) or control (1).
    #[error("unknown event service code {0}")]
    EventService(u8),
    /// A control response with an error flag but no room, or data without an error flag.
    #[error("a control response carries data only with r = 1")]
    ControlData,
}

fn control_byte(frame: &Frame) -> Result<(u8, &[u8]), WireError> {
    if frame.is_remote() {
        return Err(WireError::Remote);
    }
    match frame.data_bytes() {
        [] => Err(WireError::Empty),
        [b, rest @ ..] => Ok((*b, rest)),
    }
}

fn payload(rest: &[u8]) -> Payload {
    // A CAN frame has at most 8 bytes, so the rest after the control byte fits.
    Payload::new(rest).unwrap_or_default()
}

fn frame_of(id: cantwin_can::Id, head: u8, data: &Payload) -> Frame {
    let mut bytes = [0u8; 8];
    bytes[0] = head;
    bytes[1..=data.len()].copy_from_slice(data.as_slice());
    // At most 1 + 7 bytes: always a valid frame.
    Frame::data(id, &bytes[..=data.len()]).unwrap_or_else(|_| Frame::data_array(id, [head]))
}

/// A client's request to a basic variable (DS 202-2 Read/Write Variable, manual §3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BasicRequest {
    /// `c` = 0: write these bytes.
    Write(Payload),
    /// `c` = 1: read.
    Read,
}

impl BasicRequest {
    /// Decode a request frame.
    pub fn decode(frame: &Frame) -> Result<BasicRequest, WireError> {
        let (b, rest) = control_byte(frame)?;
        if b & 0x7F != 0 {
            return Err(WireError::Reserved(b));
        }
        if b & 0x80 == 0 {
            Ok(BasicRequest::Write(payload(rest)))
        } else if rest.is_empty() {
            Ok(BasicRequest::Read)
        } else {
            Err(WireError::ReadWithData(rest.len()))
        }
    }

    /// Encode onto the request COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        match self {
            BasicRequest::Write(d) => frame_of(id, 0x00, d),
            BasicRequest::Read => frame_of(id, 0x80, &Payload::EMPTY),
        }
    }
}

/// A server's response (confirmation) from a basic variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BasicResponse {
    /// `r` = 0: the data written (after a write) or read (after a read).
    Success(Payload),
    /// `r` = 1: error data.
    Failure(Payload),
}

impl BasicResponse {
    /// Decode a response frame.
    pub fn decode(frame: &Frame) -> Result<BasicResponse, WireError> {
        let (b, rest) = control_byte(frame)?;
        if b & 0x7F != 0 {
            return Err(WireError::Reserved(b));
        }
        Ok(if b & 0x80 == 0 {
            BasicResponse::Success(payload(rest))
        } else {
            BasicResponse::Failure(payload(rest))
        })
    }

    /// Encode onto the response COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        match self {
            BasicResponse::Success(d) => frame_of(id, 0x00, d),
            BasicResponse::Failure(d) => frame_of(id, 0x80, d),
        }
    }
}

/// Whether `frame` is a DS 202-2 remote read of the basic variable whose response COB is
/// `response_id`.
pub fn is_remote_read(frame: &Frame, response_id: cantwin_can::Id) -> bool {
    frame.is_remote() && frame.id() == response_id
}

/// A client's request to a multiplexed variable set (manual §3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MuxRequest {
    /// Which variable.
    pub mux: Mux,
    /// `None` for a read (`c` = 1), the data for a write (`c` = 0).
    pub write: Option<Payload>,
}

impl MuxRequest {
    /// Decode a request frame.
    pub fn decode(frame: &Frame) -> Result<MuxRequest, WireError> {
        let (b, rest) = control_byte(frame)?;
        let mux = Mux(b & 0x7F);
        if b & 0x80 == 0 {
            Ok(MuxRequest {
                mux,
                write: Some(payload(rest)),
            })
        } else if rest.is_empty() {
            Ok(MuxRequest { mux, write: None })
        } else {
            Err(WireError::ReadWithData(rest.len()))
        }
    }

    /// Encode onto the request COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        match &self.write {
            Some(d) => frame_of(id, self.mux.0, d),
            None => frame_of(id, 0x80 | self.mux.0, &Payload::EMPTY),
        }
    }
}

/// A server's response from a multiplexed variable set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MuxResponse {
    /// The variable the request named.
    pub mux: Mux,
    /// `Ok(data written or read)` (`r` = 0) or `Err(error data)` (`r` = 1).
    pub result: Result<Payload, Payload>,
}

impl MuxResponse {
    /// Decode a response frame.
    pub fn decode(frame: &Frame) -> Result<MuxResponse, WireError> {
        let (b, rest) = control_byte(frame)?;
        let mux = Mux(b & 0x7F);
        let data = payload(rest);
        Ok(MuxResponse {
            mux,
            result: if b & 0x80 == 0 { Ok(data) } else { Err(data) },
        })
    }

    /// Encode onto the response COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        match &self.result {
            Ok(d) => frame_of(id, self.mux.0, d),
            Err(d) => frame_of(id, 0x80 | self.mux.0, d),
        }
    }
}

const EVENT_NOTIFY: u8 = 0;
const EVENT_CONTROL: u8 = 1;
const BIT_STATE: u8 = 0x10;
const BIT_RESULT: u8 = 0x08;

/// A client's request to a controlled event: enable or disable notification (manual §3.2,
/// DS 202-2 "Control Event").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EventControl {
    /// `s`: the requested state.
    pub enable: bool,
}

impl EventControl {
    /// Decode a control request.
    pub fn decode(frame: &Frame) -> Result<EventControl, WireError> {
        let (b, rest) = control_byte(frame)?;
        let service = b >> 5;
        if service != EVENT_CONTROL {
            return Err(WireError::EventService(service));
        }
        if b & 0x0F != 0 {
            return Err(WireError::Reserved(b));
        }
        if !rest.is_empty() {
            return Err(WireError::ControlData);
        }
        Ok(EventControl {
            enable: b & BIT_STATE != 0,
        })
    }

    /// Encode onto the event's request COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        let b = EVENT_CONTROL << 5 | if self.enable { BIT_STATE } else { 0 };
        frame_of(id, b, &Payload::EMPTY)
    }
}

/// What the server sends on a controlled event's response COB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventMessage {
    /// The confirmation of a control request.
    Control {
        /// `as`: the state after the request.
        enabled: bool,
        /// `Ok` (`r` = 0) or `Err(error data)` (`r` = 1).
        result: Result<(), Payload>,
    },
    /// A notification with the event data (`c` = 0).
    Notify(Payload),
}

impl EventMessage {
    /// Decode a frame from the event's response COB.
    pub fn decode(frame: &Frame) -> Result<EventMessage, WireError> {
        let (b, rest) = control_byte(frame)?;
        match b >> 5 {
            EVENT_NOTIFY => {
                if b & 0x0F != 0 {
                    return Err(WireError::Reserved(b));
                }
                Ok(EventMessage::Notify(payload(rest)))
            }
            EVENT_CONTROL => {
                if b & 0x07 != 0 {
                    return Err(WireError::Reserved(b));
                }
                let enabled = b & BIT_STATE != 0;
                let result = if b & BIT_RESULT != 0 {
                    Err(payload(rest))
                } else if rest.is_empty() {
                    Ok(())
                } else {
                    return Err(WireError::ControlData);
                };
                Ok(EventMessage::Control { enabled, result })
            }
            other => Err(WireError::EventService(other)),
        }
    }

    /// Encode onto the event's response COB.
    pub fn encode(&self, id: cantwin_can::Id) -> Frame {
        match self {
            EventMessage::Notify(d) => frame_of(id, EVENT_NOTIFY << 5 | BIT_STATE, d),
            EventMessage::Control { enabled, result } => {
                let s = if *enabled { BIT_STATE } else { 0 };
                match result {
                    Ok(()) => frame_of(id, EVENT_CONTROL << 5 | s, &Payload::EMPTY),
                    Err(d) => frame_of(id, EVENT_CONTROL << 5 | s | BIT_RESULT, d),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;
    use proptest::prelude::*;

    fn id() -> Id {
        Id::standard(0x1B8).unwrap()
    }

    #[test]
    fn basic_write_of_the_manual_example() {
        let req = BasicRequest::Write(Payload::new(&[0xAA, 0x88, 0x13]).unwrap());
        assert_eq!(req.encode(id()).to_string(), "1B8#00AA8813");
        assert_eq!(BasicRequest::decode(&req.encode(id())), Ok(req));
        assert_eq!(BasicRequest::Read.encode(id()).to_string(), "1B8#80");
    }

    #[test]
    fn basic_request_rejects_reserved_bits_and_read_data() {
        let f = Frame::std(0x1B8, &[0x01]).unwrap();
        assert_eq!(BasicRequest::decode(&f), Err(WireError::Reserved(1)));
        let f = Frame::std(0x1B8, &[0x80, 1]).unwrap();
        assert_eq!(BasicRequest::decode(&f), Err(WireError::ReadWithData(1)));
        let f = Frame::std(0x1B8, &[]).unwrap();
        assert_eq!(BasicRequest::decode(&f), Err(WireError::Empty));
        let f = Frame::remote(id(), 4).unwrap();
        assert_eq!(BasicRequest::decode(&f), Err(WireError::Remote));
    }

    #[test]
    fn mux_frames() {
        let m = Mux::new(0x19).unwrap();
        let r = MuxRequest {
            mux: m,
            write: Some(Payload::u16(256)),
        };
        assert_eq!(r.encode(id()).to_string(), "1B8#190001");
        let r = MuxRequest {
            mux: m,
            write: None,
        };
        assert_eq!(r.encode(id()).to_string(), "1B8#99");
        let e = MuxResponse {
            mux: m,
            result: Err(Payload::u16(2)),
        };
        assert_eq!(e.encode(id()).to_string(), "1B8#990200");
        assert_eq!(MuxResponse::decode(&e.encode(id())), Ok(e));
        assert_eq!(Mux::new(0x80), None);
    }

    #[test]
    fn event_frames() {
        assert_eq!(
            EventControl { enable: true }.encode(id()).to_string(),
            "1B8#30"
        );
        assert_eq!(
            EventControl { enable: false }.encode(id()).to_string(),
            "1B8#20"
        );
        let n = EventMessage::Notify(Payload::new(&[0x00, 0x80]).unwrap());
        assert_eq!(n.encode(id()).to_string(), "1B8#100080");
        let c = EventMessage::Control {
            enabled: false,
            result: Err(Payload::u16(0)),
        };
        assert_eq!(c.encode(id()).to_string(), "1B8#280000");
        assert_eq!(EventMessage::decode(&c.encode(id())), Ok(c));
        let f = Frame::std(0x1B8, &[0x40]).unwrap();
        assert_eq!(EventMessage::decode(&f), Err(WireError::EventService(2)));
    }

    fn any_frame() -> impl Strategy<Value = Frame> {
        (any::<bool>(), proptest::collection::vec(any::<u8>(), 0..=8)).prop_map(|(rtr, d)| {
            if rtr {
                Frame::remote(id(), d.len() as u8).unwrap()
            } else {
                Frame::data(id(), &d).unwrap()
            }
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Every decoder either rejects a frame or decodes it to a message that encodes back
        /// to the same frame.
        #[test]
        fn decoders_round_trip_or_reject(f in any_frame()) {
            if let Ok(m) = BasicRequest::decode(&f) { prop_assert_eq!(m.encode(id()), f); }
            if let Ok(m) = BasicResponse::decode(&f) { prop_assert_eq!(m.encode(id()), f); }
            if let Ok(m) = MuxRequest::decode(&f) { prop_assert_eq!(m.encode(id()), f); }
            if let Ok(m) = MuxResponse::decode(&f) { prop_assert_eq!(m.encode(id()), f); }
            if let Ok(m) = EventControl::decode(&f) { prop_assert_eq!(m.encode(id()), f); }
            if let Ok(m) = EventMessage::decode(&f) {
                // A notify decodes with or without bit 4; it encodes with it.
                if !matches!(m, EventMessage::Notify(_)) { prop_assert_eq!(m.encode(id()), f); }
            }
        }
    }
}
