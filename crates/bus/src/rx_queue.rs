//! The bounded receive queue between a simulated bus and a reader on another thread.
//!
//! The simulation pushes every frame a port receives; the reader takes them, blocking up to a
//! timeout. The simulation never waits for the reader: a full queue loses frames and counts
//! them, as a controller's receive FIFO does.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// A frame an external port received, with the bus time it completed (end of EOF).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The frame.
    pub frame: cantwin_can::Frame,
    /// When it completed.
    pub at: cantwin_can::Instant,
}

/// The most frames allocated up front: a large capacity is a limit, not a promise to fill it.
const PREALLOCATE: usize = 4096;

/// The queue was closed and every frame queued before was taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the receive queue is closed")]
pub struct RxClosed;

/// A bounded, thread-safe FIFO of received frames, filled by a simulation and emptied by a
/// reader (`Send + Sync`; share it in an `Arc`).
///
/// # Overflow
///
/// When the queue holds its capacity, a pushed frame is dropped and counted
/// ([`RxQueue::overruns`]); the frames already queued stay. This is what a CAN controller's
/// receive FIFO does on overrun (the SJA1000 loses the incoming message and sets its data
/// overrun flag; bxCAN does the same with its FIFO locked), so a reader sees the oldest frames
/// in order and then a gap, never a reordered or silently shortened history.
///
/// # Closing
///
/// [`RxQueue::close`] ends the queue: further pushes are refused (not counted as overruns:
/// nobody is listening any more), blocked readers wake, and readers get the frames queued
/// before the close and then [`RxClosed`].
///
/// A panic on another thread while it held the lock does not make the queue unusable: every
/// operation leaves the queue consistent, so a poisoned lock is taken over as it is.
///
/// ```
/// use std::time::Duration;
/// use cantwin_bus::{Received, RxClosed, RxQueue};
/// use cantwin_can::{Frame, Instant};
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let q = RxQueue::new(1);
/// let frame = |b| Frame::std(0x181, &[b]).map(|frame| Received { frame, at: Instant::ZERO });
/// assert!(q.push(frame(1)?));
/// assert!(!q.push(frame(2)?)); // full: the newest frame is lost
/// assert_eq!(q.overruns(), 1);
/// q.close();
/// let first = q.recv_timeout(Duration::from_secs(1))?.ok_or("nothing queued")?;
/// assert_eq!(first.frame.data_bytes(), [1]);
/// assert_eq!(q.recv_timeout(Duration::from_secs(1)), Err(RxClosed));
/// # Ok(())
/// # }
/// ```
#[derive(Debug)]
pub struct RxQueue {
    state: Mutex<State>,
    ready: Condvar,
}

#[derive(Debug)]
struct State {
    frames: VecDeque<Received>,
    capacity: usize,
    overruns: u64,
    closed: bool,
}

