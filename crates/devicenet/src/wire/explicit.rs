//! Explicit messages (DeviceNet Vol. 1 §3, "Explicit Message Body Format"): the header
//! byte, the fragmentation byte, request and response bodies, error responses.

use super::MacId;

/// The first byte of every explicit message: `Frag | XID | MAC ID`.
///
/// The MAC ID is the *other* end: the source in a request sent on an identifier carrying
/// the destination, the destination in a response sent on an identifier carrying the
/// source (MKS DeviceNet manual: "In a request message, the device address in the CAN Data
/// Field is the source node address. In a response message it is the destination").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Header {
    /// The message is one fragment of a longer body.
    pub frag: bool,
    /// Transaction ID, echoed by the server.
    pub xid: bool,
    /// The other end's MAC ID.
    pub mac: MacId,
}

impl Header {
    /// Decode a header byte.
    pub const fn decode(b: u8) -> Header {
        Header {
            frag: b & 0x80 != 0,
            xid: b & 0x40 != 0,
            mac: MacId::from_bits(b),
        }
    }

    /// Encode the header byte.
    pub const fn encode(self) -> u8 {
        ((self.frag as u8) << 7) | ((self.xid as u8) << 6) | self.mac.get()
    }

    /// An unfragmented header.
    pub const fn new(xid: bool, mac: MacId) -> Header {
        Header {
            frag: false,
            xid,
            mac,
        }
    }
}

/// The kind of a fragment (bits 7–6 of the fragmentation byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FragKind {
    /// First fragment (count 0).
    First,
    /// Middle fragment.
    Middle,
    /// Last fragment.
    Last,
    /// Acknowledge of an explicit fragment.
    Ack,
}

/// The fragmentation protocol byte: kind and a 6-bit count that wraps modulo 64.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FragByte {
    /// The fragment's kind.
    pub kind: FragKind,
    /// The fragment count, 0–63.
    pub count: u8,
}

impl FragByte {
    /// Decode a fragmentation byte.
    pub const fn decode(b: u8) -> FragByte {
        let kind = match b >> 6 {
            0 => FragKind::First,
            1 => FragKind::Middle,
            2 => FragKind::Last,
            _ => FragKind::Ack,
        };
        FragByte {
            kind,
            count: b & 0x3F,
        }
    }

    /// Encode the byte.
    pub const fn encode(self) -> u8 {
        let k = match self.kind {
            FragKind::First => 0,
            FragKind::Middle => 1,
            FragKind::Last => 2,
            FragKind::Ack => 3,
        };
        (k << 6) | (self.count & 0x3F)
    }

    /// The fragment byte for fragment `index` of `total` (index 0 is first).
    pub const fn for_index(index: usize, total: usize) -> FragByte {
        let kind = if index == 0 {
            FragKind::First
        } else if index + 1 == total {
            FragKind::Last
        } else {
            FragKind::Middle
        };
        FragByte {
            kind,
            count: (index % 64) as u8,
        }
    }
}

/// Acknowledge status of an explicit fragment acknowledge.
pub mod ack_status {
    /// Fragment received.
    pub const SUCCESS: u8 = 0x00;
    /// The reassembled message would exceed the receiver's buffer.
    pub const TOO_MUCH_DATA: u8 = 0x01;
}

/// One explicit-message frame, decoded down to the fragmentation layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExplicitFrame<'a> {
    /// A whole message: the body starts with the service byte.
    Whole {
        /// Header byte.
        header: Header,
        /// Service byte onward.
        body: &'a [u8],
    },
    /// A fragment of a longer body.
    Fragment {
        /// Header byte (frag bit set).
        header: Header,
        /// Fragmentation byte (never [`FragKind::Ack`]).
        frag: FragByte,
        /// Up to 6 body bytes.
        data: &'a [u8],
    },
    /// An acknowledge of a fragment.
    Ack {
        /// Header byte (frag bit set).
        header: Header,
        /// The acknowledged count.
        count: u8,
        /// [`ack_status`] value.
        status: u8,
    },
}

/// A frame that is not a valid explicit message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ExplicitError {
    /// Fewer bytes than the format needs.
    #[error("explicit message too short ({0} bytes)")]
    TooShort(usize),
}

