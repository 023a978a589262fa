//! Node guarding and life guarding (CiA 301 §7.2.8.3.2.1).
//!
//! The NMT master polls a node with a remote frame on 0x700 + node-ID; the node answers
//! with one byte: the toggle bit (bit 7, 0 in the first answer after reset communication,
//! then alternating) and its state (bits 0..6). Life guarding: with guard time (0x100C, ms)
//! × life time factor (0x100D) ≠ 0, the node expects the next poll within the life time,
//! counted from each poll received; the first poll arms it. A missed poll is a life
//! guarding event (EMCY 0x8130 and the 0x1029 reaction). Guarding is not used while the
//! heartbeat producer is enabled (§7.2.8.3.2: a device uses one or the other).

use cantwin_can::{Duration, Instant};

/// The node guarding slave.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Guarding {
    toggle: bool,
    life_time: Duration,
    deadline: Option<Instant>,
    lost: bool,
}

/// What a guarding poll did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Answer {
    /// The response byte: toggle bit | state.
    pub byte: u8,
    /// The poll ends a life guarding event.
    pub recovered: bool,
}

impl Guarding {
    /// Sets the life time from 0x100C (ms) and 0x100D. A running life guard keeps its
    /// deadline until the next poll; a life time of 0 disables it at once.
    pub fn set_life_time(&mut self, guard_ms: u16, factor: u8) {
        self.life_time = Duration::from_millis(u64::from(guard_ms) * u64::from(factor));
        if self.life_time.is_zero() {
            self.deadline = None;
        }
    }

    /// The life time (0 when life guarding is off).
    pub fn life_time(&self) -> Duration {
        self.life_time
    }

    /// Reset communication: toggle back to 0, life guarding waits for the first poll.
    pub fn reset(&mut self) {
        self.toggle = false;
        self.deadline = None;
        self.lost = false;
    }

    /// Answers a poll at `now` from a node in state `state` (table 51 code).
    pub fn on_request(&mut self, state: u8, now: Instant) -> Answer {
        let byte = (u8::from(self.toggle) << 7) | (state & 0x7F);
        self.toggle = !self.toggle;
        self.deadline = if self.life_time.is_zero() {
            None
        } else {
            now.checked_add(self.life_time)
        };
        Answer {
            byte,
            recovered: core::mem::replace(&mut self.lost, false),
        }
    }

    /// Whether the life time ran out at `now` (reported once per event).
    pub fn on_tick(&mut self, now: Instant) -> bool {
        if self.deadline.is_some_and(|d| now >= d) {
            self.deadline = None;
            self.lost = true;
            return true;
        }
        false
    }

    /// Whether a life guarding event is in progress.
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// The life guarding deadline.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.deadline
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_2_8_3_2_1_toggle_and_life_time() {
        let mut g = Guarding::default();
        g.set_life_time(100, 3);
        assert_eq!(g.next_deadline(), None);
        let t0 = Instant::from_nanos(1_000);
        assert_eq!(g.on_request(0x7F, t0).byte, 0x7F);
        assert_eq!(g.on_request(5, t0).byte, 0x85);
        assert_eq!(g.on_request(5, t0).byte, 0x05);
        assert_eq!(g.next_deadline(), Some(t0 + Duration::from_millis(300)));
        assert!(!g.on_tick(t0 + Duration::from_millis(299)));
        assert!(g.on_tick(t0 + Duration::from_millis(300)));
        assert!(!g.on_tick(t0 + Duration::from_millis(600)));
        let a = g.on_request(5, t0 + Duration::from_millis(700));
        assert_eq!(
            a,
            Answer {
                byte: 0x85,
                recovered: true
            }
        );
        g.reset();
        assert_eq!(g.on_request(4, t0).byte, 0x04);
    }
}
