//! What a dashboard collects on each bus while the simulation runs: a tap that only copies
//! events into a bounded buffer, drained by the dashboard between snapshots, so the bus thread
//! does no formatting.

use cantwin_bus::{BusEvent, BusInfo, ErrorKind, PortId, Tap};
use cantwin_can::{ControllerEvent, Frame, Instant};

/// At most this many events wait between two drains (a 1 Mbit/s bus carries about 18 000
/// frames a second; the dashboard drains four times a second). Beyond it events are counted
/// as missed, never queued without bound.
pub const CAPACITY: usize = 8192;

/// One event as the dashboard keeps it.
#[derive(Debug, Clone, Copy)]
pub enum Seen {
    /// A frame completed (`dropped`: fault injection kept it from every receiver).
    Frame {
        /// End of frame.
        at: Instant,
        /// The frame.
        frame: Frame,
        /// Who sent it.
        sender: PortId,
        /// Dropped by an injected fault.
        dropped: bool,
    },
    /// A transmission ended in an error frame.
    Error {
        /// When the error flag started.
        at: Instant,
        /// The frame being sent.
        frame: Frame,
        /// Who sent it.
        sender: PortId,
        /// Why.
        kind: ErrorKind,
    },
    /// A controller event of a port.
    Controller {
        /// When.
        at: Instant,
        /// The port.
        port: PortId,
        /// What.
        event: ControllerEvent,
    },
}

/// The dashboard's tap on one bus.
#[derive(Debug, Default)]
pub struct DashboardTap {
    events: Vec<Seen>,
    missed: u64,
}

impl DashboardTap {
    /// Takes the events seen since the last call, and how many did not fit.
    pub fn drain(&mut self) -> (Vec<Seen>, u64) {
        (
            std::mem::take(&mut self.events),
            std::mem::take(&mut self.missed),
        )
    }
}

impl Tap for DashboardTap {
    fn on_event(&mut self, _bus: &BusInfo<'_>, event: &BusEvent) {
        if self.events.len() >= CAPACITY {
            self.missed += 1;
            return;
        }
        self.events.push(match *event {
            BusEvent::Frame(r) => Seen::Frame {
                at: r.end,
                frame: r.frame,
                sender: r.sender,
                dropped: r.dropped,
            },
            BusEvent::Error(r) => Seen::Error {
                at: r.detected,
                frame: r.frame,
                sender: r.sender,
                kind: r.kind,
            },
            BusEvent::Controller { port, event, at } => Seen::Controller { at, port, event },
        });
    }
}
