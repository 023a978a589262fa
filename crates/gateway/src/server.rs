//! The TCP machinery both servers share: accept loop, limits, one reader and one writer thread
//! per client, and the bookkeeping that keeps a slow, stuck or vanished client from ever
//! stalling the bus.
//!
//! Per client:
//!
//! * the reader thread reads the socket, feeds the protocol session, and writes its replies
//!   (each reply is one `write` call, so a reply never shares a write with frames);
//! * frames reach the socket in one of two ways. A port that can deliver on the bus's own
//!   thread ([`BusPort::deliver_to`], the paced virtual bus) hands each frame over as it
//!   completes: when nothing is waiting to be written, the bus thread writes it at once
//!   without blocking, which saves a thread wake-up per frame in every tool's round trip;
//!   otherwise (a write under way, the client's socket full, frames already waiting) the frame
//!   is queued for the client's writer thread. Other ports are drained by the writer thread.
//!   When the queue overflows because the client reads too slowly, or a write blocks longer
//!   than [`Limits::write_timeout`], the client is disconnected; the bus never waits for it.
//!
//! Whoever writes to the socket holds the connection's `busy` mark, so frames and replies
//! never interleave, and a frame the socket took only part of is finished before anything
//! else.

use std::collections::{HashMap, VecDeque};
use std::io::{self, ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use cantwin_can::Frame;

use crate::GatewayError;
use crate::port::{BusConnector, BusPort, PortError, Received};

/// Resource limits of a server. Every bound that keeps memory and threads finite is here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limits {
    /// Clients connected at once; one more is sent the protocol's refusal and closed.
    /// Default 64.
    pub max_clients: usize,
    /// Longest command a client may send, in bytes; a longer one gets an error reply and is
    /// dropped. Default 256 (the longest valid command of either protocol is well under 100).
    pub max_line: usize,
    /// Frames buffered per client between the bus and its socket. When full, the client is
    /// disconnected as too slow. Default 4096 (a few seconds of a busy 1 Mbit/s bus).
    pub client_queue: usize,
    /// How long one write to a client may block before the client is disconnected as stuck.
    /// Default 2 s.
    pub write_timeout: Duration,
    /// How long a client may take to open a bus after connecting (slow-loris bound).
    /// Default 10 s.
    pub handshake_timeout: Duration,
    /// Pause between the reply that starts the frame stream (`< ok >` to `rawmode`, `\r` to
    /// `O`) and the first frame, so the reply arrives alone in the client's read (python-can
    /// compares the whole read with `< ok >`). Default 50 ms.
    pub settle: Duration,
    /// Bind to addresses other than loopback. Default `false`: a server on a non-loopback
    /// address is refused unless this is set.
    pub allow_remote: bool,
    /// The kernel's send buffer per client socket (`SO_SNDBUF`, which Linux doubles), in
    /// bytes. Default `None`: the kernel sizes it (and grows it up to `net.ipv4.tcp_wmem`).
    /// A small buffer bounds the kernel memory a client that stops reading can hold, and
    /// makes it count as too slow sooner.
    pub send_buffer: Option<usize>,
    /// socketcand broadcast-manager jobs per connection: cyclic transmission jobs, plus
    /// receive operations counted once per mask they keep (a multiplex filter of N masks
    /// counts N). A command that would set up one more is answered
    /// `< error too many broadcast manager jobs >` and changes nothing. Default 4096.
    pub bcm_jobs: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_clients: 64,
            max_line: 256,
            client_queue: 4096,
            write_timeout: Duration::from_secs(2),
            handshake_timeout: Duration::from_secs(10),
            settle: Duration::from_millis(50),
            allow_remote: false,
            send_buffer: None,
            bcm_jobs: 4096,
        }
    }
}

/// Counters of a running server.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServerStats {
    /// Clients accepted since the start.
    pub accepted: u64,
    /// Clients refused because [`Limits::max_clients`] were connected.
    pub refused: u64,
    /// Clients connected now.
    pub active: usize,
    /// Clients disconnected because they read too slowly or stopped reading.
    pub too_slow: u64,
    /// Clients disconnected because they did not open a bus in time.
    pub handshake_timeouts: u64,
    /// Error replies sent.
    pub error_replies: u64,
}

/// A wire protocol served over TCP.
pub(crate) trait Protocol: Send + Sync + 'static {
    /// The protocol's name, which names its clients' ports (`socketcand 127.0.0.1:54012`).
    const NAME: &'static str;
    /// One client's protocol state.
    type Session: Session;
    /// The state of a newly connected client.
    fn session(&self) -> Self::Session;
    /// Sent on accept, as its own write.
    fn greeting(&self) -> Option<&'static [u8]>;
    /// Sent to a client refused for lack of room.
    fn refusal(&self) -> &'static [u8];
    /// Append a received frame as the protocol writes it; `false` if it cannot be carried.
    fn write_frame(&self, rx: &Received, out: &mut Vec<u8>) -> bool;
}

