//! Stateless decode and encode of everything DeviceNet puts on the wire: identifiers,
//! explicit message headers and bodies, the fragmentation protocol, Allocate/Release and
//! UCMM bodies, error responses, the duplicate MAC ID check message, the offline
//! connection set messages (group 4) and I/O fragments.
//!
//! State machines consume these types; trace decoders and capture reports reuse them.

mod explicit;
mod id;

pub use explicit::{
    BodyFormat, ExplicitError, ExplicitFrame, FragByte, FragKind, Header, Request, RequestError,
    Response, ack_status, encode_ack, encode_error, encode_success,
};
pub use id::{DnId, InvalidId, MacId, MacIdError, group1, group2, group3, group4};

/// CIP service codes used on DeviceNet (DeviceNet Vol. 1 Appendix A; CIP Vol. 1 Appendix A).
pub mod service {
    /// Get_Attributes_All.
    pub const GET_ATTRIBUTES_ALL: u8 = 0x01;
    /// Set_Attributes_All.
    pub const SET_ATTRIBUTES_ALL: u8 = 0x02;
    /// Reset.
    pub const RESET: u8 = 0x05;
    /// Get_Attribute_Single.
    pub const GET_ATTRIBUTE_SINGLE: u8 = 0x0E;
    /// Set_Attribute_Single.
    pub const SET_ATTRIBUTE_SINGLE: u8 = 0x10;
    /// Error response (always sent with the R/R bit: 0x94).
    pub const ERROR_RESPONSE: u8 = 0x14;
    /// Allocate_Master/Slave_Connection_Set (class 3), or UCMM Open Explicit Messaging
    /// Connection.
    pub const ALLOCATE: u8 = 0x4B;
    /// Release_Master/Slave_Connection_Set (class 3), or UCMM Close Connection.
    pub const RELEASE: u8 = 0x4C;
    /// Device Heartbeat.
    pub const DEVICE_HEARTBEAT: u8 = 0x4D;
    /// Device Shutdown.
    pub const DEVICE_SHUTDOWN: u8 = 0x4E;
}

/// CIP general status codes (CIP Vol. 1 Appendix B).
pub mod status {
    /// Resource unavailable.
    pub const RESOURCE_UNAVAILABLE: u8 = 0x02;
    /// Service not supported.
    pub const SERVICE_NOT_SUPPORTED: u8 = 0x08;
    /// Invalid attribute value.
    pub const INVALID_ATTRIBUTE_VALUE: u8 = 0x09;
    /// Already in requested mode/state.
    pub const ALREADY_IN_STATE: u8 = 0x0B;
    /// Object state conflict.
    pub const OBJECT_STATE_CONFLICT: u8 = 0x0C;
    /// Attribute not settable.
    pub const ATTRIBUTE_NOT_SETTABLE: u8 = 0x0E;
    /// Device state conflict.
    pub const DEVICE_STATE_CONFLICT: u8 = 0x10;
    /// Reply data too large.
    pub const REPLY_TOO_LARGE: u8 = 0x11;
    /// Not enough data.
    pub const NOT_ENOUGH_DATA: u8 = 0x13;
    /// Attribute not supported.
    pub const ATTRIBUTE_NOT_SUPPORTED: u8 = 0x14;
    /// Too much data.
    pub const TOO_MUCH_DATA: u8 = 0x15;
    /// Object does not exist (class or instance).
    pub const OBJECT_DOES_NOT_EXIST: u8 = 0x16;
    /// Vendor specific error.
    pub const VENDOR_SPECIFIC: u8 = 0x1F;
    /// Invalid parameter.
    pub const INVALID_PARAMETER: u8 = 0x20;
    /// No additional code.
    pub const NO_ADDITIONAL: u8 = 0xFF;

