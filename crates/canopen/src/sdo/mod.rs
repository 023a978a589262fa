//! Service data objects (CiA 301 §7.2.4): confirmed access to the object dictionary.
//!
//! * [`wire`]: stateless codec of SDO frames;
//! * [`server`]: one SDO server channel ([`SdoServer`]);
//! * [`crc`]: the CRC of block transfers.

pub mod crc;
pub mod server;
pub mod wire;

pub use server::{SdoCapabilities, SdoServer};
