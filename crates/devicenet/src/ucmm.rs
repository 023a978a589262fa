//! The Unconnected Message Manager (DeviceNet Vol. 1 §4, "UCMM"): opens and closes
//! explicit messaging connections on group 3 for any client, several at once.
//!
//! Requests arrive on group 3 message 6 (`0x780 | client`), responses leave on group 3
//! message 5 (`0x740 | server`). An opened connection consumes the client's requests on
//! `0x600 | client msg ID << 6 | client` and produces on `0x600 | server msg ID << 6 |
//! server`; the server picks a message ID (0–4) no other of its connections uses.

use crate::objects::CipError;
use crate::objects::connection::{ConnKind, Connection};
use crate::wire::{
    self, BodyFormat, DnId, ExplicitFrame, Header, MacId, UcmmOpen, UcmmOpenReply, group3, service,
    status,
};
use cantwin_can::{Frame, Instant};

/// The group 3 message IDs an explicit connection may use (5 and 6 belong to the UCMM).
pub const CONNECTION_MSG_IDS: core::ops::RangeInclusive<u8> = 0..=4;

/// Initial communication characteristics of a UCMM connection: produces and consumes on
/// group 3.
pub const INITIAL_COMM_GROUP3: u8 = 0x33;

/// What the UCMM of a server needs from its configuration: a copy of the slave's limits.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    /// The server's own MAC ID.
    pub mac: MacId,
    /// Explicit connections the UCMM may open at once.
    pub connections: usize,
    /// First Connection instance ID used for UCMM connections.
    pub first_instance: u16,
    /// Largest explicit message body in either direction.
    pub max_explicit: u16,
    /// Expected packet rate of a new explicit connection in ms.
    pub explicit_epr_ms: u16,
}

/// The server's limits and the UCMM connections it has open.
pub(crate) struct Parts<'a> {
    pub config: Limits,
    pub conns: &'a mut Vec<Connection>,
}

/// The body format the server answers to a requested one: 8/8 and 8/16 as asked,
/// anything else as 8/16 (the widest this device speaks).
pub fn actual_format(requested: u8) -> BodyFormat {
    match requested {
        0 => BodyFormat::F8_8,
        _ => BodyFormat::F8_16,
    }
}

fn open(p: &mut Parts<'_>, client: MacId, o: UcmmOpen, now: Instant) -> Result<Vec<u8>, CipError> {
    if o.group != UcmmOpen::GROUP3 || !CONNECTION_MSG_IDS.contains(&o.source_msg) {
        return Err(CipError::new(status::INVALID_PARAMETER));
    }
    let consumed = DnId::Group3 {
        msg: o.source_msg,
        mac: client,
    };
    if p.conns.iter().any(|c| c.consumed_id == consumed) {
        return Err(CipError::new(status::OBJECT_STATE_CONFLICT));
    }
    if p.conns.len() >= p.config.connections {
        return Err(CipError::new(status::RESOURCE_UNAVAILABLE));
    }
    let own = p.config.mac;
    let used = |m: u8| {
        p.conns
            .iter()
            .any(|c| c.produced_id == DnId::Group3 { msg: m, mac: own })
    };
    let server_msg = CONNECTION_MSG_IDS
        .clone()
        .find(|&m| !used(m))
        .ok_or(CipError::new(status::RESOURCE_UNAVAILABLE))?;
    let instance = (p.config.first_instance..=u16::MAX)
        .find(|&i| p.conns.iter().all(|c| c.instance != i))
        .ok_or(CipError::new(status::RESOURCE_UNAVAILABLE))?;
    let format = actual_format(o.format);
    let max = p.config.max_explicit;
    let mut c = Connection::new(
        instance,
        ConnKind::Explicit,
        client,
        DnId::Group3 {
            msg: server_msg,
            mac: own,
        },
        consumed,
        INITIAL_COMM_GROUP3,
        (max, max),
        p.config.explicit_epr_ms,
        now,
    );
    c.format = format;
    p.conns.push(c);
    Ok(UcmmOpenReply {
        format,
        dest_msg: o.source_msg,
        source_msg: server_msg,
        instance,
    }
    .encode()
    .to_vec())
}

fn close(p: &mut Parts<'_>, client: MacId, data: &[u8]) -> Result<Vec<u8>, CipError> {
    let [lo, hi] = data else {
        return Err(CipError::new(if data.len() < 2 {
            status::NOT_ENOUGH_DATA
        } else {
            status::TOO_MUCH_DATA
        }));
    };
    let instance = u16::from_le_bytes([*lo, *hi]);
    let i = p
        .conns
        .iter()
        .position(|c| c.instance == instance && c.peer == client)
        .ok_or(CipError::new(status::OBJECT_DOES_NOT_EXIST))?;
    p.conns.remove(i);
    Ok(Vec::new())
}

/// A frame on the UCMM request identifier from `client`; returns the response.
pub(crate) fn on_request(
    mut p: Parts<'_>,
    client: MacId,
    data: &[u8],
    now: Instant,
) -> Option<Frame> {
    let Ok(ExplicitFrame::Whole { header, body }) = ExplicitFrame::decode(data) else {
        return None;
    };
    let own = p.config.mac;
    // The header of a group 3 request carries the destination: another server's request.
    if header.mac != own {
        return None;
    }
    let (&svc, rest) = body.split_first()?;
    let result = match svc {
        service::ALLOCATE => match UcmmOpen::decode(rest) {
            Some(o) => open(&mut p, client, o, now),
            None => Err(CipError::new(status::NOT_ENOUGH_DATA)),
        },
        service::RELEASE => close(&mut p, client, rest),
        s if s & 0x80 != 0 => return None,
        _ => Err(CipError::new(status::SERVICE_NOT_SUPPORTED)),
    };
    let reply = match result {
        Ok(d) => wire::encode_success(svc, &d),
        Err(e) => wire::encode_error(e.general, e.additional).to_vec(),
    };
    let mut frame = vec![Header::new(header.xid, client).encode()];
    frame.extend_from_slice(&reply);
    Some(
        DnId::Group3 {
            msg: group3::UNCONNECTED_RESPONSE,
            mac: own,
        }
        .frame(&frame),
    )
}
