//! slcan (Lawicel CANUSB ASCII protocol) over TCP: a [`Server`] that looks like a serial CAN
//! adapter on a socket, for tools that need remote frames (python-can's `slcan` interface with
//! a `socket://HOST:PORT` channel).

mod server;
pub mod wire;

pub use server::Server;
