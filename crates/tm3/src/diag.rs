//! Diagnostics of the coupler: the manual's EMCY codes (object 0x1003 table), the module
//! and bus status of 0x1002, the 0x1003 entry format, and the life time factor advice.

/// 0x0000 ERROR_RESET_OR_NO_ERROR: an error was corrected.
pub const ERROR_RESET: u16 = 0x0000;
/// 0x0080 ANALOG_DISABLE: analog input interrupts disabled.
pub const ANALOG_DISABLE: u16 = 0x0080;
/// 0x1000 GENERIC_ERROR: internal communication error.
pub const GENERIC_ERROR: u16 = 0x1000;
/// 0x6101 SOFTWARE_RX_QUEUE_OVERRUN.
pub const RX_QUEUE_OVERRUN: u16 = 0x6101;
/// 0x6102 SOFTWARE_TX_QUEUE_OVERRUN.
pub const TX_QUEUE_OVERRUN: u16 = 0x6102;
/// 0x7001 KPI_CONFIGURATION_TIMEOUT: a module did not take its configuration in time.
pub const CONFIGURATION_TIMEOUT: u16 = 0x7001;
/// 0x7002 KPI_CONFIGURATION_ERROR: the fitted modules do not match the configuration.
pub const CONFIGURATION_ERROR: u16 = 0x7002;
/// 0x7003 KPI_RUNTIME_ERROR: a module failed or was removed at runtime.
pub const RUNTIME_ERROR: u16 = 0x7003;
/// 0x8110 MESSAGE_LOST.
pub const MESSAGE_LOST: u16 = 0x8110;
/// 0x8120 CAN_IN_ERROR_PASSIVE_MODE.
pub const ERROR_PASSIVE: u16 = 0x8120;
/// 0x8130 NODE_GUARD_OR_HEARTBEAT_ERROR.
pub const GUARD_OR_HEARTBEAT: u16 = 0x8130;
/// 0x8140 BUS_OFF_RECOVERED.
pub const BUS_OFF_RECOVERED: u16 = 0x8140;
/// 0x8210 PDO_LENGTH.
pub const PDO_LENGTH: u16 = 0x8210;
/// 0x8250 RPDO_TIMEOUT.
pub const RPDO_TIMEOUT: u16 = 0x8250;
/// 0xF001 SYNC_TIMEOUT.
pub const SYNC_TIMEOUT: u16 = 0xF001;
/// 0xFF03 ROTARY_SWITCH_CHANGED: the node-ID switches moved after power-up.
pub const ROTARY_SWITCH_CHANGED: u16 = 0xFF03;
/// 0xFF04 KPI_NOT_CONFIGURED_IN_OP: operational although not configured.
pub const NOT_CONFIGURED_IN_OP: u16 = 0xFF04;

/// The 2-bit status of a module or of the bus in 0x1002 (manual: object 1002H).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// 0: no error.
    Ok = 0,
    /// 1: configuration error.
    ConfigurationError = 1,
    /// 2: runtime error.
    RuntimeError = 2,
    /// 3: for a module "not configured but optional", for the bus "not configured".
    NotConfigured = 3,
}

/// 0x1002: module `k` (0-based) in bits 2k..2k+1, the bus in bits 30–31.
pub fn manufacturer_status(modules: &[Status], bus: Status) -> u32 {
    let mut v = (bus as u32) << 30;
    for (k, s) in modules.iter().take(14).enumerate() {
        v |= (*s as u32) << (2 * k);
    }
    v
}

/// A 0x1003 entry: EMCY code in bits 0–15, error register in 16–23, module number
/// (0 = coupler, 1..=14) in 24–31.
pub const fn history_entry(code: u16, register: u8, module: u8) -> u32 {
    code as u32 | (register as u32) << 16 | (module as u32) << 24
}

