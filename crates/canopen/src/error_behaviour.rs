//! Error behaviour, object 0x1029 (CiA 301 §7.5.2.32): the NMT state a device enters when
//! it detects a serious communication error (bus-off, heartbeat consumer timeout, life
//! guarding event).

use crate::nmt::State;

/// The reaction a 0x1029 sub-index selects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reaction {
    /// 0: change to pre-operational, only if the device is operational.
    PreOperational,
    /// 1: no change of the NMT state.
    NoChange,
    /// 2: change to stopped.
    Stopped,
    /// 0x80..=0xFF: manufacturer-specific; cantwin leaves the NMT state alone.
    Manufacturer(u8),
}

impl Reaction {
    /// The reaction a 0x1029 value selects, or `None` for the reserved values 3..=0x7F
    /// (a download of those is answered with 0x06090030).
    pub const fn from_u8(v: u8) -> Option<Reaction> {
        match v {
            0 => Some(Reaction::PreOperational),
            1 => Some(Reaction::NoChange),
            2 => Some(Reaction::Stopped),
            0x80..=0xFF => Some(Reaction::Manufacturer(v)),
            _ => None,
        }
    }

    /// The state to enter from `state`, if the reaction changes it.
    pub const fn apply(self, state: State) -> Option<State> {
        match (self, state) {
            (Reaction::PreOperational, State::Operational) => Some(State::PreOperational),
            (Reaction::Stopped, State::PreOperational | State::Operational) => Some(State::Stopped),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_5_2_32_reactions() {
        assert_eq!(
            Reaction::from_u8(0).map(|r| r.apply(State::Operational)),
            Some(Some(State::PreOperational))
        );
        assert_eq!(Reaction::PreOperational.apply(State::Stopped), None);
        assert_eq!(Reaction::PreOperational.apply(State::PreOperational), None);
        assert_eq!(Reaction::NoChange.apply(State::Operational), None);
        assert_eq!(
            Reaction::Stopped.apply(State::PreOperational),
            Some(State::Stopped)
        );
        assert_eq!(Reaction::from_u8(3), None);
        assert_eq!(Reaction::from_u8(0x7F), None);
        assert_eq!(Reaction::from_u8(0x80), Some(Reaction::Manufacturer(0x80)));
    }
}