/// One client's protocol state, driven by the bytes it sends.
pub(crate) trait Session: Send + 'static {
    /// Handle received bytes; act through `link`.
    fn on_bytes(&mut self, bytes: &[u8], link: &mut Link<'_>) -> io::Result<()>;
}

/// What a session may do to its client and its bus.
pub(crate) struct Link<'a> {
    conn: &'a Conn,
    handle: &'a ConnHandle,
    connector: &'a dyn BusConnector,
    limits: &'a Limits,
    stats: &'a Stats,
    /// [`Protocol::NAME`].
    protocol: &'static str,
}

impl Link<'_> {
    /// Write a reply, alone in one write.
    pub(crate) fn reply(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.conn.reply(bytes)
    }

    /// Write an error reply.
    pub(crate) fn error(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stats.error_replies.fetch_add(1, Ordering::Relaxed);
        self.conn.reply(bytes)
    }

    /// Attach the client to bus `channel`.
    pub(crate) fn open(&mut self, channel: &str) -> Result<(), PortError> {
        let client = match self.conn.stream.peer_addr() {
            Ok(peer) => format!("{} {peer}", self.protocol),
            Err(_) => format!("{} client", self.protocol),
        };
        let port = self
            .connector
            .open_for(channel, self.limits.client_queue, &client)?;
        // A port replaced here is dropped (and detached) after the lock is let go: detaching
        // takes the bus's lock, under which the bus may be waiting for this connection.
        let old = self.conn.port().replace(Arc::from(port));
        drop(old);
        self.conn.ready.notify_all();
        self.conn.work.notify_all();
        Ok(())
    }

    /// Detach the client from its bus.
    ///
    /// Returns once the node is detached: the writer holds the port while it waits for frames
    /// (at most one poll interval), and the port detaches when the last holder lets go.
    pub(crate) fn close(&mut self) {
        self.forward(false);
        let port = self.conn.port().take();
        // The writer lets go of the port when it next looks, which may be after a write to a
        // slow client: the port stops handing frames to this connection now (the next open
        // must not see frames of both).
        self.conn.work.notify_all();
        if let Some(port) = port {
            port.deliver_to(Box::new(|_| {}));
            let deadline = Instant::now() + RECV_POLL * 2;
            while Arc::strong_count(&port) > 1 && Instant::now() < deadline {
                thread::sleep(Duration::from_millis(1));
            }
        }
    }

    /// Have the stream pass frames through `selector` (and write them its way), or, with
    /// `None`, carry every frame in the protocol's own format. Frames queued under another
    /// selector are dropped.
    pub(crate) fn select(&mut self, selector: Option<Arc<dyn Selector>>) {
        let mut out = self.conn.out();
        if out.selector.as_ref().map(selector_addr) != selector.as_ref().map(selector_addr) {
            out.queue.clear();
            out.selector = selector;
        }
    }

    /// The server's limits.
    pub(crate) fn limits(&self) -> &Limits {
        self.limits
    }

    /// A handle on this connection for other threads (a session's timers).
    pub(crate) fn handle(&self) -> ConnHandle {
        self.handle.clone()
    }

    /// Whether the client is attached to a bus.
    pub(crate) fn is_open(&self) -> bool {
        self.conn.port().is_some()
    }

    /// Queue a frame on the client's bus.
    ///
    /// A full transmit queue holds the client back instead of refusing the frame: this
    /// reader thread waits for room, the client's socket fills, and TCP slows the client
    /// down, as the socketcand daemon's blocking write to its CAN socket does. Tools send
    /// whole bursts at once (python-canopen sends an SDO block of up to 127 segments without
    /// waiting) and expect every frame to go out. Only a queue that stays full for
    /// [`Limits::write_timeout`] (a bus that carries nothing, e.g. the node is bus-off) gives
    /// [`PortError::TxQueueFull`].
    pub(crate) fn send(&mut self, frame: Frame) -> Result<(), PortError> {
        let port = self.conn.port().clone().ok_or(PortError::Closed)?;
        let give_up = Instant::now() + self.limits.write_timeout;
        let mut pause = std::time::Duration::from_micros(100);
        loop {
            match port.send(frame) {
                Err(PortError::TxQueueFull) if Instant::now() < give_up => {
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(std::time::Duration::from_millis(2));
                }
                other => return other,
            }
        }
    }

    /// Start (after [`Limits::settle`]) or stop writing bus frames to the client.
    ///
    /// Frames received while stopped are dropped, and so is whatever is buffered when the
    /// stream starts: the client gets exactly the frames that reach the bus port after the
    /// switch. Starting again while started only restarts the pause.
    pub(crate) fn forward(&mut self, on: bool) {
        // Taken before `out`: nothing holds `out` while it waits for `port`.
        let port = self.conn.port().clone();
        let mut out = self.conn.out();
        if on != out.on {
            // Queued frames are from before the switch either way. A frame the socket took
            // only part of stays: the client's stream must not be cut mid-frame.
            out.queue.clear();
        }
        if on && !out.on {
            // Under the lock a draining writer holds, so no frame from before the switch can
            // be in flight in the writer when it sees the stream on. A port that delivers on
            // the bus's thread buffers nothing to drain (and is not touched here: the bus
            // thread takes this lock while it holds the port's).
            if !out.delivered {
                if let Some(port) = &port {
                    while let Ok(Some(_)) = port.recv_timeout(Duration::ZERO) {}
                    out.overflow_base = port.overflows();
                }
            }
        }
        out.on = on;
        out.after = Instant::now() + self.limits.settle;
        drop(out);
        self.conn.work.notify_all();
    }
}

