//! The power drive state machine (CiA 402-2, device control: the PDS FSA, power drive system finite state automaton),
//! sans-IO: the controlword and the drive's facts go in, the state and what the power stage
//! is to do come out.
//!
//! | # | from → to | event |
//! |---|---|---|
//! | 0 | start → NOT READY TO SWITCH ON | power on ([`PowerStateMachine::new`]) |
//! | 1 | NOT READY TO SWITCH ON → SWITCH ON DISABLED | initialised (the first evaluation) |
//! | 2 | SWITCH ON DISABLED → READY TO SWITCH ON | shutdown |
//! | 3 | READY TO SWITCH ON → SWITCHED ON | switch on |
//! | 4 | SWITCHED ON → OPERATION ENABLED | enable operation |
//! | 5 | OPERATION ENABLED → SWITCHED ON | disable operation (0x605C says how the drive stops) |
//! | 6 | SWITCHED ON → READY TO SWITCH ON | shutdown |
//! | 7 | READY TO SWITCH ON → SWITCH ON DISABLED | disable voltage, quick stop |
//! | 8 | OPERATION ENABLED → READY TO SWITCH ON | shutdown (0x605B says how the drive stops) |
//! | 9 | OPERATION ENABLED → SWITCH ON DISABLED | disable voltage |
//! | 10 | SWITCHED ON → SWITCH ON DISABLED | disable voltage, quick stop |
//! | 11 | OPERATION ENABLED → QUICK STOP ACTIVE | quick stop (0x605A says how) |
//! | 12 | QUICK STOP ACTIVE → SWITCH ON DISABLED | quick stop complete with 0x605A 0–4; disable voltage |
//! | 13 | any but the two below → FAULT REACTION ACTIVE | a fault (0x605E says the reaction) |
//! | 14 | FAULT REACTION ACTIVE → FAULT | fault reaction complete |
//! | 15 | FAULT → SWITCH ON DISABLED | fault reset: rising edge of bit 7, no fault present |
//! | 16 | QUICK STOP ACTIVE → OPERATION ENABLED | enable operation with 0x605A 5–8 |
//!
//! Rules this machine keeps, each from the PDS FSA of CiA 402-2:
//!
//! * An evaluation takes at most one transition, except *switch on + enable operation*
//!   (0xxx 1111) in READY TO SWITCH ON, which the command table defines as transitions 3
//!   and 4 together. So FAULT REACTION ACTIVE and QUICK STOP ACTIVE are always observable in
//!   the statusword for at least one evaluation, and fault reset (15) is never followed by
//!   the shutdown its other bits might spell.
//! * Fault reset acts on the rising edge of bit 7 only, in FAULT, and only once no fault is
//!   present. While bit 7 is set the other bits command nothing (0x0087 in READY TO SWITCH
//!   ON does not switch on).
//! * A fault present in any state other than FAULT REACTION ACTIVE and FAULT takes
//!   transition 13 before anything the controlword says; 14 follows when the caller says
//!   the fault reaction has finished.
//! * QUICK STOP ACTIVE leaves by itself to SWITCH ON DISABLED (12) when the stop is
//!   complete and 0x605A is 0–4; with 5–8 it stays, and *enable operation* takes 16.
//!   *Disable voltage* takes 12 at once.

use crate::controlword::{Command, Controlword};
use crate::options::{DisableOption, FaultReactionOption, OptionCodes, StopRamp};

/// A state of the power drive state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum State {
    /// NOT READY TO SWITCH ON: low-level power applied, the drive initialising.
    NotReadyToSwitchOn,
    /// SWITCH ON DISABLED: initialised; high voltage may be applied; the drive function is
    /// disabled.
    SwitchOnDisabled,
    /// READY TO SWITCH ON: high voltage may be applied; the drive function is disabled.
    ReadyToSwitchOn,
    /// SWITCHED ON: high voltage applied, the power amplifier ready; the drive function is
    /// disabled.
    SwitchedOn,
    /// OPERATION ENABLED: the drive function is enabled and follows the operating mode.
    OperationEnabled,
    /// QUICK STOP ACTIVE: the quick stop function (0x605A) is being performed.
    QuickStopActive,
    /// FAULT REACTION ACTIVE: a fault occurred and the fault reaction (0x605E) is being
    /// performed.
    FaultReactionActive,
    /// FAULT: the fault reaction is complete; the drive function is disabled.
    Fault,
}

