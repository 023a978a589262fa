//! The socketcand protocol (linux-can/socketcand), raw mode: a [`Server`] that puts cantwin
//! buses behind it, and a [`Client`] that attaches to such a server or to a real socketcand
//! daemon.

mod client;
mod server;
pub mod wire;

pub use client::{Client, ClientError, Remote};
pub use server::{DEFAULT_PORT, Server};
