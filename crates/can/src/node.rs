//! The sans-IO contract between a node (protocol stack, device model, gateway client) and
//! whatever drives it: the virtual bus, a socketcand gateway, real SocketCAN, a Python test.
//!
//! A node never touches a socket, a thread or a clock. The driver tells it what happened and
//! when; the node answers by putting frames into an [`Outbox`] and by saying when it next
//! wants to be woken ([`Node::next_deadline`]).

use crate::frame::Frame;
use crate::id::Id;
use crate::time::Instant;

/// Frames a node wants to send, in the order it queued them.
#[derive(Debug, Clone, Default)]
pub struct Outbox {
    frames: Vec<Frame>,
}

impl Outbox {
    /// An empty outbox.
    pub const fn new() -> Self {
        Outbox { frames: Vec::new() }
    }

    /// Queue a frame for transmission.
    #[inline]
    pub fn push(&mut self, frame: Frame) {
        self.frames.push(frame);
    }

    /// The queued frames.
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    /// How many frames are queued.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Take the queued frames out, leaving the outbox empty (and its allocation in place).
    pub fn drain(&mut self) -> std::vec::Drain<'_, Frame> {
        self.frames.drain(..)
    }

    /// Discard the queued frames.
    pub fn clear(&mut self) {
        self.frames.clear();
    }
}

/// Events of the node's own CAN controller, which CANopen and DeviceNet react to on the wire
/// (CiA 301 EMCY 0x8110/0x8120/0x8140, DeviceNet bus-off handling).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControllerEvent {
    /// A counter passed 127: the controller is error-passive.
    ErrorPassive,
    /// Both counters are back at or below 127: error-active again.
    ErrorActive,
    /// TEC passed 255: the controller is bus-off and sends nothing.
    BusOff,
    /// The controller recovered from bus-off (128 × 11 recessive bits) and is error-active.
    BusOffRecovered,
    /// A received frame was lost because the receive buffer was full.
    RxOverrun,
    /// A frame the node queued was discarded before it was sent (transmit queue full, or
    /// cleared by bus-off).
    TxDropped,
}

/// A participant on a CAN bus, driven from outside.
///
/// Drivers call [`Node::on_power_up`] once when the node is powered (and again after every
/// power cycle), [`Node::on_frame`] for each frame that passes [`Node::accepts`],
/// [`Node::on_tick`] at or after [`Node::next_deadline`], [`Node::on_sent`] when one of the
/// node's frames has been transmitted, and [`Node::on_controller_event`] when its controller
/// changes state. All of them may queue frames into the outbox.
pub trait Node {
    /// Power applied: initialise and, for CANopen, send the boot-up message.
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        let _ = (now, out);
    }

    /// A frame seen on the bus (including the node's own, if its port asked for echo).
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox);

    /// Timers: called at or after [`Node::next_deadline`].
    fn on_tick(&mut self, now: Instant, out: &mut Outbox);

    /// The next instant the node needs [`Node::on_tick`], if any.
    fn next_deadline(&self) -> Option<Instant>;

    /// One of the node's own frames finished transmission successfully at `now` (the end of
    /// its EOF). Inhibit times and "message sent" confirmations hang on this.
    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let _ = (frame, now, out);
    }

    /// The node's CAN controller changed state or lost a frame.
    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        let _ = (event, now, out);
    }

    /// The acceptance filter: whether the controller passes frames with this identifier up
    /// to the node. The default accepts everything.
    fn accepts(&self, id: Id) -> bool {
        let _ = id;
        true
    }

    /// A number that changes whenever [`Node::accepts`] may answer differently, or `None`
    /// (the default) if it may change whenever the node is called. A bus keeps every
    /// verdict it got from a node while the number stays the same, instead of asking again
    /// after each call; on a busy bus most nodes are called between two frames of the same
    /// identifier, so a node whose filter rarely changes saves that question on every frame.
    /// A node that answers `Some` must change the number (or answer `None`) before
    /// `accepts` changes, including through changes made to it between calls.
    fn acceptance_version(&self) -> Option<u64> {
        None
    }

    /// [`Node::acceptance_version`] and [`Node::next_deadline`], which a bus asks after every
    /// call into the node, in one call: through a `dyn Node` one dispatch instead of two, and
    /// the two answers computed side by side. Provided; a node has no reason to change it.
    fn after_call(&self) -> AfterCall {
        AfterCall {
            acceptance_version: self.acceptance_version(),
            next_deadline: self.next_deadline(),
        }
    }
}

/// What a node answers after every call into it ([`Node::after_call`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AfterCall {
    /// [`Node::acceptance_version`].
    pub acceptance_version: Option<u64>,
    /// [`Node::next_deadline`].
    pub next_deadline: Option<Instant>,
}

impl<N: Node + ?Sized> Node for Box<N> {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        (**self).on_power_up(now, out)
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        (**self).on_frame(frame, now, out)
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        (**self).on_tick(now, out)
    }
    fn next_deadline(&self) -> Option<Instant> {
        (**self).next_deadline()
    }
    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        (**self).on_sent(frame, now, out)
    }
    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        (**self).on_controller_event(event, now, out)
    }
    fn accepts(&self, id: Id) -> bool {
        (**self).accepts(id)
    }
    fn acceptance_version(&self) -> Option<u64> {
        (**self).acceptance_version()
    }
    fn after_call(&self) -> AfterCall {
        (**self).after_call()
    }
}

/// A node that never sends on its own and acknowledges what it sees: the port through which
/// a driver puts frames on a bus itself (a replayed master, a fuzzer, a benchmark's master).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ListenOnly;

impl Node for ListenOnly {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::Duration;

    /// A node that answers every frame with the same frame on id + 1, and ticks every 1 ms.
    struct Echo {
        next: Instant,
    }

    impl Node for Echo {
        fn on_frame(&mut self, frame: &Frame, _now: Instant, out: &mut Outbox) {
            let raw = frame.id().as_raw() as u16 + 1;
            if let Ok(f) = Frame::std(raw, frame.data_bytes()) {
                out.push(f);
            }
        }
        fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
            out.push(Frame::std(0x80, &[]).unwrap());
            self.next = now + Duration::from_millis(1);
        }
        fn next_deadline(&self) -> Option<Instant> {
            Some(self.next)
        }
        fn accepts(&self, id: Id) -> bool {
            id.as_raw() < 0x100
        }
    }

    #[test]
    fn contract_is_object_safe_and_drivable() {
        let mut node: Box<dyn Node> = Box::new(Echo {
            next: Instant::ZERO,
        });
        let mut out = Outbox::new();
        node.on_power_up(Instant::ZERO, &mut out);
        assert!(out.is_empty());
        node.on_frame(&Frame::std(0x10, &[1]).unwrap(), Instant::ZERO, &mut out);
        node.on_tick(Instant::ZERO, &mut out);
        let sent: Vec<String> = out.drain().map(|f| f.to_string()).collect();
        assert_eq!(sent, ["011#01", "080#"]);
        assert!(out.is_empty());
        assert_eq!(node.next_deadline(), Some(Instant::from_nanos(1_000_000)));
        assert!(node.accepts(Id::standard(0xFF).unwrap()));
        assert!(!node.accepts(Id::standard(0x100).unwrap()));
    }
}
