//! The drive's alarm list and the EMCY code each one travels with (§1.5, "Segnalazione
//! allarmi drive").
//!
//! The table lists alarms 23–45 (Plc1 fault … Param error) with a bare number n; the twin
//! sends them as EMCY 0xFF00 + n, like the table's other 0xFFxx codes. Opt Bus Fault travels
//! as 0xFF11 with its sub-code in the first two manufacturer-specific bytes, little-endian.

/// A drive alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Alarm {
    /// Overvoltage.
    Overvoltage,
    /// Undervoltage.
    Undervoltage,
    /// Ground fault.
    GroundFault,
    /// Overcurrent.
    Overcurrent,
    /// Desaturation.
    Desaturation,
    /// MultiUndervolt.
    MultiUndervolt,
    /// MultiOvercurr.
    MultiOvercurr,
    /// MultiDesat.
    MultiDesat,
    /// Heatsink OT.
    HeatsinkOt,
    /// HeatsinkS OTUT.
    HeatsinkSOtut,
    /// Intakeair OT.
    IntakeairOt,
    /// Motor OT.
    MotorOt,
    /// Drive overload.
    DriveOverload,
    /// Motor overload.
    MotorOverload,
    /// Bres overload.
    BresOverload,
    /// Phaseloss.
    Phaseloss,
    /// Opt Bus fault, with its sub-code (§1.5 fieldbus table).
    OptBusFault(u16),
    /// Opt 1 IO fault.
    Opt1IoFault,
    /// Opt Enc fault.
    OptEncFault,
    /// External fault.
    ExternalFault,
    /// Speed fbk loss.
    SpeedFbkLoss,
    /// Overspeed.
    Overspeed,
    /// Plc1..Plc8 fault (1..=8).
    PlcFault(u8),
    /// Emg stop alarm.
    EmgStop,
    /// Watchdog.
    Watchdog,
    /// Trap error.
    TrapError,
    /// System error.
    SystemError,
    /// User error.
    UserError,
    /// Power down.
    PowerDown,
    /// Speed ref loss.
    SpeedRefLoss,
    /// Opt 2 IO fault.
    Opt2IoFault,
    /// Param error.
    ParamError,
}

impl Alarm {
    /// Every alarm of the table (Opt Bus fault with sub-code 0, the PLC faults 1–8).
    pub fn all() -> Vec<Alarm> {
        use Alarm::*;
        let mut v = vec![
            Overvoltage,
            Undervoltage,
            GroundFault,
            Overcurrent,
            Desaturation,
            MultiUndervolt,
            MultiOvercurr,
            MultiDesat,
            HeatsinkOt,
            HeatsinkSOtut,
            IntakeairOt,
            MotorOt,
            DriveOverload,
            MotorOverload,
            BresOverload,
            Phaseloss,
            OptBusFault(0),
            Opt1IoFault,
            OptEncFault,
            ExternalFault,
            SpeedFbkLoss,
            Overspeed,
        ];
        v.extend((1..=8).map(PlcFault));
        v.extend([
            EmgStop,
            Watchdog,
            TrapError,
            SystemError,
            UserError,
            PowerDown,
            SpeedRefLoss,
            Opt2IoFault,
            ParamError,
        ]);
        v
    }

    /// The EMCY error code (§1.5 table).
    pub const fn emcy_code(self) -> u16 {
        use Alarm::*;
        match self {
            Overvoltage => 0x3210,
            Undervoltage => 0x3220,
            GroundFault => 0x2110,
            Overcurrent => 0x2310,
            Desaturation => 0x2130,
            MultiUndervolt => 0xFF06,
            MultiOvercurr => 0xFF07,
            MultiDesat => 0xFF08,
            HeatsinkOt => 0x4210,
            HeatsinkSOtut => 0x4310,
            IntakeairOt => 0x4130,
            MotorOt => 0xFF0C,
            DriveOverload => 0x8311,
            MotorOverload => 0x7121,
            BresOverload => 0x7112,
            Phaseloss => 0xFF10,
            OptBusFault(_) => 0xFF11,
            Opt1IoFault => 0xFF12,
            OptEncFault => 0x3130,
            ExternalFault => 0x9000,
            SpeedFbkLoss => 0x7310,
            Overspeed => 0x8400,
            PlcFault(k) => 0xFF00 + 22 + k as u16,
            EmgStop => 0xFF00 + 31,
            Watchdog => 0xFF00 + 32,
            TrapError => 0xFF00 + 33,
            SystemError => 0xFF00 + 34,
            UserError => 0xFF00 + 35,
            PowerDown => 0xFF00 + 36,
            SpeedRefLoss => 0xFF00 + 37,
            Opt2IoFault => 0xFF00 + 39,
            ParamError => 0xFF00 + 45,
        }
    }

