//! The CiA 402 power drive state machine (chapter 2; CiA DSP 402 §10.1.1), velocity mode.
//!
//! Transitions 0–15 are implemented; a control word is applied until the state is stable, so
//! "enable operation" (0x000F) in Ready to switch on runs transitions 3 and 4 at once.
//! Quick stop uses option code 2 (slow down on the quick stop ramp, then Switch on disabled):
//! 0x605A is not among the objects chapter 2 lists, so transition 16 (Quick stop active →
//! Operation enabled) does not exist. Fault reaction: the drive trips at once, so Fault
//! reaction active lasts until the next evaluation. Halt (bit 8) ramps to zero while set; the
//! vl ramp bits 4–6 are not used (the manual does not list them).

/// A state of the machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Not ready to switch on (initialising).
    NotReadyToSwitchOn,
    /// Switch on disabled.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on.
    SwitchedOn,
    /// Operation enabled.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

/// A control word command (CiA 402 table of device control commands).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Shutdown: 0xxx x110.
    Shutdown,
    /// Switch on: 0xxx 0111.
    SwitchOn,
    /// Enable operation / switch on + enable: 0xxx 1111.
    EnableOperation,
    /// Disable voltage: 0xxx xx0x.
    DisableVoltage,
    /// Quick stop: 0xxx x01x.
    QuickStop,
    /// None of the above (bit 7 set is handled as fault reset).
    None,
}

impl Command {
    /// Decodes bits 0–3 and 7 of a control word.
    pub const fn decode(cw: u16) -> Command {
        if cw & 0x0002 == 0 {
            Command::DisableVoltage
        } else if cw & 0x0006 == 0x0002 {
            Command::QuickStop
        } else if cw & 0x0007 == 0x0006 {
            Command::Shutdown
        } else if cw & 0x000F == 0x0007 {
            Command::SwitchOn
        } else if cw & 0x000F == 0x000F {
            Command::EnableOperation
        } else {
            Command::None
        }
    }
}

/// The state machine with the inputs it needs from the drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ds402 {
    state: State,
    last_cw: u16,
}

impl Default for Ds402 {
    fn default() -> Self {
        Ds402::new()
    }
}

impl Ds402 {
    /// After transitions 0 and 1: Switch on disabled.
    pub fn new() -> Self {
        Ds402 {
            state: State::SwitchOnDisabled,
            last_cw: 0,
        }
    }

    /// The state.
    pub fn state(&self) -> State {
        self.state
    }

    /// Whether `cw` requests a fault reset: a rising edge of bit 7 against the last control
    /// word applied.
    pub fn reset_requested(&self, cw: u16) -> bool {
        cw & 0x80 != 0 && self.last_cw & 0x80 == 0
    }

    /// Applies control word `cw` given whether a fault is active and whether the motor has
    /// stopped (to end a quick stop). Returns whether a fault reset was requested (rising edge
    /// of bit 7).
    pub fn update(&mut self, cw: u16, fault: bool, stopped: bool) -> bool {
        let reset = cw & 0x80 != 0 && self.last_cw & 0x80 == 0;
        self.last_cw = cw;
        let cmd = Command::decode(cw);
        for _ in 0..4 {
            let next = self.next(cmd, fault, stopped, reset);
            if next == self.state {
                break;
            }
            self.state = next;
        }
        reset
    }

    fn next(&self, cmd: Command, fault: bool, stopped: bool, reset: bool) -> State {
        use State::*;
        if fault && !matches!(self.state, FaultReactionActive | Fault) {
            return FaultReactionActive; // 13
        }
        match (self.state, cmd) {
            (NotReadyToSwitchOn, _) => SwitchOnDisabled,       // 1
            (FaultReactionActive, _) => Fault,                 // 14
            (Fault, _) if reset && !fault => SwitchOnDisabled, // 15
            (Fault, _) => Fault,
            (SwitchOnDisabled, Command::Shutdown) => ReadyToSwitchOn, // 2
            (ReadyToSwitchOn, Command::SwitchOn | Command::EnableOperation) => SwitchedOn, // 3
            (ReadyToSwitchOn, Command::QuickStop | Command::DisableVoltage) => SwitchOnDisabled, // 7
            (SwitchedOn, Command::EnableOperation) => OperationEnabled, // 4
            (SwitchedOn, Command::Shutdown) => ReadyToSwitchOn,         // 6
            (SwitchedOn, Command::QuickStop | Command::DisableVoltage) => SwitchOnDisabled, // 10
            (OperationEnabled, Command::SwitchOn) => SwitchedOn,        // 5
            (OperationEnabled, Command::Shutdown) => ReadyToSwitchOn,   // 8
            (OperationEnabled, Command::DisableVoltage) => SwitchOnDisabled, // 9
            (OperationEnabled, Command::QuickStop) => QuickStopActive,  // 11
            (QuickStopActive, Command::DisableVoltage) => SwitchOnDisabled, // 12
            (QuickStopActive, _) if stopped => SwitchOnDisabled,        // 12
            (s, _) => s,
        }
    }

    /// Re-evaluates with the last control word (the motor stopped, a fault appeared).
    pub fn refresh(&mut self, fault: bool, stopped: bool) {
        let cw = self.last_cw;
        let cmd = Command::decode(cw);
        for _ in 0..4 {
            let next = self.next(cmd, fault, stopped, false);
            if next == self.state {
                break;
            }
            self.state = next;
        }
    }

    /// The status word: state bits 0–3, 5, 6; bit 4 voltage enabled; bit 9 remote; bit 10
    /// target reached (given); bit 8 stays 0.
    pub fn statusword(&self, target_reached: bool) -> u16 {
        use State::*;
        let state = match self.state {
            NotReadyToSwitchOn => 0x0000,
            SwitchOnDisabled => 0x0040,
            ReadyToSwitchOn => 0x0031,
            SwitchedOn => 0x0033,
            OperationEnabled => 0x0037,
            QuickStopActive => 0x0017,
            FaultReactionActive => 0x001F,
            Fault => 0x0018,
        };
        state | 0x0200 | if target_reached { 0x0400 } else { 0 }
    }

    /// Whether the power stage is on (Operation enabled or a quick stop ramping down).
    pub fn power(&self) -> bool {
        matches!(self.state, State::OperationEnabled | State::QuickStopActive)
    }

    /// Whether the last control word holds Halt (bit 8).
    pub fn halt(&self) -> bool {
        self.last_cw & 0x0100 != 0
    }
}
