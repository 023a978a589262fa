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
    /// The entry the controller offers next, held apart from the others so that a single
    /// mailbox (and every queue's usual case) never touches the allocation behind `rest`,
    /// and arbitration reads the head from the port itself.
    head: Option<Entry>,
    /// The other entries, in queueing (sequence) order.
    rest: VecDeque<Entry>,
    depth: usize,
    order: TxOrder,
    next_seq: u64,
}

impl TxQueue {
    pub fn new(depth: usize, order: TxOrder) -> Self {
        TxQueue {
            head: None,
            rest: VecDeque::with_capacity(depth.saturating_sub(1).min(64)),
            depth,
            order,
            next_seq: 0,
        }
    }

    #[inline]
    pub fn len(&self) -> usize {
        usize::from(self.head.is_some()) + self.rest.len()
    }

    /// Queue a frame; `false` (and nothing queued) when the queue is full.
    #[inline]
    pub fn push(&mut self, frame: Frame, bits: u32) -> bool {
        if self.len() >= self.depth {
            return false;
        }
        let seq = self.next_seq;
        self.next_seq += 1;
        let entry = Entry { frame, bits, seq };
        match self.head {
            None => self.head = Some(entry),
            // A newer frame goes first only with a strictly better key: the oldest among
            // equals goes first. The head it replaces is older than the new entry but maybe
            // newer than some of the rest: it goes back in sequence order.
            Some(h)
                if self.order == TxOrder::Priority
                    && frame.arbitration_key() < h.frame.arbitration_key() =>
            {
                let pos = self.rest.partition_point(|e| e.seq < h.seq);
                self.rest.insert(pos, h);
                self.head = Some(entry);
            }
            Some(_) => self.rest.push_back(entry),
        }
        true
    }

    /// The frame the controller offers to arbitration next.
    #[inline]
    pub fn head(&self) -> Option<&Entry> {
        self.head.as_ref()
    }

    /// Take the next head out of `rest`, as the queue's order picks it.
    fn promote(&mut self) {
        let pos = match self.order {
            TxOrder::Fifo => 0,
            // `rest` is in sequence order, so the first minimum is the oldest among equals.
            TxOrder::Priority => {
                let mut best = 0;
                for (k, e) in self.rest.iter().enumerate().skip(1) {
                    if e.frame.arbitration_key() < self.rest[best].frame.arbitration_key() {
                        best = k;
                    }
                }
                best
            }
        };
        self.head = self.rest.remove(pos);
    }

    /// Remove the entry with sequence number `seq` (a frame that was transmitted).
    #[inline]
    pub fn remove(&mut self, seq: u64) -> Option<Entry> {
        match self.head {
            // The head is the usual case: it is what won arbitration.
            Some(h) if h.seq == seq => {
                self.head = None;
                if !self.rest.is_empty() {
                    self.promote();
                }
                Some(h)
            }
            _ => {
                let pos = self.rest.iter().position(|e| e.seq == seq)?;
                self.rest.remove(pos)
            }
        }
    }

    /// Discard everything; returns how many frames were discarded.
    pub fn clear(&mut self) -> usize {
        let n = self.len();
        self.head = None;
        self.rest.clear();
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

    /// The head as the queue's order picks it from all its entries (sequence order).
    fn picked(q: &TxQueue) -> Option<u64> {
        let mut all: Vec<Entry> = q.head.iter().chain(q.rest.iter()).copied().collect();
        all.sort_by_key(|e| e.seq);
        match q.order {
            TxOrder::Fifo => all.first().map(|e| e.seq),
            TxOrder::Priority => all
                .iter()
                .reduce(|best, e| {
                    if e.frame.arbitration_key() < best.frame.arbitration_key() {
                        e
                    } else {
                        best
                    }
                })
                .map(|e| e.seq),
        }
    }

    proptest::proptest! {
        /// Against a plain list in queueing order: the same frames are refused, the same
        /// head is offered, and removing any frame leaves the same queue.
        #[test]
        fn the_queue_matches_a_list_in_queueing_order(
            priority in proptest::bool::ANY,
            depth in 1usize..5,
            ops in proptest::collection::vec((0u8..4, 0u16..6), 1..120)
        ) {
            let order = if priority { TxOrder::Priority } else { TxOrder::Fifo };
            let mut q = TxQueue::new(depth, order);
            let mut model: Vec<(u64, u16)> = Vec::new();
            let mut seq = 0u64;
            for (op, v) in ops {
                match op {
                    // Queue a frame (the identifier from few values, so keys tie).
                    0 | 1 => {
                        let id = 0x100 + v;
                        let fits = model.len() < depth;
                        proptest::prop_assert_eq!(q.push(f(id), 0), fits);
                        if fits {
                            model.push((seq, id));
                            seq += 1;
                        }
                    }
                    // Send the head.
                    2 => {
                        if let Some(h) = q.head().copied() {
                            proptest::prop_assert_eq!(q.remove(h.seq).map(|e| e.seq), Some(h.seq));
                            model.retain(|e| e.0 != h.seq);
                        }
                    }
                    // Remove some other frame (the one sent while a better one was queued).
                    _ => {
                        if !model.is_empty() {
                            let (s, _) = model[usize::from(v) % model.len()];
                            proptest::prop_assert_eq!(q.remove(s).map(|e| e.seq), Some(s));
                            model.retain(|e| e.0 != s);
                        }
                    }
                }
                let expected = match order {
                    TxOrder::Fifo => model.first(),
                    TxOrder::Priority => model.iter().reduce(|b, e| if e.1 < b.1 { e } else { b }),
                };
                proptest::prop_assert_eq!(q.head().map(|e| e.seq), expected.map(|e| e.0));
                proptest::prop_assert_eq!(q.len(), model.len());
            }
        }
    }

    #[test]
    fn the_kept_head_is_the_head_the_order_picks() {
        for order in [TxOrder::Priority, TxOrder::Fifo] {
            let mut q = TxQueue::new(4, order);
            let ids = [0x300, 0x100, 0x100, 0x200, 0x050, 0x400, 0x050];
            let mut k = 0;
            for step in 0..40 {
                if step % 3 == 2 {
                    if let Some(h) = q.head().copied() {
                        assert_eq!(q.remove(h.seq).map(|e| e.seq), Some(h.seq));
                    }
                } else if q.push(f(ids[k % ids.len()]), k as u32) {
                    k += 1;
                }
                assert_eq!(q.head().map(|e| e.seq), picked(&q));
                assert!(
                    q.rest
                        .iter()
                        .zip(q.rest.iter().skip(1))
                        .all(|(a, b)| a.seq < b.seq)
                );
            }
            // A frame other than the head leaves: the head stays.
            let h = q.head().map(|e| e.seq);
            if let Some(seq) = q.rest.front().map(|e| e.seq) {
                let n = q.len();
                assert_eq!(q.remove(seq).map(|e| e.seq), Some(seq));
                assert_eq!((q.head().map(|e| e.seq), q.len()), (h, n - 1));
            }
            assert!(q.remove(u64::MAX).is_none());
            let n = q.len();
            assert_eq!(q.clear(), n);
            assert!(q.head().is_none());
            assert_eq!(q.len(), 0);
        }
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
