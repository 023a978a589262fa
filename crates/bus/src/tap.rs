//! Observers of everything that happens on a bus: captures (pcap, candump), tracing and
//! statistics hang here. Taps are invisible to nodes: they see events after the bus decided
//! them and cannot change them.

use std::any::Any;

use cantwin_can::{BitRate, ControllerEvent, Frame, Instant};

use crate::ids::{BusId, PortId};
use crate::time_map::TimeMap;

/// Why a transmission ended in an error frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// Nobody acknowledged: the transmitter saw a recessive ACK slot (§10.11.5) and starts
    /// its error flag at the ACK delimiter. Error bits before the flag: the frame through the
    /// ACK slot, i.e. `bit_length - 11`.
    Ack,
    /// Injected corruption ([`crate::FaultAction::Corrupt`]): a bit error at the last CRC
    /// bit; the flag starts where the CRC delimiter would be. Bits before the flag: the
    /// stuffed frame through the CRC sequence, i.e. `bit_length - 13`.
    Corrupted,
    /// A node runs at another bit rate: either the transmitter (receivers see a stuff error
    /// after six bits of the same level at the latest and flag it) or an error-active receiver
    /// that cannot decode the frame and flags it. cantwin places the flag after bit 6.
    BitRateMismatch,
    /// The transmitter vanished mid-frame (power cut, cable cut, forced bus-off): receivers
    /// see a form or stuff error at the bit where it stopped.
    Aborted,
}

impl ErrorKind {
    /// Bits of an error frame after the bits the frame got through: error flag (6), error
    /// delimiter (8) and intermission (3) (ISO 11898-1 §10.4.4, §10.4.6).
    pub const OVERHEAD_BITS: u32 = 6 + 8 + 3;
}

/// A frame that completed on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRecord {
    /// The frame.
    pub frame: Frame,
    /// The port that sent it.
    pub sender: PortId,
    /// Start of frame.
    pub start: Instant,
    /// End of EOF: when receivers got it and the sender's `on_sent` ran.
    pub end: Instant,
    /// When the bus is idle again (end of intermission).
    pub idle_at: Instant,
    /// Its length on the bus, intermission included.
    pub bits: u32,
    /// Whether fault injection dropped it (no node received it).
    pub dropped: bool,
    /// Whether it came from a babbling controller rather than the node.
    pub babble: bool,
}

/// A transmission that ended in an error frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorRecord {
    /// The frame that was being sent.
    pub frame: Frame,
    /// The port that sent it.
    pub sender: PortId,
    /// Start of frame.
    pub start: Instant,
    /// When the error flag started (counters change at this instant).
    pub detected: Instant,
    /// When the bus is idle again: after error flag, delimiter and intermission.
    pub idle_at: Instant,
    /// Bits the bus was occupied: bits before the flag plus [`ErrorKind::OVERHEAD_BITS`].
    pub bits: u32,
    /// Why.
    pub kind: ErrorKind,
}

/// Something a tap sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusEvent {
    /// A frame completed (possibly dropped by fault injection).
    Frame(FrameRecord),
    /// A transmission ended in an error frame.
    Error(ErrorRecord),
    /// A port's controller raised an event (error-passive, bus-off, transmit drop, …).
    Controller {
        /// The port.
        port: PortId,
        /// The event.
        event: ControllerEvent,
        /// When.
        at: Instant,
    },
}

/// What a tap knows about the bus an event happened on.
#[derive(Debug, Clone, Copy)]
pub struct BusInfo<'a> {
    /// The bus.
    pub id: BusId,
    /// Its name.
    pub name: &'a str,
    /// Its bit rate.
    pub bit_rate: BitRate,
    /// In a paced simulation, the mapping from bus time to wall time; `None` in virtual time.
    pub time_map: Option<TimeMap>,
}

/// An observer of bus events.
pub trait Tap: Send + 'static {
    /// Called for every event, in bus order.
    fn on_event(&mut self, bus: &BusInfo<'_>, event: &BusEvent);
}

/// A tap stored on a bus, with typed access back (see [`crate::Bus::tap`]).
pub trait AnyTap: Tap {
    /// As [`Any`], for downcasting.
    fn as_any(&self) -> &dyn Any;
    /// As mutable [`Any`], for downcasting.
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

impl<T: Tap> AnyTap for T {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// A tap made of a closure: `bus.add_tap(FnTap(|bus: &BusInfo<'_>, event: &BusEvent| …))`.
pub struct FnTap<F>(pub F);

impl<F> core::fmt::Debug for FnTap<F> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("FnTap")
    }
}

impl<F: FnMut(&BusInfo<'_>, &BusEvent) + Send + 'static> Tap for FnTap<F> {
    fn on_event(&mut self, bus: &BusInfo<'_>, event: &BusEvent) {
        (self.0)(bus, event)
    }
}

/// A tap that keeps every event in memory: for tests and short traces.
#[derive(Debug, Clone, Default)]
pub struct Recorder {
    /// The events seen, in order.
    pub events: Vec<BusEvent>,
}

impl Recorder {
    /// An empty recorder.
    pub fn new() -> Self {
        Recorder::default()
    }

    /// The completed frames, in order.
    pub fn frames(&self) -> impl Iterator<Item = &FrameRecord> {
        self.events.iter().filter_map(|e| match e {
            BusEvent::Frame(f) => Some(f),
            _ => None,
        })
    }

    /// The error frames, in order.
    pub fn errors(&self) -> impl Iterator<Item = &ErrorRecord> {
        self.events.iter().filter_map(|e| match e {
            BusEvent::Error(r) => Some(r),
            _ => None,
        })
    }

    /// The controller events, in order, as `(port, event, at)`.
    pub fn controller_events(&self) -> impl Iterator<Item = (PortId, ControllerEvent, Instant)> {
        self.events.iter().filter_map(|e| match *e {
            BusEvent::Controller { port, event, at } => Some((port, event, at)),
            _ => None,
        })
    }
}

impl Tap for Recorder {
    fn on_event(&mut self, _bus: &BusInfo<'_>, event: &BusEvent) {
        self.events.push(*event);
    }
}
