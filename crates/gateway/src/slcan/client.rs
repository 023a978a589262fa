//! An slcan client over TCP: attaches to a cantwin slcan server, or to a Lawicel adapter
//! behind a TCP-to-serial bridge, and is a [`BusPort`] like any other.
//!
//! The adapter answers every command in the order it got them: `\r` for success, BEL for an
//! error, `z\r`/`Z\r` for a queued frame. Received frames arrive in the same stream, between
//! those answers. The client therefore does not wait for the answer to a frame it sends (a
//! thread blocked in [`BusPort::recv_timeout`] reads the stream meanwhile); it counts the
//! answers as they come by ([`Client::tx_acknowledged`], [`Client::tx_refused`]).

use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime};

use cantwin_can::{BitRate, Frame};

use super::wire;
use crate::port::{BusConnector, BusPort, PortError, Received};
use crate::server::relock;

/// Why talking to an slcan adapter failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The connection failed or broke.
    #[error("slcan connection: {0}")]
    Io(#[from] io::Error),
    /// The adapter did not answer a command in time.
    #[error("slcan adapter did not answer `{command}` within {timeout:?}")]
    Timeout {
        /// The command left unanswered.
        command: &'static str,
        /// How long the client waited.
        timeout: Duration,
    },
    /// The adapter closed the connection.
    #[error("slcan adapter closed the connection")]
    Closed,
    /// The adapter answered a command with BEL.
    #[error("slcan adapter refused `{0}`")]
    Refused(&'static str),
    /// The adapter answered a command with a record that answers no command the client sent.
    #[error("slcan adapter answered `{command}` with {got:?}")]
    Unexpected {
        /// The command sent.
        command: &'static str,
        /// The record that came instead of `\r` or BEL.
        got: String,
    },
}

impl From<ClientError> for PortError {
    fn from(e: ClientError) -> Self {
        match e {
            ClientError::Closed => PortError::Closed,
            e => PortError::Transport(e.to_string()),
        }
    }
}

/// The Lawicel `Sn` code of a bit rate: `S0` = 10 kbit/s … `S8` = 1 Mbit/s (the CANUSB
/// manual's command list; 83.3 kbit/s, `S9`, is not a CANopen rate and has no [`BitRate`]).
pub fn bitrate_code(rate: BitRate) -> u8 {
    match rate {
        BitRate::R10K => 0,
        BitRate::R20K => 1,
        BitRate::R50K => 2,
        BitRate::R100K => 3,
        BitRate::R125K => 4,
        BitRate::R250K => 5,
        BitRate::R500K => 6,
        BitRate::R800K => 7,
        BitRate::R1M => 8,
    }
}

/// The longest record the client keeps: `T`, 8 identifier digits, the DLC, 16 data digits
/// and a 4-digit timestamp are 30 bytes; anything longer is not a record and is skipped.
const MAX_RECORD: usize = 64;

/// One thing the adapter sent.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Record {
    /// `\r`: a command succeeded.
    Ok,
    /// BEL: a command failed.
    Error,
    /// `z\r` or `Z\r`: a frame was queued for transmission.
    Sent,
    /// A received frame.
    Frame(Frame),
    /// A line that is none of these (a version or status answer, or a malformed record).
    Other(Vec<u8>),
}

/// A received frame record, with the adapter's 4-digit millisecond timestamp (`Z1`) taken
/// off if it carries one: the record's length says so, since the DLC fixes the rest.
fn parse_received(line: &[u8]) -> Option<Frame> {
    let (&kind, rest) = line.split_first()?;
    let id_len = match kind {
        b't' | b'r' => 3,
        b'T' | b'R' => 8,
        _ => return None,
    };
    let dlc = match rest.get(id_len)? {
        d @ b'0'..=b'8' => usize::from(d - b'0'),
        _ => return None,
    };
    let data_len = if kind == b'r' || kind == b'R' {
        0
    } else {
        2 * dlc
    };
    let bare = 1 + id_len + 1 + data_len;
    let record = match line.len() {
        n if n == bare => line,
        n if n == bare + 4 => &line[..bare],
        _ => return None,
    };
    wire::parse_frame(record).ok()
}

