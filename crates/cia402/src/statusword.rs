//! The statusword, 0x6041 (CiA 402-2, object 6041h): the power drive state in bits 0–3, 5 and 6,
//! and the flags beside it.
//!
//! | state | bits 6, 5, 3–0 (x: not part of the state) | as encoded here |
//! |---|---|---|
//! | NOT READY TO SWITCH ON | `x0xx 0000` | 0x0000 |
//! | SWITCH ON DISABLED | `x1xx 0000` | 0x0040 |
//! | READY TO SWITCH ON | `x01x 0001` | 0x0021 |
//! | SWITCHED ON | `x01x 0011` | 0x0023 |
//! | OPERATION ENABLED | `x01x 0111` | 0x0027 |
//! | QUICK STOP ACTIVE | `x00x 0111` | 0x0007 |
//! | FAULT REACTION ACTIVE | `x0xx 1111` | 0x000F |
//! | FAULT | `x0xx 1000` | 0x0008 |
//!
//! Where bit 5 (quick stop, active low) is not part of a state it is encoded 0; bit 4
//! (voltage enabled) comes from the drive, not from the state.

use crate::state::{PowerStateMachine, State};

/// Bit 0: ready to switch on.
pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
/// Bit 1: switched on.
pub const SWITCHED_ON: u16 = 1 << 1;
/// Bit 2: operation enabled.
pub const OPERATION_ENABLED: u16 = 1 << 2;
/// Bit 3: fault.
pub const FAULT: u16 = 1 << 3;
/// Bit 4: voltage enabled (high voltage is applied to the drive).
pub const VOLTAGE_ENABLED: u16 = 1 << 4;
/// Bit 5: quick stop, active low (0: a quick stop is being performed).
pub const QUICK_STOP: u16 = 1 << 5;
/// Bit 6: switch on disabled.
pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
/// Bit 7: warning.
pub const WARNING: u16 = 1 << 7;
/// Bit 9: remote (the controlword is processed).
pub const REMOTE: u16 = 1 << 9;
/// Bit 10: target reached.
pub const TARGET_REACHED: u16 = 1 << 10;
/// Bit 11: internal limit active.
pub const INTERNAL_LIMIT_ACTIVE: u16 = 1 << 11;
/// Bits 12 and 13: operation mode specific (pp: set-point acknowledge, following error;
/// hm: homing attained, homing error; vl: reserved).
pub const MODE_SPECIFIC: u16 = 0x3000;
/// Bits 8, 14 and 15: manufacturer-specific.
pub const MANUFACTURER_SPECIFIC: u16 = 0xC100;

/// The bits of a statusword beside the state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct StatusFlags {
    /// Bit 4: high voltage is applied to the drive.
    pub voltage_enabled: bool,
    /// Bit 7: a warning condition is present (the state does not change).
    pub warning: bool,
    /// Bit 9: the controlword is processed (remote), not a local panel.
    pub remote: bool,
    /// Bit 10: the set-point has been reached (its meaning depends on the mode; on halt,
    /// the axis has stopped).
    pub target_reached: bool,
    /// Bit 11: an internal limit is active (vl: the velocity limit function limits the
    /// target).
    pub internal_limit_active: bool,
    /// Bits 12 (bit 0 here) and 13 (bit 1 here), operation mode specific.
    pub mode_specific: u8,
    /// Bits 8, 14 and 15 as they sit in the statusword; other bits are ignored.
    pub manufacturer_specific: u16,
}

/// A statusword value with its bits named.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Statusword(pub u16);

impl Statusword {
    /// The statusword of `state` with `flags`.
    pub const fn encode(state: State, flags: StatusFlags) -> Statusword {
        let mut sw = state.statusword_bits();
        if flags.voltage_enabled {
            sw |= VOLTAGE_ENABLED;
        }
        if flags.warning {
            sw |= WARNING;
        }
        if flags.remote {
            sw |= REMOTE;
        }
        if flags.target_reached {
            sw |= TARGET_REACHED;
        }
        if flags.internal_limit_active {
            sw |= INTERNAL_LIMIT_ACTIVE;
        }
        sw |= ((flags.mode_specific as u16) & 0x3) << 12;
        sw |= flags.manufacturer_specific & MANUFACTURER_SPECIFIC;
        Statusword(sw)
    }

    /// The state bits 0–3, 5 and 6 encode, `None` for a pattern of no state.
    pub const fn state(self) -> Option<State> {
        // CiA 402-2, object 6041h, table "state coding": each state's mask leaves out its x
        // positions, and no statusword matches two states.
        let mut i = 0;
        while i < State::ALL.len() {
            let state = State::ALL[i];
            let (mask, bits) = state.statusword_pattern();
            if self.0 & mask == bits {
                return Some(state);
            }
            i += 1;
        }
        None
    }

    /// The name of the state it encodes (lower case, as a monitor shows it), or
    /// `"no defined state"`.
    pub const fn state_name(self) -> &'static str {
        match self.state() {
            Some(s) => s.name(),
            None => "no defined state",
        }
    }

    /// The bits beside the state.
    pub const fn flags(self) -> StatusFlags {
        let sw = self.0;
        StatusFlags {
            voltage_enabled: sw & VOLTAGE_ENABLED != 0,
            warning: sw & WARNING != 0,
            remote: sw & REMOTE != 0,
            target_reached: sw & TARGET_REACHED != 0,
            internal_limit_active: sw & INTERNAL_LIMIT_ACTIVE != 0,
            mode_specific: ((sw & MODE_SPECIFIC) >> 12) as u8,
            manufacturer_specific: sw & MANUFACTURER_SPECIFIC,
        }
    }

    /// Bit 3: fault.
    pub const fn fault(self) -> bool {
        self.0 & FAULT != 0
    }

    /// Bit 5 read the way it is meant: `true` while a quick stop is being performed (the
    /// bit is 0).
    pub const fn quick_stopping(self) -> bool {
        self.0 & QUICK_STOP == 0
    }
}

/// The statusword is encoded here rather than in [`crate::state`], so that the state machine
/// does not depend on its encoding.
impl PowerStateMachine {
    /// The statusword of the present state with `flags` beside it.
    pub fn statusword(&self, flags: StatusFlags) -> Statusword {
        Statusword::encode(self.state(), flags)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_6041h_state_coding_is_unambiguous() {
        // No statusword decodes as two states: each mask pattern is disjoint.
        for sw in 0..=0xFFFFu16 {
            let hits = State::ALL
                .iter()
                .filter(|s| {
                    let (mask, bits) = s.statusword_pattern();
                    sw & mask == bits
                })
                .count();
            assert!(hits <= 1, "{sw:#06x}");
            assert_eq!(hits == 1, Statusword(sw).state().is_some(), "{sw:#06x}");
        }
        assert_eq!(Statusword(0x0050).state_name(), "switch on disabled");
        assert_eq!(Statusword(0x0001).state_name(), "no defined state");
    }
}
