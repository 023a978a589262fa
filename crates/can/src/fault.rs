//! Fault confinement (ISO 11898-1 §12.1.4): transmit and receive error counters and the
//! error-active / error-passive / bus-off states they imply.

/// A node's fault confinement state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ErrorState {
    /// Both counters ≤ 127: the node sends active (dominant) error flags.
    #[default]
    Active,
    /// A counter above 127: passive error flags, suspend transmission after sending.
    Passive,
    /// TEC above 255: the node takes no part in bus activity until it recovers.
    BusOff,
}

/// The transmit (TEC) and receive (REC) error counters of a CAN controller.
///
/// Every method returns the state after the event when the event changed it, so the caller
/// can raise the matching [`crate::ControllerEvent`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ErrorCounters {
    tec: u16,
    rec: u16,
    bus_off: bool,
}

impl ErrorCounters {
    /// TEC above this is bus-off (§12.1.4.2).
    pub const BUS_OFF_LIMIT: u16 = 255;
    /// A counter above this is error-passive.
    pub const PASSIVE_LIMIT: u16 = 127;
    /// The warning limit most controllers signal (not a state of ISO 11898-1).
    pub const WARNING_LIMIT: u16 = 96;
    /// Occurrences of 11 consecutive recessive bits that end bus-off (§12.1.4.2 rule l).
    pub const RECOVERY_SEQUENCES: u32 = 128;
    /// Recessive bits in one recovery sequence.
    pub const RECOVERY_SEQUENCE_BITS: u32 = 11;

    /// Fresh counters, error-active.
    pub const fn new() -> Self {
        ErrorCounters {
            tec: 0,
            rec: 0,
            bus_off: false,
        }
    }

    /// The transmit error counter.
    pub const fn tec(&self) -> u16 {
        self.tec
    }

    /// The receive error counter.
    pub const fn rec(&self) -> u16 {
        self.rec
    }

    /// The state the counters imply.
    pub const fn state(&self) -> ErrorState {
        if self.bus_off {
            ErrorState::BusOff
        } else if self.tec > Self::PASSIVE_LIMIT || self.rec > Self::PASSIVE_LIMIT {
            ErrorState::Passive
        } else {
            ErrorState::Active
        }
    }

    fn transition(&self, before: ErrorState) -> Option<ErrorState> {
        let after = self.state();
        (after != before).then_some(after)
    }

    /// The node detected an error while transmitting and sent an error flag: TEC += 8
    /// (rule c). `ack_error` marks an ACK error: an error-passive transmitter that sees an
    /// ACK error does not count it (exception 1 of rule c), which is why a node alone on a
    /// bus stays error-passive instead of going bus-off.
    pub fn on_transmit_error(&mut self, ack_error: bool) -> Option<ErrorState> {
        let before = self.state();
        if before == ErrorState::BusOff {
            return None;
        }
        if ack_error && before == ErrorState::Passive {
            return None;
        }
        self.tec = self.tec.saturating_add(8);
        if self.tec > Self::BUS_OFF_LIMIT {
            self.bus_off = true;
        }
        self.transition(before)
    }

    /// A frame was transmitted successfully: TEC -= 1 unless 0 (rule g).
    pub fn on_transmit_success(&mut self) -> Option<ErrorState> {
        let before = self.state();
        if before == ErrorState::BusOff {
            return None;
        }
        self.tec = self.tec.saturating_sub(1);
        self.transition(before)
    }

    /// The node detected an error while receiving: REC += 1 (rule a).
    pub fn on_receive_error(&mut self) -> Option<ErrorState> {
        let before = self.state();
        if before == ErrorState::BusOff {
            return None;
        }
        // The counter is not specified beyond what decides the state; keep it bounded.
        self.rec = (self.rec + 1).min(Self::BUS_OFF_LIMIT);
        self.transition(before)
    }

    /// A receiver detected a dominant bit right after its own error flag: REC += 8 (rule b).
    pub fn on_receive_error_severe(&mut self) -> Option<ErrorState> {
        let before = self.state();
        if before == ErrorState::BusOff {
            return None;
        }
        self.rec = (self.rec + 8).min(Self::BUS_OFF_LIMIT);
        self.transition(before)
    }

    /// A frame was received successfully: REC -= 1 if between 1 and 127, or back to 127 if
    /// above (rule h allows 119..=127; cantwin picks 127, the value most controllers use).
    pub fn on_receive_success(&mut self) -> Option<ErrorState> {
        let before = self.state();
        if before == ErrorState::BusOff {
            return None;
        }
        if self.rec > Self::PASSIVE_LIMIT {
            self.rec = Self::PASSIVE_LIMIT;
        } else {
            self.rec = self.rec.saturating_sub(1);
        }
        self.transition(before)
    }

    /// Force the node bus-off (fault injection, or a controller the host switched off).
    pub fn force_bus_off(&mut self) -> Option<ErrorState> {
        let before = self.state();
        self.bus_off = true;
        self.tec = Self::BUS_OFF_LIMIT + 1;
        self.transition(before)
    }

    /// The node saw 128 × 11 recessive bits while bus-off: back to error-active with both
    /// counters at 0 (rule l).
    pub fn recover(&mut self) -> Option<ErrorState> {
        let before = self.state();
        *self = ErrorCounters::new();
        self.transition(before)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_transmit_errors_make_passive_then_thirty_two_bus_off() {
        let mut c = ErrorCounters::new();
        for i in 1..=15 {
            assert_eq!(c.on_transmit_error(false), None, "error {i}");
        }
        assert_eq!(c.tec(), 120);
        assert_eq!(c.on_transmit_error(false), Some(ErrorState::Passive));
        assert_eq!(c.tec(), 128);
        for _ in 17..=31 {
            assert_eq!(c.on_transmit_error(false), None);
        }
        assert_eq!(c.tec(), 248);
        assert_eq!(c.on_transmit_error(false), Some(ErrorState::BusOff));
        assert_eq!(
            c.on_transmit_success(),
            None,
            "a bus-off node sends nothing"
        );
        assert_eq!(c.recover(), Some(ErrorState::Active));
        assert_eq!((c.tec(), c.rec()), (0, 0));
    }

    #[test]
    fn ack_errors_stop_counting_once_passive() {
        let mut c = ErrorCounters::new();
        while c.state() == ErrorState::Active {
            c.on_transmit_error(true);
        }
        assert_eq!(c.tec(), 128);
        for _ in 0..1000 {
            assert_eq!(c.on_transmit_error(true), None);
        }
        assert_eq!(c.tec(), 128);
        assert_eq!(c.state(), ErrorState::Passive);
    }

    #[test]
    fn receive_counter_rules() {
        let mut c = ErrorCounters::new();
        for _ in 0..127 {
            c.on_receive_error();
        }
        assert_eq!(c.state(), ErrorState::Active);
        assert_eq!(c.on_receive_error(), Some(ErrorState::Passive));
        assert_eq!(c.on_receive_error_severe(), None);
        assert_eq!(c.rec(), 136);
        assert_eq!(c.on_receive_success(), Some(ErrorState::Active));
        assert_eq!(c.rec(), 127);
        c.on_receive_success();
        assert_eq!(c.rec(), 126);
    }

    #[test]
    fn success_decrements_tec_and_returns_to_active() {
        let mut c = ErrorCounters::new();
        for _ in 0..16 {
            c.on_transmit_error(false);
        }
        assert_eq!(c.state(), ErrorState::Passive);
        assert_eq!(c.on_transmit_success(), Some(ErrorState::Active));
        assert_eq!(c.tec(), 127);
    }
}
