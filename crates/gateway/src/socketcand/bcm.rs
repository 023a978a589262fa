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

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use cantwin_can::{Frame, Id};

use crate::port::Received;

/// A running timer: when it expires, and a serial number that orders timers expiring at the
/// same instant by when they were set and tells them apart.
type TimerKey = (Instant, u64);

/// The timers of one kind of job, ordered by expiry: the next one is found, set and cancelled
/// in O(log n), and [`Bcm::poll`] visits only the jobs that are due, never the others.
#[derive(Debug, Clone, Default)]
struct Timers {
    queue: BTreeMap<TimerKey, Id>,
    serial: u64,
}

impl Timers {
    fn set(&mut self, at: Instant, id: Id) -> TimerKey {
        self.serial += 1;
        let key = (at, self.serial);
        self.queue.insert(key, id);
        key
    }

    fn cancel(&mut self, key: Option<TimerKey>) {
        if let Some(key) = key {
            self.queue.remove(&key);
        }
    }

    fn next(&self) -> Option<Instant> {
        self.queue.first_key_value().map(|((at, _), _)| *at)
    }

    /// The first timer expired at `now`, taken out of the queue.
    fn pop_due(&mut self, now: Instant) -> Option<(TimerKey, Id)> {
        match self.queue.first_key_value() {
            Some((key, _)) if key.0 <= now => self.queue.pop_first(),
            _ => None,
        }
    }
}

/// A cyclic transmission job.
#[derive(Debug, Clone)]
struct TxJob {
    frame: Frame,
    interval: Duration,
    /// When the frame goes out next; `None` for a job without a running timer.
    next: Option<TimerKey>,
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
    filter: Filter,
    throttle: Duration,
    slots: Vec<Slot>,
    /// When a frame was last sent at once (`kt_lastmsg`); `None` before the first and after a
    /// throttle period with nothing to send.
    last_sent: Option<Instant>,
    /// When the throttle timer expires, if it runs.
    flush_at: Option<TimerKey>,
}

/// A command that would set up a job beyond the connection's bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Full;

/// One client's broadcast manager.
///
/// Jobs and receive operations are kept by identifier and their timers in expiry order, so a
/// command, a frame from the bus and a timer costs the same however many jobs there are. The
/// kernel bounds a BCM socket's operations only by memory; here they are bounded by
/// [`Bcm::new`]'s limit, which counts each transmission job once and each receive operation
/// once per slot it keeps (a multiplex filter of N masks takes N), so that the bound is one
/// of memory too.
#[derive(Debug, Clone)]
pub(crate) struct Bcm {
    tx: HashMap<Id, TxJob>,
    tx_timers: Timers,
    rx: HashMap<Id, RxOp>,
    rx_timers: Timers,
    /// Transmission jobs plus receive operations' slots.
    used: usize,
    limit: usize,
    /// A frame started a throttle timer since [`Bcm::take_replan`] was last asked.
    replan: bool,
    /// Job records looked at so far: what a command costs, for the tests.
    #[cfg(test)]
    visits: u64,
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
    /// A broadcast manager holding at most `limit` jobs (see [`Bcm`]).
    pub(crate) fn new(limit: usize) -> Bcm {
        Bcm {
            tx: HashMap::new(),
            tx_timers: Timers::default(),
            rx: HashMap::new(),
            rx_timers: Timers::default(),
            used: 0,
            limit,
            replan: false,
            #[cfg(test)]
            visits: 0,
        }
    }

    #[cfg(test)]
    fn visit(&mut self) {
        self.visits += 1;
    }

    #[cfg(not(test))]
    fn visit(&mut self) {}

    /// The job of `id`, or room for a new one: [`Full`] when the limit is reached.
    fn tx_entry(&mut self, id: Id) -> Result<Option<&mut TxJob>, Full> {
        self.visit();
        if self.tx.contains_key(&id) {
            return Ok(self.tx.get_mut(&id));
        }
        if self.used >= self.limit {
            return Err(Full);
        }
        Ok(None)
    }

