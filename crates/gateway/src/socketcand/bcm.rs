//! socketcand's broadcast-manager (BCM) mode without I/O: cyclic transmission jobs and receive
//! operations (subscriptions, content filters, multiplex filters, throttling) of one client,
//! driven by the frames its bus delivers and by the clock.
//!
//! The daemon's BCM mode is a thin layer over the Linux CAN broadcast manager (`net/can/bcm.c`,
//! documented in the kernel's `Documentation/networking/can.rst`, "Broadcast Manager
//! Protocol Sockets"); what each command sets up, as the daemon's `state_bcm.c` does:
//!
//! * `add SECS USECS ID DLC DATA…`: `TX_SETUP` with `SETTIMER | STARTTIMER`, interval `ival2`.
//!   The first frame goes out one interval after the command (no `TX_ANNOUNCE`); an interval
//!   of zero sets up a job that never sends. `add` for an identifier that has a job replaces
//!   its frame and restarts its timer.
//! * `update ID DLC DATA…`: `TX_SETUP` without flags: the job's frame changes, its timer runs
//!   on; without a job, one is set up that does not send.
//! * `delete ID`: `TX_DELETE`.
//! * `subscribe SECS USECS ID`: `RX_SETUP` with `RX_FILTER_ID`: every frame of the identifier.
//! * `filter SECS USECS ID DLC MASK…`: `RX_SETUP` with one mask: a frame passes when its data
//!   under the mask differs from the last frame that passed (the first always passes).
//! * `muxfilter SECS USECS ID N MASKS…`: `RX_SETUP` with N ≥ 2 masks: the first selects the
//!   multiplexer bits, each further one is compared under the multiplexer mask with a frame's
//!   data to find its multiplexer value and, on a match, filters that value's frames as
//!   `filter` does, each value with its own last frame.
//! * `unsubscribe ID`: `RX_DELETE`.
//! * `SECS USECS` of the receive commands is `ival2`, the throttle: a frame that passes is sent
//!   at once unless one was sent less than the throttle ago; then the newest such frame (per
//!   multiplexer value) is held and sent when the throttle time is up, and the throttle timer
//!   keeps running while it has something to send.
//!
//! One receive operation and one transmission job per identifier, as a BCM socket keeps them
//! (`RX_SETUP` and `TX_SETUP` for an identifier that has one replace it). Remote frames match
//! no receive operation (the kernel registers them with the remote-request bit in the mask).
//! A job's frames are this client's own, which its bus port does not hand back to it: unlike
//! the kernel's loopback, a client does not receive what its own jobs send.

use std::time::{Duration, Instant};

use cantwin_can::{Frame, Id};

use crate::port::Received;

/// A cyclic transmission job.
#[derive(Debug, Clone)]
struct TxJob {
    frame: Frame,
    interval: Duration,
    /// When the frame goes out next; `None` for a job without a running timer.
    next: Option<Instant>,
}

/// What a receive operation passes.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Filter {
    /// Every frame of the identifier.
    All,
    /// Changes of the data under a mask; with more than one mask, the first is the
    /// multiplexer mask and the others are compared per multiplexer value.
    Masks(Vec<u64>),
}

/// The state of one mask (or of the whole identifier for [`Filter::All`]).
#[derive(Debug, Clone, Default)]
struct Slot {
    /// The data of the last frame that passed (`RX_RECV` set), as a big-endian word.
    last: Option<u64>,
    /// A frame that passed while throttled, waiting for the throttle time.
    held: Option<Received>,
}

#[derive(Debug, Clone)]
struct RxOp {
    id: Id,
    filter: Filter,
    throttle: Duration,
    slots: Vec<Slot>,
    /// When a frame was last sent at once (`kt_lastmsg`); `None` before the first and after a
    /// throttle period with nothing to send.
    last_sent: Option<Instant>,
    /// When the throttle timer expires, if it runs.
    flush_at: Option<Instant>,
}

/// One client's broadcast manager.
#[derive(Debug, Clone, Default)]
pub(crate) struct Bcm {
    tx: Vec<TxJob>,
    rx: Vec<RxOp>,
    /// A frame started a throttle timer since [`Bcm::take_replan`] was last asked.
    replan: bool,
}

/// What is due at a given time: frames to transmit on the bus, frames to send to the client.
#[derive(Debug, Default)]
pub(crate) struct Due {
    pub(crate) transmit: Vec<Frame>,
    pub(crate) deliver: Vec<Received>,
}

/// A frame's data as the broadcast manager compares it: eight bytes, zero beyond the DLC.
fn word(frame: &Frame) -> u64 {
    bytes_word(frame.data_bytes())
}

fn bytes_word(bytes: &[u8]) -> u64 {
    let mut b = [0u8; 8];
    for (slot, v) in b.iter_mut().zip(bytes) {
        *slot = *v;
    }
    u64::from_be_bytes(b)
}