impl<'a> ExplicitFrame<'a> {
    /// Decode a frame's data bytes.
    pub fn decode(data: &'a [u8]) -> Result<ExplicitFrame<'a>, ExplicitError> {
        let (&h, rest) = data.split_first().ok_or(ExplicitError::TooShort(0))?;
        let header = Header::decode(h);
        if !header.frag {
            if rest.is_empty() {
                return Err(ExplicitError::TooShort(data.len()));
            }
            return Ok(ExplicitFrame::Whole { header, body: rest });
        }
        let (&f, rest) = rest
            .split_first()
            .ok_or(ExplicitError::TooShort(data.len()))?;
        let frag = FragByte::decode(f);
        if frag.kind == FragKind::Ack {
            return Ok(ExplicitFrame::Ack {
                header,
                count: frag.count,
                status: rest.first().copied().unwrap_or(ack_status::SUCCESS),
            });
        }
        Ok(ExplicitFrame::Fragment {
            header,
            frag,
            data: rest,
        })
    }

    /// The header.
    pub const fn header(&self) -> Header {
        match self {
            ExplicitFrame::Whole { header, .. }
            | ExplicitFrame::Fragment { header, .. }
            | ExplicitFrame::Ack { header, .. } => *header,
        }
    }
}

/// Encode an acknowledge: `[hdr|frag][0xC0|count][status]`.
pub fn encode_ack(xid: bool, mac: MacId, count: u8, status: u8) -> [u8; 3] {
    let h = Header {
        frag: true,
        xid,
        mac,
    };
    let f = FragByte {
        kind: FragKind::Ack,
        count,
    };
    [h.encode(), f.encode(), status]
}

/// Message body format: the widths of the class and instance fields (DeviceNet Vol. 1,
/// Allocate response / UCMM Open "message body format").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BodyFormat {
    /// 8-bit class, 8-bit instance.
    #[default]
    F8_8,
    /// 8-bit class, 16-bit instance.
    F8_16,
    /// 16-bit class, 16-bit instance.
    F16_16,
    /// 16-bit class, 8-bit instance.
    F16_8,
}

impl BodyFormat {
    /// Decode the 4-bit code (0–3); other values are not a format this stack speaks.
    pub const fn from_code(code: u8) -> Option<BodyFormat> {
        match code {
            0 => Some(BodyFormat::F8_8),
            1 => Some(BodyFormat::F8_16),
            2 => Some(BodyFormat::F16_16),
            3 => Some(BodyFormat::F16_8),
            _ => None,
        }
    }

    /// The 4-bit code.
    pub const fn code(self) -> u8 {
        match self {
            BodyFormat::F8_8 => 0,
            BodyFormat::F8_16 => 1,
            BodyFormat::F16_16 => 2,
            BodyFormat::F16_8 => 3,
        }
    }

    const fn class_len(self) -> usize {
        match self {
            BodyFormat::F8_8 | BodyFormat::F8_16 => 1,
            _ => 2,
        }
    }

    const fn instance_len(self) -> usize {
        match self {
            BodyFormat::F8_8 | BodyFormat::F16_8 => 1,
            _ => 2,
        }
    }
}

/// A request body: `[service][class][instance][service data…]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request<'a> {
    /// Service code (R/R bit clear).
    pub service: u8,
    /// Class ID.
    pub class: u16,
    /// Instance ID (0 = the class itself).
    pub instance: u16,
    /// Service data: for Get/Set_Attribute_Single the attribute ID comes first.
    pub data: &'a [u8],
}

/// Why a request body could not be parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// The body is empty.
    #[error("empty request body")]
    Empty,
    /// The R/R bit says this is a response.
    #[error("service {0:#04x} is a response")]
    NotARequest(u8),
    /// The body ends inside the class or instance field.
    #[error("request for service {0:#04x} ends before its class and instance")]
    NoPath(u8),
}

fn read_field(b: &[u8], len: usize) -> Option<(u16, &[u8])> {
    match len {
        1 => b.split_first().map(|(&v, r)| (u16::from(v), r)),
        _ => (b.len() >= 2).then(|| (u16::from_le_bytes([b[0], b[1]]), &b[2..])),
    }
}

