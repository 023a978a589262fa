//! The TCP machinery both servers share: accept loop, limits, one reader and one writer thread
//! per client, and the bookkeeping that keeps a slow, stuck or vanished client from ever
//! stalling the bus.
//!
//! Per client:
//!
//! * the reader thread reads the socket, feeds the protocol session, and writes its replies
//!   (each reply is one `write` call, so a reply never shares a write with frames);
//! * the writer thread drains the client's bus port (a bounded receive buffer, filled by the
//!   bus whatever the client does) and writes frames to the socket. When the buffer overflows
//!   because the client reads too slowly, or a write blocks longer than
//!   [`Limits::write_timeout`], the client is disconnected; the bus never waits for it.

use std::collections::HashMap;
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
    connector: &'a dyn BusConnector,
    limits: &'a Limits,
    stats: &'a Stats,
}

impl Link<'_> {
    /// Write a reply, alone in one write.
    pub(crate) fn reply(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.conn.write(bytes)
    }

    /// Write an error reply.
    pub(crate) fn error(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stats.error_replies.fetch_add(1, Ordering::Relaxed);
        self.conn.write(bytes)
    }

    /// Attach the client to bus `channel`.
    pub(crate) fn open(&mut self, channel: &str) -> Result<(), PortError> {
        let port = self.connector.open(channel, self.limits.client_queue)?;
        *self.conn.port() = Some(Arc::from(port));
        self.conn.ready.notify_all();
        Ok(())
    }

    /// Detach the client from its bus.
    ///
    /// Returns once the node is detached: the writer holds the port while it waits for frames
    /// (at most one poll interval), and the port detaches when the last holder lets go.
    pub(crate) fn close(&mut self) {
        self.forward(false);
        let port = self.conn.port().take();
        if let Some(port) = port {
            let deadline = Instant::now() + RECV_POLL * 2;
            while Arc::strong_count(&port) > 1 && Instant::now() < deadline {
                thread::sleep(Duration::from_millis(1));
            }
        }
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
        let mut f = self.conn.forward();
        if on && !f.on {
            // Under the lock the writer drains with, so no frame from before the switch can
            // be in flight in the writer when it sees the stream on.
            if let Some(port) = self.conn.port().clone() {
                while let Ok(Some(_)) = port.recv_timeout(Duration::ZERO) {}
                f.overflow_base = port.overflows();
            }
        }
        f.on = on;
        f.after = Instant::now() + self.limits.settle;
        drop(f);
        self.conn.switched.notify_all();
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

struct Forward {
    on: bool,
    /// When the first frame may be written.
    after: Instant,
    /// The port's overflow count when the stream started: overflows while stopped (the
    /// writer drains only now and then) do not count against the client.
    overflow_base: u64,
}

pub(crate) struct Conn {
    stream: TcpStream,
    writer: Mutex<TcpStream>,
    port: Mutex<Option<Arc<dyn BusPort>>>,
    forward: Mutex<Forward>,
    /// Signalled with `port` when a bus is opened or the connection closed.
    ready: Condvar,
    /// Signalled with `forward` when the stream is switched or the connection closed.
    switched: Condvar,
    closed: AtomicBool,
}

fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Conn {
    fn port(&self) -> MutexGuard<'_, Option<Arc<dyn BusPort>>> {
        relock(&self.port)
    }
    fn forward(&self) -> MutexGuard<'_, Forward> {
        relock(&self.forward)
    }
    fn write(&self, bytes: &[u8]) -> io::Result<()> {
        let mut w = relock(&self.writer);
        w.write_all(bytes)?;
        w.flush()
    }
    fn close(&self) {
        self.closed.store(true, Ordering::SeqCst);
        // Errors here mean the socket is already gone, which is the goal.
        let _ = self.stream.shutdown(Shutdown::Both);
        *self.port() = None;
        self.ready.notify_all();
        self.switched.notify_all();
    }
    fn is_closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }
}

struct Shared<P: Protocol> {
    protocol: P,
    connector: Arc<dyn BusConnector>,
    limits: Limits,
    stats: Stats,
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
    let conn = Arc::new(Conn {
        writer: Mutex::new(stream.try_clone()?),
        stream,
        port: Mutex::new(None),
        forward: Mutex::new(Forward {
            on: false,
            after: Instant::now(),
            overflow_base: 0,
        }),
        ready: Condvar::new(),
        switched: Condvar::new(),
        closed: AtomicBool::new(false),
    });
    {
        let mut conns = relock(&shared.conns);
        if conns.len() >= shared.limits.max_clients {
            drop(conns);
            shared.stats.refused.fetch_add(1, Ordering::Relaxed);
            conn.stream
                .set_write_timeout(Some(Duration::from_millis(100)))?;
            let _ = conn.write(shared.protocol.refusal());
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
        && conn.write(hi).is_err()
    {
        return;
    }
    let writer = {
        let shared = Arc::clone(shared);
        let conn = Arc::clone(conn);
        thread::Builder::new()
            .name("gateway-writer".into())
            .spawn(move || write_loop(&shared, &conn))
    };
    let Ok(writer) = writer else { return };
    read_loop(shared, conn);
    conn.close();
    // The writer only returns; a panic in it would already have closed the connection.
    let _ = writer.join();
}

fn read_loop<P: Protocol>(shared: &Shared<P>, conn: &Conn) {
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
            connector: &*shared.connector,
            limits: &shared.limits,
            stats: &shared.stats,
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

fn write_loop<P: Protocol>(shared: &Shared<P>, conn: &Conn) {
    let mut out = Vec::with_capacity(4096);
    while !conn.is_closed() {
        let Some(port) = conn.port().clone() else {
            // Wait for `open` (or for the close that ends the loop).
            let guard = conn.port();
            if guard.is_none() {
                drop(
                    conn.ready
                        .wait_timeout(guard, RECV_POLL)
                        .unwrap_or_else(|e| e.into_inner()),
                );
            }
            continue;
        };
        let (after, overflow_base) = {
            let f = conn.forward();
            if !f.on {
                // Stopped: drop what the bus delivers, under the lock `forward` takes, then
                // sleep until the stream starts or it is time to drain again.
                while let Ok(Some(_)) = port.recv_timeout(Duration::ZERO) {}
                drop(
                    conn.switched
                        .wait_timeout(f, RECV_POLL)
                        .unwrap_or_else(|e| e.into_inner()),
                );
                continue;
            }
            (f.after, f.overflow_base)
        };
        let first = match port.recv_timeout(RECV_POLL) {
            Ok(Some(rx)) => rx,
            Ok(None) => continue,
            Err(_) => break,
        };
        if port.overflows() > overflow_base {
            shared.stats.too_slow.fetch_add(1, Ordering::Relaxed);
            break;
        }
        let wait = after.saturating_duration_since(Instant::now());
        if !wait.is_zero() {
            thread::sleep(wait);
        }
        out.clear();
        shared.protocol.write_frame(&first, &mut out);
        for _ in 1..WRITE_BATCH {
            match port.recv_timeout(Duration::ZERO) {
                Ok(Some(rx)) => {
                    shared.protocol.write_frame(&rx, &mut out);
                }
                _ => break,
            }
        }
        if out.is_empty() || !conn.forward().on {
            continue;
        }
        if let Err(e) = conn.write(&out) {
            if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) {
                // A write that blocked past the write timeout: the client is stuck.
                shared.stats.too_slow.fetch_add(1, Ordering::Relaxed);
            }
            break;
        }
    }
    conn.close();
}