fn classify(line: &[u8]) -> Record {
    match line {
        b"" => Record::Ok,
        b"z" | b"Z" => Record::Sent,
        _ => match parse_received(line) {
            Some(frame) => Record::Frame(frame),
            None => Record::Other(line.to_vec()),
        },
    }
}

struct Reader {
    stream: TcpStream,
    line: Vec<u8>,
    /// Inside a line longer than [`MAX_RECORD`], until its `\r`.
    skipping: bool,
    buf: Box<[u8; 4096]>,
    pos: usize,
    len: usize,
}

impl Reader {
    /// The record a byte completes, if it completes one.
    fn push(&mut self, b: u8) -> Option<Record> {
        match b {
            b'\x07' => {
                self.line.clear();
                self.skipping = false;
                Some(Record::Error)
            }
            b'\r' if self.skipping => {
                self.skipping = false;
                Some(Record::Other(Vec::new()))
            }
            b'\r' => {
                let record = classify(&self.line);
                self.line.clear();
                Some(record)
            }
            // A bridge may add line feeds; they carry nothing.
            b'\n' => None,
            _ if self.skipping => None,
            _ if self.line.len() >= MAX_RECORD => {
                self.line.clear();
                self.skipping = true;
                None
            }
            _ => {
                self.line.push(b);
                None
            }
        }
    }