impl State {
    /// Every state.
    pub const ALL: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    /// The state's name in lower case (`"switch on disabled"`), as monitors show it;
    /// CiA 402-2 prints it in capitals.
    pub const fn name(self) -> &'static str {
        match self {
            State::NotReadyToSwitchOn => "not ready to switch on",
            State::SwitchOnDisabled => "switch on disabled",
            State::ReadyToSwitchOn => "ready to switch on",
            State::SwitchedOn => "switched on",
            State::OperationEnabled => "operation enabled",
            State::QuickStopActive => "quick stop active",
            State::FaultReactionActive => "fault reaction active",
            State::Fault => "fault",
        }
    }

    /// The statusword bits 0–3, 5 and 6 of the state (see [`crate::statusword`]).
    pub const fn statusword_bits(self) -> u16 {
        self.statusword_pattern().1
    }

    /// `(mask, bits)`: a statusword encodes the state when `sw & mask == bits`.
    pub const fn statusword_pattern(self) -> (u16, u16) {
        match self {
            State::NotReadyToSwitchOn => (0x4F, 0x00),
            State::SwitchOnDisabled => (0x4F, 0x40),
            State::ReadyToSwitchOn => (0x6F, 0x21),
            State::SwitchedOn => (0x6F, 0x23),
            State::OperationEnabled => (0x6F, 0x27),
            State::QuickStopActive => (0x6F, 0x07),
            State::FaultReactionActive => (0x4F, 0x0F),
            State::Fault => (0x4F, 0x08),
        }
    }

    /// Whether high voltage may be applied in the state (the states above SWITCH ON
    /// DISABLED and the fault states; the PDS FSA state descriptions). A drive that
    /// has its DC link up reports it in statusword bit 4.
    pub const fn voltage(self) -> bool {
        !matches!(self, State::NotReadyToSwitchOn | State::SwitchOnDisabled)
    }
}

impl core::fmt::Display for State {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Every transition of the PDS FSA: `(number, from, to)`. Transition 13 ("fault")
/// leaves every state but the two fault states and is listed once per state. Transition 0
/// (start → NOT READY TO SWITCH ON) is [`PowerStateMachine::new`].
pub const TRANSITIONS: [(u8, State, State); 21] = {
    use State::*;
    [
        (1, NotReadyToSwitchOn, SwitchOnDisabled),
        (2, SwitchOnDisabled, ReadyToSwitchOn),
        (3, ReadyToSwitchOn, SwitchedOn),
        (4, SwitchedOn, OperationEnabled),
        (5, OperationEnabled, SwitchedOn),
        (6, SwitchedOn, ReadyToSwitchOn),
        (7, ReadyToSwitchOn, SwitchOnDisabled),
        (8, OperationEnabled, ReadyToSwitchOn),
        (9, OperationEnabled, SwitchOnDisabled),
        (10, SwitchedOn, SwitchOnDisabled),
        (11, OperationEnabled, QuickStopActive),
        (12, QuickStopActive, SwitchOnDisabled),
        (13, NotReadyToSwitchOn, FaultReactionActive),
        (13, SwitchOnDisabled, FaultReactionActive),
        (13, ReadyToSwitchOn, FaultReactionActive),
        (13, SwitchedOn, FaultReactionActive),
        (13, OperationEnabled, FaultReactionActive),
        (13, QuickStopActive, FaultReactionActive),
        (14, FaultReactionActive, Fault),
        (15, Fault, SwitchOnDisabled),
        (16, QuickStopActive, OperationEnabled),
    ]
};

/// Whether transition `number` leads from `from` to `to`.
pub fn is_transition(number: u8, from: State, to: State) -> bool {
    TRANSITIONS
        .iter()
        .any(|&(n, f, t)| n == number && f == from && t == to)
}

/// What the drive tells the state machine about itself at an evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Facts {
    /// A fault is present (transition 13; transition 15 waits until it is gone).
    pub fault: bool,
    /// The fault reaction has finished, e.g. the drive has stopped (transition 14).
    pub fault_reaction_done: bool,
    /// The motor is at standstill: a quick stop is complete (transition 12) and a slow down
    /// after *disable operation* or *shutdown* has ended.
    pub stopped: bool,
}