fn push_field(out: &mut Vec<u8>, v: u16, len: usize) {
    if len == 1 {
        out.push(v as u8);
    } else {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

impl<'a> Request<'a> {
    /// Parse a request body in `format`.
    pub fn decode(body: &'a [u8], format: BodyFormat) -> Result<Request<'a>, RequestError> {
        let (&service, rest) = body.split_first().ok_or(RequestError::Empty)?;
        if service & 0x80 != 0 {
            return Err(RequestError::NotARequest(service));
        }
        let (class, rest) =
            read_field(rest, format.class_len()).ok_or(RequestError::NoPath(service))?;
        let (instance, data) =
            read_field(rest, format.instance_len()).ok_or(RequestError::NoPath(service))?;
        Ok(Request {
            service,
            class,
            instance,
            data,
        })
    }

    /// Encode the body in `format`. Class or instance values wider than the format's
    /// field are truncated to it.
    pub fn encode(&self, format: BodyFormat) -> Vec<u8> {
        let mut out = Vec::with_capacity(5 + self.data.len());
        out.push(self.service & 0x7F);
        push_field(&mut out, self.class, format.class_len());
        push_field(&mut out, self.instance, format.instance_len());
        out.extend_from_slice(self.data);
        out
    }

    /// The attribute ID of a Get/Set_Attribute_Single request.
    pub fn attribute(&self) -> Option<u8> {
        self.data.first().copied()
    }
}

/// A response body: `[service|0x80][data…]`, or an error response
/// `[0x94][general status][additional code]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Response<'a> {
    /// Success: the request's service code and the reply data.
    Success {
        /// The service code the response answers (R/R bit removed).
        service: u8,
        /// Reply data.
        data: &'a [u8],
    },
    /// Error response (service 0x14).
    Error {
        /// General status code.
        general: u8,
        /// Additional code (0xFF = none).
        additional: u8,
    },
}

impl<'a> Response<'a> {
    /// Parse a response body; `None` if it is empty, has the R/R bit clear, or is an error
    /// response without its general status.
    pub fn decode(body: &'a [u8]) -> Option<Response<'a>> {
        let (&service, data) = body.split_first()?;
        if service & 0x80 == 0 {
            return None;
        }
        let service = service & 0x7F;
        if service == super::service::ERROR_RESPONSE {
            let general = *data.first()?;
            let additional = data.get(1).copied().unwrap_or(0xFF);
            return Some(Response::Error {
                general,
                additional,
            });
        }
        Some(Response::Success { service, data })
    }
}

/// Encode a success response body.
pub fn encode_success(service: u8, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(1 + data.len());
    out.push(service | 0x80);
    out.extend_from_slice(data);
    out
}

/// Encode an error response body `[0x94][general][additional]`.
pub const fn encode_error(general: u8, additional: u8) -> [u8; 3] {
    [0x80 | super::service::ERROR_RESPONSE, general, additional]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_and_frag_byte_round_trip() {
        for b in 0..=255u8 {
            assert_eq!(Header::decode(b).encode(), b);
            assert_eq!(FragByte::decode(b).encode(), b);
        }
    }

    #[test]
    fn request_formats() {
        let r = Request {
            service: 0x0E,
            class: 0x0F,
            instance: 600,
            data: &[1],
        };
        assert_eq!(r.encode(BodyFormat::F8_16), [0x0E, 0x0F, 0x58, 0x02, 0x01]);
        assert_eq!(
            Request::decode(&[0x0E, 0x0F, 0x58, 0x02, 0x01], BodyFormat::F8_16).unwrap(),
            r
        );
        assert_eq!(
            Request::decode(&[0x0E, 0x01], BodyFormat::F8_8),
            Err(RequestError::NoPath(0x0E))
        );
        assert_eq!(
            Request::decode(&[0x8E], BodyFormat::F8_8),
            Err(RequestError::NotARequest(0x8E))
        );
    }

    /// MKS DeviceNet manual, explicit message examples (slave 5 → master 1):
    /// `42B: 01 94 08 FF` service not supported, `42B: 01 8E 36 00` a Get reply.
    #[test]
    fn mks_error_and_success_responses() {
        let f = ExplicitFrame::decode(&[0x01, 0x94, 0x08, 0xFF]).unwrap();
        let ExplicitFrame::Whole { header, body } = f else {
            panic!("{f:?}")
        };
        assert_eq!(header, Header::new(false, MacId::new(1).unwrap()));
        assert_eq!(
            Response::decode(body),
            Some(Response::Error {
                general: 0x08,
                additional: 0xFF
            })
        );
        assert_eq!(
            Response::decode(&[0x8E, 0x36, 0x00]),
            Some(Response::Success {
                service: 0x0E,
                data: &[0x36, 0x00]
            })
        );
        assert_eq!(encode_error(0x08, 0xFF), [0x94, 0x08, 0xFF]);
    }
}