    /// The next record, waiting until `deadline`; `None` when it passed.
    fn next(&mut self, deadline: Instant) -> Result<Option<Record>, ClientError> {
        loop {
            while self.pos < self.len {
                let b = self.buf[self.pos];
                self.pos += 1;
                if let Some(record) = self.push(b) {
                    return Ok(Some(record));
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
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
                    return Ok(None);
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// Wait for the answer to `command`: `Ok(true)` for `\r`, `Ok(false)` for BEL. Frames
    /// (an adapter left open by an earlier session streams them) and the answers to frames
    /// sent before are passed over.
    fn answer(&mut self, command: &'static str, timeout: Duration) -> Result<bool, ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.next(deadline)? {
                None => return Err(ClientError::Timeout { command, timeout }),
                Some(Record::Ok) => return Ok(true),
                Some(Record::Error) => return Ok(false),
                Some(Record::Frame(_) | Record::Sent) => {}
                Some(Record::Other(line)) => {
                    return Err(ClientError::Unexpected {
                        command,
                        got: String::from_utf8_lossy(&line).into_owned(),
                    });
                }
            }
        }
    }
}

/// An slcan adapter on TCP, opened on its bus.
///
/// ```no_run
/// use cantwin_can::{BitRate, Frame};
/// use cantwin_gateway::BusPort;
/// use cantwin_gateway::slcan::Client;
/// use std::time::Duration;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let bus = Client::connect("127.0.0.1:29537".parse()?, Some(BitRate::R500K), Duration::from_secs(2))?;
/// bus.send(Frame::std(0x000, &[0x01, 0x00])?)?;
/// if let Some(rx) = bus.recv_timeout(Duration::from_millis(100))? {
///     println!("{}", rx.frame);
/// }
/// bus.close()?;
/// # Ok(())
/// # }
/// ```
///
/// Remote frames go both ways (`r`/`R` records). Received frames are stamped with the wall
/// clock when the client reads them: an adapter's own timestamps (`Z1`) count milliseconds
/// modulo 60 s and are dropped.
pub struct Client {
    writer: Mutex<TcpStream>,
    reader: Mutex<Reader>,
    timeout: Duration,
    acknowledged: AtomicU64,
    refused: AtomicU64,
    /// Whether `C` was sent and the connection half-closed already.
    closed: bool,
}

impl Client {
    /// Connect to `addr` and open the adapter's channel, each command answered within
    /// `timeout`: `C` (whatever the answer: an adapter that is not open refuses it), then
    /// `Sn` if `bit_rate` is given, then `O`.
    ///
    /// A cantwin slcan server accepts any bit rate and keeps its bus's own; a real adapter
    /// needs the bus's rate.
    pub fn connect(
        addr: SocketAddr,
        bit_rate: Option<BitRate>,
        timeout: Duration,
    ) -> Result<Self, ClientError> {
        let stream = TcpStream::connect_timeout(&addr, timeout)?;
        stream.set_nodelay(true)?;
        stream.set_write_timeout(Some(timeout))?;
        let mut reader = Reader {
            stream: stream.try_clone()?,
            line: Vec::with_capacity(MAX_RECORD),
            skipping: false,
            buf: Box::new([0; 4096]),
            pos: 0,
            len: 0,
        };
        let mut writer = stream;
        writer.write_all(b"C\r")?;
        reader.answer("C", timeout)?;
        if let Some(rate) = bit_rate {
            writer.write_all(&[b'S', b'0' + bitrate_code(rate), b'\r'])?;
            if !reader.answer("S", timeout)? {
                return Err(ClientError::Refused("S"));
            }
        }
        writer.write_all(b"O\r")?;
        if !reader.answer("O", timeout)? {
            return Err(ClientError::Refused("O"));
        }
        Ok(Client {
            writer: Mutex::new(writer),
            reader: Mutex::new(reader),
            timeout,
            acknowledged: AtomicU64::new(0),
            refused: AtomicU64::new(0),
            closed: false,
        })
    }

    /// How many sent frames the adapter has acknowledged (`z`/`Z`) so far, as far as the
    /// stream has been read.
    pub fn tx_acknowledged(&self) -> u64 {
        self.acknowledged.load(Ordering::Relaxed)
    }

    /// How many BEL answers came after the handshake: frames the adapter refused to queue
    /// (its buffer full, or opened listen-only).
    pub fn tx_refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    /// Close the channel and the connection: `C`, answered within the connect timeout, then
    /// as on drop. The frames sent before reach the bus: the adapter takes `C` after them.
    pub fn close(mut self) -> Result<(), ClientError> {
        self.finish(true)
    }

    /// Sends `C`, waits for its answer if `confirm`, then half-closes and reads until the
    /// adapter closes its side, at most [`CLOSE_LINGER`]. Closing a socket with unread data
    /// in its receive buffer (frames the bus carried meanwhile) makes the OS reset the
    /// connection, and a reset discards what the adapter has not read yet, `C` and the last
    /// frames included.
    fn finish(&mut self, confirm: bool) -> Result<(), ClientError> {
        if self.closed {
            return Ok(());
        }
        self.closed = true;
        let writer = relock(&self.writer);
        let mut reader = relock(&self.reader);
        let mut w: &TcpStream = &writer;
        w.write_all(b"C\r")?;
        if confirm && !reader.answer("C", self.timeout)? {
            return Err(ClientError::Refused("C"));
        }
        writer.shutdown(std::net::Shutdown::Write)?;
        let deadline = Instant::now() + CLOSE_LINGER;
        let mut sink = [0u8; 4096];
        let mut stream = &reader.stream;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            stream.set_read_timeout(Some(left))?;
            match stream.read(&mut sink) {
                Ok(0) => return Ok(()),
                Ok(_) => {}
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Ok(());
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
}

/// How long a closing client waits for the adapter to take its last commands.
const CLOSE_LINGER: Duration = Duration::from_millis(500);

impl Drop for Client {
    fn drop(&mut self) {
        // Nothing to report to: a failing close only means the connection is gone already.
        let _ = self.finish(false);
    }
}

impl BusPort for Client {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        let mut out = Vec::with_capacity(32);
        wire::write_frame(&mut out, &frame);
        relock(&self.writer)
            .write_all(&out)
            .map_err(|e| PortError::from(ClientError::Io(e)))
    }

    fn recv_timeout(&self, timeout: Duration) -> Result<Option<Received>, PortError> {
        let deadline = Instant::now() + timeout;
        let mut reader = relock(&self.reader);
        loop {
            match reader.next(deadline)? {
                None => return Ok(None),
                Some(Record::Frame(frame)) => {
                    return Ok(Some(Received {
                        frame,
                        timestamp: SystemTime::now(),
                    }));
                }
                Some(Record::Sent) => {
                    self.acknowledged.fetch_add(1, Ordering::Relaxed);
                }
                Some(Record::Error) => {
                    self.refused.fetch_add(1, Ordering::Relaxed);
                }
                // `\r` answers nothing the client sends after the handshake; other lines
                // carry no frame.
                Some(Record::Ok | Record::Other(_)) => {}
            }
        }
    }

    fn overflows(&self) -> u64 {
        // The socket is the buffer; a server drops a client that reads too slowly.
        0
    }
}

/// An slcan adapter on TCP seen as a [`BusConnector`]: each `open` is a new connection. The
/// adapter has one bus, so the channel name is not sent anywhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Remote {
    /// The adapter's (or the server's) address.
    pub addr: SocketAddr,
    /// The bit rate to set before opening, if any.
    pub bit_rate: Option<BitRate>,
    /// Connect timeout, and how long each handshake command may take.
    pub timeout: Duration,
}

impl BusConnector for Remote {
    fn open(&self, _channel: &str, _rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        Ok(Box::new(Client::connect(
            self.addr,
            self.bit_rate,
            self.timeout,
        )?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;

    fn records(bytes: &[u8]) -> Vec<Record> {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let stream = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let mut r = Reader {
            stream,
            line: Vec::new(),
            skipping: false,
            buf: Box::new([0; 4096]),
            pos: 0,
            len: 0,
        };
        bytes.iter().filter_map(|&b| r.push(b)).collect()
    }

    #[test]
    fn answers_and_frames_in_one_stream() {
        let std = |id, data: &[u8]| Record::Frame(Frame::std(id, data).unwrap());
        assert_eq!(
            records(b"\r\x07z\rZ\rt0800\rt58584300100092010200\rV0101\r"),
            vec![
                Record::Ok,
                Record::Error,
                Record::Sent,
                Record::Sent,
                std(0x080, &[]),
                std(0x585, &[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]),
                Record::Other(b"V0101".to_vec()),
            ]
        );
    }

    #[test]
    fn timestamps_are_taken_off_by_length() {
        assert_eq!(
            records(b"t1232ABCD1F40\rr70511F40\rT1ABCDEF01FF3A98\r"),
            vec![
                Record::Frame(Frame::std(0x123, &[0xAB, 0xCD]).unwrap()),
                Record::Frame(Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap()),
                Record::Frame(Frame::data(Id::extended(0x1ABC_DEF0).unwrap(), &[0xFF]).unwrap()),
            ]
        );
        // Neither bare nor bare plus four digits: not a frame.
        assert_eq!(
            records(b"t1232ABCD1F\r"),
            vec![Record::Other(b"t1232ABCD1F".to_vec())]
        );
    }

    #[test]
    fn an_over_long_line_is_skipped_to_its_end() {
        let mut bytes = vec![b't'; 1000];
        bytes.extend_from_slice(b"\rz\r");
        assert_eq!(
            records(&bytes),
            vec![Record::Other(Vec::new()), Record::Sent]
        );
    }

    #[test]
    fn bit_rate_codes_follow_the_command_list() {
        let codes: Vec<u8> = BitRate::ALL.into_iter().map(bitrate_code).collect();
        assert_eq!(codes, [0, 1, 2, 3, 4, 5, 6, 7, 8]);
    }
}