    /// `add`: set up (or replace) the job for `frame`'s identifier, sending it at `now` and
    /// then every `interval` (once, with an interval of zero).
    pub(crate) fn add(
        &mut self,
        interval: Duration,
        frame: Frame,
        now: Instant,
    ) -> Result<(), Full> {
        let id = frame.id();
        let old = match self.tx_entry(id)? {
            Some(job) => job.next.take(),
            None => {
                self.used += 1;
                None
            }
        };
        self.tx_timers.cancel(old);
        let next = Some(self.tx_timers.set(now, id));
        self.tx.insert(
            id,
            TxJob {
                frame,
                interval,
                next,
            },
        );
        Ok(())
    }

    /// `update`: change the frame of the job for its identifier, timer untouched; a new job
    /// without a timer if there is none.
    pub(crate) fn update(&mut self, frame: Frame) -> Result<(), Full> {
        match self.tx_entry(frame.id())? {
            Some(job) => job.frame = frame,
            None => {
                self.used += 1;
                self.tx.insert(
                    frame.id(),
                    TxJob {
                        frame,
                        interval: Duration::ZERO,
                        next: None,
                    },
                );
            }
        }
        Ok(())
    }

    /// `delete`: remove the job for `id`; `false` if there was none.
    pub(crate) fn delete(&mut self, id: Id) -> bool {
        self.visit();
        let Some(job) = self.tx.remove(&id) else {
            return false;
        };
        self.tx_timers.cancel(job.next);
        self.used -= 1;
        true
    }

    /// Set up or update the receive operation of `id`; frames an update flushes from the
    /// throttle are added to `flushed`, to be sent at once.
    fn set_rx(
        &mut self,
        id: Id,
        throttle: Duration,
        filter: Filter,
        flushed: &mut Vec<Received>,
    ) -> Result<(), Full> {
        self.visit();
        let masks = filter.masks();
        let slots = masks.max(1);
        match self.rx.get_mut(&id) {
            Some(o) if masks > o.filter.masks() => {}
            Some(o) => {
                flushed.extend(o.slots.iter_mut().filter_map(|s| s.held.take()));
                // A subscription keeps what it received (the kernel clears the last frames
                // only when the update carries masks). Fewer slots than before free room.
                if masks > 0 || o.slots.len() != slots {
                    self.used = self.used - o.slots.len() + slots;
                    o.slots = vec![Slot::default(); slots];
                }
                o.filter = filter;
                o.throttle = throttle;
                o.last_sent = None;
                let timer = o.flush_at.take();
                self.rx_timers.cancel(timer);
            }
            None => {
                if self.used.saturating_add(slots) > self.limit {
                    return Err(Full);
                }
                self.used += slots;
                self.rx.insert(
                    id,
                    RxOp {
                        filter,
                        throttle,
                        slots: vec![Slot::default(); slots],
                        last_sent: None,
                        flush_at: None,
                    },
                );
            }
        }
        Ok(())
    }

    /// `subscribe`: every frame of `id`, at most one per `throttle`.
    pub(crate) fn subscribe(
        &mut self,
        id: Id,
        throttle: Duration,
        flushed: &mut Vec<Received>,
    ) -> Result<(), Full> {
        self.set_rx(id, throttle, Filter::All, flushed)
    }

    /// `filter`: frames of `id` whose data under `mask` changed, at most one per `throttle`.
    pub(crate) fn filter(
        &mut self,
        id: Id,
        throttle: Duration,
        mask: &[u8],
        flushed: &mut Vec<Received>,
    ) -> Result<(), Full> {
        self.set_rx(id, throttle, Filter::Masks(vec![bytes_word(mask)]), flushed)
    }

    /// `muxfilter`: the multiplexer mask then one filter per multiplexer value (at least two
    /// masks in all; the caller checks). Never throttled (see the module documentation).
    pub(crate) fn muxfilter(
        &mut self,
        id: Id,
        masks: &[[u8; 8]],
        flushed: &mut Vec<Received>,
    ) -> Result<(), Full> {
        let masks = masks.iter().map(|m| u64::from_be_bytes(*m)).collect();
        self.set_rx(id, Duration::ZERO, Filter::Masks(masks), flushed)
    }

