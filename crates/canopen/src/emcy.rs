//! The EMCY producer with the error register (0x1001) and the pre-defined error field
//! (0x1003), CiA 301 §7.2.7 and §7.5.2.2/§7.5.2.4.
//!
//! An error is *raised* once (raising an active code again does nothing) and *cleared*
//! once. Each raise sends an EMCY with the error code, the error register as it is after
//! the change and five manufacturer bytes, and records the code newest-first in the
//! pre-defined error field. Each clear sends the "error reset" EMCY, code 0x0000, with the
//! updated error register (§7.2.7.1, figure 43: error-free → error occurred → error-free).
//!
//! The error register (§7.5.2.2, table 47) is derived from the active errors: bit 0
//! (generic) while any error is active, bit 1 current (0x2xxx), bit 2 voltage (0x3xxx),
//! bit 3 temperature (0x4xxx), bit 4 communication (0x8xxx), bit 5 device profile
//! (0xFFxx is device-specific and sets bit 7, manufacturer-specific).
//!
//! Inhibit time (0x1015, multiples of 100 µs, §7.5.2.14): the minimum time between two
//! EMCY transmissions. EMCYs produced faster are queued (up to [`QUEUE_LEN`]), not dropped;
//! the time is counted from the moment the previous EMCY was handed to the controller.

use crate::wire::{CobId, Emcy};
use cantwin_can::{Duration, Instant};
use std::collections::VecDeque;

/// How many EMCYs wait for their inhibit time at most; further ones are dropped (the
/// error register and the error field still record them).
pub const QUEUE_LEN: usize = 16;

/// The 0x1001 bit an error code sets besides the generic bit 0 (CiA 301 table 47).
pub const fn register_bit(code: u16) -> u8 {
    match code >> 12 {
        0x2 => 1 << 1,
        0x3 => 1 << 2,
        0x4 => 1 << 3,
        0x8 => 1 << 4,
        0xF if code >> 8 == 0xFF => 1 << 7,
        _ => 0,
    }
}

/// An active error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Active {
    code: u16,
}

/// The EMCY producer of one device.
#[derive(Debug, Clone, Default)]
pub struct Producer {
    cob_id: CobId,
    inhibit: Duration,
    last_sent: Option<Instant>,
    queue: VecDeque<Emcy>,
    active: Vec<Active>,
    /// Extra register bits the application holds (bit 5 profile, bit 7 manufacturer).
    extra_register: u8,
    history: Vec<u32>,
    history_len: u8,
    changed: bool,
}

impl Producer {
    /// A producer keeping at most `history_len` entries in 0x1003.
    pub fn new(history_len: u8) -> Self {
        Producer {
            history_len,
            ..Producer::default()
        }
    }

    /// Sets the COB-ID (0x1014): bit 31 set means no EMCY is sent.
    pub fn set_cob_id(&mut self, cob_id: CobId) {
        self.cob_id = cob_id;
        if cob_id.bit31() {
            self.queue.clear();
        }
    }

    /// The COB-ID (0x1014 form).
    pub fn cob_id(&self) -> CobId {
        self.cob_id
    }

    /// Sets the inhibit time from 0x1015 (multiples of 100 µs).
    pub fn set_inhibit(&mut self, units_100us: u16) {
        self.inhibit = Duration::from_micros(u64::from(units_100us) * 100);
    }

    /// The error register (0x1001).
    pub fn register(&self) -> u8 {
        let mut r = self.extra_register;
        for a in &self.active {
            r |= 1 | register_bit(a.code);
        }
        if r != 0 {
            r |= 1;
        }
        r
    }

    /// Sets or clears application-held error register bits (bit 5 device profile, bit 7
    /// manufacturer); they count as an error for bit 0 too.
    pub fn set_register_bits(&mut self, mask: u8, on: bool) {
        if on {
            self.extra_register |= mask & !1;
        } else {
            self.extra_register &= !mask;
        }
        self.changed = true;
    }

    /// Whether `code` is active.
    pub fn is_active(&self, code: u16) -> bool {
        self.active.iter().any(|a| a.code == code)
    }

    /// Whether any error is active.
    pub fn any_active(&self) -> bool {
        !self.active.is_empty()
    }

