//! The NMT slave state machine (CiA 301 §7.3.2).
//!
//! After power-on a device initialises, sends its boot-up message and enters
//! pre-operational by itself (§7.3.2.2.1). NMT commands then move it between
//! pre-operational, operational and stopped; reset node and reset communication take it back
//! through initialising. Which services run in which state is table 81 (§7.3.2.2.5),
//! encoded in [`State::allows`].

use crate::wire::{NmtCs, NmtState};

/// The NMT state of a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Initialising: not yet booted (or being reset). Nothing but the boot-up message.
    Initialising,
    /// Pre-operational: SDO, SYNC, TIME, EMCY, error control; no PDOs.
    PreOperational,
    /// Operational: every service.
    Operational,
    /// Stopped: NMT and error control only.
    Stopped,
}

/// A communication service, for the permission table of §7.3.2.2.5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Service {
    /// NMT module control.
    Nmt,
    /// Heartbeat and node/life guarding.
    ErrorControl,
    /// SDO.
    Sdo,
    /// PDO.
    Pdo,
    /// SYNC (consumer and producer).
    Sync,
    /// TIME (consumer and producer).
    Time,
    /// EMCY (producer and consumer).
    Emcy,
}

impl State {
    /// The state code sent in heartbeat and node-guarding messages (table 51). Initialising
    /// reports as boot-up (0).
    pub const fn wire(self) -> NmtState {
        match self {
            State::Initialising => NmtState::BootUp,
            State::PreOperational => NmtState::PreOperational,
            State::Operational => NmtState::Operational,
            State::Stopped => NmtState::Stopped,
        }
    }

    /// Whether `service` is available in this state (CiA 301 §7.3.2.2.5, table 81).
    pub const fn allows(self, service: Service) -> bool {
        match self {
            State::Initialising => false,
            State::PreOperational => !matches!(service, Service::Pdo),
            State::Operational => true,
            State::Stopped => matches!(service, Service::Nmt | Service::ErrorControl),
        }
    }
}

/// What an NMT command asks of the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Transition {
    /// Nothing changes (the command asks for the current state, or comes before boot-up).
    None,
    /// Enter this state.
    Enter(State),
    /// Reset node: application and communication parameters back to their power-on
    /// values, then boot-up (§7.3.2.2.1 transitions 12, 13, 14).
    ResetNode,
    /// Reset communication: communication parameters back to their power-on values, then
    /// boot-up (transitions 9, 10, 11).
    ResetCommunication,
}

/// The transition an NMT command causes in `state` (CiA 301 figure 48, table 80).
pub const fn command(state: State, cs: NmtCs) -> Transition {
    if matches!(state, State::Initialising) {
        // A device that has not booted does not take part in NMT yet.
        return Transition::None;
    }
    let target = match cs {
        NmtCs::Start => State::Operational,
        NmtCs::Stop => State::Stopped,
        NmtCs::EnterPreOperational => State::PreOperational,
        NmtCs::ResetNode => return Transition::ResetNode,
        NmtCs::ResetCommunication => return Transition::ResetCommunication,
    };
    if target as u8 == state as u8 {
        Transition::None
    } else {
        Transition::Enter(target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_3_2_2_5_services_per_state() {
        use Service::*;
        let all = [Nmt, ErrorControl, Sdo, Pdo, Sync, Time, Emcy];
        let allowed = |s: State| {
            all.iter()
                .filter(|x| s.allows(**x))
                .copied()
                .collect::<Vec<_>>()
        };
        assert_eq!(allowed(State::Operational), all);
        assert_eq!(
            allowed(State::PreOperational),
            [Nmt, ErrorControl, Sdo, Sync, Time, Emcy]
        );
        assert_eq!(allowed(State::Stopped), [Nmt, ErrorControl]);
        assert_eq!(allowed(State::Initialising), []);
    }

    #[test]
    fn cia301_7_3_2_2_1_transitions() {
        use State::*;
        assert_eq!(
            command(PreOperational, NmtCs::Start),
            Transition::Enter(Operational)
        );
        assert_eq!(
            command(Stopped, NmtCs::Start),
            Transition::Enter(Operational)
        );
        assert_eq!(
            command(Operational, NmtCs::Stop),
            Transition::Enter(Stopped)
        );
        assert_eq!(
            command(Stopped, NmtCs::EnterPreOperational),
            Transition::Enter(PreOperational)
        );
        assert_eq!(command(Operational, NmtCs::Start), Transition::None);
        assert_eq!(command(Stopped, NmtCs::ResetNode), Transition::ResetNode);
        assert_eq!(
            command(Operational, NmtCs::ResetCommunication),
            Transition::ResetCommunication
        );
        assert_eq!(command(Initialising, NmtCs::Start), Transition::None);
        assert_eq!(Operational.wire() as u8, 5);
        assert_eq!(Stopped.wire() as u8, 4);
        assert_eq!(PreOperational.wire() as u8, 0x7F);
    }
}