    /// The meaning of a general status code (CIP Vol. 1 Appendix B, as every CIP network
    /// uses them).
    pub fn text(code: u8) -> &'static str {
        match code {
            0x00 => "success",
            0x01 => "connection failure",
            0x02 => "resource unavailable",
            0x03 => "invalid parameter value",
            0x04 => "path segment error",
            0x05 => "path destination unknown",
            0x06 => "partial transfer",
            0x07 => "connection lost",
            0x08 => "service not supported",
            0x09 => "invalid attribute value",
            0x0A => "attribute list error",
            0x0B => "already in requested mode/state",
            0x0C => "object state conflict",
            0x0D => "object already exists",
            0x0E => "attribute not settable",
            0x0F => "privilege violation",
            0x10 => "device state conflict",
            0x11 => "reply data too large",
            0x12 => "fragmentation of a primitive value",
            0x13 => "not enough data",
            0x14 => "attribute not supported",
            0x15 => "too much data",
            0x16 => "object does not exist",
            0x17 => "service fragmentation sequence not in progress",
            0x18 => "no stored attribute data",
            0x19 => "store operation failure",
            0x1A => "routing failure, request packet too large",
            0x1B => "routing failure, response packet too large",
            0x1C => "missing attribute list entry data",
            0x1D => "invalid attribute value list",
            0x1E => "embedded service error",
            0x1F => "vendor specific error",
            0x20 => "invalid parameter",
            0x21 => "write-once value or medium already written",
            0x22 => "invalid reply received",
            0x25 => "key failure in path",
            0x26 => "path size invalid",
            0x27 => "unexpected attribute in list",
            0x28 => "invalid member ID",
            0x29 => "member not settable",
            _ => "reserved or object-specific status",
        }
    }
}

/// Additional codes of Allocate/Release error responses (DeviceNet Vol. 1, Predefined
/// Master/Slave Connection Set error codes).
pub mod alloc_error {
    /// Allocated to another master (ownership conflict).
    pub const ALLOCATION_CONFLICT: u8 = 0x01;
    /// Invalid allocation/release choice: unsupported, already allocated/released, zero,
    /// or I/O without explicit messaging.
    pub const INVALID_CHOICE: u8 = 0x02;
    /// The group 2 only unconnected port received a service other than Allocate/Release.
    pub const GROUP2_ONLY_SERVICE: u8 = 0x03;
    /// Resources for the requested connection are not available.
    pub const RESOURCE_UNAVAILABLE: u8 = 0x04;
}

/// Allocation / release choice bits (DeviceNet object attribute 5, Allocate request).
pub mod choice {
    /// Explicit messaging connection.
    pub const EXPLICIT: u8 = 0x01;
    /// Polled I/O connection.
    pub const POLLED: u8 = 0x02;
    /// Bit-strobed I/O connection.
    pub const BIT_STROBED: u8 = 0x04;
    /// Multicast poll connection.
    pub const MULTICAST_POLL: u8 = 0x08;
    /// Change-of-state connection.
    pub const CHANGE_OF_STATE: u8 = 0x10;
    /// Cyclic connection.
    pub const CYCLIC: u8 = 0x20;
    /// Acknowledge suppression.
    pub const ACK_SUPPRESSION: u8 = 0x40;
}

/// Allocate_Master/Slave_Connection_Set request data (after class 3, instance 1):
/// `[allocation choice][allocator's MAC ID]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Allocate {
    /// Requested connections ([`choice`] bits).
    pub choice: u8,
    /// The master's MAC ID.
    pub allocator: MacId,
}

impl Allocate {
    /// Parse the service data; `None` if shorter than 2 bytes.
    pub fn decode(data: &[u8]) -> Option<Allocate> {
        Some(Allocate {
            choice: *data.first()?,
            allocator: MacId::from_bits(*data.get(1)?),
        })
    }

    /// Encode the service data.
    pub const fn encode(self) -> [u8; 2] {
        [self.choice, self.allocator.get()]
    }
}

/// UCMM Open Explicit Messaging Connection request data (after the 0x4B service byte,
/// no class or instance): `[requested body format][group select << 4 | source message ID]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UcmmOpen {
    /// Requested message body format code (low nibble).
    pub format: u8,
    /// Group select: 0 = group 1, 1 = group 2, 3 = group 3, 0xF = node ping.
    pub group: u8,
    /// The client's message ID for its requests.
    pub source_msg: u8,
}

impl UcmmOpen {
    /// Group select value for a group 3 connection.
    pub const GROUP3: u8 = 3;

    /// Parse the data; `None` if shorter than 2 bytes.
    pub fn decode(data: &[u8]) -> Option<UcmmOpen> {
        let a = *data.first()?;
        let b = *data.get(1)?;
        Some(UcmmOpen {
            format: a & 0x0F,
            group: b >> 4,
            source_msg: b & 0x0F,
        })
    }