/// Why the drive is stopping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// Controlword bit 8 in OPERATION ENABLED (0x605D).
    Halt,
    /// QUICK STOP ACTIVE (0x605A).
    QuickStop,
    /// FAULT REACTION ACTIVE (0x605E).
    FaultReaction,
    /// After transition 8 with 0x605B = 1.
    Shutdown,
    /// After transition 5 with 0x605C = 1.
    DisableOperation,
}

/// What the drive function does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Motion {
    /// The drive function is disabled: no torque, the motor coasts (or a brake holds it).
    Disabled,
    /// The operating mode follows its set-points.
    Operate,
    /// The drive function is enabled and brings the motor to standstill on `ramp`.
    Stop {
        /// How it decelerates.
        ramp: StopRamp,
        /// Which function stops it.
        reason: StopReason,
    },
}

/// What the power stage is to do in the present state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PowerStage {
    /// High voltage may be applied ([`State::voltage`]).
    pub voltage: bool,
    /// What the drive function does.
    pub motion: Motion,
}

impl PowerStage {
    /// Whether the drive function is enabled (the motor is under control).
    pub const fn enabled(&self) -> bool {
        !matches!(self.motion, Motion::Disabled)
    }

    /// Whether a quick stop is being performed (QUICK STOP ACTIVE with a ramp).
    pub const fn quick_stopping(&self) -> bool {
        matches!(
            self.motion,
            Motion::Stop {
                reason: StopReason::QuickStop,
                ..
            }
        )
    }

    /// Whether the drive is halted (controlword bit 8 in OPERATION ENABLED).
    pub const fn halted(&self) -> bool {
        matches!(
            self.motion,
            Motion::Stop {
                reason: StopReason::Halt,
                ..
            }
        )
    }
}

/// What one evaluation did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Step {
    /// The state before.
    pub from: State,
    /// The state after.
    pub to: State,
    /// The transitions taken, in order: none, one, or `[3, 4]`.
    pub transitions: &'static [u8],
    /// Whether the controlword had a rising edge of bit 7 (fault reset), whether or not it
    /// led to transition 15.
    pub fault_reset: bool,
}

/// The power drive state machine of one drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PowerStateMachine {
    state: State,
    controlword: u16,
    options: OptionCodes,
    slowing: Option<StopReason>,
}

impl Default for PowerStateMachine {
    fn default() -> Self {
        PowerStateMachine::new()
    }
}

impl PowerStateMachine {
    /// Transition 0: NOT READY TO SWITCH ON, with the standard option codes. The first
    /// evaluation takes transition 1.
    pub fn new() -> Self {
        PowerStateMachine {
            state: State::NotReadyToSwitchOn,
            controlword: 0,
            options: OptionCodes::STANDARD,
            slowing: None,
        }
    }

    /// After transitions 0 and 1: SWITCH ON DISABLED, the state a drive reports once it has
    /// initialised.
    pub fn switch_on_disabled() -> Self {
        PowerStateMachine {
            state: State::SwitchOnDisabled,
            ..PowerStateMachine::new()
        }
    }

