//! The ports' timer deadlines, earliest first.
//!
//! A binary min-heap of `deadline_nanos << 32 | port`: one integer comparison orders two
//! entries by deadline and then by port (ties go to the lowest port, as the bus ticks them).
//! An entry may be stale (its port's deadline changed since it was pushed); the bus skips
//! those when they come up, so a change costs one push and no search.

use cantwin_can::Instant;

#[derive(Debug, Clone, Default)]
pub(crate) struct Timers {
    /// A binary heap: every entry is at most its children `2i + 1` and `2i + 2`.
    heap: Vec<u128>,
}

impl Timers {
    #[inline]
    fn entry(at: Instant, port: usize) -> u128 {
        (u128::from(at.as_nanos()) << 32) | port as u128
    }

    /// The earliest entry: its deadline and port.
    #[inline]
    pub fn peek(&self) -> Option<(Instant, usize)> {
        self.heap.first().map(|&e| {
            (
                Instant::from_nanos((e >> 32) as u64),
                (e & 0xFFFF_FFFF) as usize,
            )
        })
    }

    /// Remove the earliest entry: the last one takes its place and sinks.
    #[inline]
    pub fn pop(&mut self) {
        let Some(last) = self.heap.pop() else {
            return;
        };
        let heap = &mut self.heap[..];
        let n = heap.len();
        if n == 0 {
            return;
        }
        let mut i = 0;
        loop {
            let left = 2 * i + 1;
            if left >= n {
                break;
            }
            let right = left + 1;
            let child = if right < n && heap[right] < heap[left] {
                right
            } else {
                left
            };
            if heap[child] >= last {
                break;
            }
            heap[i] = heap[child];
            i = child;
        }
        heap[i] = last;
    }

    /// Add port `port`'s deadline `at`: it rises while it is earlier than its parent (a
    /// deadline later than all others, the usual case, stays where it is put).
    #[inline]
    pub fn push(&mut self, at: Instant, port: usize) {
        let e = Self::entry(at, port);
        self.heap.push(e);
        let heap = &mut self.heap[..];
        let mut i = heap.len() - 1;
        while i > 0 {
            let parent = (i - 1) / 2;
            if heap[parent] <= e {
                break;
            }
            heap[i] = heap[parent];
            i = parent;
        }
        heap[i] = e;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn earliest_deadline_first_then_lowest_port() {
        let mut t = Timers::default();
        let at = Instant::from_nanos;
        t.push(at(7), 1);
        t.push(at(5), 9);
        t.push(at(5), 2);
        t.push(at(u64::MAX), 0);
        t.push(at(6), 3);
        t.push(at(5), 1);
        let mut order = Vec::new();
        while let Some(e) = t.peek() {
            order.push(e);
            t.pop();
        }
        assert_eq!(
            order,
            [
                (at(5), 1),
                (at(5), 2),
                (at(5), 9),
                (at(6), 3),
                (at(7), 1),
                (at(u64::MAX), 0)
            ]
        );
    }
}