#[derive(Debug, Default)]
struct Stats {
    accepted: AtomicU64,
    refused: AtomicU64,
    too_slow: AtomicU64,
    handshake_timeouts: AtomicU64,
    error_replies: AtomicU64,
}

/// Which frames of the bus a connection's stream carries and how it writes them, when that is
/// not every frame in the protocol's own format (socketcand's broadcast-manager mode).
pub(crate) trait Selector: Send + Sync {
    /// Whether a frame from the bus goes to the client now. A selector may keep a frame and
    /// hand it over later through [`ConnHandle::deliver_kept`]. Called with the connection's
    /// stream locked: it must not call back into the connection.
    fn select(&self, rx: &Received) -> bool;
    /// For a frame it kept, handed over now: whether the client should still get it (what
    /// selected it was not undone meanwhile). Called with the stream locked.
    fn still_selects(&self, rx: &Received) -> bool;
    /// Append the frame as the stream writes it; `false` if it cannot be carried.
    fn write(&self, rx: &Received, out: &mut Vec<u8>) -> bool;
}

/// Where a frame handed to a connection's stream comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    /// The bus's own thread (or a frame the client sent, looped back): it may be written at
    /// once.
    BusThread,
    /// The writer thread draining its port: queued, written in batches.
    Drained,
    /// A frame the selector at this address kept and hands over now.
    Kept(usize),
}

/// Append a frame as the stream writes it: its selector's way, else the protocol's.
fn write_frame<P: Protocol>(
    protocol: &P,
    selector: Option<&Arc<dyn Selector>>,
    rx: &Received,
    out: &mut Vec<u8>,
) -> bool {
    match selector {
        Some(selector) => selector.write(rx, out),
        None => protocol.write_frame(rx, out),
    }
}

/// A selector's address, to tell whether it is still the stream's.
fn selector_addr(selector: &Arc<dyn Selector>) -> usize {
    Arc::as_ptr(selector).cast::<()>().addr()
}

/// Hands a connection a frame through its server's protocol (which a handle does not name).
type Deliver = Arc<dyn Fn(&Conn, &Received, Source) + Send + Sync>;

/// A connection as seen from other threads: it ends with the connection.
#[derive(Clone)]
pub(crate) struct ConnHandle {
    conn: std::sync::Weak<Conn>,
    deliver: Deliver,
}

impl ConnHandle {
    fn new<P: Protocol>(shared: &Arc<Shared<P>>, conn: &Arc<Conn>) -> Self {
        let shared = Arc::downgrade(shared);
        ConnHandle {
            conn: Arc::downgrade(conn),
            deliver: Arc::new(move |conn: &Conn, rx: &Received, from: Source| {
                if let Some(shared) = shared.upgrade() {
                    conn.offer(&shared, rx, from);
                }
            }),
        }
    }

    /// Whether the connection has ended.
    pub(crate) fn is_closed(&self) -> bool {
        self.conn.upgrade().is_none_or(|c| c.is_closed())
    }

    /// Hand the client a frame `selector` kept: it goes out if `selector` is still the
    /// stream's and still selects it ([`Selector::still_selects`]).
    pub(crate) fn deliver_kept(&self, selector: &Arc<dyn Selector>, rx: &Received) {
        if let Some(conn) = self.conn.upgrade() {
            (self.deliver)(&conn, rx, Source::Kept(selector_addr(selector)));
        }
    }

