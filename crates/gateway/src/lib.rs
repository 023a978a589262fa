//! Gateways between a cantwin bus and the tools outside it.
//!
//! * [`socketcand`]: a socketcand server (raw and broadcast-manager modes) in front of cantwin
//!   buses, for python-can, python-canopen and anything else that speaks the linux-can
//!   socketcand protocol; and a client that attaches to such a server or to a real socketcand
//!   daemon.
//! * [`slcan`]: a Lawicel/slcan server over TCP, for tools that need remote frames
//!   (python-can's `slcan` interface with a `socket://` channel).
//! * `socketcan` (cargo feature `socketcan`, Linux): real CAN interfaces as a
//!   [`BusConnector`].
//! * [`paced`]: the buses of a paced virtual-bus simulation as a [`BusConnector`].
//!
//! Servers see buses only through [`BusConnector`] and [`BusPort`], so the same server runs on
//! the virtual bus ([`paced::PacedBus`]), on the in-memory [`memory::MemoryBus`] or on
//! hardware. They bind to
//! loopback unless told otherwise ([`Limits::allow_remote`]), bound every buffer
//! ([`Limits`]), answer malformed commands with the protocol's error reply, and drop a client
//! that cannot keep up instead of ever making the bus wait.
//!
//! ```
//! use cantwin_can::Frame;
//! use cantwin_gateway::memory::MemoryBus;
//! use cantwin_gateway::socketcand::{Client, Server};
//! use cantwin_gateway::{BusConnector, BusPort, Limits};
//! use std::sync::Arc;
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let bus = MemoryBus::new(["vcan0"]);
//! let server = Server::bind("127.0.0.1:0".parse()?, Arc::new(bus.clone()), Limits::default())?;
//! let client = Client::connect(server.local_addr(), "vcan0", Duration::from_secs(5))?;
//! let local = bus.open("vcan0", 16)?;
//! client.send(Frame::std(0x601, &[0x40, 0x00, 0x10, 0x00])?)?;
//! let rx = local.recv_timeout(Duration::from_secs(5))?.ok_or("no frame")?;
//! assert_eq!(rx.frame, Frame::std(0x601, &[0x40, 0x00, 0x10, 0x00])?);
//! server.shutdown();
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

#[doc(hidden)]
pub mod fuzz;
pub mod memory;
pub mod paced;
mod port;
mod server;
pub mod slcan;
#[cfg(feature = "socketcan")]
pub mod socketcan;
pub mod socketcand;

pub use port::{BusConnector, BusPort, PortError, Received};
pub use server::{Limits, ServerStats};

use std::net::SocketAddr;

/// Why a gateway could not start.
#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    /// Binding to an address other than loopback without [`Limits::allow_remote`].
    #[error("refusing to listen on {0}: not a loopback address and remote access not allowed")]
    RemoteBindRefused(SocketAddr),
    /// The socket could not be set up.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}
