//! socketcand's broadcast-manager (BCM) mode without I/O: cyclic transmission jobs and receive
//! operations (subscriptions, content filters, multiplex filters, throttling) of one client,
//! driven by the frames its bus delivers and by the clock.
//!
//! The daemon's BCM mode is a thin layer over the Linux CAN broadcast manager (`net/can/bcm.c`,
//! documented in the kernel's `Documentation/networking/can.rst`, "Broadcast Manager
//! Protocol Sockets"); what each command sets up, as the daemon's `state_bcm.c` does:
//!
//! * `add SECS USECS ID DLC DATA…`: `TX_SETUP` with `SETTIMER | STARTTIMER`, interval `ival2`.
//!   Starting the timer announces the frame (the kernel sets `TX_ANNOUNCE` with
//!   `STARTTIMER`): it goes out at once, then every interval; with an interval of zero it
//!   goes out once. `add` for an identifier that has a job replaces its frame, sends it at
//!   once and restarts the timer.
//! * `update ID DLC DATA…`: `TX_SETUP` without flags: the job's frame changes, its timer runs
//!   on; without a job, one is set up that does not send.
//! * `delete ID`: `TX_DELETE`.
//! * `subscribe SECS USECS ID`: `RX_SETUP` with `RX_FILTER_ID`: every frame of the identifier.
//! * `filter SECS USECS ID DLC MASK…`: `RX_SETUP` with one mask: a frame passes when its data
//!   under the mask differs from the last frame that passed (the first always passes).
//! * `muxfilter SECS USECS ID N MASKS…`: `RX_SETUP` with N ≥ 2 masks: the first selects the
//!   multiplexer bits, each further one is compared under the multiplexer mask with a frame's
//!   data to find its multiplexer value and, on a match, filters that value's frames as
//!   `filter` does, each value with its own last frame. The daemon writes this command's
//!   `SECS USECS` into another message than the one it sends, so a multiplex filter is never
//!   throttled; so it is here.
//! * A receive command for an identifier that already has an operation updates it, unless it
//!   has more masks than the operation (the kernel refuses that with `E2BIG`, which the
//!   daemon does not report: the old operation stays). An update sends what its throttle
//!   held at once and starts the throttle afresh.
//! * `unsubscribe ID`: `RX_DELETE`.
//! * `SECS USECS` of the receive commands is `ival2`, the throttle: a frame that passes is sent
//!   at once unless one was sent less than the throttle ago; then the newest such frame (per
//!   multiplexer value) is held and sent when the throttle time is up, and the throttle timer
//!   keeps running while it has something to send.
//!
//! One receive operation and one transmission job per identifier, as a BCM socket keeps them.
//! Remote frames match no receive operation (the kernel registers them with the
//! remote-request bit in the mask). The client's own frames (its `send` commands and its
//! jobs' frames) reach its receive operations too, as the kernel loops a socket's frames back
//! to the broadcast manager (on a virtual CAN interface, at once).

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