    /// Offer the client a frame from the bus (the stream's selector decides).
    pub(crate) fn offer_from_bus(&self, rx: &Received) {
        if let Some(conn) = self.conn.upgrade() {
            (self.deliver)(&conn, rx, Source::BusThread);
        }
    }

    /// Offer the client a frame it sent itself, stamped now, as if the bus had delivered it
    /// (the kernel loops a socket's frames back to its broadcast manager).
    pub(crate) fn loop_back(&self, frame: Frame) {
        self.offer_from_bus(&Received {
            frame,
            timestamp: std::time::SystemTime::now(),
        });
    }

    /// Queue a frame on the client's bus without waiting: a full transmit queue refuses it.
    pub(crate) fn send(&self, frame: Frame) -> Result<(), PortError> {
        let conn = self.conn.upgrade().ok_or(PortError::Closed)?;
        let port = conn.port().clone().ok_or(PortError::Closed)?;
        port.send(frame)
    }
}

/// Why the writer ends a connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// The client reads too slowly or not at all: its queue overflowed or a write blocked
    /// past [`Limits::write_timeout`].
    TooSlow,
    /// The socket failed (the client went away).
    Gone,
}

/// What goes to the client's socket, and who may write it.
struct Out {
    /// Whether bus frames are forwarded to the client at all.
    on: bool,
    /// When the first frame after switching the stream on may be written.
    after: Instant,
    /// The port's overflow count when the stream started: overflows while stopped (the
    /// writer drains only now and then) do not count against the client.
    overflow_base: u64,
    /// The port hands frames over on the bus's thread ([`BusPort::deliver_to`]).
    delivered: bool,
    /// The tail of a frame write the socket did not take at once; it goes out before
    /// anything else.
    pending: Vec<u8>,
    /// Frames waiting for the writer thread, oldest first.
    queue: VecDeque<Received>,
    /// Someone is writing to the socket (the writer thread or a reply): nobody else may.
    busy: bool,
    /// Replies waiting for their turn; the writer lets them go before its next batch, so a
    /// steady stream of frames to a slow client cannot hold a reply back.
    replies_waiting: usize,
    /// Set when the connection must end; the writer acts on it.
    end: Option<End>,
    /// Reused for the bus thread's immediate writes.
    scratch: Vec<u8>,
    /// Which frames go to the client, and how they are written; `None`: all, the protocol's
    /// way.
    selector: Option<Arc<dyn Selector>>,
}

impl Out {
    /// Whether a frame may be written at once: nothing before it is waiting or being written
    /// (a reply included), the stream's start pause is over, and there is a non-blocking send
    /// for it (Linux).
    fn can_write_now(&self) -> bool {
        cfg!(target_os = "linux")
            && !self.busy
            && self.replies_waiting == 0
            && self.pending.is_empty()
            && self.queue.is_empty()
            && Instant::now() >= self.after
    }
}

pub(crate) struct Conn {
    stream: TcpStream,
    port: Mutex<Option<Arc<dyn BusPort>>>,
    out: Mutex<Out>,
    /// Signalled with `port` when a bus is opened or the connection closed.
    ready: Condvar,
    /// Signalled with `out` when the writer has something to do: frames queued, a partial
    /// write to finish, the stream switched, the port changed, the connection ending.
    work: Condvar,
    /// Signalled with `out` when a write ends (`busy` cleared), for replies waiting their turn.
    quiet: Condvar,
    closed: AtomicBool,
}

/// Lock, taking over a lock poisoned by a panic elsewhere (every holder leaves the state
/// consistent).
pub(crate) fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Wait on `c` for at most `timeout`, as [`relock`] takes over a poisoned lock.
pub(crate) fn wait_on<'a, T>(
    c: &Condvar,
    g: MutexGuard<'a, T>,
    timeout: Duration,
) -> MutexGuard<'a, T> {
    c.wait_timeout(g, timeout)
        .unwrap_or_else(|e| e.into_inner())
        .0
}

