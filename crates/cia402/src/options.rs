//! The option codes that say how the drive stops (CiA 402-2, objects 605Ah–605Eh: 0x605A quick stop,
//! 0x605B shutdown, 0x605C disable operation, 0x605D halt, 0x605E fault reaction).

use cantwin_canopen::od::ObjectDictionary;

use crate::index;

/// How a drive decelerates when it stops (the common part of the option codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopRamp {
    /// On the slow down ramp (in vl mode 0x6049 vl velocity deceleration).
    SlowDown,
    /// On the quick stop ramp (in vl mode 0x604A vl velocity quick stop).
    QuickStop,
    /// At the current limit: as fast as the drive's torque allows.
    CurrentLimit,
    /// At the voltage limit: as fast as the DC link allows.
    VoltageLimit,
}

impl StopRamp {
    const fn from_code(code: i16) -> Option<StopRamp> {
        Some(match code {
            1 => StopRamp::SlowDown,
            2 => StopRamp::QuickStop,
            3 => StopRamp::CurrentLimit,
            4 => StopRamp::VoltageLimit,
            _ => return None,
        })
    }

    const fn code(self) -> i16 {
        match self {
            StopRamp::SlowDown => 1,
            StopRamp::QuickStop => 2,
            StopRamp::CurrentLimit => 3,
            StopRamp::VoltageLimit => 4,
        }
    }
}

/// 0x605A quick stop option code (CiA 402-2, object 605Ah): what QUICK STOP ACTIVE does and whether
/// the drive leaves it by itself (transition 12) or waits for "enable operation"
/// (transition 16).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QuickStopOption {
    /// 0: disable the drive function (the motor coasts), then SWITCH ON DISABLED.
    DisableDriveFunction,
    /// 1–4: stop on `ramp`, then SWITCH ON DISABLED.
    Stop(StopRamp),
    /// 5–8: stop on `ramp` and stay in QUICK STOP ACTIVE.
    StopAndStay(StopRamp),
}

impl QuickStopOption {
    /// CiA 402-2's default, 2: slow down on the quick stop ramp, then SWITCH ON DISABLED.
    pub const DEFAULT: QuickStopOption = QuickStopOption::Stop(StopRamp::QuickStop);

    /// The option a 0x605A value selects; `None` for the reserved and manufacturer-specific
    /// values.
    pub const fn from_code(code: i16) -> Option<QuickStopOption> {
        match code {
            0 => Some(QuickStopOption::DisableDriveFunction),
            1..=4 => match StopRamp::from_code(code) {
                Some(r) => Some(QuickStopOption::Stop(r)),
                None => None,
            },
            5..=8 => match StopRamp::from_code(code - 4) {
                Some(r) => Some(QuickStopOption::StopAndStay(r)),
                None => None,
            },
            _ => None,
        }
    }

    /// The 0x605A value.
    pub const fn code(self) -> i16 {
        match self {
            QuickStopOption::DisableDriveFunction => 0,
            QuickStopOption::Stop(r) => r.code(),
            QuickStopOption::StopAndStay(r) => r.code() + 4,
        }
    }

    /// Whether the drive stays in QUICK STOP ACTIVE after stopping (options 5–8).
    pub const fn stays(self) -> bool {
        matches!(self, QuickStopOption::StopAndStay(_))
    }

    /// How the drive decelerates; `None` when the drive function is disabled (option 0).
    pub const fn ramp(self) -> Option<StopRamp> {
        match self {
            QuickStopOption::DisableDriveFunction => None,
            QuickStopOption::Stop(r) | QuickStopOption::StopAndStay(r) => Some(r),
        }
    }
}

/// 0x605B shutdown and 0x605C disable operation option codes (CiA 402-2, objects 605Bh and 605Ch):
/// what the drive does when it leaves OPERATION ENABLED by transition 8 or 5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DisableOption {
    /// 0: disable the drive function at once (the motor coasts).
    DisableDriveFunction,
    /// 1: slow down on the slow down ramp, then disable the drive function.
    SlowDown,
}

impl DisableOption {
    /// The option a 0x605B/0x605C value selects; `None` for the other values.
    pub const fn from_code(code: i16) -> Option<DisableOption> {
        match code {
            0 => Some(DisableOption::DisableDriveFunction),
            1 => Some(DisableOption::SlowDown),
            _ => None,
        }
    }

    /// The 0x605B/0x605C value.
    pub const fn code(self) -> i16 {
        match self {
            DisableOption::DisableDriveFunction => 0,
            DisableOption::SlowDown => 1,
        }
    }
}

/// 0x605D halt option code (CiA 402-2, object 605Dh): how the drive stops while controlword bit 8
/// (halt) is set in OPERATION ENABLED; it stays in OPERATION ENABLED.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct HaltOption(pub StopRamp);

