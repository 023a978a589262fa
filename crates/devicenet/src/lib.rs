//! A sans-IO DeviceNet stack.
//!
//! * [`wire`]: stateless decode/encode of identifiers, explicit messages, fragmentation,
//!   Allocate/Release, UCMM, duplicate MAC ID check and I/O fragments;
//! * [`link`]: the duplicate MAC ID check;
//! * [`fragment`]: acknowledged explicit and unacknowledged I/O fragmentation;
//! * [`objects`]: the CIP objects (Identity, Message Router, DeviceNet, Connection) and
//!   the [`Application`] hook for device classes and polled I/O data;
//! * [`ucmm`]: group 3 explicit connections opened and closed by any client;
//! * [`Slave`]: a UCMM-capable Predefined Master/Slave Connection Set server;
//! * [`Scanner`]: the master: allocate, poll, explicit requests, browse;
//! * [`eds`]: ODVA Electronic Data Sheets written from a device's object model.
//!
//! Both [`Slave`] and [`Scanner`] implement [`cantwin_can::Node`]: frames in, frames out,
//! time passed in by the caller.
//!
//! # Decisions
//!
//! Where the ODVA specification is not public or the EXP-CAN/DN-ADV manual is ambiguous,
//! the stack behaves as follows (each point is pinned by a test).
//!
//! * **Allocate/Release errors** (general status / additional code): allocated to another
//!   master 0x0C/0x01; choice zero, unsupported bits, I/O without explicit messaging, or an
//!   allocator MAC ID other than the sender's 0x20/0x02; already allocated or already
//!   released 0x0B/0x02; any other service on the group 2 only port 0x08/0x03. The
//!   additional codes are the specification's; the general codes pair them as vendor
//!   traces do.
//! * **Body formats**: Allocate answers 8/8 ([`SlaveConfig::allocate_format`]); the UCMM
//!   grants 8/8 or 8/16 (a 16/16 or 16/8 request gets 8/16). The card reaches drive
//!   parameters above 255 only with 8/16 (manual §3.4.2 note 1, "byte or word depending on
//!   the allocation").
//! * **UCMM**: group 3 only; server message IDs 0–4 (5 and 6 belong to the UCMM); instances
//!   from 6; at most 2 at once for the card, which has 3 explicit connections in all (manual
//!   §3.3.1). The open response carries the client's message ID as destination and the
//!   server's as source.
//! * **Expected packet rate** is rounded up to the timer resolution (10 ms by default) and
//!   the Set reply carries the value used; the watchdog is 4 × EPR. Explicit connections
//!   start at 2500 ms with action auto-delete; the polled connection goes to Timed Out and
//!   comes back with the Reset service (0x05) on its instance or a new allocation.
//! * **Fragmentation**: a fragment's acknowledge is awaited 1 s ([`fragment::ACK_TIMEOUT`]),
//!   the fragment is sent once more, then the transfer is abandoned; a gap in the count
//!   drops the message unacknowledged; a repeat of the last fragment is acknowledged again;
//!   more than the device's limit (32 bytes) is acknowledged with status 0x01. On group 2
//!   the acknowledge header carries the master's MAC ID, on group 3 the destination's (the
//!   Rockwell 1760-DNET trace: `41B: 80 C1 00`, `41C: 80 C0 00`).
//! * **Bus-off** counts in the DeviceNet object (attribute 4, cleared only by a Set of 0);
//!   with BOI = 0 the node stays off until reset, with BOI = 1 it re-runs the duplicate MAC
//!   ID check when the controller recovers.
//! * **Card specifics** stay with the device ([`Application::request`]): the Parameter
//!   object with instance = PAR (Get_Attribute_Single is 0x0E — the manual's "0hex" lost a
//!   digit — and an erroneous Set is not answered, [`Reply::Silent`]), and Drive Parameter
//!   Access 0x66. Its typed read is 0x34 as the service table says, not the 0x36 of example
//!   D-1: services pair Get/Set (0x32/0x33, 0x34/0x35), 0x36 appears nowhere else, and the
//!   example's reply tables are copies of B-2/B-3. Replies carry the request's code | 0x80
//!   (0xB2–0xB5) as every CIP reply does.
//!
//! Not implemented: the offline connection set's behaviour (group 4; the card does not
//! claim it — its messages decode with [`wire::CommFault`] and
//! [`wire::OfflineOwnership`]), bit-strobe, change-of-state, cyclic and multicast
//! poll connections, quick connect, deferred delete, Device Heartbeat and Shutdown.
//!
//! ```
//! use cantwin_can::{BitRate, Instant, Node, Outbox};
//! use cantwin_devicenet::{Application, Identity, MacId, Slave, SlaveConfig};
//!
//! struct Io;
//! impl Application for Io {
//!     fn poll_sizes(&self) -> (u16, u16) { (2, 2) }
//!     fn produce(&mut self, _now: Instant) -> Vec<u8> { vec![0x34, 0x12] }
//!     fn consume(&mut self, _data: &[u8], _now: Instant) {}
//! }
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let identity = Identity {
//!     vendor: 0x1234, device_type: 0x02, product_code: 1, revision: (1, 0),
//!     serial: 42, product_name: "demo".into(),
//! };
//! let mut slave = Slave::new(SlaveConfig::new(MacId::new(12)?, BitRate::R500K, identity), Io)?;
//! let mut out = Outbox::new();
//! slave.on_power_up(Instant::ZERO, &mut out);
//! // The first duplicate MAC ID check request: 0x407 | 12 << 3.
//! assert_eq!(out.frames()[0].to_string(), "467#0034122A000000");
//! assert_eq!(slave.next_deadline(), Some(Instant::from_nanos(1_000_000_000)));
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod eds;
pub mod fragment;
pub mod link;
pub mod objects;
pub mod scanner;
pub mod slave;
pub mod ucmm;
pub mod wire;

pub use objects::{Application, CipError, Identity, Reply, SlaveEvent};
pub use scanner::{Scanner, ScannerConfig, ScannerEvent};
pub use slave::{ConfigError, Led, NetworkStatus, Slave, SlaveConfig};
pub use wire::MacId;
