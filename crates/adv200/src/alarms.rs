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
}
