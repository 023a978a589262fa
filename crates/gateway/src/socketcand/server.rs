//! The socketcand server: each client is a node on the bus it opens.

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread;
use std::time::{Duration, Instant};

use super::bcm::{Bcm, Due};
use super::wire::{self, Command, Framed, Framer, WireError};
use crate::GatewayError;
use crate::port::{BusConnector, PortError, Received};
use crate::server::{
    ConnHandle, Limits, Link, Protocol, Selector, ServerStats, Session, TcpServer, relock, wait_on,
};

/// socketcand's default TCP port.
pub const DEFAULT_PORT: u16 = 29536;

/// A socketcand server (raw mode) in front of the buses of a [`BusConnector`]: one channel name
/// per bus, any number of clients per bus up to [`Limits::max_clients`].
///
/// Each client that opens a bus is a node on it: its frames arbitrate and take bus time like
/// any other node's, and in raw mode it receives every frame on the bus except its own.
///
/// Both of the daemon's frame modes are served: raw mode (`< rawmode >`: every frame on the
/// bus) and its default broadcast-manager mode (cyclic jobs with `add`, `update`, `delete`;
/// frames selected with `subscribe`, `filter`, `muxfilter`, `unsubscribe`, throttled as asked;
/// see the broadcast manager's module for what each does), at most [`Limits::bcm_jobs`] jobs
/// per connection. What the server accepts beyond the
/// daemon is listed in [`wire`]: the remote frame form python-can writes, and error replies
/// for every malformed command (the daemon logs a bad command silently; here it gets
/// `< error syntax error in send command >` and the like). Control and ISO-TP commands get
/// `< error command not supported >`.
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
    const NAME: &'static str = "socketcand";
    type Session = ScSession;

    fn session(&self) -> ScSession {
        ScSession {
            framer: Framer::new(self.max_line),
            state: State::NoBus,
            bcm: None,
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
    /// The broadcast manager of BCM mode, from the first broadcast-manager command on; a new
    /// one each time the mode is entered (the daemon opens a new BCM socket, so jobs and
    /// subscriptions end with the mode).
    bcm: Option<Arc<BcmEngine>>,
}

impl Drop for ScSession {
    fn drop(&mut self) {
        self.leave_bcm();
    }
}

/// A client's broadcast manager at work: its state, shared with the stream (which asks it
/// which frames to pass) and with its timer thread (cyclic jobs and throttles).
///
/// Lock order: `gate`, then `state`. The bus's thread takes `state` (through [`Selector`])
/// while it holds the stream's lock, so nothing here calls into the connection or the bus
/// with `state` held. `gate` is held by the timer across taking due frames and transmitting
/// them, and by every command: once `delete` (or leaving the mode) returns, no frame of the
/// job is on its way to the bus, as the kernel cancels a job's timer before it returns.
struct BcmEngine {
    gate: Mutex<()>,
    state: Mutex<BcmState>,
    /// Signalled when a command or a frame may have moved the next deadline, or on stop.
    changed: Condvar,
}

struct BcmState {
    bcm: Bcm,
    stop: bool,
}

impl BcmEngine {
    fn lock(&self) -> MutexGuard<'_, BcmState> {
        relock(&self.state)
    }

    /// Run a command against the broadcast manager and let the timer re-plan.
    fn with<R>(&self, f: impl FnOnce(&mut Bcm) -> R) -> R {
        let _gate = relock(&self.gate);
        let r = f(&mut self.lock().bcm);
        self.changed.notify_all();
        r
    }

    fn stop(&self) {
        let _gate = relock(&self.gate);
        self.lock().stop = true;
        self.changed.notify_all();
    }

    /// Wait until something is due; `false` once the engine stopped or the connection ended.
    fn wait_due(&self, conn: &ConnHandle) -> bool {
        let mut st = self.lock();
        loop {
            if st.stop || conn.is_closed() {
                return false;
            }
            let now = Instant::now();
            let wait = match st.bcm.next_deadline() {
                Some(t) if t <= now => return true,
                // Without a deadline, look at the connection now and then.
                Some(t) => (t - now).min(IDLE_POLL),
                None => IDLE_POLL,
            };
            st = wait_on(&self.changed, st, wait);
        }
    }

    /// The timer thread: transmit due cyclic frames and hand over throttled ones, until the
    /// engine stops or the connection ends.
    fn run(self: &Arc<Self>, conn: &ConnHandle) {
        let me: Arc<dyn Selector> = Arc::clone(self) as Arc<dyn Selector>;
        let mut due = Due::default();
        while self.wait_due(conn) {
            {
                let _gate = relock(&self.gate);
                {
                    let mut st = self.lock();
                    if st.stop {
                        return;
                    }
                    st.bcm.poll(Instant::now(), &mut due);
                }
                for frame in due.transmit.drain(..) {
                    // A full transmit queue loses the frame, as the kernel's broadcast manager
                    // loses one the device queue refuses; the job goes on.
                    if conn.send(frame).is_ok() {
                        conn.loop_back(frame);
                    }
                }
            }
            for rx in due.deliver.drain(..) {
                conn.deliver_kept(&me, &rx);
            }
        }
    }
}

/// How often an idle broadcast-manager timer looks whether its connection ended.
const IDLE_POLL: Duration = Duration::from_millis(100);

