//! The controlword, 0x6040 (CiA 402-2, object 6040h): the device control commands in bits 0–3 and
//! 7, halt in bit 8, the operation-mode-specific bits 4–6 and 9.

/// A device control command, the pattern of controlword bits 0–3 and 7 (CiA 402-2, object 6040h,
/// table "command coding").
///
/// Two patterns have two names in the standard, depending on the state they reach:
/// [`Command::SwitchOn`] is also *disable operation* (transition 5) and
/// [`Command::EnableOperation`] is also *switch on + enable operation* (transitions 3 + 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// Shutdown, `0xxx x110`: transitions 2, 6, 8.
    Shutdown,
    /// Switch on / disable operation, `0xxx 0111`: transitions 3, 5.
    SwitchOn,
    /// Enable operation / switch on + enable operation, `0xxx 1111`: transitions 4, 16 and
    /// 3 + 4.
    EnableOperation,
    /// Disable voltage, `0xxx xx0x`: transitions 7, 9, 10, 12.
    DisableVoltage,
    /// Quick stop, `0xxx x01x`: transitions 7, 10, 11.
    QuickStop,
    /// Fault reset, `1xxx xxxx`: transition 15 on the rising edge of bit 7. While bit 7 is
    /// set the other bits command nothing.
    FaultReset,
}

impl Command {
    /// Every command, for tables and tests.
    pub const ALL: [Command; 6] = [
        Command::Shutdown,
        Command::SwitchOn,
        Command::EnableOperation,
        Command::DisableVoltage,
        Command::QuickStop,
        Command::FaultReset,
    ];

    /// The usual controlword for the command, with every other bit 0 (0x0006, 0x0007,
    /// 0x000F, 0x0000, 0x0002, 0x0080).
    pub const fn controlword(self) -> u16 {
        match self {
            Command::Shutdown => 0x0006,
            Command::SwitchOn => 0x0007,
            Command::EnableOperation => 0x000F,
            Command::DisableVoltage => 0x0000,
            Command::QuickStop => 0x0002,
            Command::FaultReset => 0x0080,
        }
    }

    /// The command's name in CiA 402-2, lower case.
    pub const fn name(self) -> &'static str {
        match self {
            Command::Shutdown => "shutdown",
            Command::SwitchOn => "switch on",
            Command::EnableOperation => "enable operation",
            Command::DisableVoltage => "disable voltage",
            Command::QuickStop => "quick stop",
            Command::FaultReset => "fault reset",
        }
    }
}

/// Bit 0: switch on.
pub const SWITCH_ON: u16 = 1 << 0;
/// Bit 1: enable voltage.
pub const ENABLE_VOLTAGE: u16 = 1 << 1;
/// Bit 2: quick stop, active low (0 commands a quick stop).
pub const QUICK_STOP: u16 = 1 << 2;
/// Bit 3: enable operation.
pub const ENABLE_OPERATION: u16 = 1 << 3;
/// Bit 7: fault reset (acts on its rising edge).
pub const FAULT_RESET: u16 = 1 << 7;
/// Bit 8: halt.
pub const HALT: u16 = 1 << 8;
/// vl mode bit 4: ramp function generator enable (CiA 402-2, vl mode controlword).
pub const VL_RFG_ENABLE: u16 = 1 << 4;
/// vl mode bit 5: ramp function generator unlock.
pub const VL_RFG_UNLOCK: u16 = 1 << 5;
/// vl mode bit 6: ramp function generator uses the reference.
pub const VL_RFG_USE_REF: u16 = 1 << 6;

/// A controlword value with its bits named.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Controlword(pub u16);

impl Controlword {
    /// The command bits 0–3 and 7 encode. Every value encodes one: the table of CiA 402-2
    /// covers all 32 patterns.
    pub const fn command(self) -> Command {
        let cw = self.0;
        if cw & FAULT_RESET != 0 {
            Command::FaultReset
        } else if cw & ENABLE_VOLTAGE == 0 {
            Command::DisableVoltage
        } else if cw & QUICK_STOP == 0 {
            Command::QuickStop
        } else if cw & SWITCH_ON == 0 {
            Command::Shutdown
        } else if cw & ENABLE_OPERATION == 0 {
            Command::SwitchOn
        } else {
            Command::EnableOperation
        }
    }

    /// Bit 7, fault reset, as a level (the state machine looks for its rising edge).
    pub const fn fault_reset(self) -> bool {
        self.0 & FAULT_RESET != 0
    }

    /// Bit 8, halt.
    pub const fn halt(self) -> bool {
        self.0 & HALT != 0
    }

    /// Bits 4–6, operation mode specific (vl: rfg enable, rfg unlock, rfg use ref; pp:
    /// new set-point, change set immediately, abs/rel; hm: homing operation start).
    pub const fn mode_bits(self) -> u8 {
        ((self.0 >> 4) & 0x7) as u8
    }

    /// Bit 9, operation mode specific (pp: change on set-point).
    pub const fn bit9(self) -> bool {
        self.0 & (1 << 9) != 0
    }

    /// Bits 11–15, manufacturer-specific.
    pub const fn manufacturer_bits(self) -> u8 {
        (self.0 >> 11) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_6040h_command_coding_covers_every_pattern() {
        // The x positions of the table do not matter.
        for cw in 0..=0xFFFFu16 {
            let c = Controlword(cw).command();
            let expected = match (cw >> 7 & 1, cw >> 3 & 1, cw >> 2 & 1, cw >> 1 & 1, cw & 1) {
                (1, ..) => Command::FaultReset,
                (0, _, _, 0, _) => Command::DisableVoltage,
                (0, _, 0, 1, _) => Command::QuickStop,
                (0, _, 1, 1, 0) => Command::Shutdown,
                (0, 0, 1, 1, 1) => Command::SwitchOn,
                _ => Command::EnableOperation,
            };
            assert_eq!(c, expected, "{cw:#06x}");
        }
        for c in Command::ALL {
            assert_eq!(Controlword(c.controlword()).command(), c);
        }
    }

    #[test]
    fn cia402_6040h_other_bits() {
        let cw = Controlword(0x8000 | HALT | VL_RFG_USE_REF | VL_RFG_ENABLE | 0x000F);
        assert!(cw.halt());
        assert_eq!(cw.mode_bits(), 0b101);
        assert_eq!(cw.manufacturer_bits(), 0x10);
        assert!(!cw.bit9());
        assert!(!cw.fault_reset());
    }
}
