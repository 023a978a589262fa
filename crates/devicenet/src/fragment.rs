//! The fragmentation protocol (DeviceNet Vol. 1 §4, "Fragmentation Protocol").
//!
//! Explicit messages longer than one frame travel acknowledged: the receiver answers every
//! fragment with an acknowledge, the sender sends the next fragment only after it, retries
//! once after [`ACK_TIMEOUT`] and then gives up. I/O messages travel unacknowledged: the
//! receiver concatenates fragments until the last one and drops the message on any gap.

use crate::wire::{FragByte, FragKind, ack_status};
use cantwin_can::{Duration, Instant};

/// How long a sender waits for the acknowledge of a fragment before sending it again.
pub const ACK_TIMEOUT: Duration = Duration::from_millis(1000);

/// How many times a fragment is sent again after an acknowledge timeout before the
/// transfer is aborted.
pub const ACK_RETRIES: u8 = 1;

/// What the receiver of an explicit fragment does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RxOutcome {
    /// Acknowledge `count` with `status`; the message is not complete.
    Ack {
        /// The acknowledged count.
        count: u8,
        /// [`ack_status`] value.
        status: u8,
    },
    /// Acknowledge `count`; the message is complete.
    Complete {
        /// The acknowledged count.
        count: u8,
        /// The reassembled body (service byte onward).
        body: Vec<u8>,
    },
    /// Out of sequence: the partial message was discarded, nothing is sent.
    Discard,
}

/// Reassembles one acknowledged explicit message.
#[derive(Debug, Clone)]
pub struct ExplicitReassembler {
    buf: Vec<u8>,
    max: usize,
    /// The count expected next, while a message is in progress.
    expected: Option<u8>,
    /// The last count acknowledged: a repeat of it (our acknowledge was lost) is
    /// acknowledged again without being appended.
    last_acked: Option<u8>,
}

impl ExplicitReassembler {
    /// A reassembler accepting bodies of at most `max` bytes.
    pub fn new(max: usize) -> Self {
        ExplicitReassembler {
            buf: Vec::new(),
            max,
            expected: None,
            last_acked: None,
        }
    }

    /// Whether a message is partly received.
    pub fn in_progress(&self) -> bool {
        self.expected.is_some()
    }

    /// Forget any partial message.
    pub fn reset(&mut self) {
        self.buf.clear();
        self.expected = None;
        self.last_acked = None;
    }

    /// A fragment arrived.
    pub fn on_fragment(&mut self, frag: FragByte, data: &[u8]) -> RxOutcome {
        match frag.kind {
            FragKind::Ack => RxOutcome::Discard,
            FragKind::First => {
                // A first fragment always starts over, even mid-message.
                self.buf.clear();
                self.buf.extend_from_slice(data);
                self.last_acked = Some(frag.count);
                if self.buf.len() > self.max {
                    self.reset();
                    return RxOutcome::Ack {
                        count: frag.count,
                        status: ack_status::TOO_MUCH_DATA,
                    };
                }
                self.expected = Some((frag.count + 1) & 0x3F);
                RxOutcome::Ack {
                    count: frag.count,
                    status: ack_status::SUCCESS,
                }
            }
            FragKind::Middle | FragKind::Last => {
                if self.last_acked == Some(frag.count) {
                    return RxOutcome::Ack {
                        count: frag.count,
                        status: ack_status::SUCCESS,
                    };
                }
                if self.expected != Some(frag.count) {
                    self.reset();
                    return RxOutcome::Discard;
                }
                if self.buf.len() + data.len() > self.max {
                    self.reset();
                    return RxOutcome::Ack {
                        count: frag.count,
                        status: ack_status::TOO_MUCH_DATA,
                    };
                }
                self.buf.extend_from_slice(data);
                self.last_acked = Some(frag.count);
                if frag.kind == FragKind::Last {
                    self.expected = None;
                    RxOutcome::Complete {
                        count: frag.count,
                        body: core::mem::take(&mut self.buf),
                    }
                } else {
                    self.expected = Some((frag.count + 1) & 0x3F);
                    RxOutcome::Ack {
                        count: frag.count,
                        status: ack_status::SUCCESS,
                    }
                }
            }
        }
    }
}

/// Progress of an acknowledged fragmented send.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TxProgress {
    /// Send this frame data now.
    Send(Vec<u8>),
    /// The last fragment was acknowledged.
    Done,
    /// The transfer was abandoned (acknowledge with an error status, or no acknowledge
    /// after the retries).
    Aborted,
    /// The acknowledge was not for the fragment in flight; nothing to do.
    Ignored,
}

/// Sends one fragmented explicit message, fragment by fragment, on acknowledges.
#[derive(Debug, Clone)]
pub struct ExplicitSender {
    frames: Vec<Vec<u8>>,
    /// Index of the fragment awaiting its acknowledge.
    current: usize,
    deadline: Instant,
    retries_left: u8,
}

impl ExplicitSender {
    /// Start sending `frames` (from [`crate::wire::explicit_frames`]); returns the sender and
    /// the first frame's data.
    pub fn start(frames: Vec<Vec<u8>>, now: Instant) -> (Self, Vec<u8>) {
        let first = frames.first().cloned().unwrap_or_default();
        (
            ExplicitSender {
                frames,
                current: 0,
                deadline: now + ACK_TIMEOUT,
                retries_left: ACK_RETRIES,
            },
            first,
        )
    }

    /// When the acknowledge of the fragment in flight is due.
    pub fn deadline(&self) -> Instant {
        self.deadline
    }

    fn count(&self) -> u8 {
        (self.current % 64) as u8
    }

