//! The card's CiA 402 power drive state machine (chapter 2): the profile's own
//! ([`cantwin_cia402::PowerStateMachine`]), with what the ADV200 fixes.
//!
//! * **Option codes**: chapter 2 lists none of 0x605A–0x605E, so the card behaves in one
//!   fixed way ([`OPTIONS`]): quick stop option 2 (slow down on the quick stop ramp, then
//!   Switch on disabled; no transition 16); *shutdown* and *disable operation* disable the
//!   drive function (the motor coasts); halt (bit 8) slows down on the vl deceleration ramp
//!   while it is set; the fault reaction disables the drive function.
//! * **Fault reaction**: the drive's alarms disable the power stage and the motor coasts
//!   down (0x605E = 0, *disable drive function*). The reaction is complete when the motor
//!   stands still: FAULT REACTION ACTIVE (statusword `x0xx 1111`) is shown while it coasts,
//!   then transition 14 to FAULT. A fault at standstill takes 13 and 14 in one evaluation.
//! * **Quick stop**: transition 11 is shown in at least one statusword, at standstill too:
//!   transition 12 (0x605A = 2, the stop complete) is taken at an evaluation after the one
//!   whose statusword showed QUICK STOP ACTIVE; the drive's control task, which runs while
//!   the power stage is on, brings that evaluation a millisecond later.
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
    /// QUICK STOP ACTIVE was entered and no statusword has shown it yet: the quick stop is
    /// not complete before it has been shown.
    unshown_quick_stop: bool,
}

impl Default for Ds402 {
    fn default() -> Self {
        Ds402::new()
    }
}

fn facts(fault: bool, stopped: bool) -> Facts {
    Facts {
        fault,
        fault_reaction_done: stopped,
        stopped,
    }
}

impl Ds402 {
    /// After transitions 0 and 1: Switch on disabled.
    pub fn new() -> Self {
        Ds402 {
            machine: PowerStateMachine::switch_on_disabled().with_options(OPTIONS),
            unshown_quick_stop: false,
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
        let step = self.machine.update(cw, self.facts(fault, stopped));
        self.after(step.transitions, fault, stopped);
        step.fault_reset
    }

    /// Re-evaluates with the last control word (the motor stopped, a fault appeared).
    pub fn refresh(&mut self, fault: bool, stopped: bool) {
        let step = self.machine.refresh(self.facts(fault, stopped));
        self.after(step.transitions, fault, stopped);
    }

    /// The facts of an evaluation: a quick stop not yet shown is not complete.
    fn facts(&self, fault: bool, stopped: bool) -> Facts {
        facts(fault, stopped && !self.unshown_quick_stop)
    }

    /// Transition 14 in the evaluation of 13 when the motor already stands still (the
    /// reaction is over when it starts); notes a quick stop to be shown.
    fn after(&mut self, transitions: &[u8], fault: bool, stopped: bool) {
        if transitions.contains(&11) {
            self.unshown_quick_stop = true;
        }
        if transitions.contains(&13) && stopped {
            self.machine.refresh(facts(fault, stopped));
        }
    }

    /// The statusword of the evaluation that has just ended, as the dictionary will serve
    /// it: see [`Ds402::statusword`]. A QUICK STOP ACTIVE it shows has been shown.
    pub fn publish(&mut self, target_reached: bool) -> u16 {
        if self.state() == State::QuickStopActive {
            self.unshown_quick_stop = false;
        }
        self.statusword(target_reached)
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
    fn cia402_fault_at_standstill_is_complete_at_once() {
        let mut m = Ds402::new();
        m.update(0x0006, false, true);
        m.update(0x000F, false, true);
        assert_eq!(m.state(), State::OperationEnabled);
        assert_eq!(m.statusword(true), 0x0637);
        m.refresh(true, true);
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