    /// The same machine following `options`.
    pub fn with_options(mut self, options: OptionCodes) -> Self {
        self.options = options;
        self
    }

    /// The option codes it follows.
    pub fn options(&self) -> OptionCodes {
        self.options
    }

    /// Follows `options` from now on (the master wrote 0x605A–0x605E).
    pub fn set_options(&mut self, options: OptionCodes) {
        self.options = options;
    }

    /// The state.
    pub fn state(&self) -> State {
        self.state
    }

    /// The last controlword evaluated.
    pub fn controlword(&self) -> u16 {
        self.controlword
    }

    /// Whether evaluating `cw` would see a rising edge of bit 7 (fault reset), so that a
    /// drive can clear its faults before the evaluation that takes transition 15.
    pub fn fault_reset_edge(&self, cw: u16) -> bool {
        Controlword(cw).fault_reset() && !Controlword(self.controlword).fault_reset()
    }

    /// Evaluates controlword `cw` with the drive's `facts`.
    pub fn update(&mut self, cw: u16, facts: Facts) -> Step {
        let fault_reset = self.fault_reset_edge(cw);
        self.controlword = cw;
        let from = self.state;
        let (to, transitions) = self.next(Controlword(cw), facts, fault_reset);
        self.slowing = match transitions {
            [] => self.slowing.filter(|_| !facts.stopped),
            [5] if self.options.disable_operation == DisableOption::SlowDown && !facts.stopped => {
                Some(StopReason::DisableOperation)
            }
            [8] if self.options.shutdown == DisableOption::SlowDown && !facts.stopped => {
                Some(StopReason::Shutdown)
            }
            _ => None,
        };
        self.state = to;
        Step {
            from,
            to,
            transitions,
            fault_reset,
        }
    }

    /// Evaluates the last controlword again with new `facts` (the motor stopped, a fault
    /// appeared or the fault reaction finished). It never sees a fault reset edge.
    pub fn refresh(&mut self, facts: Facts) -> Step {
        self.update(self.controlword, facts)
    }

    fn next(&self, cw: Controlword, facts: Facts, edge: bool) -> (State, &'static [u8]) {
        use State::*;
        let stay = (self.state, &[][..]);
        if facts.fault && !matches!(self.state, FaultReactionActive | Fault) {
            return (FaultReactionActive, &[13]);
        }
        let cmd = cw.command();
        match self.state {
            NotReadyToSwitchOn => (SwitchOnDisabled, &[1]),
            FaultReactionActive if facts.fault_reaction_done => (Fault, &[14]),
            Fault if edge && !facts.fault => (SwitchOnDisabled, &[15]),
            FaultReactionActive | Fault => stay,
            QuickStopActive => {
                let qs = self.options.quick_stop;
                let complete = qs.ramp().is_none() || facts.stopped;
                match cmd {
                    Command::DisableVoltage => (SwitchOnDisabled, &[12]),
                    Command::EnableOperation if qs.stays() => (OperationEnabled, &[16]),
                    _ if !qs.stays() && complete => (SwitchOnDisabled, &[12]),
                    _ => stay,
                }
            }
            SwitchOnDisabled => match cmd {
                Command::Shutdown => (ReadyToSwitchOn, &[2]),
                _ => stay,
            },
            ReadyToSwitchOn => match cmd {
                Command::SwitchOn => (SwitchedOn, &[3]),
                Command::EnableOperation => (OperationEnabled, &[3, 4]),
                Command::DisableVoltage | Command::QuickStop => (SwitchOnDisabled, &[7]),
                _ => stay,
            },
            SwitchedOn => match cmd {
                Command::EnableOperation => (OperationEnabled, &[4]),
                Command::Shutdown => (ReadyToSwitchOn, &[6]),
                Command::DisableVoltage | Command::QuickStop => (SwitchOnDisabled, &[10]),
                _ => stay,
            },
            OperationEnabled => match cmd {
                Command::SwitchOn => (SwitchedOn, &[5]),
                Command::Shutdown => (ReadyToSwitchOn, &[8]),
                Command::DisableVoltage => (SwitchOnDisabled, &[9]),
                Command::QuickStop => (QuickStopActive, &[11]),
                _ => stay,
            },
        }
    }

