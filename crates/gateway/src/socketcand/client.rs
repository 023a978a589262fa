//! A socketcand client in raw mode: attaches to a cantwin socketcand server or to a real
//! socketcand daemon, and is a [`BusPort`] like any other.

use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use cantwin_can::Frame;

use super::wire::{self, Framed, Framer, ServerMessage};
use crate::port::{BusConnector, BusPort, PortError, Received};
use crate::server::relock;

/// Why talking to a socketcand server failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The connection failed or broke.
    #[error("socketcand connection: {0}")]
    Io(#[from] io::Error),
    /// The server did not answer in time.
    #[error("socketcand server did not answer within {0:?}")]
    Timeout(Duration),
    /// The server closed the connection.
    #[error("socketcand server closed the connection")]
    Closed,
    /// The server answered an unexpected element during the handshake.
    #[error("socketcand handshake: expected {expected}, got {got:?}")]
    Handshake {
        /// What the handshake expected.
        expected: &'static str,
        /// What came instead.
        got: String,
    },
    /// The server refused a command (`< error … >`).
    #[error("socketcand server refused: {0}")]
    Refused(String),
}

impl From<ClientError> for PortError {
    fn from(e: ClientError) -> Self {
        match e {
            ClientError::Closed => PortError::Closed,
            e => PortError::Transport(e.to_string()),
        }
    }
}

struct Reader {
    stream: TcpStream,
    framer: Framer,
    buf: Box<[u8; 4096]>,
    pos: usize,
    len: usize,
}

enum Next {
    Element(Result<ServerMessage, wire::WireError>),
    TimedOut,
}