    /// Whether a frame of `id` would still reach the client: its receive operation exists.
    pub(crate) fn receives(&self, id: Id) -> bool {
        self.rx.contains_key(&id)
    }

    /// `unsubscribe`: remove the receive operation of `id`; `false` if there was none.
    pub(crate) fn unsubscribe(&mut self, id: Id) -> bool {
        self.visit();
        let Some(op) = self.rx.remove(&id) else {
            return false;
        };
        self.rx_timers.cancel(op.flush_at);
        self.used -= op.slots.len();
        true
    }

    /// A frame from the bus, received at `now`: the frame to send to the client at once, if
    /// any.
    pub(crate) fn on_frame(&mut self, rx: &Received, now: Instant) -> Option<Received> {
        if rx.frame.is_remote() {
            return None;
        }
        self.visit();
        let id = rx.frame.id();
        let op = self.rx.get_mut(&id)?;
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
        let (passed, start) = op.pass(slot, rx, now);
        if let Some(at) = start {
            op.flush_at = Some(self.rx_timers.set(at, id));
            self.replan = true;
        }
        passed
    }

    /// Whether [`Bcm::next_deadline`] may have moved because of a frame since last asked.
    pub(crate) fn take_replan(&mut self) -> bool {
        std::mem::take(&mut self.replan)
    }

    /// Run what is due at `now`: cyclic frames to transmit, throttled frames to send. Only the
    /// jobs that are due are looked at.
    pub(crate) fn poll(&mut self, now: Instant, due: &mut Due) {
        while let Some(((at, _), id)) = self.tx_timers.pop_due(now) {
            self.visit();
            let Some(job) = self.tx.get_mut(&id) else {
                continue;
            };
            due.transmit.push(job.frame);
            job.next = (!job.interval.is_zero())
                .then(|| self.tx_timers.set(after(at, job.interval, now), id));
        }
        while let Some(((at, _), id)) = self.rx_timers.pop_due(now) {
            self.visit();
            let Some(op) = self.rx.get_mut(&id) else {
                continue;
            };
            let before = due.deliver.len();
            due.deliver
                .extend(op.slots.iter_mut().filter_map(|s| s.held.take()));
            if due.deliver.len() > before {
                op.flush_at = Some(self.rx_timers.set(after(at, op.throttle, now), id));
            } else {
                op.flush_at = None;
                op.last_sent = None;
            }
        }
    }

