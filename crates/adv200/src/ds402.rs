//! The card's CiA 402 power drive state machine (chapter 2): the profile's own
//! ([`cantwin_cia402::PowerStateMachine`]), with what the ADV200 fixes.
//!
//! * **Option codes**: chapter 2 lists none of 0x605A–0x605E, so the card behaves in one
//!   fixed way ([`OPTIONS`]): quick stop option 2 (slow down on the quick stop ramp, then
//!   Switch on disabled; no transition 16); *shutdown* and *disable operation* disable the
//!   drive function (the motor coasts); halt (bit 8) slows down on the vl deceleration ramp
//!   while it is set; the fault reaction disables the drive function.
//! * **Fault reaction**: the drive trips at once (its alarms disable the power stage), so
//!   the reaction is complete as soon as it starts: transition 14 follows 13 in the same
//!   evaluation and the statusword shows Fault.
//! * **Start**: after transitions 0 and 1, Switch on disabled.
//! * The statusword has bit 4 (voltage enabled) in every state in which high voltage may be
//!   applied, bit 9 (remote) always, bit 10 (target reached) as the drive says; the vl ramp
//!   bits 4–6 of the controlword are not used (the manual does not list them).

pub use cantwin_cia402::State;
use cantwin_cia402::options::{DisableOption, FaultReactionOption, HaltOption, QuickStopOption};
use cantwin_cia402::{Facts, Motion, OptionCodes, PowerStateMachine, StatusFlags, StopRamp};

/// The option codes the card follows (see the [module documentation](self)).
pub const OPTIONS: OptionCodes = OptionCodes {
    quick_stop: QuickStopOption::DEFAULT,
    shutdown: DisableOption::DisableDriveFunction,
    disable_operation: DisableOption::DisableDriveFunction,
    halt: HaltOption(StopRamp::SlowDown),
    fault_reaction: FaultReactionOption::DisableDriveFunction,
};

/// The state machine with the inputs it needs from the drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ds402 {
    machine: PowerStateMachine,
}

impl Default for Ds402 {
    fn default() -> Self {
        Ds402::new()
    }
}

fn facts(fault: bool, stopped: bool) -> Facts {
    Facts {
        fault,
        fault_reaction_done: true,
        stopped,
    }
}

impl Ds402 {
    /// After transitions 0 and 1: Switch on disabled.
    pub fn new() -> Self {
        Ds402 {
            machine: PowerStateMachine::switch_on_disabled().with_options(OPTIONS),
        }
    }

    /// The state.
    pub fn state(&self) -> State {
        self.machine.state()
    }

    /// Whether `cw` requests a fault reset: a rising edge of bit 7 against the last control
    /// word applied.
    pub fn reset_requested(&self, cw: u16) -> bool {
        self.machine.fault_reset_edge(cw)
    }

    /// Applies control word `cw` given whether a fault is active and whether the motor has
    /// stopped (to end a quick stop). Returns whether a fault reset was requested (rising edge
    /// of bit 7).
    pub fn update(&mut self, cw: u16, fault: bool, stopped: bool) -> bool {
        let step = self.machine.update(cw, facts(fault, stopped));
        self.trip(fault, stopped);
        step.fault_reset
    }

    /// Re-evaluates with the last control word (the motor stopped, a fault appeared).
    pub fn refresh(&mut self, fault: bool, stopped: bool) {
        self.machine.refresh(facts(fault, stopped));
        self.trip(fault, stopped);
    }

    /// Transition 14 at once: the fault reaction is over when it starts.
    fn trip(&mut self, fault: bool, stopped: bool) {
        if self.machine.state() == State::FaultReactionActive {
            self.machine.refresh(facts(fault, stopped));
        }
    }

    /// The status word: the state bits, bit 4 voltage enabled, bit 9 remote, bit 10 target
    /// reached (given).
    pub fn statusword(&self, target_reached: bool) -> u16 {
        let flags = StatusFlags {
            voltage_enabled: self.state().voltage(),
            remote: true,
            target_reached,
            ..StatusFlags::default()
        };
        self.machine.statusword(flags).0
    }

    /// Whether the power stage is on (Operation enabled, halted or not, or a quick stop
    /// ramping down).
    pub fn power(&self) -> bool {
        self.machine.power_stage().enabled()
    }

    /// Whether the drive follows the target velocity (Operation enabled without halt).
    pub fn running(&self) -> bool {
        self.machine.power_stage().motion == Motion::Operate
    }

    /// Whether a quick stop is ramping the motor down.
    pub fn quick_stopping(&self) -> bool {
        self.machine.power_stage().quick_stopping()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_fault_reaction_is_complete_at_once() {
        let mut m = Ds402::new();
        m.update(0x0006, false, true);
        m.update(0x000F, false, true);
        assert_eq!(m.state(), State::OperationEnabled);
        assert_eq!(m.statusword(true), 0x0637);
        m.refresh(true, false);
        assert_eq!(m.state(), State::Fault);
        assert_eq!(m.statusword(false), 0x0218);
        assert!(!m.power());
        // Fault reset has priority: the rising edge of bit 7 takes 15 only.
        assert!(m.update(0x0086, false, true));
        assert_eq!(m.state(), State::SwitchOnDisabled);
        assert_eq!(m.statusword(false), 0x0240);
    }

    #[test]
    fn cia402_halt_keeps_the_power_stage_on_without_following_the_target() {
        let mut m = Ds402::new();
        m.update(0x0006, false, true);
        m.update(0x010F, false, true);
        assert_eq!(m.state(), State::OperationEnabled);
        assert!(m.power() && !m.running());
        m.update(0x000B, false, false);
        assert!(m.quick_stopping());
    }
}
