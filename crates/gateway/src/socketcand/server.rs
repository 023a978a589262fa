//! The socketcand server: each client is a node on the bus it opens.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use super::wire::{self, Command, Framed, Framer, WireError};
use crate::GatewayError;
use crate::port::{BusConnector, PortError, Received};
use crate::server::{Limits, Link, Protocol, ServerStats, Session, TcpServer};

/// socketcand's default TCP port.
pub const DEFAULT_PORT: u16 = 29536;

/// A socketcand server (raw mode) in front of the buses of a [`BusConnector`]: one channel name
/// per bus, any number of clients per bus up to [`Limits::max_clients`].
///
/// Each client that opens a bus is a node on it: its frames arbitrate and take bus time like
/// any other node's, and in raw mode it receives every frame on the bus except its own.
///
/// What the server accepts, beyond the daemon's raw mode, is listed in [`wire`]: the remote
/// frame form python-can writes, and error replies for every malformed command (the daemon
/// logs a bad `send` silently; here it gets `< error syntax error in send command >`).
/// Broadcast-manager, control and ISO-TP commands get `< error command not supported >`.
pub struct Server {
    inner: TcpServer<Socketcand>,
}

impl Server {
    /// Listen on `addr` (port 0 picks a free port) for clients of the buses of `connector`.
    ///
    /// An address other than loopback is refused unless [`Limits::allow_remote`] is set.
    pub fn bind(
        addr: SocketAddr,
        connector: Arc<dyn BusConnector>,
        limits: Limits,
    ) -> Result<Server, GatewayError> {
        let max_line = limits.max_line.min(wire::MAX_ELEMENT);
        Ok(Server {
            inner: TcpServer::bind(addr, Socketcand { max_line }, connector, limits)?,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.inner.local_addr()
    }

    /// The server's counters.
    pub fn stats(&self) -> ServerStats {
        self.inner.stats()
    }

    /// Wait until at most `clients` clients are connected; `false` if `timeout` passed first.
    pub fn wait_clients(&self, clients: usize, timeout: Duration) -> bool {
        self.inner.wait_clients(clients, timeout)
    }

    /// Stop accepting, disconnect every client and detach them from their buses.
    pub fn shutdown(mut self) {
        self.inner.shutdown();
    }
}

pub(crate) struct Socketcand {
    max_line: usize,
}

impl Protocol for Socketcand {
    type Session = ScSession;

    fn session(&self) -> ScSession {
        ScSession {
            framer: Framer::new(self.max_line),
            state: State::NoBus,
        }
    }

    fn greeting(&self) -> Option<&'static [u8]> {
        Some(wire::HI)
    }

    fn refusal(&self) -> &'static [u8] {
        b"< error too many clients >"
    }

    fn write_frame(&self, rx: &Received, out: &mut Vec<u8>) -> bool {
        wire::write_frame(out, &rx.frame, rx.timestamp)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    NoBus,
    Bcm,
    Raw,
}

pub(crate) struct ScSession {
    framer: Framer,
    state: State,
}

fn error(link: &mut Link<'_>, text: &str) -> io::Result<()> {
    let mut out = Vec::with_capacity(16 + text.len());
    wire::write_error(&mut out, text);
    link.error(&out)
}

impl ScSession {
    fn on_element(&mut self, element: &[u8], link: &mut Link<'_>) -> io::Result<()> {
        let cmd = match wire::parse_command(element) {
            Ok(c) => c,
            Err(WireError::Malformed | WireError::Empty | WireError::UnknownCommand) => {
                return error(link, "unknown command");
            }
            Err(WireError::Syntax(what)) => {
                return error(link, &format!("syntax error in {what} command"));
            }
            Err(WireError::Id(_)) => return error(link, "identifier out of range"),
            Err(WireError::Frame(_)) => return error(link, "invalid frame"),
        };
        match (cmd, self.state) {
            (Command::Echo, _) => link.reply(b"< echo >"),
            (Command::Open(_), State::Bcm | State::Raw) => error(link, "bus already open"),
            (Command::Open(name), State::NoBus) => match link.open(&name) {
                Ok(()) => {
                    self.state = State::Bcm;
                    link.reply(wire::OK)
                }
                Err(_) => error(link, "could not open bus"),
            },
            (Command::RawMode | Command::BcmMode | Command::Send(_), State::NoBus) => {
                error(link, "no bus open")
            }
            (Command::RawMode, _) => {
                self.state = State::Raw;
                // The stream starts with the frames that reach the bus port from now on, so
                // that a client may act on the bus as soon as it reads `< ok >`; the first
                // frame is written only after a pause, so the `< ok >` is read alone.
                link.forward(true);
                link.reply(wire::OK)
            }
            (Command::BcmMode, _) => {
                self.state = State::Bcm;
                link.forward(false);
                link.reply(wire::OK)
            }
            (Command::Send(frame), _) => match link.send(frame) {
                Ok(()) => Ok(()),
                Err(PortError::TxQueueFull) => error(link, "transmit queue full"),
                Err(PortError::Frame(_)) => error(link, "invalid frame"),
                // The bus is gone: end the session as the daemon does when its socket fails.
                Err(e) => Err(io::Error::new(io::ErrorKind::BrokenPipe, e)),
            },
            (Command::ControlMode | Command::IsoTpMode | Command::Other(_), _) => {
                error(link, "command not supported")
            }
        }
    }
}

impl Session for ScSession {
    fn on_bytes(&mut self, bytes: &[u8], link: &mut Link<'_>) -> io::Result<()> {
        for &b in bytes {
            match self.framer.push(b) {
                None => {}
                Some(Framed::TooLong) => error(link, "command too long")?,
                Some(Framed::Element(e)) => {
                    // The framer's buffer is reused; the command is short, copy it out.
                    let element = e.to_vec();
                    self.on_element(&element, link)?;
                }
            }
        }
        Ok(())
    }
}