    /// The five manufacturer-specific bytes of its EMCY.
    pub const fn manufacturer_bytes(self) -> [u8; 5] {
        match self {
            Alarm::OptBusFault(sub) => {
                let b = sub.to_le_bytes();
                [b[0], b[1], 0, 0, 0]
            }
            _ => [0; 5],
        }
    }

    /// The name the drive's alarm list shows.
    pub fn name(self) -> String {
        use Alarm::*;
        match self {
            Overvoltage => "Overvoltage".into(),
            Undervoltage => "Undervoltage".into(),
            GroundFault => "Ground fault".into(),
            Overcurrent => "Overcurrent".into(),
            Desaturation => "Desaturation".into(),
            MultiUndervolt => "MultiUndervolt".into(),
            MultiOvercurr => "MultiOvercurr".into(),
            MultiDesat => "MultiDesat".into(),
            HeatsinkOt => "Heatsink OT".into(),
            HeatsinkSOtut => "HeatsinkS OTUT".into(),
            IntakeairOt => "Intakeair OT".into(),
            MotorOt => "Motor OT".into(),
            DriveOverload => "Drive overload".into(),
            MotorOverload => "Motor overload".into(),
            BresOverload => "Bres overload".into(),
            Phaseloss => "Phaseloss".into(),
            OptBusFault(_) => "Opt Bus fault".into(),
            Opt1IoFault => "Opt 1 IO fault".into(),
            OptEncFault => "Opt Enc fault".into(),
            ExternalFault => "External fault".into(),
            SpeedFbkLoss => "Speed fbk loss".into(),
            Overspeed => "Overspeed".into(),
            PlcFault(k) => format!("Plc{k} fault"),
            EmgStop => "Emg stop alarm".into(),
            Watchdog => "Watchdog".into(),
            TrapError => "Trap error".into(),
            SystemError => "System error".into(),
            UserError => "User error".into(),
            PowerDown => "Power down".into(),
            SpeedRefLoss => "Speed ref loss".into(),
            Opt2IoFault => "Opt 2 IO fault".into(),
            ParamError => "Param error".into(),
        }
    }

    /// The alarm named `name` (as [`Alarm::name`], case-insensitive); Opt Bus fault with
    /// sub-code 0.
    pub fn from_name(name: &str) -> Option<Alarm> {
        let norm = |s: &str| s.to_ascii_lowercase().replace([' ', '_', '-'], "");
        let want = norm(name);
        Alarm::all().into_iter().find(|a| norm(&a.name()) == want)
    }
}

/// The Opt Bus Fault sub-codes the card raises at run time (§1.5 and §3.7.1 fieldbus
/// tables; the configuration codes are raised by [`crate::card`] and [`crate::pdc`]).
pub mod opt_bus {
    /// Bus Loss: no SYNC within the communication cycle period, enable while not Operational
    /// (not in polled I/O for DeviceNet), or the DeviceNet connection timed out.
    pub const BUS_LOSS: u16 = 0x0000;
    /// Error initializing CAN interface (an internal card error).
    pub const CAN_INIT: u16 = 0xFF04;
    /// Internal database error on channel 1; channel n is `DATABASE + n − 1` (…0xFFC3).
    pub const DATABASE: u16 = 0xFFB4;
    /// CAN msg overflow: more frames than the card can take at its bit rate.
    pub const OVERFLOW: u16 = 0x8110;
    /// LifeGuard/HeartBeat error: the master's guarding or heartbeat stopped.
    pub const GUARDING: u16 = 0x8130;
    /// CANopen: wrong NMT message length. DeviceNet: wrong baud rate.
    pub const FFC5: u16 = 0xFFC5;
    /// CANopen: invalid NMT command. DeviceNet: wrong MAC ID.
    pub const FFC6: u16 = 0xFFC6;
    /// CAN bus off ("check line state for problems").
    pub const BUS_OFF: u16 = 0xFFC7;
    /// DeviceNet: system error on connection ("check master for proper connection").
    pub const CONNECTION: u16 = 0xFFC8;
    /// DeviceNet: duplicate MAC ID check failed.
    pub const DUPLICATE_MAC: u16 = 0xFFC9;
    /// CANopen: CAN bus off again soon after recovering ("check line state for hardware
    /// problems"), see [`crate::card`].
    pub const BUS_OFF_HARDWARE: u16 = 0x8100;
}

