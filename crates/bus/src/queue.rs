//! A port's transmit queue: the controller's transmit mailboxes.

use std::collections::VecDeque;

use cantwin_can::Frame;

/// In which order a port's controller offers its pending frames to arbitration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TxOrder {
    /// The highest-priority pending frame first (lowest arbitration key), first-in first-out
    /// among equal identifiers: what controllers with several mailboxes do, and what keeps a
    /// node's own low-priority backlog from blocking its urgent frames.
    #[default]
    Priority,
    /// Strictly in the order queued (a single FIFO, as in some controllers and socket APIs).
    Fifo,
}

/// One queued frame, its cached bit length and its queueing sequence number.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Entry {
    pub frame: Frame,
    pub bits: u32,
    pub seq: u64,
}

/// A bounded transmit queue.
#[derive(Debug, Clone)]
pub(crate) struct TxQueue {
    entries: VecDeque<Entry>,
    depth: usize,
    order: TxOrder,
    next_seq: u64,
}

impl TxQueue {
    pub fn new(depth: usize, order: TxOrder) -> Self {
        TxQueue {
            entries: VecDeque::with_capacity(depth.min(64)),
            depth,
            order,
            next_seq: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Queue a frame; `false` (and nothing queued) when the queue is full.
    pub fn push(&mut self, frame: Frame, bits: u32) -> bool {
        if self.entries.len() >= self.depth {
            return false;
        }
        let seq = self.next_seq;
        self.next_seq += 1;
        self.entries.push_back(Entry { frame, bits, seq });
        true
    }

    /// The frame the controller offers to arbitration next.
    pub fn head(&self) -> Option<&Entry> {
        match self.order {
            TxOrder::Fifo => self.entries.front(),
            TxOrder::Priority if self.entries.len() <= 1 => self.entries.front(),
            // Entries are in sequence order, so the first minimum is the oldest among equals.
            TxOrder::Priority => self.entries.iter().reduce(|best, e| {
                if e.frame.arbitration_key() < best.frame.arbitration_key() {
                    e
                } else {
                    best
                }
            }),
        }
    }

    /// Remove the entry with sequence number `seq` (a frame that was transmitted).
    pub fn remove(&mut self, seq: u64) -> Option<Entry> {
        // The head is the usual case (a single mailbox, a FIFO, or the oldest frame won).
        if self.entries.front().is_some_and(|e| e.seq == seq) {
            return self.entries.pop_front();
        }
        let pos = self.entries.iter().position(|e| e.seq == seq)?;
        self.entries.remove(pos)
    }

    /// Discard everything; returns how many frames were discarded.
    pub fn clear(&mut self) -> usize {
        let n = self.entries.len();
        self.entries.clear();
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(id: u16) -> Frame {
        Frame::std(id, &[]).unwrap()
    }

    #[test]
    fn priority_order_picks_lowest_id_then_oldest() {
        let mut q = TxQueue::new(4, TxOrder::Priority);
        assert!(q.push(f(0x300), 1));
        assert!(q.push(f(0x100), 1));
        assert!(q.push(f(0x100), 2));
        assert!(q.push(f(0x200), 1));
        assert!(!q.push(f(0x000), 1), "depth 4");
        let h = *q.head().unwrap();
        assert_eq!((h.frame.id().as_raw(), h.bits), (0x100, 1));
        q.remove(h.seq);
        assert_eq!(q.head().unwrap().bits, 2);
    }

    #[test]
    fn fifo_order_is_queue_order() {
        let mut q = TxQueue::new(2, TxOrder::Fifo);
        q.push(f(0x300), 1);
        q.push(f(0x100), 1);
        assert_eq!(q.head().unwrap().frame.id().as_raw(), 0x300);
        assert_eq!(q.clear(), 2);
        assert!(q.head().is_none());
    }
}