    /// Raises `code` (not 0x0000): records it and queues the EMCY if `send`. Returns
    /// whether it was newly raised. The 0x1003 entry is the code alone.
    pub fn raise(&mut self, code: u16, manufacturer: [u8; 5], send: bool) -> bool {
        self.raise_with(code, manufacturer, send, |_| u32::from(code))
    }

    /// [`Producer::raise`] with the 0x1003 entry made by `entry` from the error register
    /// as it is after the raise (CiA 301 §7.5.2.4: bits 16–31 of an entry are
    /// manufacturer-specific additional information).
    pub fn raise_with(
        &mut self,
        code: u16,
        manufacturer: [u8; 5],
        send: bool,
        entry: impl FnOnce(u8) -> u32,
    ) -> bool {
        if code == 0 || self.is_active(code) {
            return false;
        }
        self.active.push(Active { code });
        self.occurrence(code, manufacturer, send, entry);
        true
    }

    /// One occurrence of active error `code`: its 0x1003 entry, made by `entry` from the
    /// error register as it is now, and its EMCY if `send`.
    fn occurrence(
        &mut self,
        code: u16,
        manufacturer: [u8; 5],
        send: bool,
        entry: impl FnOnce(u8) -> u32,
    ) {
        let register = self.register();
        self.record(entry(register));
        if send {
            self.enqueue(Emcy {
                code,
                register,
                manufacturer,
            });
        }
    }

    /// Reports error `code` with `manufacturer` bytes: raises it if it is not active,
    /// otherwise records another occurrence of it (a different cause in the device's own
    /// detail, such as another module) with its own 0x1003 entry and EMCY, without a second
    /// active entry. This is CANopenNode's `CO_errorReport` for another error bit of the
    /// same code. Returns whether an EMCY was queued or the code newly raised.
    pub fn report_with(
        &mut self,
        code: u16,
        manufacturer: [u8; 5],
        send: bool,
        entry: impl FnOnce(u8) -> u32,
    ) -> bool {
        if code == 0 {
            return false;
        }
        if !self.is_active(code) {
            return self.raise_with(code, manufacturer, send, entry);
        }
        self.occurrence(code, manufacturer, send, entry);
        send
    }

    /// Adds an entry to the pre-defined error field, newest first.
    fn record(&mut self, entry: u32) {
        if self.history_len > 0 {
            if self.history.len() >= usize::from(self.history_len) {
                self.history.pop();
            }
            self.history.insert(0, entry);
        }
        self.changed = true;
    }

    /// Signals another occurrence of `code` with other manufacturer-specific bytes (the
    /// same error code, a different cause in the device's own detail): queues a new EMCY if
    /// `send`, as CiA 301 §7.2.7.1 sends one per error occurrence, without adding a second
    /// active entry (one reset clears it). Raises it if it is not active. Returns whether an
    /// EMCY was queued or the code newly raised.
    pub fn signal(&mut self, code: u16, manufacturer: [u8; 5], send: bool) -> bool {
        if code == 0 {
            return false;
        }
        if !self.is_active(code) {
            return self.raise(code, manufacturer, send);
        }
        if send {
            self.enqueue(Emcy {
                code,
                register: self.register(),
                manufacturer,
            });
        }
        send
    }

    /// Clears `code`: queues the error reset EMCY (0x0000) if `send`. Returns whether it
    /// was active.
    pub fn clear(&mut self, code: u16, send: bool) -> bool {
        let Some(i) = self.active.iter().position(|a| a.code == code) else {
            return false;
        };
        self.active.remove(i);
        self.changed = true;
        if send {
            self.enqueue(Emcy {
                code: 0,
                register: self.register(),
                manufacturer: [0; 5],
            });
        }
        true
    }

    /// Forgets every active error, the queue and the inhibit timer (reset communication).
    pub fn reset(&mut self) {
        self.active.clear();
        self.queue.clear();
        self.history.clear();
        self.last_sent = None;
        self.extra_register = 0;
        self.changed = true;
    }

    /// Drops queued EMCYs (the device entered stopped, where EMCY is silent).
    pub fn drop_queue(&mut self) {
        self.queue.clear();
    }

    fn enqueue(&mut self, e: Emcy) {
        if !self.cob_id.bit31() && self.queue.len() < QUEUE_LEN {
            self.queue.push_back(e);
        }
    }