    /// Encode the data.
    pub const fn encode(self) -> [u8; 2] {
        [
            self.format & 0x0F,
            (self.group << 4) | (self.source_msg & 0x0F),
        ]
    }
}

/// UCMM Open response data: `[actual body format][dest msg ID << 4 | source msg ID]
/// [connection instance ID (UINT)]`. The destination message ID echoes the client's, the
/// source message ID is the one the server produces its responses with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UcmmOpenReply {
    /// Actual message body format.
    pub format: BodyFormat,
    /// The client's message ID (echoed).
    pub dest_msg: u8,
    /// The server's message ID.
    pub source_msg: u8,
    /// The Connection object instance the server created.
    pub instance: u16,
}

impl UcmmOpenReply {
    /// Parse the reply data.
    pub fn decode(data: &[u8]) -> Option<UcmmOpenReply> {
        if data.len() < 4 {
            return None;
        }
        Some(UcmmOpenReply {
            format: BodyFormat::from_code(data[0] & 0x0F)?,
            dest_msg: data[1] >> 4,
            source_msg: data[1] & 0x0F,
            instance: u16::from_le_bytes([data[2], data[3]]),
        })
    }

    /// Encode the reply data.
    pub const fn encode(self) -> [u8; 4] {
        let i = self.instance.to_le_bytes();
        [
            self.format.code(),
            (self.dest_msg << 4) | (self.source_msg & 0x0F),
            i[0],
            i[1],
        ]
    }
}

/// Duplicate MAC ID check message, 7 bytes on `0x407 | MAC << 3`:
/// `[R/R << 7 | physical port][vendor ID (UINT)][serial number (UDINT)]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DupMac {
    /// Response (R/R = 1) rather than request.
    pub response: bool,
    /// Physical port number (0 for a single-port device).
    pub port: u8,
    /// Vendor ID.
    pub vendor: u16,
    /// Serial number.
    pub serial: u32,
}

impl DupMac {
    /// Parse the 7 data bytes (longer frames are accepted, shorter rejected).
    pub fn decode(data: &[u8]) -> Option<DupMac> {
        if data.len() < 7 {
            return None;
        }
        Some(DupMac {
            response: data[0] & 0x80 != 0,
            port: data[0] & 0x7F,
            vendor: u16::from_le_bytes([data[1], data[2]]),
            serial: u32::from_le_bytes([data[3], data[4], data[5], data[6]]),
        })
    }

    /// Encode the 7 data bytes.
    pub const fn encode(self) -> [u8; 7] {
        let v = self.vendor.to_le_bytes();
        let s = self.serial.to_le_bytes();
        [
            ((self.response as u8) << 7) | (self.port & 0x7F),
            v[0],
            v[1],
            s[0],
            s[1],
            s[2],
            s[3],
        ]
    }
}

/// Whom a group 4 communication-faulted request addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommFaultTarget {
    /// Short form (2 bytes): a MAC ID, with the "match" bit.
    Mac {
        /// Match bit.
        matched: bool,
        /// The value field (a MAC ID).
        mac: MacId,
    },
    /// Long form (8 bytes): a device by vendor ID and serial number.
    Device {
        /// Vendor ID.
        vendor: u16,
        /// Serial number.
        serial: u32,
    },
}

/// Communication faulted request/response of the offline connection set (group 4
/// messages 0x2D/0x2C): `[rsv | match | value][R/R | service]` or
/// `[reserved][R/R | service][vendor ID][serial number]` (field layout as Wireshark's
/// DeviceNet dissector decodes it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommFault {
    /// Response rather than request.
    pub response: bool,
    /// Service code.
    pub service: u8,
    /// The addressed device.
    pub target: CommFaultTarget,
}

impl CommFault {
    /// Parse a 2- or 8-byte message.
    pub fn decode(data: &[u8]) -> Option<CommFault> {
        let b1 = *data.get(1)?;
        let target = match data.len() {
            2 => CommFaultTarget::Mac {
                matched: data[0] & 0x40 != 0,
                mac: MacId::from_bits(data[0]),
            },
            8 => CommFaultTarget::Device {
                vendor: u16::from_le_bytes([data[2], data[3]]),
                serial: u32::from_le_bytes([data[4], data[5], data[6], data[7]]),
            },
            _ => return None,
        };
        Some(CommFault {
            response: b1 & 0x80 != 0,
            service: b1 & 0x7F,
            target,
        })
    }

