//! An in-memory bus without timing: every frame sent on a port is delivered at once to every
//! other port on the same channel.
//!
//! It has the receive semantics of a real bus port (all frames but one's own, a bounded
//! receive buffer whose overflow is counted and never blocks the sender) but no arbitration and
//! no bus time. It is what gateway tests and library users plug in when the frames matter and
//! the timing does not.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, Weak};
use std::time::{Duration, Instant, SystemTime};

use cantwin_can::Frame;

use crate::port::{BusConnector, BusPort, PortError, Received};

/// A set of named in-memory buses.
///
/// ```
/// use cantwin_can::Frame;
/// use cantwin_gateway::memory::MemoryBus;
/// use cantwin_gateway::{BusConnector, BusPort};
/// use std::time::Duration;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let bus = MemoryBus::new(["vcan0"]);
/// let a = bus.open("vcan0", 16)?;
/// let b = bus.open("vcan0", 16)?;
/// a.send(Frame::std(0x123, &[1, 2])?)?;
/// let got = b.recv_timeout(Duration::from_secs(1))?.ok_or("nothing received")?;
/// assert_eq!(got.frame, Frame::std(0x123, &[1, 2])?);
/// // A port never receives its own frames.
/// assert_eq!(a.recv_timeout(Duration::ZERO)?, None);
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct MemoryBus {
    channels: Arc<HashMap<String, Arc<Channel>>>,
}

#[derive(Debug, Default)]
struct Channel {
    ports: Mutex<Vec<Weak<Inbox>>>,
}

#[derive(Debug)]
struct Inbox {
    queue: Mutex<VecDeque<Received>>,
    ready: Condvar,
    capacity: usize,
    overflows: AtomicU64,
}

impl Inbox {
    fn lock(&self) -> MutexGuard<'_, VecDeque<Received>> {
        // A poisoned queue still holds valid frames: keep going.
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn deliver(&self, rx: Received) {
        let mut q = self.lock();
        if q.len() >= self.capacity {
            self.overflows.fetch_add(1, Ordering::Relaxed);
        } else {
            q.push_back(rx);
            self.ready.notify_one();
        }
    }
}

impl MemoryBus {
    /// Buses with these channel names.
    pub fn new<I, S>(channels: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        MemoryBus {
            channels: Arc::new(
                channels
                    .into_iter()
                    .map(|c| (c.into(), Arc::new(Channel::default())))
                    .collect(),
            ),
        }
    }

    /// Deliver `frame` to every port on `channel` as if a node without a port had sent it at
    /// `timestamp`; `false` for an unknown channel.
    pub fn inject(&self, channel: &str, frame: Frame, timestamp: SystemTime) -> bool {
        let Some(ch) = self.channels.get(channel) else {
            return false;
        };
        let ports = ch.ports.lock().unwrap_or_else(|e| e.into_inner());
        for port in ports.iter().filter_map(Weak::upgrade) {
            port.deliver(Received { frame, timestamp });
        }
        true
    }

    /// How many ports are attached to `channel` right now (0 for an unknown channel).
    pub fn attached(&self, channel: &str) -> usize {
        self.channels.get(channel).map_or(0, |c| {
            let mut ports = c.ports.lock().unwrap_or_else(|e| e.into_inner());
            ports.retain(|p| p.strong_count() > 0);
            ports.len()
        })
    }
}

/// A port on a [`MemoryBus`]. Dropping it detaches it.
#[derive(Debug)]
pub struct MemoryPort {
    channel: Arc<Channel>,
    inbox: Arc<Inbox>,
}

impl BusConnector for MemoryBus {
    fn open(&self, channel: &str, rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        let ch = self
            .channels
            .get(channel)
            .ok_or_else(|| PortError::UnknownChannel(channel.to_owned()))?;
        let inbox = Arc::new(Inbox {
            queue: Mutex::new(VecDeque::new()),
            ready: Condvar::new(),
            capacity: rx_capacity.max(1),
            overflows: AtomicU64::new(0),
        });
        let mut ports = ch.ports.lock().unwrap_or_else(|e| e.into_inner());
        ports.retain(|p| p.strong_count() > 0);
        ports.push(Arc::downgrade(&inbox));
        Ok(Box::new(MemoryPort {
            channel: Arc::clone(ch),
            inbox,
        }))
    }
}

impl BusPort for MemoryPort {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        let rx = Received {
            frame,
            timestamp: SystemTime::now(),
        };
        let ports = self.channel.ports.lock().unwrap_or_else(|e| e.into_inner());
        for port in ports.iter().filter_map(Weak::upgrade) {
            if !Arc::ptr_eq(&port, &self.inbox) {
                port.deliver(rx);
            }
        }
        Ok(())
    }

    fn recv_timeout(&self, timeout: Duration) -> Result<Option<Received>, PortError> {
        let deadline = Instant::now().checked_add(timeout);
        let mut q = self.inbox.lock();
        loop {
            if let Some(rx) = q.pop_front() {
                return Ok(Some(rx));
            }
            let left = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => Duration::from_secs(3600),
            };
            if left.is_zero() {
                return Ok(None);
            }
            q = self
                .inbox
                .ready
                .wait_timeout(q, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    fn overflows(&self) -> u64 {
        self.inbox.overflows.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overflow_is_counted_and_never_blocks_the_sender() {
        let bus = MemoryBus::new(["can0"]);
        let a = bus.open("can0", 4).unwrap();
        let b = bus.open("can0", 2).unwrap();
        for i in 0..5u8 {
            a.send(Frame::std(0x100, &[i]).unwrap()).unwrap();
        }
        assert_eq!(b.overflows(), 3);
        let first = b.recv_timeout(Duration::ZERO).unwrap().unwrap();
        assert_eq!(first.frame.data_bytes(), &[0]);
        let second = b.recv_timeout(Duration::ZERO).unwrap().unwrap();
        assert_eq!(second.frame.data_bytes(), &[1]);
        assert_eq!(b.recv_timeout(Duration::ZERO).unwrap(), None);
    }

    #[test]
    fn unknown_channel_and_detach() {
        let bus = MemoryBus::new(["can0"]);
        assert_eq!(
            bus.open("can1", 1).err(),
            Some(PortError::UnknownChannel("can1".into()))
        );
        let a = bus.open("can0", 1).unwrap();
        assert_eq!(bus.attached("can0"), 1);
        drop(a);
        assert_eq!(bus.attached("can0"), 0);
    }
}