impl Reader {
    /// The next element, waiting until `deadline`.
    fn next(&mut self, deadline: Instant) -> Result<Next, ClientError> {
        loop {
            while self.pos < self.len {
                let b = self.buf[self.pos];
                self.pos += 1;
                match self.framer.push(b) {
                    Some(Framed::Element(e)) => {
                        return Ok(Next::Element(wire::parse_server_message(e)));
                    }
                    // An element longer than the protocol allows: skipped by the framer.
                    Some(Framed::TooLong) | None => {}
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(Next::TimedOut);
            }
            // A zero read timeout means "block forever" to the OS: never pass one.
            self.stream
                .set_read_timeout(Some(left.max(Duration::from_micros(1))))?;
            match self.stream.read(&mut self.buf[..]) {
                Ok(0) => return Err(ClientError::Closed),
                Ok(n) => {
                    self.pos = 0;
                    self.len = n;
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Ok(Next::TimedOut);
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
        }
    }

    fn expect_ok(&mut self, what: &'static str, timeout: Duration) -> Result<(), ClientError> {
        let deadline = Instant::now() + timeout;
        match self.next(deadline)? {
            Next::TimedOut => Err(ClientError::Timeout(timeout)),
            Next::Element(Ok(ServerMessage::Ok)) => Ok(()),
            Next::Element(Ok(ServerMessage::Error(text))) => Err(ClientError::Refused(text)),
            Next::Element(other) => Err(ClientError::Handshake {
                expected: what,
                got: format!("{other:?}"),
            }),
        }
    }
}

/// A raw-mode socketcand connection to one bus.
///
/// ```no_run
/// use cantwin_can::Frame;
/// use cantwin_gateway::BusPort;
/// use cantwin_gateway::socketcand::Client;
/// use std::time::Duration;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let bus = Client::connect("127.0.0.1:29536".parse()?, "vcan0", Duration::from_secs(2))?;
/// bus.send(Frame::std(0x000, &[0x01, 0x00])?)?;
/// if let Some(rx) = bus.recv_timeout(Duration::from_millis(100))? {
///     println!("{}", rx.frame);
/// }
/// # Ok(())
/// # }
/// ```
///
/// A remote frame is sent as a `send` with its DLC and no data bytes: a cantwin server takes
/// it as a remote frame, a real socketcand daemon rejects it (silently). Remote frames from the
/// bus never reach a raw-mode client. For remote frames use the slcan gateway.
pub struct Client {
    writer: Mutex<TcpStream>,
    reader: Mutex<Reader>,
    server_errors: AtomicU64,
    last_error: Mutex<Option<String>>,
}

impl Client {
    /// Connect to `addr`, open bus `channel` and switch to raw mode, each step answered
    /// within `timeout`.
    pub fn connect(
        addr: SocketAddr,
        channel: &str,
        timeout: Duration,
    ) -> Result<Self, ClientError> {
        let stream = TcpStream::connect_timeout(&addr, timeout)?;
        stream.set_nodelay(true)?;
        stream.set_write_timeout(Some(timeout))?;
        let mut reader = Reader {
            stream: stream.try_clone()?,
            framer: Framer::new(wire::MAX_ELEMENT),
            buf: Box::new([0; 4096]),
            pos: 0,
            len: 0,
        };
        let mut writer = stream;
        match reader.next(Instant::now() + timeout)? {
            Next::Element(Ok(ServerMessage::Hi)) => {}
            Next::TimedOut => return Err(ClientError::Timeout(timeout)),
            Next::Element(other) => {
                return Err(ClientError::Handshake {
                    expected: "< hi >",
                    got: format!("{other:?}"),
                });
            }
        }
        let mut open = Vec::new();
        wire::write_open(&mut open, channel);
        writer.write_all(&open)?;
        reader.expect_ok("< ok > to open", timeout)?;
        writer.write_all(b"< rawmode >")?;
        reader.expect_ok("< ok > to rawmode", timeout)?;
        Ok(Client {
            writer: Mutex::new(writer),
            reader: Mutex::new(reader),
            server_errors: AtomicU64::new(0),
            last_error: Mutex::new(None),
        })
    }

    /// How many `< error … >` elements the server sent since the handshake.
    pub fn server_errors(&self) -> u64 {
        self.server_errors.load(Ordering::Relaxed)
    }

    /// The text of the last `< error … >` the server sent.
    pub fn last_server_error(&self) -> Option<String> {
        relock(&self.last_error).clone()
    }
}

/// How long a closing client waits for the server to take its last frames.
const CLOSE_LINGER: Duration = Duration::from_millis(500);

impl Drop for Client {
    /// Closes so that the frames sent last reach the bus. Closing a socket with unread
    /// data in its receive buffer (frames the bus carried meanwhile) makes the OS reset
    /// the connection, and a reset discards what the server has not read yet: the last
    /// SDO segment of a transfer, say, which leaves the device's SDO server waiting in the
    /// middle of it. So: half-close, then read until the server closes its side, at most
    /// `CLOSE_LINGER`.
    fn drop(&mut self) {
        let writer = relock(&self.writer);
        if writer.shutdown(std::net::Shutdown::Write).is_err() {
            return;
        }
        let reader = relock(&self.reader);
        let deadline = Instant::now() + CLOSE_LINGER;
        let mut sink = [0u8; 4096];
        let mut stream = &reader.stream;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
                return;
            }
            match stream.read(&mut sink) {
                Ok(0) => return,
                Ok(_) => {}
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => return,
            }
        }
    }
}

impl BusPort for Client {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        let mut out = Vec::with_capacity(40);
        wire::write_send(&mut out, &frame);
        relock(&self.writer)
            .write_all(&out)
            .map_err(|e| PortError::from(ClientError::Io(e)))
    }

    fn recv_timeout(&self, timeout: Duration) -> Result<Option<Received>, PortError> {
        let deadline = Instant::now() + timeout;
        let mut reader = relock(&self.reader);
        loop {
            match reader.next(deadline)? {
                Next::TimedOut => return Ok(None),
                Next::Element(Ok(ServerMessage::Frame { frame, timestamp })) => {
                    return Ok(Some(Received { frame, timestamp }));
                }
                Next::Element(Ok(ServerMessage::Error(text))) => {
                    self.server_errors.fetch_add(1, Ordering::Relaxed);
                    *relock(&self.last_error) = Some(text);
                }
                // Echoes, statistics and elements that do not parse carry no frame.
                Next::Element(_) => {}
            }
        }
    }

    fn overflows(&self) -> u64 {
        // The socket is the buffer; a server drops a client that reads too slowly.
        0
    }
}

/// A socketcand server seen as a [`BusConnector`]: each `open` is a new connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Remote {
    /// The server's address.
    pub addr: SocketAddr,
    /// Connect and handshake timeout.
    pub timeout: Duration,
}

impl BusConnector for Remote {
    fn open(&self, channel: &str, _rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        match Client::connect(self.addr, channel, self.timeout) {
            Ok(c) => Ok(Box::new(c)),
            Err(ClientError::Refused(_)) => Err(PortError::UnknownChannel(channel.to_owned())),
            Err(e) => Err(e.into()),
        }
    }
}
