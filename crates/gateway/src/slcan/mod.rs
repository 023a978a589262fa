//! slcan (Lawicel CANUSB ASCII protocol) over TCP: a [`Server`] that looks like a serial CAN
//! adapter on a socket, for tools that need remote frames (python-can's `slcan` interface with
//! a `socket://HOST:PORT` channel); and a [`Client`] that opens such a server, or a real
//! adapter behind a TCP-to-serial bridge, as a bus port.

mod client;
mod server;
pub mod wire;

pub use client::{Client, ClientError, Remote, bitrate_code};
pub use server::Server;
