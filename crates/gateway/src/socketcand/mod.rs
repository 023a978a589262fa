//! The socketcand protocol (linux-can/socketcand): a [`Server`] that puts cantwin buses behind
//! it, in raw mode and in the daemon's default broadcast-manager mode (subscriptions, content
//! filters, throttling, cyclic transmission), and a [`Client`] (raw mode) that attaches to
//! such a server or to a real socketcand daemon.

mod bcm;
mod client;
mod server;
pub mod wire;

pub use client::{Client, ClientError, Remote};
pub use server::{DEFAULT_PORT, Server};
