//! The seam between gateways and buses: a [`BusPort`] is one node's attachment to a bus, a
//! [`BusConnector`] hands out ports by channel name.
//!
//! Servers only ever talk to these two traits, so the same socketcand or slcan server can sit
//! on the in-process virtual bus, on the in-memory [`crate::memory::MemoryBus`], or on real
//! hardware; and the socketcand client implements them too, so a remote bus looks like a
//! local one.

use std::time::SystemTime;

use cantwin_can::{Frame, FrameError};

/// Why a port operation failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PortError {
    /// No bus with this channel name.
    #[error("no bus named {0:?}")]
    UnknownChannel(String),
    /// The node's transmit queue is full; the frame was not queued.
    #[error("transmit queue full")]
    TxQueueFull,
    /// The port was detached, or the bus or the connection behind it is gone.
    #[error("port closed")]
    Closed,
    /// A frame that cannot be carried.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The transport under the port failed (socket error, protocol violation).
    #[error("{0}")]
    Transport(String),
}

/// A frame received on a port, with the wall-clock time it completed on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The frame.
    pub frame: Frame,
    /// When the frame completed on the bus, as wall time (a virtual bus maps its bus time to
    /// the wall clock it is paced against).
    pub timestamp: SystemTime,
}

/// One node's attachment to a bus.
///
/// The port receives every frame on the bus except its own, into a bounded buffer: when the
/// buffer is full, further frames are dropped and counted ([`BusPort::overflows`]) and the
/// bus never waits. Dropping the port detaches the node.
///
/// Methods take `&self` so that one thread can block in [`BusPort::recv_timeout`] while
/// another sends.
pub trait BusPort: Send + Sync {
    /// Queue a frame for transmission. It arbitrates and takes bus time like any other node's
    /// frame; this returns once it is queued, not once it is sent.
    fn send(&self, frame: Frame) -> Result<(), PortError>;

    /// The next received frame, waiting at most `timeout`; `Ok(None)` on timeout.
    fn recv_timeout(&self, timeout: std::time::Duration) -> Result<Option<Received>, PortError>;

    /// How many received frames were dropped because the receive buffer was full.
    fn overflows(&self) -> u64;

    /// Have the bus hand every frame this port receives to `sink`, on the bus's own thread
    /// as the frame completes, instead of buffering it for [`BusPort::recv_timeout`]; frames
    /// buffered so far go to the sink first. The sink must not block.
    ///
    /// Returns whether the port does so. A port that cannot (the default) drops the sink and
    /// keeps buffering; its reader keeps calling [`BusPort::recv_timeout`].
    fn deliver_to(&self, sink: Box<dyn FnMut(Received) + Send>) -> bool {
        drop(sink);
        false
    }
}

/// Hands out ports on named buses.
pub trait BusConnector: Send + Sync {
    /// Attach a new node to the bus called `channel`, with a receive buffer of `rx_capacity`
    /// frames.
    fn open(&self, channel: &str, rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError>;

    /// As [`BusConnector::open`], for `client` (a server's client, named by its protocol
    /// and address: `socketcand 127.0.0.1:54012`), which a connector may pass on to name
    /// the port; by default the name is not kept.
    fn open_for(
        &self,
        channel: &str,
        rx_capacity: usize,
        client: &str,
    ) -> Result<Box<dyn BusPort>, PortError> {
        let _ = client;
        self.open(channel, rx_capacity)
    }
}

impl<T: BusPort + ?Sized> BusPort for Box<T> {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        (**self).send(frame)
    }
    fn recv_timeout(&self, timeout: std::time::Duration) -> Result<Option<Received>, PortError> {
        (**self).recv_timeout(timeout)
    }
    fn overflows(&self) -> u64 {
        (**self).overflows()
    }
    fn deliver_to(&self, sink: Box<dyn FnMut(Received) + Send>) -> bool {
        (**self).deliver_to(sink)
    }
}

impl<T: BusConnector + ?Sized> BusConnector for std::sync::Arc<T> {
    fn open(&self, channel: &str, rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        (**self).open(channel, rx_capacity)
    }
    fn open_for(
        &self,
        channel: &str,
        rx_capacity: usize,
        client: &str,
    ) -> Result<Box<dyn BusPort>, PortError> {
        (**self).open_for(channel, rx_capacity, client)
    }
}