impl Bcm {
    /// `add`: set up (or replace) the job for `frame`'s identifier, sending every `interval`
    /// from `now + interval` on; an interval of zero sends nothing.
    pub(crate) fn add(&mut self, interval: Duration, frame: Frame, now: Instant) {
        let next = (!interval.is_zero()).then(|| now + interval);
        let job = TxJob {
            frame,
            interval,
            next,
        };
        match self.tx.iter_mut().find(|j| j.frame.id() == frame.id()) {
            Some(j) => *j = job,
            None => self.tx.push(job),
        }
    }

    /// `update`: change the frame of the job for its identifier, timer untouched; a new job
    /// without a timer if there is none.
    pub(crate) fn update(&mut self, frame: Frame) {
        match self.tx.iter_mut().find(|j| j.frame.id() == frame.id()) {
            Some(j) => j.frame = frame,
            None => self.tx.push(TxJob {
                frame,
                interval: Duration::ZERO,
                next: None,
            }),
        }
    }

    /// `delete`: remove the job for `id`; `false` if there was none.
    pub(crate) fn delete(&mut self, id: Id) -> bool {
        let before = self.tx.len();
        self.tx.retain(|j| j.frame.id() != id);
        self.tx.len() != before
    }

    fn set_rx(&mut self, id: Id, throttle: Duration, filter: Filter) {
        let slots = match &filter {
            Filter::All => 1,
            Filter::Masks(m) => m.len(),
        };
        let op = RxOp {
            id,
            filter,
            throttle,
            slots: vec![Slot::default(); slots],
            last_sent: None,
            flush_at: None,
        };
        match self.rx.iter_mut().find(|o| o.id == id) {
            Some(o) => *o = op,
            None => self.rx.push(op),
        }
    }

    /// `subscribe`: every frame of `id`, at most one per `throttle`.
    pub(crate) fn subscribe(&mut self, id: Id, throttle: Duration) {
        self.set_rx(id, throttle, Filter::All);
    }

    /// `filter`: frames of `id` whose data under `mask` changed, at most one per `throttle`.
    pub(crate) fn filter(&mut self, id: Id, throttle: Duration, mask: &[u8]) {
        self.set_rx(id, throttle, Filter::Masks(vec![bytes_word(mask)]));
    }

    /// `muxfilter`: the multiplexer mask then one filter per multiplexer value (at least two
    /// masks in all; the caller checks).
    pub(crate) fn muxfilter(&mut self, id: Id, throttle: Duration, masks: &[[u8; 8]]) {
        let masks = masks.iter().map(|m| u64::from_be_bytes(*m)).collect();
        self.set_rx(id, throttle, Filter::Masks(masks));
    }

    /// `unsubscribe`: remove the receive operation of `id`; `false` if there was none.
    pub(crate) fn unsubscribe(&mut self, id: Id) -> bool {
        let before = self.rx.len();
        self.rx.retain(|o| o.id != id);
        self.rx.len() != before
    }

    /// A frame from the bus, received at `now`: the frame to send to the client at once, if
    /// any.
    pub(crate) fn on_frame(&mut self, rx: &Received, now: Instant) -> Option<Received> {
        if rx.frame.is_remote() {
            return None;
        }
        let op = self.rx.iter_mut().find(|o| o.id == rx.frame.id())?;
        let data = word(&rx.frame);
        let slot = match &op.filter {
            Filter::All => 0,
            Filter::Masks(masks) => {
                let slot = match masks.as_slice() {
                    [_] => 0,
                    [mux, values @ ..] => 1 + values.iter().position(|v| mux & data == mux & v)?,
                    [] => return None,
                };
                let mask = masks[slot];
                if op.slots[slot]
                    .last
                    .is_some_and(|last| last & mask == data & mask)
                {
                    return None;
                }
                slot
            }
        };
        let timer_was = op.flush_at;
        let passed = op.pass(slot, rx, now);
        self.replan |= op.flush_at != timer_was;
        passed
    }

    /// Whether [`Bcm::next_deadline`] may have moved because of a frame since last asked.
    pub(crate) fn take_replan(&mut self) -> bool {
        std::mem::take(&mut self.replan)
    }

