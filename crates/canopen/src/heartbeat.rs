//! Heartbeat producer (0x1017) and consumer (0x1016), CiA 301 §7.2.8.3.2.2.
//!
//! Producer: with a producer heartbeat time `t` ≠ 0 ms the device sends its state on
//! 0x700 + node-ID every `t`. The protocol starts with the transition from initialising to
//! pre-operational and the boot-up message counts as the first heartbeat, so the first
//! heartbeat proper follows the boot-up at boot + `t`. Beats are scheduled from the
//! previous deadline, not from the time the driver called, so they never drift. A new
//! 0x1017 value restarts the cycle: the next heartbeat is due one new period after the
//! write (CiA 301 says the protocol "begins immediately"; an immediate extra frame is not
//! required, and one period later keeps the producer's spacing).
//!
//! Consumer: each 0x1016 entry (node-ID in bits 16..23, time in ms in bits 0..15) watches
//! one producer. Monitoring starts with the first heartbeat received from it; a heartbeat
//! not followed by the next within the consumer time is a heartbeat event. A boot-up
//! message (state 0) from the producer stops monitoring until its next heartbeat.

use cantwin_can::{Duration, Instant};

/// The heartbeat producer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Producer {
    period: Duration,
    next: Option<Instant>,
}

impl Producer {
    /// Sets the producer time in ms (0 disables). If running, the next heartbeat is due one
    /// new period after `now`.
    pub fn set_time(&mut self, ms: u16, now: Instant, running: bool) {
        self.period = Duration::from_millis(u64::from(ms));
        self.next = if running && ms != 0 {
            now.checked_add(self.period)
        } else {
            None
        };
    }

    /// The producer time (zero when disabled).
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Whether the producer is enabled (0x1017 ≠ 0).
    pub fn enabled(&self) -> bool {
        !self.period.is_zero()
    }

    /// The boot-up message went out at `boot`: the first heartbeat is due at boot + period.
    pub fn start(&mut self, boot: Instant) {
        self.next = if self.enabled() {
            boot.checked_add(self.period)
        } else {
            None
        };
    }

    /// Stops producing (reset).
    pub fn stop(&mut self) {
        self.next = None;
    }

    /// When the next heartbeat is due.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.next
    }

    /// Whether a heartbeat is due at `now`; if so the next one is scheduled.
    pub fn poll(&mut self, now: Instant) -> bool {
        match self.next {
            Some(t) if now >= t => {
                // A driver that calls late still gets one beat per call and the schedule
                // catches up to the first deadline after `now`.
                let mut n = t + self.period;
                if n <= now {
                    let behind = now.saturating_duration_since(t).as_nanos();
                    let p = self.period.as_nanos().max(1);
                    n = t + Duration::from_nanos((behind / p + 1) * p);
                }
                self.next = Some(n);
                true
            }
            _ => false,
        }
    }
}

/// One 0x1016 entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Entry {
    node: u8,
    time: Duration,
    /// The monitoring deadline; `None` until the first heartbeat.
    deadline: Option<Instant>,
    /// The producer timed out and has not been heard from since.
    lost: bool,
}

/// What a received heartbeat meant to the consumer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Heard {
    /// The node is not monitored.
    NotMonitored,
    /// Monitoring (re)started or continued.
    Alive,
    /// The node had timed out and is heard again.
    Recovered,
    /// A boot-up message: monitoring stops until the next heartbeat. `was_lost` tells
    /// whether the node had timed out.
    BootUp {
        /// The node had timed out before.
        was_lost: bool,
    },
}

/// The heartbeat consumer: one entry per 0x1016 sub-index.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Consumer {
    entries: Vec<Entry>,
}

/// Splits a 0x1016 value into node-ID and time in ms.
pub const fn split(raw: u32) -> (u8, u16) {
    (((raw >> 16) & 0xFF) as u8, (raw & 0xFFFF) as u16)
}

/// Whether a 0x1016 value configures monitoring (node-ID 1..=127, time ≠ 0).
pub const fn active(raw: u32) -> bool {
    let (node, ms) = split(raw);
    node >= 1 && node <= 127 && ms != 0
}

impl Consumer {
    /// A consumer with `n` unused entries.
    pub fn new(n: u8) -> Self {
        Consumer {
            entries: vec![
                Entry {
                    node: 0,
                    time: Duration::ZERO,
                    deadline: None,
                    lost: false,
                };
                usize::from(n)
            ],
        }
    }