    /// What the power stage is to do now.
    pub fn power_stage(&self) -> PowerStage {
        use State::*;
        let motion = match self.state {
            NotReadyToSwitchOn | SwitchOnDisabled | Fault => Motion::Disabled,
            ReadyToSwitchOn | SwitchedOn => match self.slowing {
                Some(reason) => Motion::Stop {
                    ramp: StopRamp::SlowDown,
                    reason,
                },
                None => Motion::Disabled,
            },
            OperationEnabled if Controlword(self.controlword).halt() => Motion::Stop {
                ramp: self.options.halt.0,
                reason: StopReason::Halt,
            },
            OperationEnabled => Motion::Operate,
            QuickStopActive => match self.options.quick_stop.ramp() {
                Some(ramp) => Motion::Stop {
                    ramp,
                    reason: StopReason::QuickStop,
                },
                None => Motion::Disabled,
            },
            FaultReactionActive => match self.options.fault_reaction {
                FaultReactionOption::DisableDriveFunction => Motion::Disabled,
                FaultReactionOption::Stop(ramp) => Motion::Stop {
                    ramp,
                    reason: StopReason::FaultReaction,
                },
            },
        };
        PowerStage {
            voltage: self.state.voltage(),
            motion,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(path: &[u16]) -> PowerStateMachine {
        let mut m = PowerStateMachine::switch_on_disabled();
        for cw in path {
            m.update(*cw, Facts::default());
        }
        m
    }

    #[test]
    fn cia402_fsa_start_takes_transitions_0_and_1() {
        let mut m = PowerStateMachine::new();
        assert_eq!(m.state(), State::NotReadyToSwitchOn);
        let s = m.update(0x0006, Facts::default());
        assert_eq!(s.transitions, [1]);
        assert_eq!(m.state(), State::SwitchOnDisabled);
    }

    #[test]
    fn cia402_fsa_switch_on_and_enable_operation_is_3_then_4() {
        let mut m = at(&[0x0006]);
        let s = m.update(0x000F, Facts::default());
        assert_eq!(
            (s.from, s.to),
            (State::ReadyToSwitchOn, State::OperationEnabled)
        );
        assert_eq!(s.transitions, [3, 4]);
        assert_eq!(m.power_stage().motion, Motion::Operate);
    }

    #[test]
    fn cia402_fsa_disable_operation_with_slow_down_keeps_the_drive_enabled_until_stopped() {
        let mut m = at(&[0x0006, 0x000F]);
        m.update(0x0007, Facts::default());
        assert_eq!(m.state(), State::SwitchedOn);
        assert_eq!(
            m.power_stage().motion,
            Motion::Stop {
                ramp: StopRamp::SlowDown,
                reason: StopReason::DisableOperation
            }
        );
        m.refresh(Facts {
            stopped: true,
            ..Facts::default()
        });
        assert_eq!(m.power_stage().motion, Motion::Disabled);
        // With 0x605C = 0 the drive function is disabled at once.
        let mut m = at(&[0x0006, 0x000F]).with_options(OptionCodes {
            disable_operation: DisableOption::DisableDriveFunction,
            ..OptionCodes::STANDARD
        });
        m.update(0x0007, Facts::default());
        assert!(!m.power_stage().enabled());
    }

    #[test]
    fn cia402_fsa_halt_stops_in_operation_enabled() {
        let mut m = at(&[0x0006, 0x000F]);
        m.update(0x010F, Facts::default());
        assert_eq!(m.state(), State::OperationEnabled);
        assert!(m.power_stage().halted());
        m.update(0x000F, Facts::default());
        assert_eq!(m.power_stage().motion, Motion::Operate);
    }
}
