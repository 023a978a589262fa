//! Modes of operation (CiA 402-2, objects 6060h and 6061h: 0x6060 modes of operation, 0x6061 modes of operation
//! display) and the supported drive modes of 0x6502.

/// An operating mode as 0x6060 and 0x6061 code it (CiA 402-2, object 6060h, value definition).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Mode {
    /// Profile position mode (pp), 1.
    ProfilePosition,
    /// Velocity mode (vl), 2.
    Velocity,
    /// Profile velocity mode (pv), 3.
    ProfileVelocity,
    /// Profile torque mode (tq), 4.
    ProfileTorque,
    /// Homing mode (hm), 6.
    Homing,
    /// Interpolated position mode (ip), 7.
    InterpolatedPosition,
    /// Cyclic synchronous position mode (csp), 8.
    CyclicSyncPosition,
    /// Cyclic synchronous velocity mode (csv), 9.
    CyclicSyncVelocity,
    /// Cyclic synchronous torque mode (cst), 10.
    CyclicSyncTorque,
}

impl Mode {
    /// Every mode CiA 402-2 defines, in the order of their codes.
    pub const ALL: [Mode; 9] = [
        Mode::ProfilePosition,
        Mode::Velocity,
        Mode::ProfileVelocity,
        Mode::ProfileTorque,
        Mode::Homing,
        Mode::InterpolatedPosition,
        Mode::CyclicSyncPosition,
        Mode::CyclicSyncVelocity,
        Mode::CyclicSyncTorque,
    ];

    /// The value 0x6060 and 0x6061 hold for this mode.
    pub const fn code(self) -> i8 {
        match self {
            Mode::ProfilePosition => 1,
            Mode::Velocity => 2,
            Mode::ProfileVelocity => 3,
            Mode::ProfileTorque => 4,
            Mode::Homing => 6,
            Mode::InterpolatedPosition => 7,
            Mode::CyclicSyncPosition => 8,
            Mode::CyclicSyncVelocity => 9,
            Mode::CyclicSyncTorque => 10,
        }
    }

    /// The mode a 0x6060 value selects; `None` for 0 (no mode), the reserved values and the
    /// manufacturer-specific negative ones.
    pub const fn from_code(code: i8) -> Option<Mode> {
        Some(match code {
            1 => Mode::ProfilePosition,
            2 => Mode::Velocity,
            3 => Mode::ProfileVelocity,
            4 => Mode::ProfileTorque,
            6 => Mode::Homing,
            7 => Mode::InterpolatedPosition,
            8 => Mode::CyclicSyncPosition,
            9 => Mode::CyclicSyncVelocity,
            10 => Mode::CyclicSyncTorque,
            _ => return None,
        })
    }

    /// The bit of 0x6502 that says the drive supports this mode (CiA 402-2, object 6502h: bit 0
    /// pp, 1 vl, 2 pv, 3 tq, 4 reserved, 5 hm, 6 ip, 7 csp, 8 csv, 9 cst).
    pub const fn supported_bit(self) -> u32 {
        let bit = match self {
            Mode::ProfilePosition => 0,
            Mode::Velocity => 1,
            Mode::ProfileVelocity => 2,
            Mode::ProfileTorque => 3,
            Mode::Homing => 5,
            Mode::InterpolatedPosition => 6,
            Mode::CyclicSyncPosition => 7,
            Mode::CyclicSyncVelocity => 8,
            Mode::CyclicSyncTorque => 9,
        };
        1 << bit
    }

    /// The usual abbreviation (`pp`, `vl`, `csp` …).
    pub const fn abbreviation(self) -> &'static str {
        match self {
            Mode::ProfilePosition => "pp",
            Mode::Velocity => "vl",
            Mode::ProfileVelocity => "pv",
            Mode::ProfileTorque => "tq",
            Mode::Homing => "hm",
            Mode::InterpolatedPosition => "ip",
            Mode::CyclicSyncPosition => "csp",
            Mode::CyclicSyncVelocity => "csv",
            Mode::CyclicSyncTorque => "cst",
        }
    }
}

/// The modes a drive supports: the value of 0x6502 (CiA 402-2, object 6502h). Bits 16–31 are
/// manufacturer-specific and kept as given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct SupportedModes(pub u32);

impl SupportedModes {
    /// No mode.
    pub const NONE: SupportedModes = SupportedModes(0);
    /// Velocity mode only (a frequency converter such as the ADV200 in its CiA 402
    /// personality).
    pub const VELOCITY: SupportedModes = SupportedModes(Mode::Velocity.supported_bit());

    /// The set of `modes`.
    pub const fn of(modes: &[Mode]) -> SupportedModes {
        let mut bits = 0;
        let mut i = 0;
        while i < modes.len() {
            bits |= modes[i].supported_bit();
            i += 1;
        }
        SupportedModes(bits)
    }

    /// Whether `mode` is among them.
    pub const fn contains(self, mode: Mode) -> bool {
        self.0 & mode.supported_bit() != 0
    }

    /// The supported modes, in the order of their codes.
    pub fn modes(self) -> impl Iterator<Item = Mode> {
        Mode::ALL.into_iter().filter(move |m| self.contains(*m))
    }

    /// The lowest and highest 0x6060 code among them, `None` when there is none: the limits
    /// a dictionary can state for 0x6060 (codes between them that are not supported still
    /// need the device's own check).
    pub fn code_range(self) -> Option<(i8, i8)> {
        let mut modes = self.modes();
        let first = modes.next()?.code();
        let last = modes.last().map_or(first, Mode::code);
        Some((first, last))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_6060h_mode_codes_round_trip() {
        for m in Mode::ALL {
            assert_eq!(Mode::from_code(m.code()), Some(m));
        }
        for code in [0, 5, 11, 127, -1, -128] {
            assert_eq!(Mode::from_code(code), None);
        }
    }

    #[test]
    fn cia402_6502h_supported_drive_mode_bits() {
        assert_eq!(SupportedModes::VELOCITY.0, 0x0002);
        let servo = SupportedModes::of(&[
            Mode::ProfilePosition,
            Mode::ProfileVelocity,
            Mode::Homing,
            Mode::CyclicSyncPosition,
        ]);
        assert_eq!(servo.0, 0x00A5);
        assert!(servo.contains(Mode::Homing));
        assert!(!servo.contains(Mode::Velocity));
        assert_eq!(servo.code_range(), Some((1, 8)));
        assert_eq!(SupportedModes::VELOCITY.code_range(), Some((2, 2)));
        assert_eq!(SupportedModes::NONE.code_range(), None);
    }
}