    /// Configures entry `sub` (1-based) from its 0x1016 value; monitoring of that entry
    /// starts over (waits for the next heartbeat). Out-of-range entries are ignored.
    pub fn set(&mut self, sub: u8, raw: u32) {
        let Some(e) = usize::from(sub)
            .checked_sub(1)
            .and_then(|i| self.entries.get_mut(i))
        else {
            return;
        };
        let (node, ms) = split(raw);
        *e = Entry {
            node: if active(raw) { node } else { 0 },
            time: Duration::from_millis(u64::from(ms)),
            deadline: None,
            lost: false,
        };
    }

    /// Whether `raw` for entry `sub` would monitor a node another entry already monitors
    /// (CiA 301 §7.5.2.19: answered with 0x06040043).
    pub fn conflicts(&self, sub: u8, raw: u32) -> bool {
        let (node, _) = split(raw);
        active(raw)
            && self
                .entries
                .iter()
                .enumerate()
                .any(|(i, e)| i + 1 != usize::from(sub) && e.node == node)
    }

    /// Whether `node` is monitored by some entry.
    #[inline]
    pub fn watches(&self, node: u8) -> bool {
        node != 0 && self.entries.iter().any(|e| e.node == node)
    }

    /// The node-IDs monitored by some entry: the only producers whose heartbeats change
    /// the consumer.
    pub fn nodes(&self) -> impl Iterator<Item = u8> + '_ {
        self.entries.iter().map(|e| e.node).filter(|&n| n != 0)
    }

    /// A heartbeat or boot-up from `node` with state code `state` at `now`.
    pub fn on_heartbeat(&mut self, node: u8, state: u8, now: Instant) -> Heard {
        let Some(e) = self
            .entries
            .iter_mut()
            .find(|e| node != 0 && e.node == node)
        else {
            return Heard::NotMonitored;
        };
        let was_lost = core::mem::replace(&mut e.lost, false);
        if state == 0 {
            e.deadline = None;
            return Heard::BootUp { was_lost };
        }
        e.deadline = now.checked_add(e.time);
        if was_lost {
            Heard::Recovered
        } else {
            Heard::Alive
        }
    }

    /// Entries whose deadline passed at `now`: they are marked lost (and stop monitoring
    /// until the next heartbeat) and their node-IDs handed to `lost`.
    pub fn on_tick(&mut self, now: Instant, mut lost: impl FnMut(u8)) {
        for e in &mut self.entries {
            if e.deadline.is_some_and(|d| now >= d) {
                e.deadline = None;
                e.lost = true;
                lost(e.node);
            }
        }
    }

    /// Whether any monitored producer is currently lost.
    pub fn any_lost(&self) -> bool {
        self.entries.iter().any(|e| e.lost)
    }

    /// Bytes of heap used.
    pub fn heap_bytes(&self) -> usize {
        self.entries.capacity() * core::mem::size_of::<Entry>()
    }

    /// The earliest monitoring deadline.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.entries.iter().filter_map(|e| e.deadline).min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    fn at(ms: u64) -> Instant {
        Instant::from_nanos(ms * MS)
    }

    #[test]
    fn producer_first_beat_one_period_after_boot_and_no_drift() {
        let mut p = Producer::default();
        p.set_time(100, at(0), false);
        p.start(at(5));
        assert_eq!(p.next_deadline(), Some(at(105)));
        assert!(!p.poll(at(104)));
        assert!(p.poll(at(106)));
        assert_eq!(p.next_deadline(), Some(at(205)));
        assert!(p.poll(at(450)));
        assert_eq!(p.next_deadline(), Some(at(505)));
        p.set_time(0, at(500), true);
        assert_eq!(p.next_deadline(), None);
    }

    #[test]
    fn consumer_arms_on_first_heartbeat_and_boot_up_disarms() {
        let mut c = Consumer::new(2);
        c.set(1, 0x0003_0064); // node 3, 100 ms
        assert!(c.conflicts(2, 0x0003_00C8));
        assert!(!c.conflicts(1, 0x0003_00C8));
        assert!(!c.conflicts(2, 0x0003_0000));
        assert_eq!(c.next_deadline(), None);
        assert_eq!(c.on_heartbeat(3, 5, at(10)), Heard::Alive);
        assert_eq!(c.next_deadline(), Some(at(110)));
        let mut lost = vec![];
        c.on_tick(at(110), |n| lost.push(n));
        assert_eq!(lost, [3]);
        assert!(c.any_lost());
        assert_eq!(c.on_heartbeat(3, 5, at(200)), Heard::Recovered);
        assert_eq!(
            c.on_heartbeat(3, 0, at(250)),
            Heard::BootUp { was_lost: false }
        );
        assert_eq!(c.next_deadline(), None);
        assert_eq!(c.on_heartbeat(4, 5, at(250)), Heard::NotMonitored);
    }
}
