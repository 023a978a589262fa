//! TIME producer and consumer (CiA 301 §7.2.6, object 0x1012).
//!
//! 0x1012 bit 31 makes the device consume TIME messages, bit 30 produce them; bit 29
//! selects a 29-bit identifier. A TIME message carries a TIME_OF_DAY (6 bytes). The
//! producer sends when the application publishes a time (CiA 301 leaves the moment to the
//! application).

use crate::od::TimeOfDay;
use crate::wire::{self, CobId};
use cantwin_can::{Frame, Id};

/// The TIME service of one device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeService {
    cob_id: CobId,
    id: Id,
}

impl Default for TimeService {
    fn default() -> Self {
        TimeService::new(CobId(0x100))
    }
}

impl TimeService {
    /// The service configured by a 0x1012 value.
    pub fn new(cob_id: CobId) -> Self {
        TimeService {
            cob_id,
            id: cob_id.can_id(),
        }
    }

    /// The 0x1012 value.
    pub fn cob_id(&self) -> CobId {
        self.cob_id
    }

    /// Whether the device consumes TIME (bit 31).
    pub fn consumer(&self) -> bool {
        self.cob_id.bit31()
    }

    /// Whether the device produces TIME (bit 30).
    pub fn producer(&self) -> bool {
        self.cob_id.bit30()
    }

    /// The CAN identifier of TIME messages.
    #[inline]
    pub fn id(&self) -> Id {
        self.id
    }

    /// The TIME frame for `time`, if the device is a producer.
    pub fn produce(&self, time: TimeOfDay) -> Option<Frame> {
        self.producer().then(|| wire::Time(time).encode(self.id))
    }

    /// A received frame on the TIME identifier, if the device consumes TIME and it is a
    /// valid TIME message.
    pub fn consume(&self, frame: &Frame) -> Option<TimeOfDay> {
        if !self.consumer() {
            return None;
        }
        wire::Time::decode(frame).ok().map(|t| t.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_5_2_12_bits_30_and_31() {
        let tod = TimeOfDay { ms: 1, days: 2 };
        let off = TimeService::default();
        assert_eq!(off.produce(tod), None);
        let f = Frame::std(0x100, &[1, 0, 0, 0, 2, 0]).unwrap();
        assert_eq!(off.consume(&f), None);
        let both = TimeService::new(CobId(0xC000_0100));
        assert_eq!(both.produce(tod), Some(f));
        assert_eq!(both.consume(&f), Some(tod));
    }
}
