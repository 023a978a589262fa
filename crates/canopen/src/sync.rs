//! SYNC consumer and producer (CiA 301 §7.2.5; objects 0x1005, 0x1006, 0x1007, 0x1019).
//!
//! * 0x1005 COB-ID SYNC: bit 30 makes the device the SYNC producer, bit 29 selects a
//!   29-bit identifier, bits 0..28 the identifier.
//! * 0x1006 communication cycle period in µs: the producer's interval (0: no SYNC).
//! * 0x1007 synchronous window length in µs: synchronous PDOs are sent only within it
//!   after a SYNC (0: no window).
//! * 0x1019 synchronous counter overflow value: 0 sends SYNC without data; 2..=240 adds a
//!   counter byte that runs 1, 2, …, overflow value, 1, … (§7.5.2.37).
//!
//! The producer sends its first SYNC one cycle period after it starts (entering
//! pre-operational or operational, or a new configuration), the counter starting at 1. A
//! changed cycle period applies after the SYNC already scheduled; an idle producer sends
//! its first SYNC one new period after the change.
//! A SYNC producer treats its own SYNC as received (its synchronous PDOs follow it).

use crate::wire::{self, CobId};
use cantwin_can::{Duration, Frame, Id, Instant};

/// EMCY error code of a SYNC whose length does not match 0x1019 (CiA 301 table 21).
pub const EMCY_SYNC_LENGTH: u16 = 0x8240;

/// The SYNC service of one device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncService {
    cob_id: CobId,
    id: Id,
    period: Duration,
    window: Duration,
    overflow: u8,
    counter: u8,
    next: Option<Instant>,
    last: Option<Instant>,
}

impl Default for SyncService {
    fn default() -> Self {
        SyncService {
            cob_id: CobId(0x80),
            id: CobId(0x80).can_id(),
            period: Duration::ZERO,
            window: Duration::ZERO,
            overflow: 0,
            counter: 1,
            next: None,
            last: None,
        }
    }
}

impl SyncService {
    /// Sets 0x1005. Producing starts or stops accordingly if `running` (at `now`).
    pub fn set_cob_id(&mut self, cob_id: CobId, now: Instant, running: bool) {
        self.cob_id = cob_id;
        self.id = cob_id.can_id();
        self.restart(now, running);
    }

    /// Sets 0x1006 (µs). A running producer keeps the SYNC already scheduled; an idle one
    /// starts one new period after `now`.
    pub fn set_period(&mut self, us: u32, now: Instant, running: bool) {
        self.period = Duration::from_micros(u64::from(us));
        if self.next.is_none() || self.period.is_zero() {
            self.restart(now, running);
        }
    }

    /// Sets 0x1007 (µs).
    pub fn set_window(&mut self, us: u32) {
        self.window = Duration::from_micros(u64::from(us));
    }

    /// Sets 0x1019.
    pub fn set_overflow(&mut self, value: u8) {
        self.overflow = value;
        self.counter = 1;
    }

    /// The COB-ID SYNC.
    pub fn cob_id(&self) -> CobId {
        self.cob_id
    }

    /// The CAN identifier SYNC messages use.
    #[inline]
    pub fn id(&self) -> Id {
        self.id
    }

    /// The cycle period (0x1006).
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Whether this device produces SYNC (0x1005 bit 30).
    pub fn is_producer(&self) -> bool {
        self.cob_id.bit30()
    }

    /// (Re)starts the producer at `now` if `running`: first SYNC one period later, counter
    /// back to 1. Stops it otherwise.
    pub fn restart(&mut self, now: Instant, running: bool) {
        self.counter = 1;
        self.next = if running && self.is_producer() && !self.period.is_zero() {
            now.checked_add(self.period)
        } else {
            None
        };
    }

    /// Stops producing (stopped state, reset).
    pub fn stop(&mut self) {
        self.next = None;
        self.counter = 1;
    }

    /// When the next SYNC is due.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.next
    }

    /// The SYNC frame due at `now`, if any; the producer counts it as received.
    pub fn poll(&mut self, now: Instant) -> Option<(Frame, Option<u8>)> {
        let t = self.next.filter(|t| now >= *t)?;
        let mut n = t + self.period;
        if n <= now {
            let p = self.period.as_nanos().max(1);
            let behind = now.saturating_duration_since(t).as_nanos();
            n = t + Duration::from_nanos((behind / p + 1) * p);
        }
        self.next = Some(n);
        let counter = (self.overflow >= 2).then_some(self.counter);
        if counter.is_some() {
            self.counter = if self.counter >= self.overflow {
                1
            } else {
                self.counter + 1
            };
        }
        self.last = Some(now);
        Some((wire::Sync { counter }.encode(self.id), counter))
    }

    /// A frame on the SYNC identifier: `Ok(counter)`, or `Err(EMCY code)` if its length
    /// does not match 0x1019 (0 bytes without a counter, 1 byte with one).
    pub fn on_receive(&mut self, frame: &Frame, now: Instant) -> Result<Option<u8>, u16> {
        let sync = wire::Sync::decode(frame).map_err(|_| EMCY_SYNC_LENGTH)?;
        if sync.counter.is_some() != (self.overflow >= 2) {
            return Err(EMCY_SYNC_LENGTH);
        }
        self.last = Some(now);
        Ok(sync.counter)
    }

    /// Whether `now` is inside the synchronous window after the last SYNC (always, with no
    /// window configured).
    pub fn window_open(&self, now: Instant) -> bool {
        if self.window.is_zero() {
            return true;
        }
        self.last
            .is_some_and(|t| now.saturating_duration_since(t) < self.window)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: u64 = 1_000;

    #[test]
    fn cia301_7_5_2_37_counter_runs_to_overflow_then_restarts_at_1() {
        let mut s = SyncService::default();
        let t0 = Instant::ZERO;
        s.set_overflow(3);
        s.set_cob_id(CobId(0x4000_0080), t0, true);
        s.set_period(1000, t0, true);
        let mut got = vec![];
        let mut t = t0;
        for _ in 0..5 {
            t = s.next_deadline().unwrap();
            let (f, c) = s.poll(t).unwrap();
            assert_eq!(f.data_bytes(), [c.unwrap()]);
            got.push((t.as_nanos() / US, c.unwrap()));
        }
        assert_eq!(got, [(1000, 1), (2000, 2), (3000, 3), (4000, 1), (5000, 2)]);
        assert!(s.poll(t).is_none());
        assert_eq!(
            s.on_receive(&Frame::std(0x80, &[]).unwrap(), t),
            Err(EMCY_SYNC_LENGTH)
        );
    }

    #[test]
    fn cia301_7_5_2_22_window() {
        let mut s = SyncService::default();
        s.set_window(500);
        let t = Instant::from_nanos(10 * US);
        assert!(!s.window_open(t));
        assert_eq!(s.on_receive(&Frame::std(0x80, &[]).unwrap(), t), Ok(None));
        assert!(s.window_open(t + Duration::from_micros(499)));
        assert!(!s.window_open(t + Duration::from_micros(500)));
    }
}