    /// The pre-defined error field, newest first (0x1003 sub 1..).
    pub fn history(&self) -> &[u32] {
        &self.history
    }

    /// Writing 0 to 0x1003 sub 0 clears the field.
    pub fn clear_history(&mut self) {
        self.history.clear();
        self.changed = true;
    }

    /// Whether the register or the history changed since the last call (the device
    /// mirrors them into the dictionary).
    pub fn take_changed(&mut self) -> bool {
        core::mem::replace(&mut self.changed, false)
    }

    /// Bytes of heap used.
    pub fn heap_bytes(&self) -> usize {
        self.queue.capacity() * core::mem::size_of::<Emcy>()
            + self.active.capacity() * core::mem::size_of::<Active>()
            + self.history.capacity() * 4
    }

    /// When the next queued EMCY may be sent.
    pub fn next_deadline(&self) -> Option<Instant> {
        if self.queue.is_empty() {
            return None;
        }
        Some(match self.last_sent {
            Some(t) if !self.inhibit.is_zero() => t + self.inhibit,
            _ => Instant::ZERO,
        })
    }

    /// The next EMCY to send at `now`, if one is queued and the inhibit time allows.
    pub fn poll(&mut self, now: Instant) -> Option<Emcy> {
        if self.next_deadline().is_none_or(|t| now < t) {
            return None;
        }
        let e = self.queue.pop_front()?;
        self.last_sent = Some(now);
        Some(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_5_2_2_error_register_bits() {
        let mut p = Producer::new(4);
        p.set_cob_id(CobId(0x85));
        assert_eq!(p.register(), 0);
        p.raise(0x8130, [0; 5], true);
        assert_eq!(p.register(), 0x11);
        p.raise(0x3210, [0; 5], true);
        assert_eq!(p.register(), 0x15);
        p.raise(0xFF01, [0; 5], true);
        assert_eq!(p.register(), 0x95);
        p.clear(0x8130, true);
        p.clear(0x3210, true);
        p.clear(0xFF01, true);
        assert_eq!(p.register(), 0);
        assert_eq!(p.history(), [0xFF01, 0x3210, 0x8130]);
    }

    #[test]
    fn cia301_7_5_2_14_inhibit_queues() {
        let mut p = Producer::new(2);
        p.set_cob_id(CobId(0x85));
        p.set_inhibit(10); // 1 ms
        p.raise(0x1000, [0; 5], true);
        p.raise(0x2000, [0; 5], true);
        p.raise(0x3000, [0; 5], true);
        let t = Instant::from_nanos(5_000);
        assert_eq!(p.poll(t).map(|e| e.code), Some(0x1000));
        assert_eq!(p.poll(t), None);
        assert_eq!(p.next_deadline(), Some(t + Duration::from_millis(1)));
        assert_eq!(
            p.poll(t + Duration::from_millis(1)).map(|e| e.code),
            Some(0x2000)
        );
        assert_eq!(
            p.poll(t + Duration::from_millis(2))
                .map(|e| (e.code, e.register)),
            Some((0x3000, 0x07))
        );
        assert_eq!(p.history(), [0x3000, 0x2000]);
        assert!(!p.raise(0x3000, [0; 5], true));
    }

    #[test]
    fn cia301_7_2_7_1_another_occurrence_with_other_details_is_sent_again() {
        let mut p = Producer::new(0);
        p.set_cob_id(CobId(0x85));
        let t = Instant::from_nanos(1_000);
        assert!(p.signal(0xFF11, [0xC7, 0xFF, 0, 0, 0], true));
        assert!(p.signal(0xFF11, [0x00, 0x81, 0, 0, 0], true));
        let sent: Vec<_> = std::iter::from_fn(|| p.poll(t))
            .map(|e| (e.code, e.manufacturer))
            .collect();
        assert_eq!(
            sent,
            [
                (0xFF11, [0xC7, 0xFF, 0, 0, 0]),
                (0xFF11, [0x00, 0x81, 0, 0, 0])
            ]
        );
        // One active entry: one reset clears it.
        assert!(p.clear(0xFF11, true));
        assert!(!p.is_active(0xFF11));
        assert!(!p.signal(0x0000, [0; 5], true));
    }
}