    /// An acknowledge arrived.
    pub fn on_ack(&mut self, count: u8, status: u8, now: Instant) -> TxProgress {
        if count != self.count() {
            return TxProgress::Ignored;
        }
        if status != ack_status::SUCCESS {
            return TxProgress::Aborted;
        }
        self.current += 1;
        match self.frames.get(self.current) {
            None => TxProgress::Done,
            Some(f) => {
                self.deadline = now + ACK_TIMEOUT;
                self.retries_left = ACK_RETRIES;
                TxProgress::Send(f.clone())
            }
        }
    }

    /// Time passed; call at or after [`ExplicitSender::deadline`].
    pub fn on_tick(&mut self, now: Instant) -> Option<TxProgress> {
        if now < self.deadline {
            return None;
        }
        if self.retries_left == 0 {
            return Some(TxProgress::Aborted);
        }
        self.retries_left -= 1;
        self.deadline = now + ACK_TIMEOUT;
        self.frames
            .get(self.current)
            .map(|f| TxProgress::Send(f.clone()))
    }
}

/// Reassembles unacknowledged I/O fragments.
#[derive(Debug, Clone, Default)]
pub struct IoReassembler {
    buf: Vec<u8>,
    expected: Option<u8>,
    max: usize,
}

impl IoReassembler {
    /// A reassembler for messages of at most `max` bytes.
    pub fn new(max: usize) -> Self {
        IoReassembler {
            buf: Vec::new(),
            expected: None,
            max,
        }
    }

    /// A frame of a fragmented I/O connection arrived; returns the message when complete.
    /// A gap, an overlong message or a fragment without a first one drops the message.
    pub fn on_frame(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        let (&b, rest) = data.split_first()?;
        let frag = FragByte::decode(b);
        match frag.kind {
            FragKind::First => {
                self.buf.clear();
                self.buf.extend_from_slice(rest);
                self.expected = Some((frag.count + 1) & 0x3F);
                None
            }
            FragKind::Middle | FragKind::Last if self.expected == Some(frag.count) => {
                self.buf.extend_from_slice(rest);
                if self.buf.len() > self.max {
                    self.expected = None;
                    self.buf.clear();
                    return None;
                }
                if frag.kind == FragKind::Last {
                    self.expected = None;
                    Some(core::mem::take(&mut self.buf))
                } else {
                    self.expected = Some((frag.count + 1) & 0x3F);
                    None
                }
            }
            _ => {
                self.expected = None;
                self.buf.clear();
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{Header, MacId, explicit_frames, io_fragments};

    fn fb(b: u8) -> FragByte {
        FragByte::decode(b)
    }

    #[test]
    fn reassembles_and_reacks_duplicates() {
        let mut r = ExplicitReassembler::new(32);
        assert_eq!(
            r.on_fragment(fb(0x00), &[1, 2, 3, 4, 5, 6]),
            RxOutcome::Ack {
                count: 0,
                status: 0
            }
        );
        // The master did not see our ack and sends fragment 0 again... as a first: restart.
        assert_eq!(
            r.on_fragment(fb(0x00), &[1, 2, 3, 4, 5, 6]),
            RxOutcome::Ack {
                count: 0,
                status: 0
            }
        );
        assert_eq!(
            r.on_fragment(fb(0x41), &[7]),
            RxOutcome::Ack {
                count: 1,
                status: 0
            }
        );
        // Repeat of fragment 1: acknowledged again, not appended.
        assert_eq!(
            r.on_fragment(fb(0x41), &[7]),
            RxOutcome::Ack {
                count: 1,
                status: 0
            }
        );
        assert_eq!(
            r.on_fragment(fb(0x82), &[8]),
            RxOutcome::Complete {
                count: 2,
                body: vec![1, 2, 3, 4, 5, 6, 7, 8]
            }
        );
    }

    #[test]
    fn gap_discards_and_overflow_acks_too_much_data() {
        let mut r = ExplicitReassembler::new(8);
        r.on_fragment(fb(0x00), &[0; 6]);
        assert_eq!(r.on_fragment(fb(0x42), &[0]), RxOutcome::Discard);
        assert!(!r.in_progress());
        r.on_fragment(fb(0x00), &[0; 6]);
        assert_eq!(
            r.on_fragment(fb(0x81), &[0; 3]),
            RxOutcome::Ack {
                count: 1,
                status: ack_status::TOO_MUCH_DATA
            }
        );
    }

    #[test]
    fn sender_waits_retries_once_and_aborts() {
        let frames = explicit_frames(Header::new(false, MacId::new(1).unwrap()), &[0u8; 13]);
        assert_eq!(frames.len(), 3);
        let t0 = Instant::ZERO;
        let (mut s, first) = ExplicitSender::start(frames.clone(), t0);
        assert_eq!(first, frames[0]);
        assert_eq!(s.on_ack(1, 0, t0), TxProgress::Ignored);
        assert_eq!(s.on_ack(0, 0, t0), TxProgress::Send(frames[1].clone()));
        assert_eq!(s.on_tick(t0 + Duration::from_millis(999)), None);
        let t1 = t0 + ACK_TIMEOUT;
        assert_eq!(s.on_tick(t1), Some(TxProgress::Send(frames[1].clone())));
        assert_eq!(s.on_tick(t1 + ACK_TIMEOUT), Some(TxProgress::Aborted));
    }

    #[test]
    fn io_reassembly_round_trip_and_gap() {
        let data: Vec<u8> = (0..20).collect();
        let frames = io_fragments(&data);
        let mut r = IoReassembler::new(32);
        let mut got = None;
        for f in &frames {
            got = r.on_frame(f);
        }
        assert_eq!(got, Some(data));
        assert_eq!(r.on_frame(&frames[0]), None);
        assert_eq!(r.on_frame(&frames[2]), None);
        assert_eq!(r.on_frame(&frames[1]), None);
    }
}