    /// Run what is due at `now`: cyclic frames to transmit, throttled frames to send.
    pub(crate) fn poll(&mut self, now: Instant, due: &mut Due) {
        for job in &mut self.tx {
            let Some(next) = job.next else { continue };
            if next > now {
                continue;
            }
            due.transmit.push(job.frame);
            // Cycles missed while the host was busy are skipped, as the kernel's timer
            // forwarding does: the next frame is due one interval after the last due time
            // that has passed.
            let missed = (now - next).as_nanos() / job.interval.as_nanos().max(1);
            let step = job
                .interval
                .saturating_mul(u32::try_from(missed + 1).unwrap_or(u32::MAX));
            job.next = Some(next + step);
        }
        for op in &mut self.rx {
            if op.flush_at.is_some_and(|t| t <= now) {
                let before = due.deliver.len();
                due.deliver
                    .extend(op.slots.iter_mut().filter_map(|s| s.held.take()));
                if due.deliver.len() > before {
                    op.flush_at = Some(now + op.throttle);
                } else {
                    op.flush_at = None;
                    op.last_sent = None;
                }
            }
        }
    }

    /// When [`Bcm::poll`] has something to do next.
    pub(crate) fn next_deadline(&self) -> Option<Instant> {
        let tx = self.tx.iter().filter_map(|j| j.next);
        let rx = self.rx.iter().filter_map(|o| o.flush_at);
        tx.chain(rx).min()
    }
}

impl RxOp {
    /// The frame passed the filter of `slot` (`bcm_rx_update_and_send`).
    fn pass(&mut self, slot: usize, rx: &Received, now: Instant) -> Option<Received> {
        let s = &mut self.slots[slot];
        s.last = Some(word(&rx.frame));
        if self.throttle.is_zero() {
            return Some(*rx);
        }
        if self.flush_at.is_some() {
            s.held = Some(*rx);
            return None;
        }
        if let Some(sent) = self.last_sent
            && now.saturating_duration_since(sent) < self.throttle
        {
            s.held = Some(*rx);
            self.flush_at = Some(sent + self.throttle);
            return None;
        }
        self.last_sent = Some(now);
        Some(*rx)
    }
}

#[cfg(test)]
mod tests {
    use std::time::{SystemTime, UNIX_EPOCH};

    use super::*;

    fn at(start: Instant, ms: u64) -> Instant {
        start + Duration::from_millis(ms)
    }

    fn rx(id: u16, data: &[u8]) -> Received {
        Received {
            frame: Frame::std(id, data).expect("a valid frame"),
            timestamp: UNIX_EPOCH + Duration::from_secs(1),
        }
    }

    fn data(r: Option<Received>) -> Option<Vec<u8>> {
        r.map(|r| r.frame.data_bytes().to_vec())
    }

    fn std(id: u16) -> Id {
        Id::standard(id).expect("a standard identifier")
    }

    #[test]
    fn subscribe_passes_every_frame_of_its_identifier_only() {
        let t = Instant::now();
        let mut b = Bcm::default();
        b.subscribe(std(0x123), Duration::ZERO);
        assert_eq!(data(b.on_frame(&rx(0x123, &[1]), t)), Some(vec![1]));
        assert_eq!(data(b.on_frame(&rx(0x123, &[1]), t)), Some(vec![1]));
        assert_eq!(b.on_frame(&rx(0x124, &[1]), t), None);
        let remote = Received {
            frame: Frame::remote(std(0x123), 1).expect("a remote frame"),
            timestamp: SystemTime::UNIX_EPOCH,
        };
        assert_eq!(b.on_frame(&remote, t), None);
        assert!(b.unsubscribe(std(0x123)));
        assert!(!b.unsubscribe(std(0x123)));
        assert_eq!(b.on_frame(&rx(0x123, &[1]), t), None);
    }

    #[test]
    fn filter_passes_the_first_frame_and_then_changes_under_its_mask() {
        // The daemon's example: `< filter 0 0 123 8 FF 00 F8 00 00 00 00 00 >`.
        let t = Instant::now();
        let mut b = Bcm::default();
        b.filter(std(0x123), Duration::ZERO, &[0xFF, 0x00, 0xF8]);
        let f = |d: &[u8]| rx(0x123, d);
        assert!(
            b.on_frame(&f(&[1, 2, 0x08]), t).is_some(),
            "the first frame"
        );
        assert_eq!(
            b.on_frame(&f(&[1, 9, 0x0F]), t),
            None,
            "only masked-out bits changed"
        );
        assert!(b.on_frame(&f(&[2, 9, 0x0F]), t).is_some(), "byte 0 changed");
        assert_eq!(
            b.on_frame(&f(&[2, 0, 0x0C]), t),
            None,
            "0x0C and 0x0F agree under F8"
        );
        assert!(
            b.on_frame(&f(&[2, 0, 0x10]), t).is_some(),
            "a bit of F8 changed"
        );
        // A shorter frame compares as zeros beyond its length.
        assert!(b.on_frame(&f(&[2]), t).is_some());
        assert_eq!(b.on_frame(&f(&[2, 0, 0]), t), None);
    }