impl RxQueue {
    /// An open, empty queue holding up to `capacity` frames (at least one: a queue that holds
    /// nothing would lose every frame).
    pub fn new(capacity: usize) -> Self {
        RxQueue {
            state: Mutex::new(State {
                frames: VecDeque::with_capacity(capacity.min(PREALLOCATE)),
                capacity: capacity.max(1),
                overruns: 0,
                closed: false,
            }),
            ready: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queue a received frame and wake a waiting reader. Returns whether it was queued: `false`
    /// when the queue was full (the frame is lost and counted) or closed (it is dropped).
    pub fn push(&self, frame: Received) -> bool {
        let mut s = self.lock();
        if s.closed {
            return false;
        }
        if s.frames.len() >= s.capacity {
            s.overruns += 1;
            return false;
        }
        s.frames.push_back(frame);
        drop(s);
        self.ready.notify_one();
        true
    }

    /// The oldest queued frame if there is one; `Ok(None)` when the queue is empty and open.
    pub fn try_recv(&self) -> Result<Option<Received>, RxClosed> {
        let mut s = self.lock();
        match s.frames.pop_front() {
            Some(r) => Ok(Some(r)),
            None if s.closed => Err(RxClosed),
            None => Ok(None),
        }
    }

    /// The oldest queued frame, waiting up to `timeout` for one; `Ok(None)` on timeout,
    /// [`RxClosed`] once the queue was closed and is empty. A timeout too large to reach waits
    /// for a frame or the close.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<Received>, RxClosed> {
        let deadline = Instant::now().checked_add(timeout);
        let mut s = self.lock();
        loop {
            if let Some(r) = s.frames.pop_front() {
                return Ok(Some(r));
            }
            if s.closed {
                return Err(RxClosed);
            }
            // Wakeups may be spurious or for a frame another reader took: look again, with
            // what is left of the timeout.
            s = match deadline {
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    self.ready
                        .wait_timeout(s, left)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
                None => self.ready.wait(s).unwrap_or_else(PoisonError::into_inner),
            };
        }
    }

    /// Frames lost because the queue was full.
    pub fn overruns(&self) -> u64 {
        self.lock().overruns
    }

    /// Frames queued now.
    pub fn len(&self) -> usize {
        self.lock().frames.len()
    }

    /// Whether no frame is queued now.
    pub fn is_empty(&self) -> bool {
        self.lock().frames.is_empty()
    }

    /// Close the queue (see [Closing](RxQueue#closing)) and wake every waiting reader. Returns
    /// whether this call closed it: `false` if it was closed already.
    pub fn close(&self) -> bool {
        let was_closed = std::mem::replace(&mut self.lock().closed, true);
        self.ready.notify_all();
        !was_closed
    }

    /// Whether the queue was closed.
    pub fn is_closed(&self) -> bool {
        self.lock().closed
    }

    /// Drop every queued frame (not counted as overruns).
    pub fn clear(&self) {
        self.lock().frames.clear();
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use cantwin_can::Frame;

    use super::*;

    /// Long enough for any thread to be scheduled; only ever waited out on failure.
    const PATIENCE: Duration = Duration::from_secs(30);

    fn frame(n: u8) -> Received {
        Received {
            frame: Frame::std(0x100, &[n]).expect("a valid frame"),
            at: cantwin_can::Instant::from_nanos(u64::from(n) * 1000),
        }
    }

    fn data(r: Option<Received>) -> Option<u8> {
        r.map(|r| r.frame.data_bytes()[0])
    }

    #[test]
    fn frames_come_out_in_the_order_they_went_in() {
        let q = RxQueue::new(8);
        for n in 0..5 {
            assert!(q.push(frame(n)));
        }
        assert_eq!(q.len(), 5);
        for n in 0..5 {
            assert_eq!(q.try_recv().map(data), Ok(Some(n)));
        }
        assert_eq!(q.try_recv(), Ok(None));
        assert!(q.is_empty());
    }

    #[test]
    fn a_full_queue_drops_and_counts_the_newest_frames() {
        let q = RxQueue::new(2);
        let queued: Vec<bool> = (0..5).map(|n| q.push(frame(n))).collect();
        assert_eq!(queued, [true, true, false, false, false]);
        assert_eq!(q.overruns(), 3);
        assert_eq!(q.len(), 2);
        assert_eq!(q.try_recv().map(data), Ok(Some(0)));
        assert_eq!(q.try_recv().map(data), Ok(Some(1)));
        // Room again: frames are queued, the count stays.
        assert!(q.push(frame(5)));
        assert_eq!(q.try_recv().map(data), Ok(Some(5)));
        assert_eq!(q.overruns(), 3);
    }

    #[test]
    fn a_capacity_of_zero_holds_one_frame() {
        let q = RxQueue::new(0);
        assert!(q.push(frame(0)));
        assert!(!q.push(frame(1)));
        assert_eq!(q.overruns(), 1);
    }

    #[test]
    fn recv_timeout_on_an_empty_queue_returns_none() {
        let q = RxQueue::new(4);
        assert_eq!(q.recv_timeout(Duration::from_millis(10)), Ok(None));
        assert_eq!(q.recv_timeout(Duration::ZERO), Ok(None));
    }

    #[test]
    fn recv_timeout_takes_a_queued_frame_without_waiting() {
        let q = RxQueue::new(4);
        q.push(frame(7));
        assert_eq!(q.recv_timeout(Duration::ZERO).map(data), Ok(Some(7)));
    }

    #[test]
    fn frames_queued_before_the_close_are_still_delivered() {
        let q = RxQueue::new(4);
        q.push(frame(1));
        q.push(frame(2));
        assert!(q.close());
        assert!(q.is_closed());
        assert!(!q.push(frame(3)), "a closed queue takes no frames");
        assert_eq!(q.overruns(), 0);
        assert_eq!(q.try_recv().map(data), Ok(Some(1)));
        assert_eq!(q.recv_timeout(PATIENCE).map(data), Ok(Some(2)));
        assert_eq!(q.try_recv(), Err(RxClosed));
        assert_eq!(q.recv_timeout(PATIENCE), Err(RxClosed));
    }

    #[test]
    fn only_the_first_close_reports_closing() {
        let q = RxQueue::new(4);
        assert!(q.close());
        assert!(!q.close());
        assert!(q.is_closed());
    }

    #[test]
    fn clear_drops_queued_frames_without_counting_them() {
        let q = RxQueue::new(4);
        q.push(frame(1));
        q.push(frame(2));
        q.close();
        q.clear();
        assert_eq!(q.len(), 0);
        assert_eq!(q.overruns(), 0);
        assert_eq!(q.try_recv(), Err(RxClosed));
    }

    #[test]
    fn close_wakes_a_blocked_reader() {
        let q = Arc::new(RxQueue::new(4));
        let reader = {
            let q = Arc::clone(&q);
            std::thread::spawn(move || q.recv_timeout(PATIENCE))
        };
        // Whether the reader is already waiting or not, it must end with the close.
        q.close();
        assert_eq!(reader.join().expect("the reader thread"), Err(RxClosed));
    }

    #[test]
    fn a_push_wakes_a_blocked_reader() {
        let q = Arc::new(RxQueue::new(4));
        let reader = {
            let q = Arc::clone(&q);
            std::thread::spawn(move || q.recv_timeout(PATIENCE))
        };
        q.push(frame(9));
        assert_eq!(
            reader.join().expect("the reader thread").map(data),
            Ok(Some(9))
        );
    }

    #[test]
    fn an_unreachable_timeout_waits_for_the_close() {
        let q = Arc::new(RxQueue::new(4));
        let reader = {
            let q = Arc::clone(&q);
            std::thread::spawn(move || q.recv_timeout(Duration::MAX))
        };
        q.close();
        assert_eq!(reader.join().expect("the reader thread"), Err(RxClosed));
    }
}
