//! The slcan server: each client is an adapter on one bus, a node on it while open.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use super::wire::{self, Command};
use crate::GatewayError;
use crate::port::{BusConnector, PortError, Received};
use crate::server::{Limits, Link, Protocol, ServerStats, Session, TcpServer};

/// The version the server reports to `V`: hardware 1, software 1.
const VERSION: &[u8] = b"V0101\r";
/// The serial number the server reports to `N`.
const SERIAL: &[u8] = b"NCTW1\r";
/// The status flags reported to `F`: no error condition.
const STATUS: &[u8] = b"F00\r";

/// An slcan server over TCP in front of one bus.
///
/// Each client behaves as a Lawicel adapter: `O` attaches it to the bus as a node (answer
/// `\r`), `C` detaches it; while open it receives every frame on the bus except its own as
/// `t`/`T`/`r`/`R` records, and its `t`/`T`/`r`/`R` records are transmitted (answer `z\r` or
/// `Z\r`). `L` opens listen-only: transmissions are refused. Bit rate commands (`Sn`,
/// `sxxyy`) are accepted while closed and do not change the bus, whose bit rate is its own.
/// `V`, `N` and `F` answer a version, a serial number and empty status flags; `Z0` is
/// accepted, `Z1` (timestamps) refused. Errors and commands out of place (`O` while open,
/// `S` while open, a frame while closed) are answered with BEL, as the adapter does.
pub struct Server {
    inner: TcpServer<Slcan>,
}

impl Server {
    /// Listen on `addr` (port 0 picks a free port); clients attach to bus `channel` of
    /// `connector`.
    ///
    /// An address other than loopback is refused unless [`Limits::allow_remote`] is set.
    pub fn bind(
        addr: SocketAddr,
        connector: Arc<dyn BusConnector>,
        channel: &str,
        limits: Limits,
    ) -> Result<Server, GatewayError> {
        let protocol = Slcan {
            channel: channel.to_owned(),
            max_line: limits.max_line,
        };
        Ok(Server {
            inner: TcpServer::bind(addr, protocol, connector, limits)?,
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

    /// Stop accepting, disconnect every client and detach them from the bus.
    pub fn shutdown(mut self) {
        self.inner.shutdown();
    }
}

pub(crate) struct Slcan {
    channel: String,
    max_line: usize,
}

impl Protocol for Slcan {
    const NAME: &'static str = "slcan";
    type Session = SlSession;

    fn session(&self) -> SlSession {
        SlSession {
            channel: self.channel.clone(),
            max_line: self.max_line,
            line: Vec::new(),
            skipping: false,
            listen_only: false,
        }
    }

    fn greeting(&self) -> Option<&'static [u8]> {
        None
    }

    fn refusal(&self) -> &'static [u8] {
        wire::ERROR
    }

    fn write_frame(&self, rx: &Received, out: &mut Vec<u8>) -> bool {
        wire::write_frame(out, &rx.frame);
        true
    }
}

pub(crate) struct SlSession {
    channel: String,
    max_line: usize,
    line: Vec<u8>,
    skipping: bool,
    listen_only: bool,
}

impl SlSession {
    fn on_line(&mut self, link: &mut Link<'_>) -> io::Result<()> {
        let cmd = match wire::parse_command(&self.line) {
            Ok(c) => c,
            Err(_) => return link.error(wire::ERROR),
        };
        let open = link.is_open();
        match cmd {
            Command::Empty => link.reply(wire::OK),
            Command::Open | Command::ListenOnly if open => {
                // Restart the pause before the first frame: python-can sends `O` twice and
                // frames streamed between the two were seen to get lost.
                link.forward(true);
                link.error(wire::ERROR)
            }
            Command::Open | Command::ListenOnly => match link.open(&self.channel) {
                Ok(()) => {
                    self.listen_only = cmd == Command::ListenOnly;
                    // Frames reaching the port from now on are streamed, after a pause.
                    link.forward(true);
                    link.reply(wire::OK)
                }
                Err(_) => link.error(wire::ERROR),
            },
            Command::Close if open => {
                link.close();
                link.reply(wire::OK)
            }
            Command::Bitrate(_) | Command::Btr(..) if !open => link.reply(wire::OK),
            Command::Close | Command::Bitrate(_) | Command::Btr(..) => link.error(wire::ERROR),
            Command::Version => link.reply(VERSION),
            Command::Serial => link.reply(SERIAL),
            Command::Status => link.reply(STATUS),
            Command::Timestamps(false) => link.reply(wire::OK),
            Command::Timestamps(true) => link.error(wire::ERROR),
            Command::Transmit(_) if !open || self.listen_only => link.error(wire::ERROR),
            Command::Transmit(frame) => match link.send(frame) {
                Ok(()) if frame.is_extended() => link.reply(wire::SENT_EXTENDED),
                Ok(()) => link.reply(wire::SENT_STANDARD),
                Err(PortError::Closed) => {
                    Err(io::Error::new(io::ErrorKind::BrokenPipe, PortError::Closed))
                }
                Err(_) => link.error(wire::ERROR),
            },
        }
    }
}

impl Session for SlSession {
    fn on_bytes(&mut self, bytes: &[u8], link: &mut Link<'_>) -> io::Result<()> {
        for &b in bytes {
            match b {
                b'\r' => {
                    if self.skipping {
                        self.skipping = false;
                        link.error(wire::ERROR)?;
                    } else {
                        self.on_line(link)?;
                    }
                    self.line.clear();
                }
                // Some hosts end lines with `\r\n`: the line feed carries nothing.
                b'\n' => {}
                _ if self.skipping => {}
                _ if self.line.len() >= self.max_line => {
                    self.line.clear();
                    self.skipping = true;
                }
                _ => self.line.push(b),
            }
        }
        Ok(())
    }
}