impl Selector for BcmEngine {
    fn select(&self, rx: &Received) -> bool {
        let (passed, replan) = {
            let mut st = self.lock();
            let passed = !st.stop && st.bcm.on_frame(rx, Instant::now()).is_some();
            (passed, st.bcm.take_replan())
        };
        if replan {
            // A held frame started a throttle timer.
            self.changed.notify_all();
        }
        passed
    }

    fn still_selects(&self, rx: &Received) -> bool {
        let st = self.lock();
        !st.stop && st.bcm.receives(rx.frame.id())
    }

    fn write(&self, rx: &Received, out: &mut Vec<u8>) -> bool {
        wire::write_bcm_frame(out, &rx.frame, rx.timestamp)
    }
}

fn error(link: &mut Link<'_>, text: &str) -> io::Result<()> {
    let mut out = Vec::with_capacity(16 + text.len());
    wire::write_error(&mut out, text);
    link.error(&out)
}

impl ScSession {
    /// The broadcast manager of this BCM session, started (with its timer thread and as the
    /// stream's selector) on first use.
    fn bcm(&mut self, link: &mut Link<'_>) -> io::Result<Arc<BcmEngine>> {
        if let Some(engine) = &self.bcm {
            return Ok(Arc::clone(engine));
        }
        let engine = Arc::new(BcmEngine {
            gate: Mutex::new(()),
            state: Mutex::new(BcmState {
                bcm: Bcm::new(link.limits().bcm_jobs),
                stop: false,
            }),
            changed: Condvar::new(),
        });
        let conn = link.handle();
        let timer = Arc::clone(&engine);
        thread::Builder::new()
            .name("socketcand-bcm".into())
            .spawn(move || timer.run(&conn))?;
        link.select(Some(Arc::clone(&engine) as Arc<dyn Selector>));
        link.forward(true);
        self.bcm = Some(Arc::clone(&engine));
        Ok(engine)
    }

    /// End the broadcast manager's jobs and subscriptions.
    fn leave_bcm(&mut self) {
        if let Some(engine) = self.bcm.take() {
            engine.stop();
        }
    }

    /// A broadcast-manager command, in BCM mode. Like the daemon, a command that succeeds has
    /// no reply (nor has `delete` or `unsubscribe` of something that does not exist).
    fn on_bcm(&mut self, cmd: Command, link: &mut Link<'_>) -> io::Result<()> {
        let engine = self.bcm(link)?;
        let now = Instant::now();
        let mut flushed = Vec::new();
        let done = match cmd {
            Command::Add { interval, frame } => engine.with(|b| b.add(interval, frame, now)),
            Command::Update(frame) => engine.with(|b| b.update(frame)),
            Command::Delete(id) => {
                engine.with(|b| b.delete(id));
                Ok(())
            }
            Command::Subscribe { throttle, id } => {
                engine.with(|b| b.subscribe(id, throttle, &mut flushed))
            }
            Command::Filter { throttle, id, mask } => {
                engine.with(|b| b.filter(id, throttle, &mask, &mut flushed))
            }
            // Never throttled, as by the daemon (see the broadcast manager's module).
            Command::MuxFilter { id, masks, .. } => {
                engine.with(|b| b.muxfilter(id, &masks, &mut flushed))
            }
            Command::Unsubscribe(id) => {
                engine.with(|b| b.unsubscribe(id));
                Ok(())
            }
            _ => Ok(()),
        };
        if done.is_err() {
            // The kernel refuses an operation it has no memory for (`ENOMEM`), which the
            // daemon does not report; a client told why is better served, in the daemon's
            // error element (`doc/protocol.md`, "< error ... >").
            return error(link, "too many broadcast manager jobs");
        }
        let me: Arc<dyn Selector> = engine;
        let conn = link.handle();
        for rx in &flushed {
            conn.deliver_kept(&me, rx);
        }
        Ok(())
    }

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
                self.leave_bcm();
                // The stream starts with the frames that reach the bus port from now on, so
                // that a client may act on the bus as soon as it reads `< ok >`; the first
                // frame is written only after a pause, so the `< ok >` is read alone.
                link.select(None);
                link.forward(true);
                link.reply(wire::OK)
            }
            (Command::BcmMode, State::Bcm) => link.reply(wire::OK),
            (Command::BcmMode, _) => {
                self.state = State::Bcm;
                link.forward(false);
                link.select(None);
                link.reply(wire::OK)
            }
            (cmd, State::Bcm) if cmd.is_broadcast_manager() => self.on_bcm(cmd, link),
            (cmd, State::NoBus) if cmd.is_broadcast_manager() => error(link, "no bus open"),
            // As the daemon answers a broadcast-manager command in raw mode.
            (cmd, State::Raw) if cmd.is_broadcast_manager() => error(link, "unknown command"),
            (Command::Send(frame), state) => match link.send(frame) {
                Ok(()) => {
                    // The kernel loops a socket's frames back to its broadcast manager.
                    if state == State::Bcm && self.bcm.is_some() {
                        link.handle().loop_back(frame);
                    }
                    Ok(())
                }
                Err(PortError::TxQueueFull) => error(link, "transmit queue full"),
                Err(PortError::Frame(_)) => error(link, "invalid frame"),
                // The bus is gone: end the session as the daemon does when its socket fails.
                Err(e) => Err(io::Error::new(io::ErrorKind::BrokenPipe, e)),
            },
            (_, _) => error(link, "command not supported"),
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