/// A fault inside the card that nothing on the bus or in the parameters causes: the
/// table's "Internal error, contact manufacturer" rows (§1.5, §3.7.1). The twin lets a test
/// or a scenario give the card one of these defects; like every code marked `Cfg` in the
/// table, the card finds it when it configures itself at the next drive reset, and keeps
/// finding it at every reset until the defect is gone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CardFault {
    /// FF04 Error initializing CAN interface: the card stays off the bus.
    CanInit,
    /// FFB4..FFC3 Internal database error on channel n (1..=16): the card runs, in Opt Bus
    /// Fault.
    Database(u8),
}

impl CardFault {
    /// The Opt Bus Fault sub-code.
    pub const fn code(self) -> u16 {
        match self {
            CardFault::CanInit => opt_bus::CAN_INIT,
            CardFault::Database(n) => opt_bus::DATABASE + n as u16 - 1,
        }
    }

    /// The fault whose sub-code is `code` (FF04 or FFB4..FFC3).
    pub const fn from_code(code: u16) -> Option<CardFault> {
        match code {
            opt_bus::CAN_INIT => Some(CardFault::CanInit),
            0xFFB4..=0xFFC3 => Some(CardFault::Database((code - opt_bus::DATABASE + 1) as u8)),
            _ => None,
        }
    }
}

impl core::str::FromStr for CardFault {
    type Err = String;

    /// The sub-code as the manual prints it, hexadecimal with or without `0x`: `FF04`,
    /// `FFB4` … `FFC3`.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        let hex = t
            .strip_prefix("0x")
            .or_else(|| t.strip_prefix("0X"))
            .unwrap_or(t);
        u16::from_str_radix(hex, 16)
            .ok()
            .and_then(CardFault::from_code)
            .ok_or_else(|| {
                format!(
                    "{s:?} is not an internal card fault (FF04 CAN interface, FFB4..FFC3 database of channel 1..16)"
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_1_5_bare_numbers_become_ff00_plus_n() {
        assert_eq!(Alarm::PlcFault(1).emcy_code(), 0xFF17);
        assert_eq!(Alarm::PlcFault(8).emcy_code(), 0xFF1E);
        assert_eq!(Alarm::ParamError.emcy_code(), 0xFF2D);
        assert_eq!(Alarm::from_name("heatsink ot"), Some(Alarm::HeatsinkOt));
        assert_eq!(Alarm::from_name("Plc3 fault"), Some(Alarm::PlcFault(3)));
        let codes: std::collections::BTreeSet<u16> =
            Alarm::all().iter().map(|a| a.emcy_code()).collect();
        assert_eq!(codes.len(), Alarm::all().len(), "codes are distinct");
    }

    #[test]
    fn manual_1_5_internal_card_errors_ff04_and_ffb4_to_ffc3() {
        assert_eq!(CardFault::CanInit.code(), 0xFF04);
        assert_eq!(CardFault::Database(1).code(), 0xFFB4);
        assert_eq!(CardFault::Database(16).code(), 0xFFC3);
        for code in [0xFF04, 0xFFB4, 0xFFBB, 0xFFC3] {
            assert_eq!(CardFault::from_code(code).map(CardFault::code), Some(code));
        }
        assert_eq!(CardFault::from_code(0xFFC4), None);
        assert_eq!(CardFault::from_code(0xFFB3), None);
        assert_eq!("ffb5".parse(), Ok(CardFault::Database(2)));
        assert_eq!("0xFF04".parse(), Ok(CardFault::CanInit));
        assert!(
            "FF01"
                .parse::<CardFault>()
                .unwrap_err()
                .contains("FFB4..FFC3")
        );
    }
}