impl HaltOption {
    /// The option a 0x605D value (1–4) selects.
    pub const fn from_code(code: i16) -> Option<HaltOption> {
        match StopRamp::from_code(code) {
            Some(r) => Some(HaltOption(r)),
            None => None,
        }
    }

    /// The 0x605D value.
    pub const fn code(self) -> i16 {
        self.0.code()
    }
}

/// 0x605E fault reaction option code (CiA 402-2, object 605Eh): what FAULT REACTION ACTIVE does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultReactionOption {
    /// 0: disable the drive function (the motor is free to rotate).
    DisableDriveFunction,
    /// 1–4: stop on `ramp`.
    Stop(StopRamp),
}

impl FaultReactionOption {
    /// The option a 0x605E value selects; `None` for the reserved and manufacturer-specific
    /// values.
    pub const fn from_code(code: i16) -> Option<FaultReactionOption> {
        match code {
            0 => Some(FaultReactionOption::DisableDriveFunction),
            _ => match StopRamp::from_code(code) {
                Some(r) => Some(FaultReactionOption::Stop(r)),
                None => None,
            },
        }
    }

    /// The 0x605E value.
    pub const fn code(self) -> i16 {
        match self {
            FaultReactionOption::DisableDriveFunction => 0,
            FaultReactionOption::Stop(r) => r.code(),
        }
    }
}

/// The five option codes a power state machine follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct OptionCodes {
    /// 0x605A.
    pub quick_stop: QuickStopOption,
    /// 0x605B.
    pub shutdown: DisableOption,
    /// 0x605C.
    pub disable_operation: DisableOption,
    /// 0x605D.
    pub halt: HaltOption,
    /// 0x605E.
    pub fault_reaction: FaultReactionOption,
}

impl OptionCodes {
    /// The defaults CiA 402-2 gives the objects: quick stop 2, shutdown 0, disable
    /// operation 1, halt 1, fault reaction 2.
    pub const STANDARD: OptionCodes = OptionCodes {
        quick_stop: QuickStopOption::DEFAULT,
        shutdown: DisableOption::DisableDriveFunction,
        disable_operation: DisableOption::SlowDown,
        halt: HaltOption(StopRamp::SlowDown),
        fault_reaction: FaultReactionOption::Stop(StopRamp::QuickStop),
    };

    /// The option codes `od` holds: each object the dictionary has and whose value is
    /// defined; the others keep the value in `fallback` (a device without the objects
    /// behaves in one fixed way, which `fallback` states).
    pub fn from_od(od: &ObjectDictionary, fallback: OptionCodes) -> OptionCodes {
        let code = |index: u16| -> Option<i16> {
            let v = od.get(index, 0).ok()?.as_i128()?;
            i16::try_from(v).ok()
        };
        OptionCodes {
            quick_stop: code(index::QUICK_STOP_OPTION_CODE)
                .and_then(QuickStopOption::from_code)
                .unwrap_or(fallback.quick_stop),
            shutdown: code(index::SHUTDOWN_OPTION_CODE)
                .and_then(DisableOption::from_code)
                .unwrap_or(fallback.shutdown),
            disable_operation: code(index::DISABLE_OPERATION_OPTION_CODE)
                .and_then(DisableOption::from_code)
                .unwrap_or(fallback.disable_operation),
            halt: code(index::HALT_OPTION_CODE)
                .and_then(HaltOption::from_code)
                .unwrap_or(fallback.halt),
            fault_reaction: code(index::FAULT_REACTION_OPTION_CODE)
                .and_then(FaultReactionOption::from_code)
                .unwrap_or(fallback.fault_reaction),
        }
    }
}

impl Default for OptionCodes {
    fn default() -> Self {
        OptionCodes::STANDARD
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_605xh_option_codes_round_trip() {
        for code in -2..=10 {
            if let Some(o) = QuickStopOption::from_code(code) {
                assert_eq!(o.code(), code);
            } else {
                assert!(!(0..=8).contains(&code));
            }
            if let Some(o) = DisableOption::from_code(code) {
                assert_eq!(o.code(), code);
            } else {
                assert!(!(0..=1).contains(&code));
            }
            if let Some(o) = HaltOption::from_code(code) {
                assert_eq!(o.code(), code);
            } else {
                assert!(!(1..=4).contains(&code));
            }
            if let Some(o) = FaultReactionOption::from_code(code) {
                assert_eq!(o.code(), code);
            } else {
                assert!(!(0..=4).contains(&code));
            }
        }
        assert!(QuickStopOption::from_code(6).is_some_and(QuickStopOption::stays));
        assert!(!QuickStopOption::DEFAULT.stays());
        assert_eq!(QuickStopOption::DisableDriveFunction.ramp(), None);
    }
}