impl Conn {
    fn port(&self) -> MutexGuard<'_, Option<Arc<dyn BusPort>>> {
        relock(&self.port)
    }
    fn out(&self) -> MutexGuard<'_, Out> {
        relock(&self.out)
    }

    /// Write a reply alone, after the write under way. A client that reads slowly but reads
    /// gets its reply however long the frames ahead of it take; a write that makes no
    /// progress for the socket's write timeout ends the connection, and the reply with it.
    fn reply(&self, bytes: &[u8]) -> io::Result<()> {
        let mut out = self.out();
        out.replies_waiting += 1;
        while out.busy || !out.pending.is_empty() {
            if self.is_closed() {
                out.replies_waiting -= 1;
                return Err(ErrorKind::BrokenPipe.into());
            }
            out = wait_on(&self.quiet, out, RECV_POLL);
        }
        out.replies_waiting -= 1;
        out.busy = true;
        drop(out);
        let written = (&self.stream).write_all(bytes);
        self.out().busy = false;
        self.quiet.notify_all();
        // Frames may have been queued while the reply was written.
        self.work.notify_all();
        written
    }

    /// Take a frame for the client: from the bus's thread for a port that delivers there, or
    /// from a selector's timer (written at once if nothing is ahead of it and the server's
    /// [`DirectBudget`] allows), or from the writer thread for a port it drains (queued; the
    /// writer writes queued frames in batches). Frames from the bus go through the stream's
    /// selector. Never blocks on the socket.
    fn offer<P: Protocol>(&self, shared: &Shared<P>, rx: &Received, from: Source) {
        let mut out = self.out();
        if !out.on || out.end.is_some() {
            return;
        }
        let selected = match (from, &out.selector) {
            (Source::Kept(by), Some(selector)) => {
                selector_addr(selector) == by && selector.still_selects(rx)
            }
            (Source::Kept(_), None) => false,
            (_, Some(selector)) => selector.select(rx),
            (_, None) => true,
        };
        if !selected {
            return;
        }
        if from != Source::Drained && out.can_write_now() && shared.direct.take() {
            let mut bytes = std::mem::take(&mut out.scratch);
            bytes.clear();
            if write_frame(&shared.protocol, out.selector.as_ref(), rx, &mut bytes) {
                match send_now(&self.stream, &bytes) {
                    Ok(n) if n == bytes.len() => {}
                    Ok(n) => out.pending.extend_from_slice(&bytes[n..]),
                    Err(e)
                        if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) =>
                    {
                        out.pending.extend_from_slice(&bytes);
                    }
                    Err(_) => out.end = Some(End::Gone),
                }
            }
            out.scratch = bytes;
            let wake = !out.pending.is_empty() || out.end.is_some();
            drop(out);
            if wake {
                self.work.notify_all();
            }
            return;
        }
        if out.queue.len() >= shared.limits.client_queue {
            out.end = Some(End::TooSlow);
        } else {
            out.queue.push_back(*rx);
        }
        drop(out);
        self.work.notify_all();
    }

    /// Write what is pending and queued, blocking (bounded by the socket's write timeout).
    /// Writer thread only.
    fn flush<P: Protocol>(
        &self,
        protocol: &P,
        batch: &mut VecDeque<Received>,
        buf: &mut Vec<u8>,
    ) -> Result<(), End> {
        let mut out = self.out();
        loop {
            if let Some(end) = out.end {
                return Err(end);
            }
            if out.pending.is_empty() && out.queue.is_empty() {
                return Ok(());
            }
            if out.busy || (out.replies_waiting > 0 && out.pending.is_empty()) {
                // A reply is being written or waits for its turn; frames follow it.
                out = wait_on(&self.quiet, out, RECV_POLL);
                continue;
            }
            if out.pending.is_empty() {
                let wait = out.after.saturating_duration_since(Instant::now());
                if !wait.is_zero() {
                    drop(out);
                    thread::sleep(wait);
                    out = self.out();
                    continue;
                }
            }
            buf.clear();
            buf.append(&mut out.pending);
            // A waiting reply goes right after the tail of the frame it waits for. The frames
            // are taken out under the lock and formatted after it: the bus's thread may be
            // waiting for the lock to hand over the next frame.
            batch.clear();
            let selector = out.selector.clone();
            if out.replies_waiting == 0 {
                if out.queue.len() <= WRITE_BATCH {
                    std::mem::swap(&mut out.queue, batch);
                } else {
                    batch.extend(out.queue.drain(..WRITE_BATCH));
                }
            }
            out.busy = true;
            drop(out);
            for rx in batch.drain(..) {
                write_frame(protocol, selector.as_ref(), &rx, buf);
            }
            let written = (&self.stream).write_all(buf);
            out = self.out();
            out.busy = false;
            self.quiet.notify_all();
            if let Err(e) = written {
                // A write that blocked past the write timeout: the client is stuck.
                return Err(match e.kind() {
                    ErrorKind::WouldBlock | ErrorKind::TimedOut => End::TooSlow,
                    _ => End::Gone,
                });
            }
        }
    }

    fn close(&self) {
        self.closed.store(true, Ordering::SeqCst);
        // Errors here mean the socket is already gone, which is the goal.
        let _ = self.stream.shutdown(Shutdown::Both);
        // Dropped after the lock is let go (see `Link::open`).
        let port = self.port().take();
        drop(port);
        self.ready.notify_all();
        self.work.notify_all();
        self.quiet.notify_all();
    }
    fn is_closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }
}