    /// Encode the message.
    pub fn encode(&self) -> Vec<u8> {
        let b1 = ((self.response as u8) << 7) | (self.service & 0x7F);
        match self.target {
            CommFaultTarget::Mac { matched, mac } => {
                vec![((matched as u8) << 6) | mac.get(), b1]
            }
            CommFaultTarget::Device { vendor, serial } => {
                let mut v = vec![0, b1];
                v.extend_from_slice(&vendor.to_le_bytes());
                v.extend_from_slice(&serial.to_le_bytes());
                v
            }
        }
    }
}

/// Offline ownership request/response (group 4 messages 0x2F/0x2E):
/// `[client MAC ID][R/R | allocate][vendor ID][serial number]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OfflineOwnership {
    /// Response rather than request.
    pub response: bool,
    /// The client's MAC ID.
    pub client: MacId,
    /// Allocate field (7 bits).
    pub allocate: u8,
    /// Vendor ID.
    pub vendor: u16,
    /// Serial number.
    pub serial: u32,
}

impl OfflineOwnership {
    /// Parse the 8 data bytes.
    pub fn decode(data: &[u8]) -> Option<OfflineOwnership> {
        if data.len() != 8 {
            return None;
        }
        Some(OfflineOwnership {
            response: data[1] & 0x80 != 0,
            client: MacId::from_bits(data[0]),
            allocate: data[1] & 0x7F,
            vendor: u16::from_le_bytes([data[2], data[3]]),
            serial: u32::from_le_bytes([data[4], data[5], data[6], data[7]]),
        })
    }

    /// Encode the 8 data bytes.
    pub fn encode(&self) -> [u8; 8] {
        let v = self.vendor.to_le_bytes();
        let s = self.serial.to_le_bytes();
        [
            self.client.get(),
            ((self.response as u8) << 7) | (self.allocate & 0x7F),
            v[0],
            v[1],
            s[0],
            s[1],
            s[2],
            s[3],
        ]
    }
}

/// Split an I/O message of a fragmented connection into frames' data
/// `[fragment byte][≤ 7 bytes]` (unacknowledged fragmentation, DeviceNet Vol. 1 §4).
pub fn io_fragments(data: &[u8]) -> Vec<Vec<u8>> {
    if data.is_empty() {
        return vec![vec![FragByte::for_index(0, 1).encode()]];
    }
    let chunks: Vec<&[u8]> = data.chunks(7).collect();
    let total = chunks.len().max(2);
    let mut out = Vec::with_capacity(total);
    for (i, c) in chunks.iter().enumerate() {
        let mut f = Vec::with_capacity(8);
        f.push(FragByte::for_index(i, total).encode());
        f.extend_from_slice(c);
        out.push(f);
    }
    if chunks.len() == 1 {
        // A single chunk still needs a "last" to close the sequence.
        out.push(vec![FragByte::for_index(1, 2).encode()]);
    }
    out
}

