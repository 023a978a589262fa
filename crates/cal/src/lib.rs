//! A sans-IO CAL CMS stack (CiA DS 201–207, CAN Application Layer): basic and multiplexed
//! variables and controlled events, in the server and the client (master) role.
//!
//! * [`wire`]: stateless encode/decode of the CMS frames;
//! * [`server`]: [`CmsServer`], which serves indications through an [`Application`] and
//!   keeps the enable state of controlled events;
//! * [`client`]: [`CmsClient`], the CAL master: confirmed requests with timeouts,
//!   confirmations, error responses and event notifications as [`ClientEvent`]s.
//!
//! # The services (DS 202-1, DS 202-2)
//!
//! * **Read/Write basic variable** (DS 202-2 p. 6): a confirmed service on two COBs, the
//!   request COB (client → server) and the response COB (server → client). DS 202-2 also
//!   allows a read on "one remote COB": a remote frame on the response COB, answered by a
//!   data frame on it; the server answers both forms.
//! * **Read/Write multiplexed variable**: the same two COBs shared by a set of variables;
//!   every request and response names its variable with a multiplexor.
//! * **Controlled event** (DS 202-2 p. 21): a client enables or disables notification with a
//!   confirmed control service; while enabled, the server notifies (unconfirmed) on the
//!   response COB.
//!
//! COB-IDs are CAN identifiers (11 bit) as CAL uses them; user objects live in 0–1760
//! ([`CAL_USER_COB_MAX`]), the identifiers above belong to NMT, DBT and LMT.
//!
//! # Byte layout
//!
//! The public DS 202-2 text describes the services but its bit tables are not available to
//! this project; the layout follows the diagrams of the only device we twin that uses CMS
//! (TDE MACNO OPEN DRIVE application 003, §3.1–§3.3), and where the scan of a diagram is
//! unreadable, the choice that keeps every frame self-describing. See [`wire`] for the
//! table. In short: one control byte, then the data; bit 7 of a variable's control byte is
//! `c` (0 write, 1 read) in a request and `r` (0 success, 1 failure) in a response; a
//! multiplexed variable puts its multiplexor into bits 6–0; an event's control byte has the
//! service code `c` in bits 7–5 (0 notify, 1 control), the requested or actual state in
//! bit 4 and the result `r` in bit 3. Error data follow a failure flag; what they mean is
//! the application's.
//!
//! ```
//! use cantwin_cal::{
//!     Application, ClientEvent, ClientObject, CmsClient, CmsServer, CobPair, Mux, ObjectIndex,
//!     ObjectKind, Payload, ServerObject,
//! };
//! use cantwin_can::{Instant, Outbox};
//!
//! /// One multiplexed variable set with a single variable, 0x05.
//! struct Params(u16);
//! impl Application for Params {
//!     fn read_basic(&mut self, _: ObjectIndex, _: Instant) -> Result<Payload, Payload> {
//!         Err(Payload::u16(0))
//!     }
//!     fn write_basic(&mut self, _: ObjectIndex, _: &[u8], _: Instant) -> Result<Payload, Payload> {
//!         Err(Payload::u16(0))
//!     }
//!     fn read_mux(&mut self, _: ObjectIndex, mux: Mux, _: Instant) -> Result<Payload, Payload> {
//!         if mux.raw() == 5 { Ok(Payload::u16(self.0)) } else { Err(Payload::u16(1)) }
//!     }
//!     fn write_mux(&mut self, _: ObjectIndex, mux: Mux, d: &[u8], _: Instant) -> Result<Payload, Payload> {
//!         match (mux.raw(), d) {
//!             (5, [lo, hi]) => { self.0 = u16::from_le_bytes([*lo, *hi]); Ok(Payload::u16(self.0)) }
//!             (5, _) => Err(Payload::u16(2)),
//!             _ => Err(Payload::u16(1)),
//!         }
//!     }
//! }
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let cobs = CobPair::new(1100, 1099)?;
//! let mut server = CmsServer::new(vec![ServerObject { kind: ObjectKind::MultiplexedVariable, cobs }])?;
//! let mut client = CmsClient::new(vec![ClientObject::new(ObjectKind::MultiplexedVariable, cobs)]);
//! let mut app = Params(0);
//! let (mut to_server, mut to_client) = (Outbox::new(), Outbox::new());
//! let mux = Mux::new(5).ok_or("mux")?;
//! client.write_mux(ObjectIndex(0), mux, &[0x88, 0x13], Instant::ZERO, &mut to_server)?;
//! assert_eq!(to_server.frames()[0].to_string(), "44C#058813");
//! for f in to_server.drain() {
//!     server.handle(&f, &mut app, Instant::ZERO, &mut to_client);
//! }
//! assert_eq!(to_client.frames()[0].to_string(), "44B#058813");
//! for f in to_client.drain() {
//!     client.handle(&f, Instant::ZERO);
//! }
//! assert!(matches!(client.poll_event(), Some(ClientEvent::Confirmed { data, .. }) if data.as_u16() == Some(5000)));
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod client;
pub mod server;
pub mod wire;

use cantwin_can::Id;

pub use client::{ClientError, ClientEvent, ClientObject, CmsClient, Request};
pub use server::{Application, CmsServer, DuplicateCob, ObjectIndex, ServerObject};
pub use wire::{Mux, Payload, WireError};

/// The highest COB-ID of user objects in CAL (identifiers 1761–2031 are reserved for the
/// NMT, DBT and LMT services); the OPEN DRIVE's P180–P187 range is 0–1760 too.
pub const CAL_USER_COB_MAX: u16 = 1760;

/// The kinds of CMS object this stack implements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObjectKind {
    /// A Read/Write basic variable.
    BasicVariable,
    /// A Read/Write multiplexed variable set.
    MultiplexedVariable,
    /// A controlled event.
    ControlledEvent,
}

/// A COB-ID outside 0–1760.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("COB-ID {0} is outside the CAL user range 0-1760")]
pub struct CobIdError(pub u16);

/// The two COBs of a confirmed CMS object, seen from the server.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CobPair {
    /// Client → server (the server's receive box).
    pub request: Id,
    /// Server → client (the server's transmit box).
    pub response: Id,
}

impl CobPair {
    /// The pair from two COB-IDs (0–1760), taken as 11-bit CAN identifiers.
    pub fn new(request: u16, response: u16) -> Result<CobPair, CobIdError> {
        Ok(CobPair {
            request: cob_id(request)?,
            response: cob_id(response)?,
        })
    }
}

/// A CAL COB-ID (0–1760) as a CAN identifier.
pub fn cob_id(raw: u16) -> Result<Id, CobIdError> {
    if raw > CAL_USER_COB_MAX {
        return Err(CobIdError(raw));
    }
    Id::standard(raw).map_err(|_| CobIdError(raw))
}