/// Write without blocking: as much of `bytes` as the socket takes now.
#[cfg(target_os = "linux")]
fn send_now(stream: &TcpStream, bytes: &[u8]) -> io::Result<usize> {
    // MSG_NOSIGNAL: a vanished client is an error, not a signal that ends the process (the
    // library may be embedded in a program that did not ignore SIGPIPE).
    socket2::SockRef::from(stream).send_with_flags(bytes, libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL)
}

/// Without a per-call non-blocking send every frame goes through the writer thread.
#[cfg(not(target_os = "linux"))]
fn send_now(_stream: &TcpStream, _bytes: &[u8]) -> io::Result<usize> {
    Err(ErrorKind::WouldBlock.into())
}

/// How many frames per second the bus's thread may write to this server's clients itself.
/// Each such write is a system call on the bus's thread (a few microseconds on loopback);
/// beyond this rate frames go to the clients' writer threads, which batch them, so that a busy
/// bus fanned out to many clients never slows the simulation down. A few clients in a
/// request-and-answer exchange stay far below it.
const DIRECT_PER_SECOND: u64 = 10_000;
/// Direct writes allowed at once, beyond the rate: one frame to each of a few clients.
const DIRECT_BURST: u64 = 16;

/// The server-wide budget of the bus thread's direct writes: a generic cell rate algorithm
/// (ITU-T I.371) on one atomic, the theoretical arrival time of the next write.
struct DirectBudget {
    origin: Instant,
    /// Nanoseconds after `origin`.
    next: AtomicU64,
}

impl DirectBudget {
    const INTERVAL: u64 = 1_000_000_000 / DIRECT_PER_SECOND;
    const TOLERANCE: u64 = Self::INTERVAL * (DIRECT_BURST - 1);

    fn new() -> Self {
        DirectBudget {
            origin: Instant::now(),
            next: AtomicU64::new(0),
        }
    }

    /// Whether one more direct write fits the budget now (and count it if so).
    fn take(&self) -> bool {
        let now = u64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(u64::MAX);
        let mut next = self.next.load(Ordering::Relaxed);
        loop {
            let from = next.max(now);
            if from - now > Self::TOLERANCE {
                return false;
            }
            match self.next.compare_exchange_weak(
                next,
                from + Self::INTERVAL,
                Ordering::Relaxed,
                Ordering::Relaxed,
            ) {
                Ok(_) => return true,
                Err(seen) => next = seen,
            }
        }
    }
}

struct Shared<P: Protocol> {
    protocol: P,
    connector: Arc<dyn BusConnector>,
    limits: Limits,
    stats: Stats,
    direct: DirectBudget,
    conns: Mutex<HashMap<u64, Arc<Conn>>>,
    idle: Condvar,
    stop: AtomicBool,
}

/// A running TCP server for protocol `P`.
pub(crate) struct TcpServer<P: Protocol> {
    shared: Arc<Shared<P>>,
    addr: SocketAddr,
    acceptor: Option<JoinHandle<()>>,
}

impl<P: Protocol> TcpServer<P> {
    pub(crate) fn bind(
        addr: SocketAddr,
        protocol: P,
        connector: Arc<dyn BusConnector>,
        limits: Limits,
    ) -> Result<Self, GatewayError> {
        if !addr.ip().is_loopback() && !limits.allow_remote {
            return Err(GatewayError::RemoteBindRefused(addr));
        }
        let listener = TcpListener::bind(addr)?;
        let addr = listener.local_addr()?;
        // Non-blocking accept so the loop notices `shutdown` without a wake-up connection.
        listener.set_nonblocking(true)?;
        let shared = Arc::new(Shared {
            protocol,
            connector,
            limits,
            stats: Stats::default(),
            direct: DirectBudget::new(),
            conns: Mutex::new(HashMap::new()),
            idle: Condvar::new(),
            stop: AtomicBool::new(false),
        });
        let acceptor = {
            let shared = Arc::clone(&shared);
            thread::Builder::new()
                .name(format!("gateway-accept-{}", addr.port()))
                .spawn(move || accept_loop(&shared, &listener))?
        };
        Ok(TcpServer {
            shared,
            addr,
            acceptor: Some(acceptor),
        })
    }

    pub(crate) fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    pub(crate) fn stats(&self) -> ServerStats {
        let s = &self.shared.stats;
        ServerStats {
            accepted: s.accepted.load(Ordering::Relaxed),
            refused: s.refused.load(Ordering::Relaxed),
            active: relock(&self.shared.conns).len(),
            too_slow: s.too_slow.load(Ordering::Relaxed),
            handshake_timeouts: s.handshake_timeouts.load(Ordering::Relaxed),
            error_replies: s.error_replies.load(Ordering::Relaxed),
        }
    }

