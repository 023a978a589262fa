//! The dashboard's connections: at most a fixed number at once, each served by hyper's
//! HTTP/1 connection with its header-read timeout, and closed when nothing moves on it for the
//! idle timeout.
//!
//! The process shares its descriptors with the gateways, so the cap is what keeps their
//! reserve: a connection over it is accepted, answered 503 and closed at once, rather than
//! left in the listen backlog where a client waits on it indefinitely. Accepting it costs a
//! descriptor for the moment of the answer only.

use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::Instant;

/// The bounds of the dashboard's connections.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Connections served at once.
    pub max_connections: usize,
    /// How long a request's head may take to arrive, from the connection's opening or the
    /// end of the previous answer on it.
    pub header_timeout: Duration,
    /// How long a connection may see no byte move either way.
    pub idle_timeout: Duration,
}

/// The kernel's send buffer per connection (`SO_SNDBUF`, which Linux doubles). Left to
/// itself the kernel grows it to megabytes for an event stream whose reader stopped reading
/// (`net.ipv4.tcp_wmem`), which both costs that memory and keeps bytes moving, so the idle
/// timeout only starts after tens of seconds. 64 KiB still carries the snapshots (tens of
/// KiB four times a second) over a 100 ms round trip.
const SEND_BUFFER: usize = 64 * 1024;

/// How long the accept loop pauses after a failed accept (out of descriptors): long enough
/// not to spin, short enough to serve again as soon as descriptors are free.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(20);

/// Accepts and serves until `stop` resolves.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: Limits,
    refusal: Arc<[u8]>,
    stop: impl std::future::Future<Output = ()>,
) {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    tokio::pin!(stop);
    loop {
        let accepted = tokio::select! {
            _ = &mut stop => return,
            a = listener.accept() => a,
        };
        let stream = match accepted {
            Ok((stream, _)) => stream,
            Err(_) => {
                tokio::time::sleep(ACCEPT_BACKOFF).await;
                continue;
            }
        };
        match slots.clone().try_acquire_owned() {
            Ok(slot) => {
                tokio::spawn(connection(stream, app.clone(), limits, slot));
            }
            Err(_) => {
                // A fresh socket's send buffer is empty: the answer goes out without
                // waiting, and dropping the stream closes it. A client whose request had
                // already arrived may see a reset instead (RFC 1122 §4.2.2.13: a close with
                // data unread), which ends its connection as promptly.
                let _ = stream.try_write(&refusal);
            }
        }
    }
}

/// Serves one connection; `_slot` is its place under the cap, given back when it ends.
async fn connection(stream: TcpStream, app: Router, limits: Limits, _slot: OwnedSemaphorePermit) {
    let _ = stream.set_nodelay(true);
    // Best effort: a socket that keeps the kernel's size is served all the same.
    let _ = socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER);
    let epoch = Instant::now();
    let moved = Arc::new(AtomicU64::new(0));
    let io = TokioIo::new(Watched {
        io: stream,
        epoch,
        moved: moved.clone(),
    });
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    let conn = http.serve_connection(io, TowerToHyperService::new(app));
    tokio::pin!(conn);
    loop {
        let seen = moved.load(Ordering::Relaxed);
        let deadline = epoch + Duration::from_millis(seen) + limits.idle_timeout;
        tokio::select! {
            _ = &mut conn => return,
            _ = tokio::time::sleep_until(deadline) => {
                if moved.load(Ordering::Relaxed) == seen {
                    // Nothing moved for the idle timeout (a stalled body, an event stream
                    // nobody reads): dropping the connection closes its socket.
                    return;
                }
            }
        }
    }
}

/// A socket that notes when a byte last moved on it (milliseconds since `epoch`).
struct Watched {
    io: TcpStream,
    epoch: Instant,
    moved: Arc<AtomicU64>,
}

impl Watched {
    fn touch(&self) {
        let ms = u64::try_from(self.epoch.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.moved.store(ms, Ordering::Relaxed);
    }
}

impl AsyncRead for Watched {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let r = Pin::new(&mut this.io).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            this.touch();
        }
        r
    }
}

impl AsyncWrite for Watched {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.touch();
        }
        r
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write_vectored(cx, bufs);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.touch();
        }
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_shutdown(cx)
    }
}
