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
//! * [`Scanner`]: the master: allocate, poll, explicit requests, browse.
//!
//! Both [`Slave`] and [`Scanner`] implement [`cantwin_can::Node`]: frames in, frames out,
//! time passed in by the caller.
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