    pub(crate) fn wait_clients(&self, at_most: usize, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut conns = relock(&self.shared.conns);
        while conns.len() > at_most {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            conns = self
                .shared
                .idle
                .wait_timeout(conns, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        true
    }

    pub(crate) fn shutdown(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(a) = self.acceptor.take() {
            // The accept loop only ends by seeing the flag; a panic there has nothing to
            // hand over.
            let _ = a.join();
        }
        for conn in relock(&self.shared.conns).values() {
            conn.close();
        }
        self.wait_clients(0, Duration::from_secs(5));
    }
}

impl<P: Protocol> Drop for TcpServer<P> {
    fn drop(&mut self) {
        self.shutdown();
    }
}

const ACCEPT_POLL: Duration = Duration::from_millis(10);
const RECV_POLL: Duration = Duration::from_millis(100);
/// Frames gathered into one write to a client.
const WRITE_BATCH: usize = 64;

fn accept_loop<P: Protocol>(shared: &Arc<Shared<P>>, listener: &TcpListener) {
    let mut next_id = 0u64;
    while !shared.stop.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((stream, _peer)) => {
                next_id += 1;
                // A client that vanished while being set up leaves nothing behind.
                let _ = admit(shared, stream, next_id);
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => thread::sleep(ACCEPT_POLL),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            // Out of descriptors and the like: back off and keep serving the others.
            Err(_) => thread::sleep(ACCEPT_POLL * 10),
        }
    }
}

fn admit<P: Protocol>(shared: &Arc<Shared<P>>, stream: TcpStream, id: u64) -> io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_write_timeout(Some(shared.limits.write_timeout))?;
    if let Some(size) = shared.limits.send_buffer {
        socket2::SockRef::from(&stream).set_send_buffer_size(size)?;
    }
    let conn = Arc::new(Conn {
        stream,
        port: Mutex::new(None),
        out: Mutex::new(Out {
            on: false,
            after: Instant::now(),
            overflow_base: 0,
            delivered: false,
            pending: Vec::new(),
            queue: VecDeque::new(),
            busy: false,
            replies_waiting: 0,
            end: None,
            scratch: Vec::new(),
            selector: None,
        }),
        ready: Condvar::new(),
        work: Condvar::new(),
        quiet: Condvar::new(),
        closed: AtomicBool::new(false),
    });
    {
        let mut conns = relock(&shared.conns);
        if conns.len() >= shared.limits.max_clients {
            drop(conns);
            shared.stats.refused.fetch_add(1, Ordering::Relaxed);
            conn.stream
                .set_write_timeout(Some(Duration::from_millis(100)))?;
            let _ = conn.reply(shared.protocol.refusal());
            conn.close();
            return Ok(());
        }
        conns.insert(id, Arc::clone(&conn));
    }
    shared.stats.accepted.fetch_add(1, Ordering::Relaxed);
    let spawned = {
        let shared = Arc::clone(shared);
        let conn = Arc::clone(&conn);
        thread::Builder::new()
            .name(format!("gateway-client-{id}"))
            .spawn(move || {
                serve(&shared, &conn);
                conn.close();
                relock(&shared.conns).remove(&id);
                shared.idle.notify_all();
            })
    };
    if let Err(e) = spawned {
        conn.close();
        relock(&shared.conns).remove(&id);
        shared.idle.notify_all();
        return Err(e);
    }
    Ok(())
}

/// The reader side of one client; spawns and joins its writer.
fn serve<P: Protocol>(shared: &Arc<Shared<P>>, conn: &Arc<Conn>) {
    if let Some(hi) = shared.protocol.greeting()
        && conn.reply(hi).is_err()
    {
        return;
    }
    let handle = ConnHandle::new(shared, conn);
    let writer = {
        let shared = Arc::clone(shared);
        let conn = Arc::clone(conn);
        let handle = handle.clone();
        thread::Builder::new()
            .name("gateway-writer".into())
            .spawn(move || write_loop(&shared, &conn, &handle))
    };
    let Ok(writer) = writer else { return };
    read_loop(shared, conn, &handle);
    conn.close();
    // The writer only returns; a panic in it would already have closed the connection.
    let _ = writer.join();
}

