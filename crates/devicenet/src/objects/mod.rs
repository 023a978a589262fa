//! CIP objects as the slave serves them, and the application hook.
//!
//! The standard objects (Identity 0x01, Message Router 0x02, DeviceNet 0x03, Connection
//! 0x05) are served by the stack from attribute tables. Every other class (a Parameter
//! object, a vendor class such as Drive Parameter Access 0x66) goes to
//! [`Application::request`]; a class nobody serves gets "object does not exist".

pub mod connection;
pub mod devicenet;
pub mod identity;
pub mod parameter;

use crate::wire::{Request, status};
use cantwin_can::Instant;

pub use identity::Identity;

/// A CIP error: general status and additional code (0xFF = none).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CipError {
    /// General status code ([`crate::wire::status`]).
    pub general: u8,
    /// Additional code.
    pub additional: u8,
}

impl CipError {
    /// An error without additional code.
    pub const fn new(general: u8) -> CipError {
        CipError {
            general,
            additional: status::NO_ADDITIONAL,
        }
    }

    /// An error with an additional code.
    pub const fn with(general: u8, additional: u8) -> CipError {
        CipError {
            general,
            additional,
        }
    }
}

/// The answer to an explicit request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// Success, with the service's reply data (the stack adds `service | 0x80`).
    Data(Vec<u8>),
    /// Error response.
    Error(CipError),
    /// No answer at all (some devices stay silent on a refused request; the client times
    /// out).
    Silent,
}

impl From<CipError> for Reply {
    fn from(e: CipError) -> Self {
        Reply::Error(e)
    }
}

/// What happened on the network, for the device's LEDs, alarms and state display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlaveEvent {
    /// The duplicate MAC ID check passed: the node is on-line.
    Online,
    /// Another node owns our MAC ID: communication faulted.
    DuplicateMac,
    /// The CAN controller went bus-off.
    BusOff,
    /// A master allocated connections ([`crate::wire::choice`] bits now allocated).
    Allocated {
        /// The master.
        master: crate::wire::MacId,
        /// All allocated choice bits.
        choice: u8,
    },
    /// Connections were released; `choice` bits remain allocated.
    Released {
        /// The remaining allocation.
        choice: u8,
    },
    /// The polled I/O connection became established (expected packet rate set).
    IoEstablished,
    /// The polled I/O connection's inactivity watchdog expired.
    IoTimedOut,
    /// A poll command carried data of another length than the connection's consumed size
    /// (the master's scan list does not match the device's I/O). The data is not consumed:
    /// longer is discarded by the connection (CIP Vol. 1 Connection object,
    /// consumed_connection_size), shorter would leave items without values.
    IoLengthMismatch {
        /// Bytes received (after reassembly of a fragmented command).
        received: u16,
        /// The consumed connection size.
        expected: u16,
    },
    /// An explicit connection's inactivity watchdog expired and it was deleted.
    ExplicitTimedOut {
        /// Its Connection instance.
        instance: u16,
    },
    /// Identity Reset was requested (0 = power cycle, 1 = factory defaults).
    Reset(u8),
}

/// The device behind the stack: polled I/O data, device-specific classes, events.
pub trait Application {
    /// Polled I/O sizes in bytes: (produced by the slave, consumed by the slave).
    fn poll_sizes(&self) -> (u16, u16);

    /// The poll response data (input data of the master), `produced` bytes.
    fn produce(&mut self, now: Instant) -> Vec<u8>;

    /// Poll command data (output data of the master). Empty = the master is idle.
    fn consume(&mut self, data: &[u8], now: Instant);

    /// An explicit request the stack routes to the device. `None` lets the stack serve
    /// it (standard classes) or answer "object does not exist".
    fn request(&mut self, req: &Request<'_>, now: Instant) -> Option<Reply> {
        let _ = (req, now);
        None
    }

    /// A network event.
    fn event(&mut self, event: SlaveEvent, now: Instant) {
        let _ = (event, now);
    }
}

/// Access rule of an attribute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Get only.
    Get,
    /// Get and Set.
    GetSet,
}

/// One row of an attribute table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AttrDef {
    /// Attribute ID.
    pub id: u8,
    /// Access rule.
    pub access: Access,
}

/// Shorthand for a Get-only attribute row.
pub const fn get(id: u8) -> AttrDef {
    AttrDef {
        id,
        access: Access::Get,
    }
}

/// Shorthand for a Get/Set attribute row.
pub const fn get_set(id: u8) -> AttrDef {
    AttrDef {
        id,
        access: Access::GetSet,
    }
}

/// Serve Get_Attribute_Single / Set_Attribute_Single from an attribute table:
/// missing attribute ID → "not enough data", unknown attribute → "attribute not
/// supported", Set on a Get-only one → "attribute not settable", other services →
/// "service not supported".
pub fn attribute_service(
    req: &Request<'_>,
    table: &[AttrDef],
    get: impl FnOnce(u8) -> Vec<u8>,
    set: impl FnOnce(u8, &[u8]) -> Result<Vec<u8>, CipError>,
) -> Reply {
    use crate::wire::service::{GET_ATTRIBUTE_SINGLE, SET_ATTRIBUTE_SINGLE};
    if req.service != GET_ATTRIBUTE_SINGLE && req.service != SET_ATTRIBUTE_SINGLE {
        return CipError::new(status::SERVICE_NOT_SUPPORTED).into();
    }
    let Some(attr) = req.attribute() else {
        return CipError::new(status::NOT_ENOUGH_DATA).into();
    };
    let Some(def) = table.iter().find(|d| d.id == attr) else {
        return CipError::new(status::ATTRIBUTE_NOT_SUPPORTED).into();
    };
    if req.service == GET_ATTRIBUTE_SINGLE {
        if req.data.len() > 1 {
            return CipError::new(status::TOO_MUCH_DATA).into();
        }
        return Reply::Data(get(attr));
    }
    if def.access == Access::Get {
        return CipError::new(status::ATTRIBUTE_NOT_SETTABLE).into();
    }
    match set(attr, &req.data[1..]) {
        Ok(d) => Reply::Data(d),
        Err(e) => e.into(),
    }
}

/// Check a Set value's length: shorter → "not enough data", longer → "too much data".
pub fn exact_len(data: &[u8], n: usize) -> Result<(), CipError> {
    match data.len().cmp(&n) {
        core::cmp::Ordering::Less => Err(CipError::new(status::NOT_ENOUGH_DATA)),
        core::cmp::Ordering::Greater => Err(CipError::new(status::TOO_MUCH_DATA)),
        core::cmp::Ordering::Equal => Ok(()),
    }
}

/// The Message Router (class 0x02): routes requests, exposes only its class revision.
pub fn message_router(req: &Request<'_>) -> Reply {
    match req.instance {
        0 => attribute_service(
            req,
            &[get(1)],
            |_| 1u16.to_le_bytes().to_vec(),
            |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
        ),
        1 => attribute_service(
            req,
            &[],
            |_| Vec::new(),
            |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
        ),
        _ => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
    }
}