    /// When [`Bcm::poll`] has something to do next.
    pub(crate) fn next_deadline(&self) -> Option<Instant> {
        match (self.tx_timers.next(), self.rx_timers.next()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

impl RxOp {
    /// The frame passed the filter of `slot` (`bcm_rx_update_and_send`): the frame to send at
    /// once, if any, and when to start the throttle timer, if it is to start.
    fn pass(
        &mut self,
        slot: usize,
        rx: &Received,
        now: Instant,
    ) -> (Option<Received>, Option<Instant>) {
        let s = &mut self.slots[slot];
        s.last = Some(word(&rx.frame));
        if self.throttle.is_zero() {
            return (Some(*rx), None);
        }
        if self.flush_at.is_some() {
            s.held = Some(*rx);
            return (None, None);
        }
        if let Some(sent) = self.last_sent
            && now.saturating_duration_since(sent) < self.throttle
        {
            s.held = Some(*rx);
            return (None, Some(sent + self.throttle));
        }
        self.last_sent = Some(now);
        (Some(*rx), None)
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
        let mut b = Bcm::new(16);
        b.subscribe(std(0x123), Duration::ZERO, &mut Vec::new())
            .expect("room for the job");
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
        let mut b = Bcm::new(16);
        b.filter(
            std(0x123),
            Duration::ZERO,
            &[0xFF, 0x00, 0xF8],
            &mut Vec::new(),
        )
        .expect("room for the job");
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
        let mut b = Bcm::new(16);
        b.muxfilter(
            std(0x123),
            &[
                [0xFF, 0, 0, 0, 0, 0, 0, 0],
                [0x33, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF],
                [0x56, 0xFF, 0, 0, 0, 0, 0xFF, 0xFF],
            ],
            &mut Vec::new(),
        )
        .expect("room for the job");
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
        let mut b = Bcm::new(16);
        b.subscribe(std(0x181), Duration::from_millis(100), &mut Vec::new())
            .expect("room for the job");
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
        let mut b = Bcm::new(16);
        let frame = |n: u8| Frame::std(0x123, &[n]).expect("a valid frame");
        b.add(Duration::from_millis(20), frame(1), t)
            .expect("room for the job");
        let mut due = Due::default();
        b.poll(t, &mut due);
        assert_eq!(due.transmit, [frame(1)], "announced when the timer starts");
        b.poll(at(t, 19), &mut due);
        assert_eq!(due.transmit.len(), 1);
        b.poll(at(t, 20), &mut due);
        assert_eq!(due.transmit, [frame(1), frame(1)]);
        b.update(frame(2)).expect("room for the job");
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
        b.add(Duration::from_millis(50), frame(3), at(t, 96))
            .expect("room for the job");
        assert_eq!(b.next_deadline(), Some(at(t, 96)));
        assert!(b.delete(std(0x123)));
        assert!(!b.delete(std(0x123)));
        assert_eq!(b.next_deadline(), None);
    }

    #[test]
    fn a_zero_interval_sends_once_and_an_update_without_a_job_sends_nothing() {
        let t = Instant::now();
        let mut b = Bcm::new(16);
        b.add(Duration::ZERO, Frame::std(0x123, &[1]).expect("a frame"), t)
            .expect("room for the job");
        b.update(Frame::std(0x124, &[1]).expect("a frame"))
            .expect("room for the job");
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
        let mut b = Bcm::new(16);
        let mut flushed = Vec::new();
        b.subscribe(std(0x181), Duration::from_millis(100), &mut flushed)
            .expect("room for the job");
        assert!(b.on_frame(&rx(0x181, &[1]), t).is_some());
        assert_eq!(b.on_frame(&rx(0x181, &[2]), at(t, 10)), None, "held");
        // More masks than the subscription has (none): refused, the subscription stays.
        b.filter(std(0x181), Duration::ZERO, &[0xFF], &mut flushed)
            .expect("room for the job");
        assert!(flushed.is_empty());
        assert_eq!(
            b.on_frame(&rx(0x181, &[3]), at(t, 20)),
            None,
            "still throttled"
        );
        // The same kind again: the held frame is flushed, the throttle starts afresh.
        b.subscribe(std(0x181), Duration::ZERO, &mut flushed)
            .expect("room for the job");
        assert_eq!(data(flushed.pop()), Some(vec![3]));
        assert_eq!(data(b.on_frame(&rx(0x181, &[4]), at(t, 21))), Some(vec![4]));
        // A filter may become a subscription (fewer masks).
        b.filter(std(0x200), Duration::ZERO, &[0xFF], &mut flushed)
            .expect("room for the job");
        b.subscribe(std(0x200), Duration::ZERO, &mut flushed)
            .expect("room for the job");
        assert!(b.on_frame(&rx(0x200, &[1]), t).is_some());
        assert!(
            b.on_frame(&rx(0x200, &[1]), t).is_some(),
            "no change needed any more"
        );
        assert!(b.receives(std(0x200)));
        assert!(!b.receives(std(0x201)));
    }
    fn ext(n: u32) -> Id {
        Id::extended(0x1000_0000 + n).expect("an extended identifier")
    }

    fn ext_frame(n: u32) -> Frame {
        Frame::data(ext(n), &[n as u8]).expect("a frame")
    }

    #[test]
    fn the_limit_counts_jobs_and_the_masks_of_receive_operations() {
        let t = Instant::now();
        let mut b = Bcm::new(4);
        let mut flushed = Vec::new();
        for n in 0..3 {
            b.add(Duration::from_millis(10), ext_frame(n), t)
                .expect("room");
        }
        b.subscribe(ext(9), Duration::ZERO, &mut flushed)
            .expect("room");
        assert_eq!(b.add(Duration::ZERO, ext_frame(3), t), Err(Full));
        assert_eq!(
            b.update(ext_frame(3)),
            Err(Full),
            "update would set up a job"
        );
        assert_eq!(b.subscribe(ext(8), Duration::ZERO, &mut flushed), Err(Full));
        // What exists may change: it takes no more room.
        b.add(Duration::ZERO, ext_frame(0), t)
            .expect("a replaced job");
        b.update(ext_frame(1)).expect("an updated job");
        b.subscribe(ext(9), Duration::from_millis(5), &mut flushed)
            .expect("an updated subscription");
        // Deleting makes room, for one job; a multiplex filter of three masks takes three.
        assert!(b.delete(ext(0)) && b.delete(ext(1)));
        let masks = [[0xFF, 0, 0, 0, 0, 0, 0, 0], [1; 8], [2; 8]];
        assert_eq!(b.muxfilter(ext(7), &masks, &mut flushed), Err(Full));
        assert!(b.unsubscribe(ext(9)));
        b.muxfilter(ext(7), &masks, &mut flushed)
            .expect("three slots free");
        assert_eq!(b.add(Duration::ZERO, ext_frame(5), t), Err(Full));
        assert!(!b.receives(ext(8)));
        assert!(flushed.is_empty());
    }

    /// What each command and timer costs, in job records looked at, with `n` cyclic jobs and
    /// `n` throttled subscriptions set up.
    fn costs(n: u32) -> Vec<u64> {
        let t = Instant::now();
        let mut b = Bcm::new(2 * n as usize + 8);
        let mut flushed = Vec::new();
        for i in 0..n {
            b.add(Duration::from_secs(10), ext_frame(i), t)
                .expect("room");
            b.subscribe(ext(i), Duration::from_millis(100), &mut flushed)
                .expect("room");
        }
        let mut due = Due::default();
        b.poll(t, &mut due);
        assert_eq!(due.transmit.len(), n as usize, "each job announced");
        let mut cost = Vec::new();
        let mut step = |b: &mut Bcm, f: &mut dyn FnMut(&mut Bcm)| {
            let before = b.visits;
            f(b);
            cost.push(b.visits - before);
        };
        let r = |i: u32| Received {
            frame: ext_frame(i),
            timestamp: UNIX_EPOCH,
        };
        step(&mut b, &mut |b| {
            b.add(Duration::from_secs(10), ext_frame(n), at(t, 1))
                .expect("room");
        });
        step(&mut b, &mut |b| b.update(ext_frame(1)).expect("a job"));
        step(&mut b, &mut |b| assert!(b.delete(ext(2))));
        step(&mut b, &mut |b| {
            b.subscribe(ext(n), Duration::ZERO, &mut Vec::new())
                .expect("room");
        });
        step(&mut b, &mut |b| assert!(b.unsubscribe(ext(3))));
        // A frame that passes, one held by its throttle, one nobody asked for.
        step(&mut b, &mut |b| {
            assert!(b.on_frame(&r(4), at(t, 2)).is_some())
        });
        step(&mut b, &mut |b| {
            assert!(b.on_frame(&r(4), at(t, 3)).is_none())
        });
        step(&mut b, &mut |b| {
            assert!(b.on_frame(&r(n + 1), at(t, 3)).is_none())
        });
        // Timers: the new job's announcement, nothing due, then the one throttle.
        step(&mut b, &mut |b| {
            let mut due = Due::default();
            b.poll(at(t, 50), &mut due);
            assert_eq!(due.transmit, [ext_frame(n)]);
        });
        step(&mut b, &mut |b| {
            let mut due = Due::default();
            b.poll(at(t, 60), &mut due);
            assert!(due.transmit.is_empty() && due.deliver.is_empty());
        });
        assert_eq!(
            b.next_deadline(),
            Some(at(t, 102)),
            "the held frame's throttle"
        );
        step(&mut b, &mut |b| {
            let mut due = Due::default();
            b.poll(at(t, 102), &mut due);
            assert_eq!(due.deliver.len(), 1);
        });
        cost
    }

    #[test]
    fn a_command_costs_the_same_however_many_jobs_there_are() {
        let few = costs(10);
        assert_eq!(few, costs(20_000));
        assert!(few.iter().all(|&c| c <= 1), "{few:?}");
    }
}
