//! Layer setting services (CiA 305): the node-ID and bit rate of a node set over the bus
//! by an LSS master, the node found by its LSS address (0x1018 sub 1–4).
//!
//! * [`wire`]: the frames on 0x7E5 (master → slave) and 0x7E4 (slave → master);
//! * [`slave`]: the slave's state machine ([`Slave`]), which a device puts in front of its
//!   CiA 301 stack;
//! * [`master`]: the master ([`Master`]), one service at a time, fastscan included;
//! * [`store`]: where a slave keeps what store configuration stores.
//!
//! ```
//! use cantwin_can::{BitRate, Instant, Node, Outbox};
//! use cantwin_canopen::lss::{Address, Master, MemoryStore, Mode, Outcome, Service, Slave};
//! use cantwin_can::Duration;
//!
//! let address = Address { vendor: 1, product: 2, revision: 3, serial: 4 };
//! let mut slave = Slave::new(address, 0xFF, BitRate::R500K, Box::new(MemoryStore::new()));
//! let mut master = Master::new(Duration::from_millis(100));
//! let (mut to_slave, mut to_master) = (Outbox::new(), Outbox::new());
//! master.start(Service::SwitchGlobal(Mode::Configuration), Instant::ZERO, &mut to_slave).unwrap();
//! master.poll();
//! master.start(Service::ConfigureNodeId(42), Instant::ZERO, &mut to_slave).unwrap();
//! for f in to_slave.drain() {
//!     slave.on_frame(&f, Instant::ZERO, &mut to_master);
//! }
//! for f in to_master.drain() {
//!     master.on_frame(&f, Instant::ZERO, &mut to_slave);
//! }
//! assert_eq!(master.poll(), Some(Outcome::Done));
//! assert_eq!(slave.pending_node_id(), 42);
//! ```

pub mod master;
pub mod slave;
pub mod store;
pub mod wire;

pub use master::{Busy, Master, Outcome, Scan, Service};
pub use slave::{Slave, SlaveEvent};
pub use store::{FileStore, MemoryStore, Store, Stored};
pub use wire::{Address, IdentifyField, Mode, Part, Request, Response, UNCONFIGURED};

#[cfg(test)]
mod tests;