impl Filter {
    /// The operation's frame count in the kernel (`nframes`: 0 for a subscription).
    fn masks(&self) -> usize {
        match self {
            Filter::All => 0,
            Filter::Masks(m) => m.len(),
        }
    }
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

/// The first time after `now` on the grid `from + k · period` (k ≥ 1): a timer that fired
/// late keeps its cadence, and cycles the host missed are skipped rather than sent in a
/// burst.
fn after(from: Instant, period: Duration, now: Instant) -> Instant {
    let missed = now.saturating_duration_since(from).as_nanos() / period.as_nanos().max(1);
    let steps = u32::try_from(missed + 1).unwrap_or(u32::MAX);
    from + period.saturating_mul(steps)
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
    /// `add`: set up (or replace) the job for `frame`'s identifier, sending it at `now` and
    /// then every `interval` (once, with an interval of zero).
    pub(crate) fn add(&mut self, interval: Duration, frame: Frame, now: Instant) {
        let job = TxJob {
            frame,
            interval,
            next: Some(now),
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

    /// Set up or update the receive operation of `id`; frames an update flushes from the
    /// throttle are added to `flushed`, to be sent at once.
    fn set_rx(&mut self, id: Id, throttle: Duration, filter: Filter, flushed: &mut Vec<Received>) {
        let masks = filter.masks();
        let slots = masks.max(1);
        match self.rx.iter_mut().find(|o| o.id == id) {
            Some(o) if masks > o.filter.masks() => {}
            Some(o) => {
                flushed.extend(o.slots.iter_mut().filter_map(|s| s.held.take()));
                // A subscription keeps what it received (the kernel clears the last frames
                // only when the update carries masks).
                if masks > 0 || o.slots.len() != slots {
                    o.slots = vec![Slot::default(); slots];
                }
                o.filter = filter;
                o.throttle = throttle;
                o.last_sent = None;
                o.flush_at = None;
            }
            None => self.rx.push(RxOp {
                id,
                filter,
                throttle,
                slots: vec![Slot::default(); slots],
                last_sent: None,
                flush_at: None,
            }),
        }
    }

    /// `subscribe`: every frame of `id`, at most one per `throttle`.
    pub(crate) fn subscribe(&mut self, id: Id, throttle: Duration, flushed: &mut Vec<Received>) {
        self.set_rx(id, throttle, Filter::All, flushed);
    }

    /// `filter`: frames of `id` whose data under `mask` changed, at most one per `throttle`.
    pub(crate) fn filter(
        &mut self,
        id: Id,
        throttle: Duration,
        mask: &[u8],
        flushed: &mut Vec<Received>,
    ) {
        self.set_rx(id, throttle, Filter::Masks(vec![bytes_word(mask)]), flushed);
    }

    /// `muxfilter`: the multiplexer mask then one filter per multiplexer value (at least two
    /// masks in all; the caller checks). Never throttled (see the module documentation).
    pub(crate) fn muxfilter(&mut self, id: Id, masks: &[[u8; 8]], flushed: &mut Vec<Received>) {
        let masks = masks.iter().map(|m| u64::from_be_bytes(*m)).collect();
        self.set_rx(id, Duration::ZERO, Filter::Masks(masks), flushed);
    }

    /// Whether a frame of `id` would still reach the client: its receive operation exists.
    pub(crate) fn receives(&self, id: Id) -> bool {
        self.rx.iter().any(|o| o.id == id)
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
            job.next = (!job.interval.is_zero()).then(|| after(next, job.interval, now));
        }
        for op in &mut self.rx {
            let Some(at) = op.flush_at else { continue };
            if at <= now {
                let before = due.deliver.len();
                due.deliver
                    .extend(op.slots.iter_mut().filter_map(|s| s.held.take()));
                if due.deliver.len() > before {
                    op.flush_at = Some(after(at, op.throttle, now));
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
        b.subscribe(std(0x123), Duration::ZERO, &mut Vec::new());
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
        b.filter(
            std(0x123),
            Duration::ZERO,
            &[0xFF, 0x00, 0xF8],
            &mut Vec::new(),
        );
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
            &[
                [0xFF, 0, 0, 0, 0, 0, 0, 0],
                [0x33, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF],
                [0x56, 0xFF, 0, 0, 0, 0, 0xFF, 0xFF],
            ],
            &mut Vec::new(),
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
        b.subscribe(std(0x181), Duration::from_millis(100), &mut Vec::new());
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
    fn add_sends_at_once_then_every_interval_and_update_keeps_the_timer() {
        let t = Instant::now();
        let mut b = Bcm::default();
        let frame = |n: u8| Frame::std(0x123, &[n]).expect("a valid frame");
        b.add(Duration::from_millis(20), frame(1), t);
        let mut due = Due::default();
        b.poll(t, &mut due);
        assert_eq!(due.transmit, [frame(1)], "announced when the timer starts");
        b.poll(at(t, 19), &mut due);
        assert_eq!(due.transmit.len(), 1);
        b.poll(at(t, 20), &mut due);
        assert_eq!(due.transmit, [frame(1), frame(1)]);
        b.update(frame(2));
        assert_eq!(
            b.next_deadline(),
            Some(at(t, 40)),
            "update leaves the timer"
        );
        // The host was away for three cycles: one frame, then the cycle goes on on its grid.
        due.transmit.clear();
        b.poll(at(t, 95), &mut due);
        assert_eq!(due.transmit, [frame(2)]);
        assert_eq!(b.next_deadline(), Some(at(t, 100)));
        // `add` again sends at once and restarts the timer from now.
        b.add(Duration::from_millis(50), frame(3), at(t, 96));
        assert_eq!(b.next_deadline(), Some(at(t, 96)));
        assert!(b.delete(std(0x123)));
        assert!(!b.delete(std(0x123)));
        assert_eq!(b.next_deadline(), None);
    }

    #[test]
    fn a_zero_interval_sends_once_and_an_update_without_a_job_sends_nothing() {
        let t = Instant::now();
        let mut b = Bcm::default();
        b.add(Duration::ZERO, Frame::std(0x123, &[1]).expect("a frame"), t);
        b.update(Frame::std(0x124, &[1]).expect("a frame"));
        let mut due = Due::default();
        b.poll(at(t, 10_000), &mut due);
        assert_eq!(due.transmit, [Frame::std(0x123, &[1]).expect("a frame")]);
        assert_eq!(b.next_deadline(), None);
        b.poll(at(t, 20_000), &mut due);
        assert_eq!(due.transmit.len(), 1);
        assert!(b.delete(std(0x124)), "update set up a job");
    }

    #[test]
    fn setting_up_an_identifier_again_updates_it_unless_it_needs_more_masks() {
        let t = Instant::now();
        let mut b = Bcm::default();
        let mut flushed = Vec::new();
        b.subscribe(std(0x181), Duration::from_millis(100), &mut flushed);
        assert!(b.on_frame(&rx(0x181, &[1]), t).is_some());
        assert_eq!(b.on_frame(&rx(0x181, &[2]), at(t, 10)), None, "held");
        // More masks than the subscription has (none): refused, the subscription stays.
        b.filter(std(0x181), Duration::ZERO, &[0xFF], &mut flushed);
        assert!(flushed.is_empty());
        assert_eq!(
            b.on_frame(&rx(0x181, &[3]), at(t, 20)),
            None,
            "still throttled"
        );
        // The same kind again: the held frame is flushed, the throttle starts afresh.
        b.subscribe(std(0x181), Duration::ZERO, &mut flushed);
        assert_eq!(data(flushed.pop()), Some(vec![3]));
        assert_eq!(data(b.on_frame(&rx(0x181, &[4]), at(t, 21))), Some(vec![4]));
        // A filter may become a subscription (fewer masks).
        b.filter(std(0x200), Duration::ZERO, &[0xFF], &mut flushed);
        b.subscribe(std(0x200), Duration::ZERO, &mut flushed);
        assert!(b.on_frame(&rx(0x200, &[1]), t).is_some());
        assert!(
            b.on_frame(&rx(0x200, &[1]), t).is_some(),
            "no change needed any more"
        );
        assert!(b.receives(std(0x200)));
        assert!(!b.receives(std(0x201)));
    }
}