/// Split an explicit message body (service byte onward) into frames' data. Bodies of up to
/// 7 bytes go whole; longer ones as `[hdr|frag][fragment byte][≤ 6 bytes]` fragments.
pub fn explicit_frames(header: Header, body: &[u8]) -> Vec<Vec<u8>> {
    if body.len() <= 7 {
        let mut f = Vec::with_capacity(1 + body.len());
        f.push(
            Header {
                frag: false,
                ..header
            }
            .encode(),
        );
        f.extend_from_slice(body);
        return vec![f];
    }
    let chunks: Vec<&[u8]> = body.chunks(6).collect();
    let total = chunks.len();
    chunks
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut f = Vec::with_capacity(8);
            f.push(
                Header {
                    frag: true,
                    ..header
                }
                .encode(),
            );
            f.push(FragByte::for_index(i, total).encode());
            f.extend_from_slice(c);
            f
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn general_status_codes_have_the_cip_texts() {
        assert_eq!(status::text(0x14), "attribute not supported");
        assert_eq!(
            status::text(status::OBJECT_DOES_NOT_EXIST),
            "object does not exist"
        );
        assert_eq!(status::text(0x23), "reserved or object-specific status");
    }

    /// I-7242D DeviceNet/Modbus RTU Gateway User's Manual v1.1 (ICP DAS, 2006), §7.2.8:
    /// master 0x0A allocates explicit messaging from slave 0x09.
    #[test]
    fn allocate_body_from_icpdas_trace() {
        let body = [0x4B, 0x03, 0x01, 0x01, 0x0A];
        let r = Request::decode(&body, BodyFormat::F8_8).unwrap();
        assert_eq!((r.service, r.class, r.instance), (0x4B, 3, 1));
        let a = Allocate::decode(r.data).unwrap();
        assert_eq!(a.choice, choice::EXPLICIT);
        assert_eq!(a.allocator, MacId::new(0x0A).unwrap());
    }

    /// Rockwell 1760-DNET user manual (1760-UM003A), §4 "DeviceNet Functions": a 9-byte
    /// response body from slave 3 to master 0 goes as `80 00 B2 C2 05 00 05 09` then
    /// `80 81 0D 05 04`.
    #[test]
    fn explicit_fragmentation_matches_rockwell_trace() {
        let body = [0xB2, 0xC2, 0x05, 0x00, 0x05, 0x09, 0x0D, 0x05, 0x04];
        let frames = explicit_frames(Header::new(false, MacId::new(0).unwrap()), &body);
        assert_eq!(
            frames,
            vec![
                vec![0x80, 0x00, 0xB2, 0xC2, 0x05, 0x00, 0x05, 0x09],
                vec![0x80, 0x81, 0x0D, 0x05, 0x04]
            ]
        );
        assert_eq!(
            encode_ack(false, MacId::new(0).unwrap(), 1, 0),
            [0x80, 0xC1, 0x00]
        );
    }

    #[test]
    fn io_fragmentation_of_16_words() {
        let data: Vec<u8> = (0..32).collect();
        let frames = io_fragments(&data);
        assert_eq!(frames.len(), 5);
        assert_eq!(frames[0][0], 0x00);
        assert_eq!(frames[1][0], 0x41);
        assert_eq!(frames[4], vec![0x84, 28, 29, 30, 31]);
    }

    #[test]
    fn group4_offline_messages_round_trip() {
        let short = CommFault {
            response: false,
            service: 0x4B,
            target: CommFaultTarget::Mac {
                matched: true,
                mac: MacId::new(5).unwrap(),
            },
        };
        assert_eq!(short.encode(), [0x45, 0x4B]);
        assert_eq!(CommFault::decode(&short.encode()), Some(short));
        let long = CommFault {
            response: true,
            service: 0x4B,
            target: CommFaultTarget::Device {
                vendor: 0x0123,
                serial: 0x0A0B_0C0D,
            },
        };
        assert_eq!(CommFault::decode(&long.encode()), Some(long));
        assert_eq!(CommFault::decode(&[0, 0, 0]), None);
        let o = OfflineOwnership {
            response: false,
            client: MacId::new(0).unwrap(),
            allocate: 1,
            vendor: 0x0123,
            serial: 7,
        };
        assert_eq!(o.encode(), [0, 1, 0x23, 0x01, 7, 0, 0, 0]);
        assert_eq!(OfflineOwnership::decode(&o.encode()), Some(o));
    }

    #[test]
    fn dup_mac_and_ucmm_round_trip() {
        let d = DupMac {
            response: true,
            port: 0,
            vendor: 0x1234,
            serial: 0xDEAD_BEEF,
        };
        assert_eq!(d.encode(), [0x80, 0x34, 0x12, 0xEF, 0xBE, 0xAD, 0xDE]);
        assert_eq!(DupMac::decode(&d.encode()), Some(d));
        // A UCMM open asking for 16/16, group 3, client message ID 4.
        let o = UcmmOpen::decode(&[0x02, 0x34]).unwrap();
        assert_eq!((o.format, o.group, o.source_msg), (2, 3, 4));
        let r = UcmmOpenReply {
            format: BodyFormat::F8_16,
            dest_msg: 4,
            source_msg: 1,
            instance: 6,
        };
        assert_eq!(UcmmOpenReply::decode(&r.encode()), Some(r));
    }
}
