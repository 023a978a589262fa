//! Fault injection rules, applied when a frame starts on the bus and decided by the bus's
//! seeded [`SplitMix64`](crate::SplitMix64), so a scenario replays identically.

use cantwin_can::Id;

use crate::ids::PortId;

/// What happens to a frame a rule selects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultAction {
    /// The frame occupies the bus and is acknowledged (the sender sees success and its
    /// `on_sent` runs) but no node receives it: loss above the wire, such as every receiver
    /// overrunning. Taps see it with `dropped: true`.
    Drop,
    /// A bit of the frame is flipped on the wire at the last bit of the CRC sequence. The
    /// transmitter, which monitors every bit it sends, detects a bit error there
    /// (ISO 11898-1 §10.11) and starts an error flag at the next bit, where the CRC delimiter
    /// would be; see [`crate::ErrorKind::Corrupted`] for the timing.
    Corrupt,
}

/// Which transmission attempts a rule selects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameSelector {
    /// The attempt with this number: attempts are every start of frame on the bus,
    /// retransmissions included, numbered from 0.
    Attempt(u64),
    /// Each attempt independently with this probability (0.0–1.0), drawn from the bus's seeded
    /// generator.
    Fraction(f64),
    /// Every attempt carrying this identifier.
    Id(Id),
    /// Every attempt.
    All,
}

/// One fault injection rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultRule {
    /// What to do with a selected frame.
    pub action: FaultAction,
    /// Which attempts are selected.
    pub selector: FrameSelector,
    /// Only frames sent by this port, if set.
    pub sender: Option<PortId>,
    /// How many more frames the rule may hit; `None` for no limit.
    pub remaining: Option<u64>,
}

impl FaultRule {
    /// Drop the frames `selector` picks.
    pub const fn drop(selector: FrameSelector) -> Self {
        FaultRule {
            action: FaultAction::Drop,
            selector,
            sender: None,
            remaining: None,
        }
    }

    /// Corrupt the frames `selector` picks.
    pub const fn corrupt(selector: FrameSelector) -> Self {
        FaultRule {
            action: FaultAction::Corrupt,
            selector,
            sender: None,
            remaining: None,
        }
    }

    /// Restrict the rule to frames sent by `port`.
    pub const fn from_port(mut self, port: PortId) -> Self {
        self.sender = Some(port);
        self
    }

    /// Let the rule hit at most `n` frames.
    pub const fn times(mut self, n: u64) -> Self {
        self.remaining = Some(n);
        self
    }
}