fn read_loop<P: Protocol>(shared: &Shared<P>, conn: &Conn, handle: &ConnHandle) {
    let mut session = shared.protocol.session();
    let mut buf = [0u8; 1024];
    let deadline = Instant::now() + shared.limits.handshake_timeout;
    let mut reader = &conn.stream;
    let mut opened = false;
    loop {
        if conn.is_closed() {
            return;
        }
        if !opened {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                shared
                    .stats
                    .handshake_timeouts
                    .fetch_add(1, Ordering::Relaxed);
                return;
            }
            if conn.stream.set_read_timeout(Some(left)).is_err() {
                return;
            }
        }
        let n = match reader.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => continue,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(_) => return,
        };
        let mut link = Link {
            conn,
            handle,
            connector: &*shared.connector,
            limits: &shared.limits,
            stats: &shared.stats,
            protocol: P::NAME,
        };
        if session.on_bytes(&buf[..n], &mut link).is_err() {
            return;
        }
        if !opened && link.is_open() {
            opened = true;
            if conn.stream.set_read_timeout(None).is_err() {
                return;
            }
        }
    }
}

fn write_loop<P: Protocol>(shared: &Shared<P>, conn: &Conn, handle: &ConnHandle) {
    let mut buf = Vec::with_capacity(4096);
    let mut batch = VecDeque::with_capacity(WRITE_BATCH);
    // The port this loop last asked to deliver on the bus's thread, and whether it does.
    let mut asked: Option<(Arc<dyn BusPort>, bool)> = None;
    while !conn.is_closed() {
        let Some(port) = conn.port().clone() else {
            asked = None;
            conn.out().delivered = false;
            // Wait for `open` (or for the close that ends the loop).
            let guard = conn.port();
            if guard.is_none() {
                drop(wait_on(&conn.ready, guard, RECV_POLL));
            }
            continue;
        };
        let known = asked
            .as_ref()
            .filter(|(p, _)| std::ptr::addr_eq(Arc::as_ptr(p), Arc::as_ptr(&port)))
            .map(|(_, delivers)| *delivers);
        let delivers = match known {
            Some(delivers) => delivers,
            None => {
                conn.out().delivered = false;
                // The bus owns the sink; the handle holds the connection weakly, so a closed
                // connection is not kept alive by it.
                let handle = handle.clone();
                let delivers = port.deliver_to(Box::new(move |rx| handle.offer_from_bus(&rx)));
                conn.out().delivered = delivers;
                asked = Some((Arc::clone(&port), delivers));
                delivers
            }
        };
        let step = if delivers {
            wait_delivered(conn, &*port)
        } else {
            drain(shared, conn, &*port)
        };
        let flushed = step.and_then(|()| conn.flush(&shared.protocol, &mut batch, &mut buf));
        match flushed {
            Ok(()) => {}
            Err(End::TooSlow) => {
                shared.stats.too_slow.fetch_add(1, Ordering::Relaxed);
                break;
            }
            Err(End::Gone) => break,
        }
    }
    conn.close();
}

/// A delivering port: wait until there is something to write or to act on.
fn wait_delivered(conn: &Conn, port: &dyn BusPort) -> Result<(), End> {
    let out = conn.out();
    if out.end.is_none() && out.pending.is_empty() && out.queue.is_empty() {
        drop(wait_on(&conn.work, out, RECV_POLL));
    } else {
        drop(out);
    }
    // The port buffers nothing now; it only reports that the bus stopped or let it go.
    match port.recv_timeout(Duration::ZERO) {
        Err(_) => Err(End::Gone),
        Ok(_) => Ok(()),
    }
}

/// A port the writer drains: take what the bus buffered (dropping it while the stream is
/// stopped), waiting up to a poll interval for the first frame.
fn drain<P: Protocol>(shared: &Shared<P>, conn: &Conn, port: &dyn BusPort) -> Result<(), End> {
    let overflow_base = {
        let out = conn.out();
        if !out.on {
            // Stopped: drop what the bus delivers, under the lock `forward` takes, then sleep
            // until the stream starts or it is time to drain again.
            while let Ok(Some(_)) = port.recv_timeout(Duration::ZERO) {}
            drop(wait_on(&conn.work, out, RECV_POLL));
            return Ok(());
        }
        out.overflow_base
    };
    let first = match port.recv_timeout(RECV_POLL) {
        Ok(Some(rx)) => rx,
        Ok(None) => return Ok(()),
        Err(_) => return Err(End::Gone),
    };
    if port.overflows() > overflow_base {
        return Err(End::TooSlow);
    }
    conn.offer(shared, &first, Source::Drained);
    for _ in 1..WRITE_BATCH {
        match port.recv_timeout(Duration::ZERO) {
            Ok(Some(rx)) => conn.offer(shared, &rx, Source::Drained),
            _ => break,
        }
    }
    Ok(())
}