/// What is wrong with a guarding configuration (manual: 100DH, "unexpected machine
/// operation": set the life time factor to at least 2 when node guarding is used).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LifeTimeWarning {
    /// Guard time set, factor 1: one late guarding request already is a life guarding
    /// event.
    #[error("life time factor 1 with guard time {guard_time_ms} ms: set 0x100D to at least 2")]
    FactorOne {
        /// 0x100C.
        guard_time_ms: u16,
    },
    /// Guard time set, factor 0: the master is not monitored at all.
    #[error(
        "guard time {guard_time_ms} ms with life time factor 0: life guarding is off; set 0x100D to at least 2"
    )]
    FactorZero {
        /// 0x100C.
        guard_time_ms: u16,
    },
}

/// Checks 0x100C/0x100D against the manual's advice (factor ≥ 2 when guarding is used).
pub fn check_life_time(guard_time_ms: u16, life_time_factor: u8) -> Option<LifeTimeWarning> {
    match (guard_time_ms, life_time_factor) {
        (0, _) => None,
        (g, 0) => Some(LifeTimeWarning::FactorZero { guard_time_ms: g }),
        (g, 1) => Some(LifeTimeWarning::FactorOne { guard_time_ms: g }),
        _ => None,
    }
}

/// [`check_life_time`] on the values an EDS or DCF gives 0x100C and 0x100D
/// (`ParameterValue` when present, else `DefaultValue`; absent counts as 0).
pub fn check_life_time_eds(eds: &cantwin_eds::Eds) -> Option<LifeTimeWarning> {
    let value = |index| {
        let e = eds.entry(index, 0)?;
        match e.parameter_value.as_ref().or(e.default_value.as_ref())? {
            cantwin_eds::EdsValue::Integer(v) => Some(*v),
            _ => None,
        }
    };
    let guard = value(0x100C)
        .and_then(|v| u16::try_from(v).ok())
        .unwrap_or(0);
    let factor = value(0x100D)
        .and_then(|v| u8::try_from(v).ok())
        .unwrap_or(0);
    check_life_time(guard, factor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_1002_bit_assignment() {
        let mut m = [Status::Ok; 14];
        m[0] = Status::ConfigurationError;
        m[2] = Status::RuntimeError;
        m[13] = Status::NotConfigured;
        assert_eq!(
            manufacturer_status(&m, Status::RuntimeError),
            0x8000_0000 | 0x0C00_0000 | 0x20 | 0x01
        );
        assert_eq!(manufacturer_status(&[], Status::NotConfigured), 0xC000_0000);
    }

    #[test]
    fn manual_1003_entry_layout() {
        assert_eq!(history_entry(0x7003, 0x81, 3), 0x0381_7003);
    }

    #[test]
    fn manual_100d_advice_on_a_dcf() {
        let island = crate::island::Island::from_references(&["TM3DI8"]).unwrap();
        let mut eds = crate::eds::eds(&island).unwrap();
        assert_eq!(check_life_time_eds(&eds), None);
        let set = |eds: &mut cantwin_eds::Eds, index, v| {
            eds.objects.get_mut(&index).unwrap().entry.parameter_value =
                Some(cantwin_eds::EdsValue::Integer(v));
        };
        set(&mut eds, 0x100C, 250);
        set(&mut eds, 0x100D, 1);
        assert_eq!(
            check_life_time_eds(&eds),
            Some(LifeTimeWarning::FactorOne { guard_time_ms: 250 })
        );
        set(&mut eds, 0x100D, 3);
        assert_eq!(check_life_time_eds(&eds), None);
    }

    #[test]
    fn manual_100d_life_time_factor_advice() {
        assert_eq!(check_life_time(0, 0), None);
        assert_eq!(check_life_time(0, 1), None);
        assert_eq!(check_life_time(100, 2), None);
        assert_eq!(
            check_life_time(100, 1),
            Some(LifeTimeWarning::FactorOne { guard_time_ms: 100 })
        );
        assert_eq!(
            check_life_time(100, 0),
            Some(LifeTimeWarning::FactorZero { guard_time_ms: 100 })
        );
    }
}