    #[test]
    fn muxfilter_filters_each_multiplexer_value_on_its_own() {
        // The daemon's example: multiplexer in byte 0, value 0x33 watched on all other bytes.
        let t = Instant::now();
        let mut b = Bcm::default();
        b.muxfilter(
            std(0x123),
            Duration::ZERO,
            &[
                [0xFF, 0, 0, 0, 0, 0, 0, 0],
                [0x33, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF],
                [0x56, 0xFF, 0, 0, 0, 0, 0xFF, 0xFF],
            ],
        );
        let f = |d: &[u8]| rx(0x123, d);
        assert!(b.on_frame(&f(&[0x33, 1]), t).is_some());
        assert_eq!(b.on_frame(&f(&[0x33, 1]), t), None);
        assert!(
            b.on_frame(&f(&[0x56, 1]), t).is_some(),
            "its own first frame"
        );
        assert_eq!(
            b.on_frame(&f(&[0x56, 1, 5]), t),
            None,
            "byte 2 is not watched for 0x56"
        );
        assert!(b.on_frame(&f(&[0x33, 2]), t).is_some());
        assert_eq!(b.on_frame(&f(&[0x44, 2]), t), None, "no filter for 0x44");
    }

    #[test]
    fn a_throttled_subscription_sends_at_once_then_the_newest_frame_per_period() {
        let t = Instant::now();
        let mut b = Bcm::default();
        b.subscribe(std(0x181), Duration::from_millis(100));
        let f = |n: u8| rx(0x181, &[n]);
        assert_eq!(data(b.on_frame(&f(1), t)), Some(vec![1]));
        assert!(!b.take_replan());
        assert_eq!(b.on_frame(&f(2), at(t, 10)), None);
        assert!(b.take_replan(), "the throttle timer started");
        assert_eq!(b.on_frame(&f(3), at(t, 20)), None);
        assert!(!b.take_replan(), "it was running already");
        assert_eq!(b.next_deadline(), Some(at(t, 100)));
        let mut due = Due::default();
        b.poll(at(t, 99), &mut due);
        assert!(due.deliver.is_empty());
        b.poll(at(t, 100), &mut due);
        assert_eq!(
            data(due.deliver.pop()),
            Some(vec![3]),
            "the newest held frame"
        );
        // The timer runs on: a frame inside the next period is held again.
        assert_eq!(b.on_frame(&f(4), at(t, 150)), None);
        b.poll(at(t, 200), &mut due);
        assert_eq!(data(due.deliver.pop()), Some(vec![4]));
        // A period with nothing to send stops the timer; the next frame goes at once.
        b.poll(at(t, 300), &mut due);
        assert!(due.deliver.is_empty());
        assert_eq!(b.next_deadline(), None);
        assert_eq!(data(b.on_frame(&f(5), at(t, 900))), Some(vec![5]));
        // Past the throttle since the last one sent: at once.
        assert_eq!(data(b.on_frame(&f(6), at(t, 1_001))), Some(vec![6]));
    }

    #[test]
    fn add_sends_every_interval_from_one_interval_on_and_update_keeps_the_timer() {
        let t = Instant::now();
        let mut b = Bcm::default();
        let frame = |n: u8| Frame::std(0x123, &[n]).expect("a valid frame");
        b.add(Duration::from_millis(20), frame(1), t);
        assert_eq!(b.next_deadline(), Some(at(t, 20)));
        let mut due = Due::default();
        b.poll(at(t, 19), &mut due);
        assert!(
            due.transmit.is_empty(),
            "no frame before the first interval"
        );
        b.poll(at(t, 20), &mut due);
        assert_eq!(due.transmit, [frame(1)]);
        b.update(frame(2));
        assert_eq!(
            b.next_deadline(),
            Some(at(t, 40)),
            "update leaves the timer"
        );
        // The host was away for three cycles: one frame, then the cycle goes on.
        b.poll(at(t, 95), &mut due);
        assert_eq!(due.transmit, [frame(1), frame(2)]);
        assert_eq!(b.next_deadline(), Some(at(t, 100)));
        // `add` again restarts the timer from now.
        b.add(Duration::from_millis(50), frame(3), at(t, 96));
        assert_eq!(b.next_deadline(), Some(at(t, 146)));
        assert!(b.delete(std(0x123)));
        assert!(!b.delete(std(0x123)));
        assert_eq!(b.next_deadline(), None);
    }

    #[test]
    fn a_zero_interval_or_an_update_without_a_job_sends_nothing() {
        let t = Instant::now();
        let mut b = Bcm::default();
        b.add(Duration::ZERO, Frame::std(0x123, &[1]).expect("a frame"), t);
        b.update(Frame::std(0x124, &[1]).expect("a frame"));
        assert_eq!(b.next_deadline(), None);
        let mut due = Due::default();
        b.poll(at(t, 10_000), &mut due);
        assert!(due.transmit.is_empty());
        assert!(b.delete(std(0x124)), "update set up a job");
    }
}
