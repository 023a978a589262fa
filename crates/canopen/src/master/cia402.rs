//! A CiA 402 master: drives servo and motor drives through the power drive system state
//! machine, switches their modes of operation, runs profile position and profile velocity
//! moves and homing, and streams cyclic synchronous set-points (csp, csv) after each SYNC.
//!
//! [`DriveMaster`] is a [`Node`] that owns a [`Master`] and runs one job at a time per
//! drive (an *axis*) with the master's SDO client:
//!
//! | job | what goes on the wire (CiA 402-2) | done when |
//! |---|---|---|
//! | [`DriveMaster::switch`] | read 0x6041, write 0x6040 with the command of the next transition, read 0x6041 until the state changed, repeat | 0x6041 shows the target state |
//! | [`DriveMaster::quick_stop`] | 0x6040 = 0x0002 | QUICK STOP ACTIVE (from OPERATION ENABLED) or SWITCH ON DISABLED |
//! | [`DriveMaster::fault_reset`] | 0x6040 = 0x0000, then 0x0080 (the rising edge of bit 7) | the state is no longer FAULT |
//! | [`DriveMaster::set_mode`] | 0x6060 = mode | 0x6061 shows the mode |
//! | [`DriveMaster::profile_position`] | 0x6081/0x6083/0x6084 (optional), 0x607A, controlword bit 4 (new set-point) with bits 5 and 6 | set-point acknowledge (0x6041 bit 12), then bit 4 cleared; optionally target reached (bit 10) |
//! | [`DriveMaster::profile_velocity`] | 0x6083/0x6084 (optional), 0x60FF, controlword without halt | optionally target reached (bit 10) |
//! | [`DriveMaster::home`] | 0x6060 = 6 if needed, 0x6098, 0x6099/0x609A (optional), controlword bit 4 rising | homing attained (bit 12) with target reached (bit 10); bit 13 is a homing error |
//! | [`DriveMaster::start_stream`] | reads 0x6061 (must be csp or csv) and 0x6064 | streaming: after every SYNC the master sends, an RPDO with the set-point |
//!
//! Every wait has a timeout ([`AxisConfig`]); a drive that shows FAULT while a job waits
//! ends the job with [`DriveError::Fault`] and the error code of 0x603F. The statusword is
//! polled by SDO, or taken from a TPDO that carries it in its first two bytes
//! ([`AxisConfig::statusword_pdo`]).
//!
//! Cyclic set-points: CiA 402-2 csp and csv take their target (0x607A, 0x60FF) from a
//! synchronous RPDO; the drive applies it at the next SYNC. The master sends each axis's
//! RPDO right after each of its own SYNC frames, so every set-point sent after SYNC *k*
//! acts at SYNC *k* + 1 on every axis at once. [`DriveMaster::move_cyclic`] gives several
//! axes new targets reached in the same number of cycles: a coordinated move.
//!
//! ```
//! use cantwin_can::{Instant, Node, Outbox};
//! use cantwin_canopen::master::cia402::{AxisConfig, DriveMaster, PowerTarget};
//!
//! let mut drives = DriveMaster::new();
//! drives.add_axis(2, AxisConfig::default())?;
//! let mut out = Outbox::new();
//! drives.switch(2, PowerTarget::OperationEnabled, Instant::ZERO, &mut out)?;
//! // The first step reads the statusword.
//! let sent: Vec<String> = out.drain().map(|f| f.to_string()).collect();
//! assert_eq!(sent, ["602#4041600000000000"]);
//! # Ok::<(), cantwin_canopen::master::cia402::DriveError>(())
//! ```

use std::collections::{BTreeMap, VecDeque};

use super::{Master, MasterError, MasterEvent, Mode, SdoEvent, TransferId};
use crate::abort::AbortCode;
use crate::sdo::wire::Mux;
use crate::wire::SYNC_COB_ID;
use cantwin_can::{ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};

/// 0x603F error code.
pub const ERROR_CODE: u16 = 0x603F;
/// 0x6040 controlword.
pub const CONTROLWORD: u16 = 0x6040;
/// 0x6041 statusword.
pub const STATUSWORD: u16 = 0x6041;
/// 0x6060 modes of operation.
pub const MODES_OF_OPERATION: u16 = 0x6060;
/// 0x6061 modes of operation display.
pub const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
/// 0x6064 position actual value.
pub const POSITION_ACTUAL_VALUE: u16 = 0x6064;
/// 0x606C velocity actual value.
pub const VELOCITY_ACTUAL_VALUE: u16 = 0x606C;
/// 0x607A target position.
pub const TARGET_POSITION: u16 = 0x607A;
/// 0x6081 profile velocity.
pub const PROFILE_VELOCITY: u16 = 0x6081;
/// 0x6083 profile acceleration.
pub const PROFILE_ACCELERATION: u16 = 0x6083;
/// 0x6084 profile deceleration.
pub const PROFILE_DECELERATION: u16 = 0x6084;
/// 0x6098 homing method.
pub const HOMING_METHOD: u16 = 0x6098;
/// 0x6099 homing speeds (sub 1: speed during search for switch, sub 2: for zero).
pub const HOMING_SPEEDS: u16 = 0x6099;
/// 0x609A homing acceleration.
pub const HOMING_ACCELERATION: u16 = 0x609A;
/// 0x60FF target velocity.
pub const TARGET_VELOCITY: u16 = 0x60FF;

/// Controlword commands (CiA 402-2, object 6040h, table "command coding"), with every
/// other bit 0.
pub mod command {
    /// Shutdown: transitions 2, 6, 8.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on / disable operation: transitions 3, 5.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation: transitions 4, 16.
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Disable voltage: transitions 7, 9, 10, 12.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop: transitions 7, 10, 11.
    pub const QUICK_STOP: u16 = 0x0002;
    /// Fault reset: transition 15, on the rising edge of bit 7.
    pub const FAULT_RESET: u16 = 0x0080;
}

/// Controlword bit 4: pp new set-point, hm homing operation start.
pub const CW_BIT4: u16 = 1 << 4;
/// Controlword bit 5, pp: change set immediately.
pub const CW_CHANGE_SET_IMMEDIATELY: u16 = 1 << 5;
/// Controlword bit 6, pp: the target is relative.
pub const CW_RELATIVE: u16 = 1 << 6;
/// Controlword bit 8: halt.
pub const CW_HALT: u16 = 1 << 8;

/// Statusword bit 10: target reached.
pub const SW_TARGET_REACHED: u16 = 1 << 10;
/// Statusword bit 11: internal limit active.
pub const SW_INTERNAL_LIMIT_ACTIVE: u16 = 1 << 11;
/// Statusword bit 12: pp set-point acknowledge, pv speed (zero), hm homing attained, csp/csv
/// drive follows the command value.
pub const SW_BIT12: u16 = 1 << 12;
/// Statusword bit 13: pp and csp following error, pv max slippage error, hm homing error.
pub const SW_BIT13: u16 = 1 << 13;

/// A state of the power drive system (CiA 402-2, PDS FSA), as the statusword shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DriveState {
    /// NOT READY TO SWITCH ON (`x0xx 0000`).
    NotReadyToSwitchOn,
    /// SWITCH ON DISABLED (`x1xx 0000`).
    SwitchOnDisabled,
    /// READY TO SWITCH ON (`x01x 0001`).
    ReadyToSwitchOn,
    /// SWITCHED ON (`x01x 0011`).
    SwitchedOn,
    /// OPERATION ENABLED (`x01x 0111`).
    OperationEnabled,
    /// QUICK STOP ACTIVE (`x00x 0111`).
    QuickStopActive,
    /// FAULT REACTION ACTIVE (`x0xx 1111`).
    FaultReactionActive,
    /// FAULT (`x0xx 1000`).
    Fault,
}

impl DriveState {
    /// Every state.
    pub const ALL: [DriveState; 8] = [
        DriveState::NotReadyToSwitchOn,
        DriveState::SwitchOnDisabled,
        DriveState::ReadyToSwitchOn,
        DriveState::SwitchedOn,
        DriveState::OperationEnabled,
        DriveState::QuickStopActive,
        DriveState::FaultReactionActive,
        DriveState::Fault,
    ];

    /// `(mask, bits)` of the state in bits 0–3, 5 and 6 (CiA 402-2, object 6041h, table
    /// "state coding"; x positions are outside the mask).
    const fn pattern(self) -> (u16, u16) {
        match self {
            DriveState::NotReadyToSwitchOn => (0x4F, 0x00),
            DriveState::SwitchOnDisabled => (0x4F, 0x40),
            DriveState::ReadyToSwitchOn => (0x6F, 0x21),
            DriveState::SwitchedOn => (0x6F, 0x23),
            DriveState::OperationEnabled => (0x6F, 0x27),
            DriveState::QuickStopActive => (0x6F, 0x07),
            DriveState::FaultReactionActive => (0x4F, 0x0F),
            DriveState::Fault => (0x4F, 0x08),
        }
    }

    /// The state a statusword shows, `None` for a pattern of no state.
    pub fn from_statusword(sw: u16) -> Option<DriveState> {
        DriveState::ALL.into_iter().find(|s| {
            let (mask, bits) = s.pattern();
            sw & mask == bits
        })
    }

    /// The state's name, lower case (`"operation enabled"`).
    pub const fn name(self) -> &'static str {
        match self {
            DriveState::NotReadyToSwitchOn => "not ready to switch on",
            DriveState::SwitchOnDisabled => "switch on disabled",
            DriveState::ReadyToSwitchOn => "ready to switch on",
            DriveState::SwitchedOn => "switched on",
            DriveState::OperationEnabled => "operation enabled",
            DriveState::QuickStopActive => "quick stop active",
            DriveState::FaultReactionActive => "fault reaction active",
            DriveState::Fault => "fault",
        }
    }

    const fn is_fault(self) -> bool {
        matches!(self, DriveState::Fault | DriveState::FaultReactionActive)
    }
}

impl core::fmt::Display for DriveState {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// The name of the state a statusword shows, or `"no defined state"`.
pub fn state_name(sw: u16) -> &'static str {
    DriveState::from_statusword(sw).map_or("no defined state", DriveState::name)
}

/// A state a master asks for with [`DriveMaster::switch`]: the states a controlword
/// reaches (the others are entered by the drive itself or by [`DriveMaster::quick_stop`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PowerTarget {
    /// SWITCH ON DISABLED (disable voltage).
    SwitchOnDisabled,
    /// READY TO SWITCH ON (shutdown).
    ReadyToSwitchOn,
    /// SWITCHED ON (switch on, disable operation).
    SwitchedOn,
    /// OPERATION ENABLED (enable operation).
    OperationEnabled,
}

impl PowerTarget {
    /// The state.
    pub const fn state(self) -> DriveState {
        match self {
            PowerTarget::SwitchOnDisabled => DriveState::SwitchOnDisabled,
            PowerTarget::ReadyToSwitchOn => DriveState::ReadyToSwitchOn,
            PowerTarget::SwitchedOn => DriveState::SwitchedOn,
            PowerTarget::OperationEnabled => DriveState::OperationEnabled,
        }
    }
}

/// The next step from `from` toward `to` along the PDS FSA.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Toward {
    /// The drive is there.
    Arrived,
    /// Write this controlword.
    Send(u16),
    /// The drive leaves this state by itself (NOT READY TO SWITCH ON: transition 1).
    Wait,
    /// The drive is in FAULT or FAULT REACTION ACTIVE: only a fault reset leads out.
    Faulted,
}

/// The next step from `from` toward `to` (CiA 402-2, PDS FSA transitions 2–12 and 16).
pub const fn toward(from: DriveState, to: PowerTarget) -> Toward {
    use DriveState as S;
    use PowerTarget as T;
    use command::*;
    match (from, to) {
        (S::SwitchOnDisabled, T::SwitchOnDisabled)
        | (S::ReadyToSwitchOn, T::ReadyToSwitchOn)
        | (S::SwitchedOn, T::SwitchedOn)
        | (S::OperationEnabled, T::OperationEnabled) => Toward::Arrived,
        (S::NotReadyToSwitchOn, _) => Toward::Wait,
        (S::Fault | S::FaultReactionActive, _) => Toward::Faulted,
        // Transition 2.
        (S::SwitchOnDisabled, _) => Toward::Send(SHUTDOWN),
        // Transitions 7 and 3.
        (S::ReadyToSwitchOn, T::SwitchOnDisabled) => Toward::Send(DISABLE_VOLTAGE),
        (S::ReadyToSwitchOn, _) => Toward::Send(SWITCH_ON),
        // Transitions 10, 6, 4.
        (S::SwitchedOn, T::SwitchOnDisabled) => Toward::Send(DISABLE_VOLTAGE),
        (S::SwitchedOn, T::ReadyToSwitchOn) => Toward::Send(SHUTDOWN),
        (S::SwitchedOn, T::OperationEnabled) => Toward::Send(ENABLE_OPERATION),
        // Transitions 9, 8, 5.
        (S::OperationEnabled, T::SwitchOnDisabled) => Toward::Send(DISABLE_VOLTAGE),
        (S::OperationEnabled, T::ReadyToSwitchOn) => Toward::Send(SHUTDOWN),
        (S::OperationEnabled, T::SwitchedOn) => Toward::Send(SWITCH_ON),
        // Transition 16 (with 0x605A 5–8; with 0–4 the drive goes to SWITCH ON DISABLED
        // by itself once stopped, transition 12, and the walk goes on from there).
        (S::QuickStopActive, T::OperationEnabled) => Toward::Send(ENABLE_OPERATION),
        // Transition 12.
        (S::QuickStopActive, _) => Toward::Send(DISABLE_VOLTAGE),
    }
}

/// A mode of operation as 0x6060 and 0x6061 code it (CiA 402-2, object 6060h).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum OpMode {
    /// Profile position (pp), 1.
    ProfilePosition,
    /// Velocity (vl), 2.
    Velocity,
    /// Profile velocity (pv), 3.
    ProfileVelocity,
    /// Profile torque (tq), 4.
    ProfileTorque,
    /// Homing (hm), 6.
    Homing,
    /// Interpolated position (ip), 7.
    InterpolatedPosition,
    /// Cyclic synchronous position (csp), 8.
    CyclicSyncPosition,
    /// Cyclic synchronous velocity (csv), 9.
    CyclicSyncVelocity,
    /// Cyclic synchronous torque (cst), 10.
    CyclicSyncTorque,
}

impl OpMode {
    /// Every mode, in the order of their codes.
    pub const ALL: [OpMode; 9] = [
        OpMode::ProfilePosition,
        OpMode::Velocity,
        OpMode::ProfileVelocity,
        OpMode::ProfileTorque,
        OpMode::Homing,
        OpMode::InterpolatedPosition,
        OpMode::CyclicSyncPosition,
        OpMode::CyclicSyncVelocity,
        OpMode::CyclicSyncTorque,
    ];

    /// The 0x6060 value.
    pub const fn code(self) -> i8 {
        match self {
            OpMode::ProfilePosition => 1,
            OpMode::Velocity => 2,
            OpMode::ProfileVelocity => 3,
            OpMode::ProfileTorque => 4,
            OpMode::Homing => 6,
            OpMode::InterpolatedPosition => 7,
            OpMode::CyclicSyncPosition => 8,
            OpMode::CyclicSyncVelocity => 9,
            OpMode::CyclicSyncTorque => 10,
        }
    }

    /// The mode of a 0x6060/0x6061 value (`None`: no mode, reserved or manufacturer-specific).
    pub fn from_code(code: i8) -> Option<OpMode> {
        OpMode::ALL.into_iter().find(|m| m.code() == code)
    }

    /// The usual abbreviation: pp, vl, pv, tq, hm, ip, csp, csv, cst.
    pub const fn abbreviation(self) -> &'static str {
        match self {
            OpMode::ProfilePosition => "pp",
            OpMode::Velocity => "vl",
            OpMode::ProfileVelocity => "pv",
            OpMode::ProfileTorque => "tq",
            OpMode::Homing => "hm",
            OpMode::InterpolatedPosition => "ip",
            OpMode::CyclicSyncPosition => "csp",
            OpMode::CyclicSyncVelocity => "csv",
            OpMode::CyclicSyncTorque => "cst",
        }
    }

    /// The mode of an abbreviation (`"pt"` is accepted for profile torque too).
    pub fn from_abbreviation(text: &str) -> Option<OpMode> {
        let t = text.trim().to_ascii_lowercase();
        if t == "pt" {
            return Some(OpMode::ProfileTorque);
        }
        OpMode::ALL.into_iter().find(|m| m.abbreviation() == t)
    }

    /// The mode's name (`"profile position"`).
    pub const fn name(self) -> &'static str {
        match self {
            OpMode::ProfilePosition => "profile position",
            OpMode::Velocity => "velocity",
            OpMode::ProfileVelocity => "profile velocity",
            OpMode::ProfileTorque => "profile torque",
            OpMode::Homing => "homing",
            OpMode::InterpolatedPosition => "interpolated position",
            OpMode::CyclicSyncPosition => "cyclic synchronous position",
            OpMode::CyclicSyncVelocity => "cyclic synchronous velocity",
            OpMode::CyclicSyncTorque => "cyclic synchronous torque",
        }
    }
}

/// The name of a 0x6061 value: the mode's abbreviation, `"none"` for 0, else the number.
pub fn mode_name(code: i8) -> String {
    match OpMode::from_code(code) {
        Some(m) => m.abbreviation().to_string(),
        None if code == 0 => "none".to_string(),
        None => format!("{code} (not a CiA 402 mode)"),
    }
}

/// Settings of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisConfig {
    /// How long one state transition, a mode switch or a set-point acknowledge may take.
    pub step_timeout: Duration,
    /// How long a move may take to reach its target, and homing to finish.
    pub move_timeout: Duration,
    /// The time between two SDO reads of a statusword being waited for.
    pub poll_interval: Duration,
    /// The COB-ID of a TPDO that carries the statusword in its first two bytes (CiA
    /// 402-3's predefined TPDO1 does): waits then take the statusword from it instead of
    /// reading it by SDO. The TPDO must be sent on change or under a running SYNC.
    pub statusword_pdo: Option<u16>,
}

impl Default for AxisConfig {
    fn default() -> Self {
        AxisConfig {
            step_timeout: Duration::from_secs(1),
            move_timeout: Duration::from_secs(60),
            poll_interval: Duration::from_millis(10),
            statusword_pdo: None,
        }
    }
}

/// A profile position move ([`DriveMaster::profile_position`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PositionMove {
    /// 0x607A, in position units.
    pub target: i32,
    /// Controlword bit 6: relative to the present target (or position, per 0x60F2).
    pub relative: bool,
    /// Controlword bit 5: change set immediately (abort the move under way).
    pub immediately: bool,
    /// 0x6081, written first when given.
    pub profile_velocity: Option<u32>,
    /// 0x6083, written first when given.
    pub acceleration: Option<u32>,
    /// 0x6084, written first when given.
    pub deceleration: Option<u32>,
    /// Wait for target reached (statusword bit 10), else done at the acknowledge.
    pub wait: bool,
}

/// A profile velocity command ([`DriveMaster::profile_velocity`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VelocityMove {
    /// 0x60FF, in velocity units.
    pub target: i32,
    /// 0x6083, written first when given.
    pub acceleration: Option<u32>,
    /// 0x6084, written first when given.
    pub deceleration: Option<u32>,
    /// Wait for target reached (statusword bit 10: the velocity is reached).
    pub wait: bool,
}

/// A homing run ([`DriveMaster::home`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Homing {
    /// 0x6098: the method (CiA 402-2 homing methods −128..=127; 1–35 and 37 standard).
    pub method: i8,
    /// 0x6099 sub 1: speed during search for switch.
    pub switch_speed: Option<u32>,
    /// 0x6099 sub 2: speed during search for zero.
    pub zero_speed: Option<u32>,
    /// 0x609A: homing acceleration.
    pub acceleration: Option<u32>,
}

/// Which cyclic synchronous mode a stream feeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CyclicMode {
    /// csp: the RPDO carries 0x607A target position.
    Position,
    /// csv: the RPDO carries 0x60FF target velocity.
    Velocity,
}

impl CyclicMode {
    /// The mode of operation.
    pub const fn mode(self) -> OpMode {
        match self {
            CyclicMode::Position => OpMode::CyclicSyncPosition,
            CyclicMode::Velocity => OpMode::CyclicSyncVelocity,
        }
    }
}

/// How an axis's set-points reach the drive ([`DriveMaster::start_stream`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamConfig {
    /// csp or csv.
    pub mode: CyclicMode,
    /// The COB-ID of the drive's synchronous RPDO for the set-point (transmission type
    /// 0–240).
    pub rpdo: u16,
    /// The RPDO maps 0x6040 controlword (16 bits) before the set-point (32 bits), as
    /// CiA 402-3's predefined mappings do; else the set-point alone.
    pub with_controlword: bool,
}

/// A set-point profile: from `from` to `to` in `cycles` SYNC periods with the
/// minimum-jerk shape s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ (zero velocity and acceleration at both
/// ends), then `to` held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trajectory {
    /// The set-point before the first cycle.
    pub from: i32,
    /// The last set-point.
    pub to: i32,
    /// How many cycles the move takes (0: `to` at once).
    pub cycles: u32,
}

impl Trajectory {
    /// `value` held.
    pub const fn hold(value: i32) -> Self {
        Trajectory {
            from: value,
            to: value,
            cycles: 0,
        }
    }

    /// The set-point of cycle `k` (1-based; cycle `cycles` and later give `to`).
    pub fn at(&self, k: u32) -> i32 {
        if k >= self.cycles {
            return self.to;
        }
        let tau = f64::from(k) / f64::from(self.cycles);
        let s = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau));
        let v = f64::from(self.from) + (f64::from(self.to) - f64::from(self.from)) * s;
        // Between `from` and `to`, so inside i32.
        v.round() as i32
    }
}

/// What a job was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobKind {
    /// [`DriveMaster::switch`].
    Switch(PowerTarget),
    /// [`DriveMaster::quick_stop`].
    QuickStop,
    /// [`DriveMaster::fault_reset`].
    FaultReset,
    /// [`DriveMaster::set_mode`].
    SetMode(OpMode),
    /// [`DriveMaster::profile_position`].
    ProfilePosition,
    /// [`DriveMaster::profile_velocity`].
    ProfileVelocity,
    /// [`DriveMaster::home`].
    Home,
    /// [`DriveMaster::start_stream`].
    Stream,
    /// [`DriveMaster::inspect`].
    Inspect,
}

/// What a drive showed when a job ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Snapshot {
    /// 0x6041, as last read.
    pub statusword: Option<u16>,
    /// 0x6061.
    pub mode: Option<i8>,
    /// 0x603F.
    pub error_code: Option<u16>,
    /// 0x6064.
    pub position: Option<i32>,
    /// 0x606C.
    pub velocity: Option<i32>,
}

impl Snapshot {
    /// The state the statusword shows.
    pub fn state(&self) -> Option<DriveState> {
        self.statusword.and_then(DriveState::from_statusword)
    }
}

/// Why a job failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DriveError {
    /// The node-ID is not an axis, or out of range.
    #[error("node {0} is not an axis of this master")]
    NoAxis(u8),
    /// The axis is running another job.
    #[error("node {0} is busy with another job")]
    Busy(u8),
    /// The master refused a transfer.
    #[error(transparent)]
    Master(#[from] MasterError),
    /// An SDO transfer was aborted.
    #[error("SDO access to {index:#06X} sub {sub} aborted: {code}")]
    Sdo {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The abort code.
        code: AbortCode,
    },
    /// A value of the wrong size.
    #[error("{index:#06X} sub {sub} has an unexpected size")]
    Malformed {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// A wait ran out.
    #[error("timed out waiting for {waiting_for} (statusword {})", fmt_sw(*.statusword))]
    Timeout {
        /// What was waited for.
        waiting_for: &'static str,
        /// The last statusword seen.
        statusword: Option<u16>,
    },
    /// The drive is in FAULT or FAULT REACTION ACTIVE.
    #[error("the drive is in fault (0x603F error code {})", fmt_code(*.error_code))]
    Fault {
        /// 0x603F, if it could be read.
        error_code: Option<u16>,
    },
    /// The job needs OPERATION ENABLED.
    #[error("the drive is in {}, not operation enabled (enable it first)", state_opt(*.statusword))]
    NotEnabled {
        /// The statusword read.
        statusword: u16,
    },
    /// The drive is in another mode of operation.
    #[error("the drive is in mode {}, not {} (switch the mode first)", mode_name(*.shown), .wanted.abbreviation())]
    WrongMode {
        /// The mode the job needs.
        wanted: OpMode,
        /// 0x6061.
        shown: i8,
    },
    /// Statusword bit 13 in pp or csp: following error.
    #[error("following error (statusword {statusword:#06X})")]
    FollowingError {
        /// The statusword.
        statusword: u16,
    },
    /// Statusword bit 13 in hm: homing error.
    #[error("homing error (statusword {statusword:#06X})")]
    HomingError {
        /// The statusword.
        statusword: u16,
    },
    /// The state machine went round without reaching the target.
    #[error("the drive did not follow the state machine (statusword {statusword:#06X})")]
    NoProgress {
        /// The last statusword.
        statusword: u16,
    },
}

fn fmt_sw(sw: Option<u16>) -> String {
    match sw {
        Some(sw) => format!("{sw:#06X}, {}", state_name(sw)),
        None => "not read".to_string(),
    }
}

fn fmt_code(code: Option<u16>) -> String {
    match code {
        Some(c) => format!("{c:#06X}"),
        None => "not readable".to_string(),
    }
}

fn state_opt(sw: u16) -> &'static str {
    state_name(sw)
}

/// A job's end, or another event of the network.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DriveEvent {
    /// A job ended.
    Finished {
        /// The axis.
        node: u8,
        /// The job.
        job: JobKind,
        /// What the drive showed, or why the job failed.
        result: Result<Snapshot, DriveError>,
    },
    /// A cyclic trajectory sent its last set-point (it is held from now on).
    TrajectoryDone {
        /// The axis.
        node: u8,
        /// The last set-point.
        set_point: i32,
    },
    /// An event of the underlying [`Master`] that is not one of the jobs' transfers.
    Master(MasterEvent),
}

/// What a waited-for statusword must show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cond {
    /// A state other than this (after a controlword of the walk).
    Left(DriveState),
    /// QUICK STOP ACTIVE or SWITCH ON DISABLED.
    QuickStopped,
    /// Not FAULT nor FAULT REACTION ACTIVE.
    FaultCleared,
    /// Not FAULT REACTION ACTIVE (transition 14 done).
    ReactionDone,
    /// 0x6061 shows this mode.
    ModeShown(OpMode),
    /// pp bit 12 at this level.
    SetPointAck(bool),
    /// pp bit 10 with bit 12 cleared.
    PositionReached,
    /// pv bit 10 seen after a statusword without it, or at least a poll interval after
    /// the write.
    VelocityReached { since: Instant, seen_clear: bool },
    /// hm bits 10 and 12. When the drive showed bit 12 before the start (a previous
    /// homing's), only after a statusword without it or one read at least a poll interval
    /// after the start: the drive may not have taken the start yet.
    Homed { armed: bool, since: Instant },
}

enum Verdict {
    Met,
    NotYet,
    Fail(DriveError),
}

impl Cond {
    fn what(&self) -> &'static str {
        match self {
            Cond::Left(_) => "the state to change",
            Cond::QuickStopped => "quick stop active or switch on disabled",
            Cond::FaultCleared => "the fault to clear",
            Cond::ReactionDone => "the fault reaction to end",
            Cond::ModeShown(_) => "0x6061 to show the mode",
            Cond::SetPointAck(true) => "set-point acknowledge (bit 12)",
            Cond::SetPointAck(false) => "set-point acknowledge to clear (bit 12)",
            Cond::PositionReached | Cond::VelocityReached { .. } => "target reached (bit 10)",
            Cond::Homed { .. } => "homing attained (bits 10 and 12)",
        }
    }

    fn reads(&self) -> u16 {
        match self {
            Cond::ModeShown(_) => MODES_OF_OPERATION_DISPLAY,
            _ => STATUSWORD,
        }
    }

    fn check(&mut self, value: u16, now: Instant, poll: Duration) -> Verdict {
        let sw = value;
        let state = DriveState::from_statusword(sw);
        let faulted = state.is_some_and(DriveState::is_fault);
        match self {
            Cond::FaultCleared => {
                return if faulted || state.is_none() {
                    Verdict::NotYet
                } else {
                    Verdict::Met
                };
            }
            Cond::ReactionDone => {
                return if state == Some(DriveState::FaultReactionActive) || state.is_none() {
                    Verdict::NotYet
                } else {
                    Verdict::Met
                };
            }
            Cond::ModeShown(m) => {
                // The value is 0x6061, an INTEGER8 in the low byte.
                return if value as u8 as i8 == m.code() {
                    Verdict::Met
                } else {
                    Verdict::NotYet
                };
            }
            _ => {}
        }
        if faulted {
            return Verdict::Fail(DriveError::Fault { error_code: None });
        }
        let met = match self {
            Cond::Left(from) => state.is_some_and(|s| s != *from),
            Cond::QuickStopped => matches!(
                state,
                Some(DriveState::QuickStopActive | DriveState::SwitchOnDisabled)
            ),
            Cond::SetPointAck(level) => (sw & SW_BIT12 != 0) == *level,
            Cond::PositionReached => {
                if sw & SW_BIT13 != 0 {
                    return Verdict::Fail(DriveError::FollowingError { statusword: sw });
                }
                sw & SW_TARGET_REACHED != 0 && sw & SW_BIT12 == 0
            }
            Cond::VelocityReached { since, seen_clear } => {
                if sw & SW_TARGET_REACHED == 0 {
                    *seen_clear = true;
                    false
                } else {
                    *seen_clear || now.saturating_duration_since(*since) >= poll
                }
            }
            Cond::Homed { armed, since } => {
                if sw & SW_BIT13 != 0 {
                    return Verdict::Fail(DriveError::HomingError { statusword: sw });
                }
                if sw & SW_BIT12 == 0 || now.saturating_duration_since(*since) >= poll {
                    *armed = true;
                }
                *armed && sw & (SW_TARGET_REACHED | SW_BIT12) == SW_TARGET_REACHED | SW_BIT12
            }
            Cond::FaultCleared | Cond::ReactionDone | Cond::ModeShown(_) => false,
        };
        if met { Verdict::Met } else { Verdict::NotYet }
    }
}

/// What a read is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Then {
    /// Kept in the snapshot; an abort fails the job.
    Keep,
    /// Kept; an abort leaves the value unknown.
    Optional,
    /// 0x6041 must show OPERATION ENABLED.
    RequireEnabled,
    /// 0x6061 must show the mode.
    RequireMode(OpMode),
    /// 0x6061: switch to the mode unless shown.
    EnsureMode(OpMode),
    /// 0x6041 before a homing start: arms the wait if bit 12 is clear.
    ArmHoming,
    /// 0x6064: the stream's first set-point.
    StreamFrom,
    /// 0x6041 for a fault reset.
    ResetIfFaulted,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Step {
    Write(u16, u8, Vec<u8>),
    Controlword(u16),
    Read(u16, u8, Then),
    Await { cond: Cond, timeout: Duration },
    Walk(PowerTarget),
    ReadErrorCode,
    StartStream(StreamConfig),
}

#[derive(Debug, Clone)]
struct Job {
    kind: JobKind,
    steps: VecDeque<Step>,
    transfer: Option<TransferId>,
    /// The active wait's deadline and next poll.
    deadline: Option<Instant>,
    wake: Option<Instant>,
    snapshot: Snapshot,
    /// Controlwords written by the walk (bounded: a drive that does not follow fails).
    walked: u8,
    /// Set when the job fails on a fault: 0x603F is read before the error is reported.
    failing: Option<DriveError>,
    homing_armed: bool,
    stream_from: Option<i32>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stream {
    config: StreamConfig,
    trajectory: Trajectory,
    cycle: u32,
    last: i32,
    done_reported: bool,
}

#[derive(Debug, Clone)]
struct Axis {
    config: AxisConfig,
    controlword: u16,
    job: Option<Job>,
    stream: Option<Stream>,
    /// The statusword of the last TPDO ([`AxisConfig::statusword_pdo`]).
    pdo_statusword: Option<u16>,
}

/// The most controlwords one [`DriveMaster::switch`] writes: the longest path (FAULT
/// aside) has four transitions; a drive bouncing back gets a few more before the job fails.
const MAX_WALK: u8 = 8;

/// A CiA 402 master over a CANopen [`Master`] (see the module documentation).
#[derive(Debug, Clone)]
pub struct DriveMaster {
    master: Master,
    axes: BTreeMap<u8, Axis>,
    /// The transfers the jobs started, by axis.
    mine: BTreeMap<TransferId, u8>,
    events: VecDeque<(Instant, DriveEvent)>,
}

impl Default for DriveMaster {
    fn default() -> Self {
        DriveMaster::new()
    }
}

fn is_sync(f: &Frame) -> bool {
    matches!(f.id(), Id::Standard(s) if s.as_raw() == SYNC_COB_ID) && !f.is_remote()
}

fn le_i32(data: &[u8]) -> Option<i32> {
    <[u8; 4]>::try_from(data).ok().map(i32::from_le_bytes)
}

fn le_u16(data: &[u8]) -> Option<u16> {
    <[u8; 2]>::try_from(data).ok().map(u16::from_le_bytes)
}

fn le_i8(data: &[u8]) -> Option<i8> {
    <[u8; 1]>::try_from(data).ok().map(i8::from_le_bytes)
}

impl DriveMaster {
    /// A drive master over a default [`Master`].
    pub fn new() -> Self {
        DriveMaster::with_master(Master::new())
    }

    /// A drive master over `master`.
    pub fn with_master(master: Master) -> Self {
        DriveMaster {
            master,
            axes: BTreeMap::new(),
            mine: BTreeMap::new(),
            events: VecDeque::new(),
        }
    }

    /// The CANopen master (NMT, SYNC, PDO configuration, other transfers).
    pub fn master(&self) -> &Master {
        &self.master
    }

    /// The CANopen master, to start NMT commands, SYNC and PDO configuration; its events
    /// come out of [`Self::poll_event`] as [`DriveEvent::Master`].
    pub fn master_mut(&mut self) -> &mut Master {
        &mut self.master
    }

    /// Adds drive `node` (1–127) as an axis (replacing its settings if present).
    pub fn add_axis(&mut self, node: u8, config: AxisConfig) -> Result<(), DriveError> {
        if !(1..=127).contains(&node) {
            return Err(DriveError::NoAxis(node));
        }
        let axis = self.axes.entry(node).or_insert(Axis {
            config,
            controlword: 0,
            job: None,
            stream: None,
            pdo_statusword: None,
        });
        axis.config = config;
        Ok(())
    }

    /// The next event, oldest first.
    pub fn poll_event(&mut self) -> Option<(Instant, DriveEvent)> {
        self.events.pop_front()
    }

    /// Whether `node` runs a job.
    pub fn is_busy(&self, node: u8) -> bool {
        self.axes.get(&node).is_some_and(|a| a.job.is_some())
    }

    /// The controlword last written to `node`.
    pub fn controlword(&self, node: u8) -> Option<u16> {
        self.axes.get(&node).map(|a| a.controlword)
    }

    /// The statusword of `node`'s last TPDO ([`AxisConfig::statusword_pdo`]).
    pub fn pdo_statusword(&self, node: u8) -> Option<u16> {
        self.axes.get(&node).and_then(|a| a.pdo_statusword)
    }

    /// The set-point `node`'s stream sent last, if it streams.
    pub fn set_point(&self, node: u8) -> Option<i32> {
        self.axes.get(&node)?.stream.map(|s| s.last)
    }

    fn begin(
        &mut self,
        node: u8,
        kind: JobKind,
        steps: Vec<Step>,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let axis = self.axes.get_mut(&node).ok_or(DriveError::NoAxis(node))?;
        if axis.job.is_some() {
            return Err(DriveError::Busy(node));
        }
        axis.job = Some(Job {
            kind,
            steps: steps.into(),
            transfer: None,
            deadline: None,
            wake: None,
            snapshot: Snapshot {
                statusword: None,
                mode: None,
                error_code: None,
                position: None,
                velocity: None,
            },
            walked: 0,
            failing: None,
            homing_armed: false,
            stream_from: None,
        });
        let mut local = Outbox::new();
        self.advance(node, now, &mut local);
        self.relay(local, now, out);
        Ok(())
    }

    /// Brings `node` to `target` along the PDS FSA: each controlword is written after the
    /// statusword shows the state it applies to (CiA 402-2, transitions 2–12, 16).
    pub fn switch(
        &mut self,
        node: u8,
        target: PowerTarget,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        self.begin(
            node,
            JobKind::Switch(target),
            vec![Step::Walk(target)],
            now,
            out,
        )
    }

    /// Quick stop (controlword 0x0002: transition 11 from OPERATION ENABLED, 7 or 10 from
    /// READY TO SWITCH ON and SWITCHED ON); done when the drive shows QUICK STOP ACTIVE or
    /// SWITCH ON DISABLED.
    pub fn quick_stop(
        &mut self,
        node: u8,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let timeout = self.step_timeout(node)?;
        let steps = vec![
            Step::Controlword(command::QUICK_STOP),
            Step::Await {
                cond: Cond::QuickStopped,
                timeout,
            },
        ];
        self.begin(node, JobKind::QuickStop, steps, now, out)
    }

    /// Fault reset (transition 15): reads the statusword; in FAULT writes controlword
    /// 0x0000 then 0x0080, so that bit 7 rises whatever was written before (0x0000 commands
    /// nothing in FAULT), and waits until the drive has left FAULT (a fault still present
    /// keeps it there: [`DriveError::Timeout`]). In FAULT REACTION ACTIVE it first waits
    /// for the reaction to end (transition 14); a drive not in fault is left alone.
    pub fn fault_reset(
        &mut self,
        node: u8,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let steps = vec![Step::Read(STATUSWORD, 0, Then::ResetIfFaulted)];
        self.begin(node, JobKind::FaultReset, steps, now, out)
    }

    /// Writes 0x6060 and waits until 0x6061 shows the mode (CiA 402-2, object 6061h: the
    /// display follows once the drive has switched).
    pub fn set_mode(
        &mut self,
        node: u8,
        mode: OpMode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let timeout = self.step_timeout(node)?;
        let steps = vec![
            Step::Write(MODES_OF_OPERATION, 0, vec![mode.code() as u8]),
            Step::Await {
                cond: Cond::ModeShown(mode),
                timeout,
            },
        ];
        self.begin(node, JobKind::SetMode(mode), steps, now, out)
    }

    /// A profile position move (CiA 402-2, pp: the set-point handshake of controlword
    /// bit 4 and statusword bit 12). Needs OPERATION ENABLED and pp.
    pub fn profile_position(
        &mut self,
        node: u8,
        mv: PositionMove,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (step, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::RequireMode(OpMode::ProfilePosition),
            ),
        ];
        for (index, value) in [
            (PROFILE_VELOCITY, mv.profile_velocity),
            (PROFILE_ACCELERATION, mv.acceleration),
            (PROFILE_DECELERATION, mv.deceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, 0, v.to_le_bytes().to_vec()));
            }
        }
        let mut flags = command::ENABLE_OPERATION;
        if mv.relative {
            flags |= CW_RELATIVE;
        }
        if mv.immediately {
            flags |= CW_CHANGE_SET_IMMEDIATELY;
        }
        steps.extend([
            Step::Write(TARGET_POSITION, 0, mv.target.to_le_bytes().to_vec()),
            // Bit 4 low first: the drive takes the set-point on its rising edge.
            Step::Controlword(flags),
            Step::Controlword(flags | CW_BIT4),
            Step::Await {
                cond: Cond::SetPointAck(true),
                timeout: step,
            },
            Step::Controlword(flags),
        ]);
        if mv.wait {
            steps.push(Step::Await {
                cond: Cond::PositionReached,
                timeout: moving,
            });
        }
        steps.push(Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional));
        self.begin(node, JobKind::ProfilePosition, steps, now, out)
    }

    /// A profile velocity command (CiA 402-2, pv): 0x60FF and enable operation without
    /// halt. Needs OPERATION ENABLED and pv.
    pub fn profile_velocity(
        &mut self,
        node: u8,
        mv: VelocityMove,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (_, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::RequireMode(OpMode::ProfileVelocity),
            ),
        ];
        for (index, value) in [
            (PROFILE_ACCELERATION, mv.acceleration),
            (PROFILE_DECELERATION, mv.deceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, 0, v.to_le_bytes().to_vec()));
            }
        }
        steps.push(Step::Write(
            TARGET_VELOCITY,
            0,
            mv.target.to_le_bytes().to_vec(),
        ));
        steps.push(Step::Controlword(command::ENABLE_OPERATION));
        if mv.wait {
            steps.push(Step::Await {
                cond: Cond::VelocityReached {
                    since: Instant::ZERO,
                    seen_clear: false,
                },
                timeout: moving,
            });
        }
        steps.push(Step::Read(VELOCITY_ACTUAL_VALUE, 0, Then::Optional));
        self.begin(node, JobKind::ProfileVelocity, steps, now, out)
    }

    /// Homing (CiA 402-2, hm): switches to hm if 0x6061 shows another mode, writes the
    /// method and the optional speeds and acceleration, starts with the rising edge of
    /// controlword bit 4 and waits for homing attained. Needs OPERATION ENABLED.
    pub fn home(
        &mut self,
        node: u8,
        homing: Homing,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (_, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::EnsureMode(OpMode::Homing),
            ),
            Step::Write(HOMING_METHOD, 0, vec![homing.method as u8]),
        ];
        for (index, sub, value) in [
            (HOMING_SPEEDS, 1, homing.switch_speed),
            (HOMING_SPEEDS, 2, homing.zero_speed),
            (HOMING_ACCELERATION, 0, homing.acceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, sub, v.to_le_bytes().to_vec()));
            }
        }
        steps.extend([
            Step::Controlword(command::ENABLE_OPERATION),
            Step::Read(STATUSWORD, 0, Then::ArmHoming),
            Step::Controlword(command::ENABLE_OPERATION | CW_BIT4),
            Step::Await {
                cond: Cond::Homed {
                    armed: false,
                    since: Instant::ZERO,
                },
                timeout: moving,
            },
            Step::Controlword(command::ENABLE_OPERATION),
            Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional),
        ]);
        self.begin(node, JobKind::Home, steps, now, out)
    }

    /// Starts cyclic set-points for `node` (csp or csv, which 0x6061 must show): csp holds
    /// the position 0x6064 reads, csv holds 0; from the next SYNC the master sends, the
    /// set-point goes out in the RPDO after every SYNC. Change it with
    /// [`Self::move_cyclic`]; stop with [`Self::stop_stream`].
    pub fn start_stream(
        &mut self,
        node: u8,
        config: StreamConfig,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let mut steps = vec![Step::Read(
            MODES_OF_OPERATION_DISPLAY,
            0,
            Then::RequireMode(config.mode.mode()),
        )];
        if config.mode == CyclicMode::Position {
            steps.push(Step::Read(POSITION_ACTUAL_VALUE, 0, Then::StreamFrom));
        }
        steps.push(Step::StartStream(config));
        self.begin(node, JobKind::Stream, steps, now, out)
    }

    /// Stops `node`'s stream (no more set-points: a drive in csp or csv reacts as CiA 402
    /// and its manufacturer say for a missing set-point).
    pub fn stop_stream(&mut self, node: u8) {
        if let Some(a) = self.axes.get_mut(&node) {
            a.stream = None;
        }
    }

    /// Gives every listed axis a new target reached in `cycles` SYNC periods, starting at
    /// the next SYNC for all of them (a coordinated move). Each axis must stream.
    /// [`DriveEvent::TrajectoryDone`] reports each end.
    pub fn move_cyclic(&mut self, targets: &[(u8, i32)], cycles: u32) -> Result<(), DriveError> {
        for (node, _) in targets {
            if self.axes.get(node).and_then(|a| a.stream).is_none() {
                return Err(DriveError::NoAxis(*node));
            }
        }
        for (node, to) in targets {
            if let Some(s) = self.axes.get_mut(node).and_then(|a| a.stream.as_mut()) {
                s.trajectory = Trajectory {
                    from: s.last,
                    to: *to,
                    cycles,
                };
                s.cycle = 0;
                s.done_reported = false;
            }
        }
        Ok(())
    }

    /// Reads 0x6041, 0x6061, 0x603F, 0x6064 and 0x606C (the last four optional: a drive
    /// without them leaves them unknown).
    pub fn inspect(&mut self, node: u8, now: Instant, out: &mut Outbox) -> Result<(), DriveError> {
        let steps = vec![
            Step::Read(STATUSWORD, 0, Then::Keep),
            Step::Read(MODES_OF_OPERATION_DISPLAY, 0, Then::Optional),
            Step::Read(ERROR_CODE, 0, Then::Optional),
            Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional),
            Step::Read(VELOCITY_ACTUAL_VALUE, 0, Then::Optional),
        ];
        self.begin(node, JobKind::Inspect, steps, now, out)
    }

    fn step_timeout(&self, node: u8) -> Result<Duration, DriveError> {
        Ok(self.timeouts(node)?.0)
    }

    fn timeouts(&self, node: u8) -> Result<(Duration, Duration), DriveError> {
        let a = self.axes.get(&node).ok_or(DriveError::NoAxis(node))?;
        Ok((a.config.step_timeout, a.config.move_timeout))
    }

    // ---- the job interpreter ----

    fn finish(&mut self, node: u8, result: Result<(), DriveError>, now: Instant) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let Some(job) = axis.job.take() else {
            return;
        };
        let result = result.map(|()| job.snapshot);
        self.events.push_back((
            now,
            DriveEvent::Finished {
                node,
                job: job.kind,
                result,
            },
        ));
    }

    /// Fails the job; a fault first reads 0x603F.
    fn fail(&mut self, node: u8, error: DriveError, now: Instant, out: &mut Outbox) {
        let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) else {
            return;
        };
        if matches!(error, DriveError::Fault { .. }) && job.failing.is_none() {
            job.failing = Some(error);
            job.steps.clear();
            job.steps.push_back(Step::ReadErrorCode);
            job.deadline = None;
            job.wake = None;
            self.advance(node, now, out);
            return;
        }
        self.finish(node, Err(error), now);
    }

    fn sdo(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        data: Option<Vec<u8>>,
        now: Instant,
        out: &mut Outbox,
    ) {
        let mux = Mux::new(index, sub);
        let r = match data {
            None => self.master.upload(node, mux, Mode::Auto, now, out),
            Some(d) => self.master.download(node, mux, d, Mode::Auto, now, out),
        };
        match r {
            Ok(id) => {
                self.mine.insert(id, node);
                if let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) {
                    job.transfer = Some(id);
                }
            }
            Err(e) => self.fail(node, e.into(), now, out),
        }
    }

    /// Runs `node`'s job until it waits for a transfer, a poll or a statusword.
    fn advance(&mut self, node: u8, now: Instant, out: &mut Outbox) {
        loop {
            let Some(axis) = self.axes.get_mut(&node) else {
                return;
            };
            let pdo = axis.config.statusword_pdo.is_some();
            let pdo_sw = axis.pdo_statusword;
            let Some(job) = axis.job.as_mut() else {
                return;
            };
            if job.transfer.is_some() || job.wake.is_some_and(|w| now < w) {
                return;
            }
            job.wake = None;
            let Some(step) = job.steps.front_mut() else {
                let failing = job.failing;
                match failing {
                    Some(e) => self.finish(node, Err(e), now),
                    None => self.finish(node, Ok(()), now),
                }
                return;
            };
            match step {
                Step::Write(index, sub, data) => {
                    let (index, sub, data) = (*index, *sub, data.clone());
                    self.sdo(node, index, sub, Some(data), now, out);
                    return;
                }
                Step::Controlword(cw) => {
                    let cw = *cw;
                    axis.controlword = cw;
                    self.sdo(
                        node,
                        CONTROLWORD,
                        0,
                        Some(cw.to_le_bytes().to_vec()),
                        now,
                        out,
                    );
                    return;
                }
                Step::Read(index, sub, _) => {
                    let (index, sub) = (*index, *sub);
                    self.sdo(node, index, sub, None, now, out);
                    return;
                }
                Step::ReadErrorCode => {
                    self.sdo(node, ERROR_CODE, 0, None, now, out);
                    return;
                }
                Step::Walk(_) => {
                    self.sdo(node, STATUSWORD, 0, None, now, out);
                    return;
                }
                Step::StartStream(config) => {
                    let config = *config;
                    let from = job.stream_from.unwrap_or(0);
                    job.steps.pop_front();
                    axis.stream = Some(Stream {
                        config,
                        trajectory: Trajectory::hold(from),
                        cycle: 0,
                        last: from,
                        done_reported: true,
                    });
                    continue;
                }
                Step::Await { cond, timeout } => {
                    if job.deadline.is_none() {
                        job.deadline = Some(now.checked_add(*timeout).unwrap_or(Instant::MAX));
                        if let Cond::VelocityReached { since, .. } = cond {
                            *since = now;
                        }
                        if let Cond::Homed { armed, since } = cond {
                            *armed = job.homing_armed;
                            *since = now;
                        }
                    }
                    if pdo && cond.reads() == STATUSWORD {
                        // The TPDO may have come before the write's confirmation: the
                        // last one counts (every condition here is one the statusword
                        // before the write does not meet, or is armed against it).
                        if let Some(sw) = pdo_sw {
                            self.judge(node, sw, now, out);
                            if self.waiting_on_pdo(node) {
                                return;
                            }
                            continue;
                        }
                        return;
                    }
                    let index = cond.reads();
                    self.sdo(node, index, 0, None, now, out);
                    return;
                }
            }
        }
    }

    /// Whether `node`'s job waits for a statusword from its TPDO.
    fn waiting_on_pdo(&self, node: u8) -> bool {
        let Some(a) = self.axes.get(&node) else {
            return false;
        };
        a.config.statusword_pdo.is_some()
            && a.job.as_ref().is_some_and(|j| {
                j.transfer.is_none()
                    && j.deadline.is_some()
                    && matches!(j.steps.front(), Some(Step::Await { cond, .. }) if cond.reads() == STATUSWORD)
            })
    }

    /// A statusword (or 0x6061 value) for the job's wait.
    fn judge(&mut self, node: u8, value: u16, now: Instant, out: &mut Outbox) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let poll = axis.config.poll_interval;
        let pdo = axis.config.statusword_pdo.is_some();
        let Some(job) = axis.job.as_mut() else {
            return;
        };
        let Some(Step::Await { cond, .. }) = job.steps.front_mut() else {
            return;
        };
        let by_pdo = pdo && cond.reads() == STATUSWORD;
        if cond.reads() == STATUSWORD {
            job.snapshot.statusword = Some(value);
        } else {
            job.snapshot.mode = Some(value as u8 as i8);
        }
        let what = cond.what();
        match cond.check(value, now, poll) {
            Verdict::Met => {
                job.steps.pop_front();
                job.deadline = None;
            }
            Verdict::NotYet => {
                if job.deadline.is_some_and(|d| now >= d) {
                    let statusword = job.snapshot.statusword;
                    self.fail(
                        node,
                        DriveError::Timeout {
                            waiting_for: what,
                            statusword,
                        },
                        now,
                        out,
                    );
                } else if !by_pdo {
                    job.wake = Some(now.checked_add(poll).unwrap_or(Instant::MAX));
                }
            }
            Verdict::Fail(e) => self.fail(node, e, now, out),
        }
    }

    /// The end of one of the jobs' transfers.
    fn on_transfer(
        &mut self,
        node: u8,
        id: TransferId,
        event: SdoEvent,
        now: Instant,
        out: &mut Outbox,
    ) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let step_timeout = axis.config.step_timeout;
        let Some(job) = axis.job.as_mut() else {
            return;
        };
        if job.transfer != Some(id) {
            // A poll that outlived its job's wait.
            return;
        }
        job.transfer = None;
        let (mux, result) = match event {
            SdoEvent::Completed { mux, data } => (mux, Ok(data)),
            SdoEvent::Aborted { mux, code, .. } => (mux, Err(code)),
            SdoEvent::Progress { .. } | SdoEvent::FellBack { .. } => return,
        };
        let Some(step) = job.steps.front().cloned() else {
            return;
        };
        let aborted = |code| DriveError::Sdo {
            index: mux.index,
            sub: mux.sub,
            code,
        };
        let malformed = DriveError::Malformed {
            index: mux.index,
            sub: mux.sub,
        };
        match step {
            Step::Write(..) | Step::Controlword(_) => match result {
                Ok(_) => {
                    job.steps.pop_front();
                }
                Err(code) => return self.fail(node, aborted(code), now, out),
            },
            Step::ReadErrorCode => {
                job.snapshot.error_code = result.ok().and_then(|d| le_u16(&d));
                job.steps.pop_front();
                if let Some(DriveError::Fault { error_code }) = job.failing.as_mut() {
                    *error_code = job.snapshot.error_code;
                }
            }
            Step::Read(index, _, then) => {
                let data = match (result, then) {
                    (Ok(d), _) => d,
                    (Err(_), Then::Optional) => {
                        job.steps.pop_front();
                        return self.advance(node, now, out);
                    }
                    (Err(code), _) => return self.fail(node, aborted(code), now, out),
                };
                job.steps.pop_front();
                if let Err(e) = Self::take_read(job, index, then, &data, step_timeout) {
                    return self.fail(node, e, now, out);
                }
            }
            Step::Walk(target) => {
                let sw = match result {
                    Ok(d) => match le_u16(&d) {
                        Some(sw) => sw,
                        None => return self.fail(node, malformed, now, out),
                    },
                    Err(code) => return self.fail(node, aborted(code), now, out),
                };
                job.snapshot.statusword = Some(sw);
                let Some(state) = DriveState::from_statusword(sw) else {
                    return self.fail(node, DriveError::NoProgress { statusword: sw }, now, out);
                };
                let timeout = step_timeout;
                match toward(state, target) {
                    Toward::Arrived => {
                        job.steps.pop_front();
                    }
                    Toward::Faulted => {
                        return self.fail(node, DriveError::Fault { error_code: None }, now, out);
                    }
                    Toward::Send(_) | Toward::Wait if job.walked >= MAX_WALK => {
                        return self.fail(
                            node,
                            DriveError::NoProgress { statusword: sw },
                            now,
                            out,
                        );
                    }
                    Toward::Send(cw) => {
                        job.walked += 1;
                        job.steps.push_front(Step::Await {
                            cond: Cond::Left(state),
                            timeout,
                        });
                        job.steps.push_front(Step::Controlword(cw));
                    }
                    Toward::Wait => {
                        job.walked += 1;
                        job.steps.push_front(Step::Await {
                            cond: Cond::Left(state),
                            timeout,
                        });
                    }
                }
            }
            Step::Await { cond, .. } => {
                let width = if cond.reads() == STATUSWORD { 2 } else { 1 };
                let value = match result {
                    Ok(d) if d.len() == width => {
                        if width == 2 {
                            le_u16(&d).unwrap_or(0)
                        } else {
                            u16::from(d[0])
                        }
                    }
                    Ok(_) => return self.fail(node, malformed, now, out),
                    Err(code) => return self.fail(node, aborted(code), now, out),
                };
                self.judge(node, value, now, out);
            }
            Step::StartStream(_) => {}
        }
        self.advance(node, now, out);
    }

    /// Applies a completed read to the job.
    fn take_read(
        job: &mut Job,
        index: u16,
        then: Then,
        data: &[u8],
        step_timeout: Duration,
    ) -> Result<(), DriveError> {
        let malformed = DriveError::Malformed { index, sub: 0 };
        match index {
            STATUSWORD => job.snapshot.statusword = Some(le_u16(data).ok_or(malformed)?),
            MODES_OF_OPERATION_DISPLAY => job.snapshot.mode = Some(le_i8(data).ok_or(malformed)?),
            ERROR_CODE => job.snapshot.error_code = Some(le_u16(data).ok_or(malformed)?),
            POSITION_ACTUAL_VALUE => job.snapshot.position = Some(le_i32(data).ok_or(malformed)?),
            VELOCITY_ACTUAL_VALUE => job.snapshot.velocity = Some(le_i32(data).ok_or(malformed)?),
            _ => {}
        }
        match then {
            Then::Keep | Then::Optional => Ok(()),
            Then::RequireEnabled => {
                let sw = job.snapshot.statusword.unwrap_or(0);
                match DriveState::from_statusword(sw) {
                    Some(DriveState::OperationEnabled) => Ok(()),
                    Some(s) if s.is_fault() => Err(DriveError::Fault { error_code: None }),
                    _ => Err(DriveError::NotEnabled { statusword: sw }),
                }
            }
            Then::RequireMode(wanted) => {
                let shown = job.snapshot.mode.unwrap_or(0);
                if shown == wanted.code() {
                    Ok(())
                } else {
                    Err(DriveError::WrongMode { wanted, shown })
                }
            }
            Then::EnsureMode(wanted) => {
                if job.snapshot.mode != Some(wanted.code()) {
                    job.steps.push_front(Step::Await {
                        cond: Cond::ModeShown(wanted),
                        timeout: step_timeout,
                    });
                    job.steps.push_front(Step::Write(
                        MODES_OF_OPERATION,
                        0,
                        vec![wanted.code() as u8],
                    ));
                }
                Ok(())
            }
            Then::ArmHoming => {
                job.homing_armed = job.snapshot.statusword.is_some_and(|sw| sw & SW_BIT12 == 0);
                Ok(())
            }
            Then::StreamFrom => {
                job.stream_from = job.snapshot.position;
                Ok(())
            }
            Then::ResetIfFaulted => {
                let sw = job.snapshot.statusword.unwrap_or(0);
                match DriveState::from_statusword(sw) {
                    Some(DriveState::FaultReactionActive) => {
                        job.steps
                            .push_front(Step::Read(STATUSWORD, 0, Then::ResetIfFaulted));
                        job.steps.push_front(Step::Await {
                            cond: Cond::ReactionDone,
                            timeout: step_timeout,
                        });
                    }
                    Some(DriveState::Fault) => {
                        job.steps.push_front(Step::Await {
                            cond: Cond::FaultCleared,
                            timeout: step_timeout,
                        });
                        job.steps
                            .push_front(Step::Controlword(command::FAULT_RESET));
                        job.steps
                            .push_front(Step::Controlword(command::DISABLE_VOLTAGE));
                    }
                    _ => {}
                }
                Ok(())
            }
        }
    }

    /// Hands the master's frames on; after each SYNC, every stream's RPDO.
    fn relay(&mut self, mut local: Outbox, now: Instant, out: &mut Outbox) {
        let frames: Vec<Frame> = local.drain().collect();
        for f in frames {
            out.push(f);
            if is_sync(&f) {
                self.on_sync(now, out);
            }
        }
        self.collect(now, out);
    }

    fn on_sync(&mut self, now: Instant, out: &mut Outbox) {
        for (&node, axis) in self.axes.iter_mut() {
            let Some(s) = axis.stream.as_mut() else {
                continue;
            };
            s.cycle = s.cycle.saturating_add(1);
            let value = s.trajectory.at(s.cycle);
            s.last = value;
            let mut data = [0u8; 6];
            let len = if s.config.with_controlword {
                data[..2].copy_from_slice(&axis.controlword.to_le_bytes());
                data[2..6].copy_from_slice(&value.to_le_bytes());
                6
            } else {
                data[..4].copy_from_slice(&value.to_le_bytes());
                4
            };
            if let Ok(f) = Frame::std(s.config.rpdo, &data[..len]) {
                out.push(f);
            }
            if !s.done_reported && s.cycle >= s.trajectory.cycles {
                s.done_reported = true;
                self.events.push_back((
                    now,
                    DriveEvent::TrajectoryDone {
                        node,
                        set_point: value,
                    },
                ));
            }
        }
    }

    /// Routes the master's events: the jobs' transfers to the jobs, the rest out.
    fn collect(&mut self, now: Instant, out: &mut Outbox) {
        while let Some((at, event)) = self.master.poll_event() {
            match event {
                MasterEvent::Sdo { id, event, .. } if self.mine.contains_key(&id) => {
                    let terminal =
                        matches!(event, SdoEvent::Completed { .. } | SdoEvent::Aborted { .. });
                    let node = if terminal {
                        self.mine.remove(&id)
                    } else {
                        self.mine.get(&id).copied()
                    };
                    if let Some(node) = node {
                        let mut local = Outbox::new();
                        self.on_transfer(node, id, event, now, &mut local);
                        self.relay_plain(local, now, out);
                    }
                }
                other => self.events.push_back((at, DriveEvent::Master(other))),
            }
        }
    }

    /// Like [`Self::relay`] for frames the jobs queued (SDO requests, never SYNC).
    fn relay_plain(&mut self, mut local: Outbox, now: Instant, out: &mut Outbox) {
        let frames: Vec<Frame> = local.drain().collect();
        for f in frames {
            out.push(f);
            if is_sync(&f) {
                self.on_sync(now, out);
            }
        }
    }

    fn is_stream_frame(&self, frame: &Frame) -> bool {
        let raw = frame.id().as_raw();
        matches!(frame.id(), Id::Standard(_))
            && self
                .axes
                .values()
                .any(|a| a.stream.is_some_and(|s| u32::from(s.config.rpdo) == raw))
    }
}

impl Node for DriveMaster {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_power_up(now, &mut local);
        self.relay(local, now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if let Id::Standard(sid) = frame.id()
            && !frame.is_remote()
        {
            let raw = sid.as_raw();
            let hit: Vec<u8> = self
                .axes
                .iter()
                .filter(|(_, a)| a.config.statusword_pdo == Some(raw))
                .map(|(n, _)| *n)
                .collect();
            if let Some(sw) = le_u16(frame.data_bytes().get(..2).unwrap_or(&[])) {
                for node in hit {
                    let mut local = Outbox::new();
                    if let Some(a) = self.axes.get_mut(&node) {
                        a.pdo_statusword = Some(sw);
                    }
                    if self.waiting_on_pdo(node) {
                        self.judge(node, sw, now, &mut local);
                        self.advance(node, now, &mut local);
                    }
                    self.relay_plain(local, now, out);
                }
            }
        }
        let mut local = Outbox::new();
        self.master.on_frame(frame, now, &mut local);
        self.relay(local, now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_tick(now, &mut local);
        self.relay(local, now, out);
        let nodes: Vec<u8> = self.axes.keys().copied().collect();
        for node in nodes {
            let mut local = Outbox::new();
            let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) else {
                continue;
            };
            // A wait whose deadline passed with no answer (a silent drive, or a TPDO that
            // never came).
            if job.deadline.is_some_and(|d| now >= d) && job.transfer.is_none() {
                let waiting_for = match job.steps.front() {
                    Some(Step::Await { cond, .. }) => cond.what(),
                    _ => "the drive",
                };
                let statusword = job.snapshot.statusword;
                self.fail(
                    node,
                    DriveError::Timeout {
                        waiting_for,
                        statusword,
                    },
                    now,
                    &mut local,
                );
            } else if job.wake.is_some_and(|w| now >= w) {
                self.advance(node, now, &mut local);
            }
            self.relay_plain(local, now, out);
        }
        self.collect(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let mut next = self.master.next_deadline();
        for a in self.axes.values() {
            if let Some(job) = &a.job {
                for t in [job.wake, job.deadline.filter(|_| job.transfer.is_none())]
                    .into_iter()
                    .flatten()
                {
                    next = Some(next.map_or(t, |n| n.min(t)));
                }
            }
        }
        next
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        // The master counts its own frames in its transmit window; the streams' RPDOs are
        // not its.
        if self.is_stream_frame(frame) {
            return;
        }
        let mut local = Outbox::new();
        self.master.on_sent(frame, now, &mut local);
        self.relay(local, now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_controller_event(event, now, &mut local);
        self.relay(local, now, out);
    }
}

#[cfg(test)]
mod tests {
    //! The master against a small CiA 402 drive model in virtual time: an SDO server over
    //! the profile's objects and a 1 ms control cycle that follows the PDS FSA, switches
    //! modes, runs pp, pv and hm and applies synchronous RPDO set-points at SYNC.
    use super::*;
    use crate::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
    use crate::sdo::SdoServer;
    use std::sync::Arc;

    const NODE: u8 = 3;
    const CYCLE: Duration = Duration::from_millis(1);

    fn description() -> crate::od::OdDescription {
        use DataType as T;
        let v = |b: OdBuilder, index, name: &str, ty, access| {
            b.var(index, SubObject::new(name, ty, access))
        };
        let mut b = OdBuilder::new();
        b = v(b, ERROR_CODE, "Error code", T::Unsigned16, Access::Ro);
        b = v(b, CONTROLWORD, "Controlword", T::Unsigned16, Access::Rw);
        b = v(b, STATUSWORD, "Statusword", T::Unsigned16, Access::Ro);
        b = v(
            b,
            MODES_OF_OPERATION,
            "Modes of operation",
            T::Integer8,
            Access::Rw,
        );
        b = v(
            b,
            MODES_OF_OPERATION_DISPLAY,
            "Modes of operation display",
            T::Integer8,
            Access::Ro,
        );
        b = v(
            b,
            POSITION_ACTUAL_VALUE,
            "Position actual value",
            T::Integer32,
            Access::Ro,
        );
        b = v(
            b,
            VELOCITY_ACTUAL_VALUE,
            "Velocity actual value",
            T::Integer32,
            Access::Ro,
        );
        b = v(
            b,
            TARGET_POSITION,
            "Target position",
            T::Integer32,
            Access::Rw,
        );
        b = v(
            b,
            PROFILE_VELOCITY,
            "Profile velocity",
            T::Unsigned32,
            Access::Rw,
        );
        b = v(b, HOMING_METHOD, "Homing method", T::Integer8, Access::Rw);
        b = v(
            b,
            TARGET_VELOCITY,
            "Target velocity",
            T::Integer32,
            Access::Rw,
        );
        b.build().expect("valid")
    }

    /// The drive model. Quick stop behaves as 0x605A = 2 (stop, then SWITCH ON DISABLED
    /// after 3 cycles); pp moves 100 units a cycle at most; pv steps 10 units a cycle;
    /// homing takes 5 cycles and sets the position to 0, method −1 fails; 0x6061 follows
    /// 0x6060 after 2 cycles.
    struct Drive {
        od: ObjectDictionary,
        server: SdoServer,
        state: DriveState,
        next: Instant,
        last_cw: u16,
        mode_delay: u8,
        quick_stop_left: u8,
        fault: bool,
        position: i32,
        velocity: i32,
        target: i32,
        ack: bool,
        homing_left: Option<u8>,
        homed: bool,
        homing_error: bool,
        buffered: Option<i32>,
        tpdo: bool,
        sent_sw: Option<u16>,
        /// Frames the drive ignores (a drive that stopped answering).
        silent: bool,
    }

    impl Drive {
        fn new() -> Self {
            Drive {
                od: ObjectDictionary::new(Arc::new(description()), NODE),
                server: SdoServer::for_node(NODE),
                state: DriveState::NotReadyToSwitchOn,
                next: Instant::ZERO,
                last_cw: 0,
                mode_delay: 0,
                quick_stop_left: 0,
                fault: false,
                position: 1234,
                velocity: 0,
                target: 0,
                ack: false,
                homing_left: None,
                homed: false,
                homing_error: false,
                buffered: None,
                tpdo: false,
                sent_sw: None,
                silent: false,
            }
        }

        fn u(&self, index: u16) -> u64 {
            self.od.get_unsigned(index, 0).unwrap_or(0)
        }

        fn i(&self, index: u16) -> i64 {
            match self.od.get(index, 0) {
                Ok(Value::Integer8(v)) => i64::from(v),
                Ok(Value::Integer32(v)) => i64::from(v),
                _ => 0,
            }
        }

        fn mode(&self) -> i8 {
            self.i(MODES_OF_OPERATION_DISPLAY) as i8
        }

        fn statusword(&self) -> u16 {
            let mut sw = self.state.pattern().1;
            if self.state != DriveState::NotReadyToSwitchOn
                && self.state != DriveState::SwitchOnDisabled
            {
                sw |= 1 << 4;
            }
            let enabled = self.state == DriveState::OperationEnabled;
            match OpMode::from_code(self.mode()) {
                Some(OpMode::ProfilePosition) => {
                    if self.position == self.target {
                        sw |= SW_TARGET_REACHED;
                    }
                    if self.ack {
                        sw |= SW_BIT12;
                    }
                }
                Some(OpMode::ProfileVelocity)
                    if self.velocity == self.i(TARGET_VELOCITY) as i32 =>
                {
                    sw |= SW_TARGET_REACHED;
                }
                Some(OpMode::Homing) => {
                    if self.homed && self.homing_left.is_none() {
                        sw |= SW_TARGET_REACHED | SW_BIT12;
                    }
                    if self.homing_error {
                        sw |= SW_BIT13;
                    }
                }
                Some(OpMode::CyclicSyncPosition) if enabled => sw |= SW_BIT12,
                _ => {}
            }
            sw
        }

        /// One control cycle: the PDS FSA (CiA 402-2), then the mode's motion.
        fn cycle(&mut self) {
            use DriveState as S;
            let cw = self.u(CONTROLWORD) as u16;
            let rising = |bit: u16| cw & bit != 0 && self.last_cw & bit == 0;
            let cmd = cw & 0x8F;
            self.state = match self.state {
                _ if self.fault && !self.state.is_fault() => S::FaultReactionActive,
                S::FaultReactionActive => S::Fault,
                S::Fault if rising(0x80) && !self.fault => S::SwitchOnDisabled,
                S::Fault => S::Fault,
                S::NotReadyToSwitchOn => S::SwitchOnDisabled,
                S::SwitchOnDisabled if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
                S::ReadyToSwitchOn if cmd & 0x8F == 0x07 => S::SwitchedOn,
                S::ReadyToSwitchOn if cmd & 0x82 == 0 || cmd & 0x86 == 0x02 => S::SwitchOnDisabled,
                S::SwitchedOn if cmd & 0x8F == 0x0F => S::OperationEnabled,
                S::SwitchedOn if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
                S::SwitchedOn if cmd & 0x82 == 0 || cmd & 0x86 == 0x02 => S::SwitchOnDisabled,
                S::OperationEnabled if cmd & 0x8F == 0x07 => S::SwitchedOn,
                S::OperationEnabled if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
                S::OperationEnabled if cmd & 0x82 == 0 => S::SwitchOnDisabled,
                S::OperationEnabled if cmd & 0x86 == 0x02 => {
                    self.quick_stop_left = 3;
                    S::QuickStopActive
                }
                S::QuickStopActive if cmd & 0x82 == 0 => S::SwitchOnDisabled,
                S::QuickStopActive => {
                    self.quick_stop_left = self.quick_stop_left.saturating_sub(1);
                    if self.quick_stop_left == 0 {
                        S::SwitchOnDisabled
                    } else {
                        S::QuickStopActive
                    }
                }
                s => s,
            };
            let wanted = self.i(MODES_OF_OPERATION) as i8;
            if wanted != self.mode() {
                self.mode_delay += 1;
                if self.mode_delay >= 2 {
                    self.mode_delay = 0;
                    let _ = self
                        .od
                        .set(MODES_OF_OPERATION_DISPLAY, 0, &Value::Integer8(wanted));
                }
            }
            if self.state == S::OperationEnabled {
                match OpMode::from_code(self.mode()) {
                    Some(OpMode::ProfilePosition) => {
                        if rising(CW_BIT4) {
                            let t = self.i(TARGET_POSITION) as i32;
                            self.target = if cw & CW_RELATIVE != 0 {
                                self.target + t
                            } else {
                                t
                            };
                            self.ack = true;
                        } else if cw & CW_BIT4 == 0 {
                            self.ack = false;
                        }
                        let d = (self.target - self.position).clamp(-100, 100);
                        self.position += d;
                    }
                    Some(OpMode::ProfileVelocity) => {
                        let t = self.i(TARGET_VELOCITY) as i32;
                        self.velocity += (t - self.velocity).clamp(-10, 10);
                    }
                    Some(OpMode::Homing) => {
                        if rising(CW_BIT4) {
                            self.homed = false;
                            self.homing_error = false;
                            if self.i(HOMING_METHOD) == -1 {
                                self.homing_error = true;
                            } else {
                                self.homing_left = Some(5);
                            }
                        }
                        if let Some(left) = self.homing_left {
                            if left == 0 {
                                self.homing_left = None;
                                self.homed = true;
                                self.position = 0;
                                self.target = 0;
                            } else {
                                self.homing_left = Some(left - 1);
                            }
                        }
                    }
                    _ => {}
                }
            }
            self.last_cw = cw;
            self.publish();
        }

        fn publish(&mut self) {
            let sw = self.statusword();
            let _ = self.od.set(STATUSWORD, 0, &Value::Unsigned16(sw));
            let _ = self
                .od
                .set(POSITION_ACTUAL_VALUE, 0, &Value::Integer32(self.position));
            let _ = self
                .od
                .set(VELOCITY_ACTUAL_VALUE, 0, &Value::Integer32(self.velocity));
            let _ = self.od.set(
                ERROR_CODE,
                0,
                &Value::Unsigned16(if self.fault { 0x2310 } else { 0 }),
            );
        }
    }

    impl Node for Drive {
        fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
            if self.silent {
                return;
            }
            let raw = frame.id().as_raw();
            if raw == 0x600 + u32::from(NODE) {
                self.server.on_frame(frame, now, &mut self.od, out);
            } else if raw == 0x200 + u32::from(NODE) {
                // RPDO: controlword + target position, synchronous.
                let d = frame.data_bytes();
                if d.len() >= 6 {
                    let _ = self.od.set(
                        CONTROLWORD,
                        0,
                        &Value::Unsigned16(u16::from_le_bytes([d[0], d[1]])),
                    );
                    self.buffered = Some(i32::from_le_bytes([d[2], d[3], d[4], d[5]]));
                }
            } else if raw == u32::from(SYNC_COB_ID)
                && self.mode() == OpMode::CyclicSyncPosition.code()
                && let Some(p) = self.buffered.take()
                && self.state == DriveState::OperationEnabled
            {
                self.position = p;
            }
        }

        fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
            self.server.on_tick(now, &mut self.od, out);
            if now >= self.next {
                self.next = now + CYCLE;
                self.cycle();
                let sw = self.statusword();
                if self.tpdo && self.sent_sw != Some(sw) {
                    self.sent_sw = Some(sw);
                    out.push(
                        Frame::std(0x180 + u16::from(NODE), &sw.to_le_bytes()).expect("valid"),
                    );
                }
            }
        }

        fn next_deadline(&self) -> Option<Instant> {
            Some(match self.server.next_deadline() {
                Some(d) => d.min(self.next),
                None => self.next,
            })
        }
    }

    /// The master and the drive; every frame reaches the other side 200 µs after it is
    /// sent, in order.
    struct Net {
        master: DriveMaster,
        drive: Drive,
        now: Instant,
        wire: VecDeque<(Instant, bool, Frame)>,
        log: Vec<(Instant, String)>,
    }

    const LATENCY: Duration = Duration::from_micros(200);

    impl Net {
        fn new(config: AxisConfig) -> Self {
            let mut master = DriveMaster::new();
            master.add_axis(NODE, config).expect("valid node");
            Net {
                master,
                drive: Drive::new(),
                now: Instant::ZERO,
                wire: VecDeque::new(),
                log: Vec::new(),
            }
        }

        fn send(&mut self, out: &mut Outbox, from_master: bool) {
            for f in out.drain().collect::<Vec<_>>() {
                self.log.push((self.now, f.to_string()));
                self.wire.push_back((self.now + LATENCY, from_master, f));
                if from_master {
                    let mut more = Outbox::new();
                    self.master.on_sent(&f, self.now, &mut more);
                    self.send(&mut more, true);
                }
            }
        }

        fn with<R>(&mut self, f: impl FnOnce(&mut DriveMaster, Instant, &mut Outbox) -> R) -> R {
            let mut out = Outbox::new();
            let r = f(&mut self.master, self.now, &mut out);
            self.send(&mut out, true);
            r
        }

        /// Runs until the next event, at most `limit` of virtual time.
        fn event(&mut self, limit: Duration) -> Option<(Instant, DriveEvent)> {
            let end = self.now + limit;
            loop {
                if let Some(e) = self.master.poll_event() {
                    return Some(e);
                }
                let times = [
                    self.wire.front().map(|w| w.0),
                    self.master.next_deadline(),
                    self.drive.next_deadline(),
                ];
                let t = times.into_iter().flatten().min()?;
                if t > end {
                    self.now = end;
                    return None;
                }
                self.now = self.now.max(t);
                let mut out = Outbox::new();
                if self.wire.front().is_some_and(|w| w.0 <= self.now) {
                    let (_, from_master, f) = self.wire.pop_front().expect("present");
                    if from_master {
                        self.drive.on_frame(&f, self.now, &mut out);
                        self.send(&mut out, false);
                    } else {
                        self.master.on_frame(&f, self.now, &mut out);
                        self.send(&mut out, true);
                    }
                } else if self.master.next_deadline().is_some_and(|d| d <= self.now) {
                    self.master.on_tick(self.now, &mut out);
                    self.send(&mut out, true);
                } else {
                    self.drive.on_tick(self.now, &mut out);
                    self.send(&mut out, false);
                }
            }
        }

        /// The end of the running job.
        fn finished(&mut self) -> Result<Snapshot, DriveError> {
            loop {
                match self.event(Duration::from_secs(120)) {
                    Some((_, DriveEvent::Finished { result, .. })) => return result,
                    Some(_) => {}
                    None => panic!("no job ended"),
                }
            }
        }

        fn enable(&mut self) {
            self.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
                .expect("started");
            let s = self.finished().expect("enabled");
            assert_eq!(s.state(), Some(DriveState::OperationEnabled));
        }

        fn mode(&mut self, mode: OpMode) {
            self.with(|m, now, out| m.set_mode(NODE, mode, now, out))
                .expect("started");
            assert_eq!(self.finished().expect("switched").mode, Some(mode.code()));
        }

        /// The controlwords written by SDO, in order.
        fn controlwords(&self) -> Vec<u16> {
            self.log
                .iter()
                .filter_map(|(_, f)| {
                    let rest =
                        f.strip_prefix(&format!("{:03X}#2B4060", 0x600 + u16::from(NODE)))?;
                    u16::from_str_radix(&rest[2..6], 16)
                        .ok()
                        .map(u16::swap_bytes)
                })
                .collect()
        }
    }

    #[test]
    fn cia402_6041h_state_coding_decodes_every_state() {
        for s in DriveState::ALL {
            assert_eq!(DriveState::from_statusword(s.pattern().1), Some(s));
            // Bits outside the pattern do not change the state.
            assert_eq!(
                DriveState::from_statusword(s.pattern().1 | 0xFF90 & !s.pattern().0),
                Some(s)
            );
        }
        assert_eq!(DriveState::from_statusword(0x0001), None);
        assert_eq!(state_name(0x0637), "operation enabled");
    }

    #[test]
    fn cia402_pds_fsa_paths_reach_every_target() {
        // From every state but the fault ones, following toward() through the drive's
        // transitions reaches each target within four controlwords.
        for from in DriveState::ALL {
            for to in [
                PowerTarget::SwitchOnDisabled,
                PowerTarget::ReadyToSwitchOn,
                PowerTarget::SwitchedOn,
                PowerTarget::OperationEnabled,
            ] {
                let mut d = Drive::new();
                d.state = from;
                let mut steps = 0;
                loop {
                    match toward(d.state, to) {
                        Toward::Arrived => break,
                        Toward::Faulted => {
                            assert!(from.is_fault());
                            break;
                        }
                        Toward::Send(cw) => {
                            d.od.set(CONTROLWORD, 0, &Value::Unsigned16(cw))
                                .expect("exists");
                            for _ in 0..4 {
                                d.cycle();
                            }
                        }
                        Toward::Wait => d.cycle(),
                    }
                    steps += 1;
                    assert!(steps <= 4, "{from:?} -> {to:?}");
                }
                if !from.is_fault() {
                    assert_eq!(d.state, to.state(), "{from:?} -> {to:?}");
                }
            }
        }
    }

    #[test]
    fn cia402_pds_fsa_enable_walks_transitions_2_3_4() {
        let mut n = Net::new(AxisConfig::default());
        n.enable();
        assert_eq!(n.controlwords(), [0x0006, 0x0007, 0x000F]);
        // And back down: disable voltage (transition 9) in one step.
        n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchOnDisabled, now, out))
            .expect("started");
        assert_eq!(
            n.finished().expect("done").state(),
            Some(DriveState::SwitchOnDisabled)
        );
        assert_eq!(n.controlwords()[3..], [0x0000]);
        // Disable operation (5) from OPERATION ENABLED.
        n.enable();
        n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchedOn, now, out))
            .expect("started");
        assert_eq!(
            n.finished().expect("done").state(),
            Some(DriveState::SwitchedOn)
        );
        assert_eq!(n.controlwords().last(), Some(&0x0007));
    }

    #[test]
    fn cia402_pds_fsa_with_statusword_from_a_tpdo() {
        let mut n = Net::new(AxisConfig {
            statusword_pdo: Some(0x180 + u16::from(NODE)),
            ..AxisConfig::default()
        });
        n.drive.tpdo = true;
        n.enable();
        assert_eq!(n.controlwords(), [0x0006, 0x0007, 0x000F]);
        // Only the walk's reads of the statusword go by SDO (one per step), no polls.
        let reads = n
            .log
            .iter()
            .filter(|(_, f)| f.starts_with("603#4041600"))
            .count();
        assert_eq!(reads, 4);
    }

    #[test]
    fn cia402_quick_stop_then_fault_reset() {
        let mut n = Net::new(AxisConfig::default());
        n.enable();
        n.with(|m, now, out| m.quick_stop(NODE, now, out))
            .expect("started");
        let s = n.finished().expect("stopped");
        assert_eq!(s.state(), Some(DriveState::QuickStopActive));
        // 0x605A = 2 here: the drive goes to SWITCH ON DISABLED by itself; enable walks
        // from there again (transitions 12, then 2, 3, 4).
        n.enable();
        assert_eq!(
            n.controlwords()[3..],
            [0x0002, 0x000F, 0x0006, 0x0007, 0x000F]
        );

        // A fault while enabling: the job fails with 0x603F.
        n.drive.fault = true;
        n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchedOn, now, out))
            .expect("started");
        assert_eq!(
            n.finished(),
            Err(DriveError::Fault {
                error_code: Some(0x2310)
            })
        );
        // Fault reset while the fault is present: the drive stays in FAULT.
        n.with(|m, now, out| m.fault_reset(NODE, now, out))
            .expect("started");
        assert!(matches!(
            n.finished(),
            Err(DriveError::Timeout { waiting_for: "the fault to clear", statusword: Some(sw) }) if sw & 0x4F == 0x08
        ));
        n.drive.fault = false;
        n.with(|m, now, out| m.fault_reset(NODE, now, out))
            .expect("started");
        assert_eq!(
            n.finished().expect("reset").state(),
            Some(DriveState::SwitchOnDisabled)
        );
        // Bit 7 rose from 0: 0x0000 before each 0x0080.
        let cws = n.controlwords();
        assert_eq!(cws[cws.len() - 4..], [0x0000, 0x0080, 0x0000, 0x0080]);
        // A fault reset of a drive without fault writes nothing.
        let before = n.controlwords().len();
        n.with(|m, now, out| m.fault_reset(NODE, now, out))
            .expect("started");
        assert!(n.finished().is_ok());
        assert_eq!(n.controlwords().len(), before);
    }

    #[test]
    fn cia402_6061h_mode_switch_waits_for_the_display() {
        let mut n = Net::new(AxisConfig::default());
        let start = n.now;
        n.mode(OpMode::ProfilePosition);
        // The model shows the mode two cycles after the write: at least one poll more.
        assert!(n.now - start >= Duration::from_millis(2));
        let polls = n
            .log
            .iter()
            .filter(|(_, f)| f.starts_with("603#4061600"))
            .count();
        assert!(polls >= 2, "{polls}");
    }

    #[test]
    fn cia402_pp_set_point_handshake_and_target_reached() {
        let mut n = Net::new(AxisConfig::default());
        // Not enabled: a clear refusal before anything is written.
        let mv = PositionMove {
            target: 5000,
            wait: true,
            ..PositionMove::default()
        };
        n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
            .expect("started");
        assert!(matches!(n.finished(), Err(DriveError::NotEnabled { .. })));
        n.enable();
        n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
            .expect("started");
        assert_eq!(
            n.finished(),
            Err(DriveError::WrongMode {
                wanted: OpMode::ProfilePosition,
                shown: 0
            })
        );
        n.mode(OpMode::ProfilePosition);
        n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
            .expect("started");
        let s = n.finished().expect("moved");
        assert_eq!(s.position, Some(5000));
        assert_eq!(n.drive.position, 5000);
        // Bit 4 low, high (new set-point), low after the acknowledge.
        assert_eq!(n.controlwords()[3..], [0x000F, 0x001F, 0x000F]);
        // Relative, change immediately.
        let rel = PositionMove {
            target: -2000,
            relative: true,
            immediately: true,
            wait: true,
            ..PositionMove::default()
        };
        n.with(|m, now, out| m.profile_position(NODE, rel, now, out))
            .expect("started");
        assert_eq!(n.finished().expect("moved").position, Some(3000));
        assert_eq!(n.controlwords()[6..], [0x006F, 0x007F, 0x006F]);
    }

    #[test]
    fn cia402_pv_target_velocity_reached() {
        let mut n = Net::new(AxisConfig::default());
        n.enable();
        n.mode(OpMode::ProfileVelocity);
        let mv = VelocityMove {
            target: 300,
            wait: true,
            ..VelocityMove::default()
        };
        n.with(|m, now, out| m.profile_velocity(NODE, mv, now, out))
            .expect("started");
        assert_eq!(n.finished().expect("reached").velocity, Some(300));
    }

    #[test]
    fn cia402_hm_homing_attained_and_homing_error() {
        let mut n = Net::new(AxisConfig::default());
        n.enable();
        // Homing switches the mode itself.
        let h = Homing {
            method: 35,
            ..Homing::default()
        };
        n.with(|m, now, out| m.home(NODE, h, now, out))
            .expect("started");
        let s = n.finished().expect("homed");
        assert_eq!(s.position, Some(0));
        assert_eq!(n.drive.mode(), OpMode::Homing.code());
        assert_eq!(n.controlwords()[3..], [0x000F, 0x001F, 0x000F]);
        // Homing again: the previous run's "attained" does not end the new one early.
        n.drive.position = 77;
        n.with(|m, now, out| m.home(NODE, h, now, out))
            .expect("started");
        assert_eq!(n.finished().expect("homed").position, Some(0));
        let bad = Homing {
            method: -1,
            ..Homing::default()
        };
        n.with(|m, now, out| m.home(NODE, bad, now, out))
            .expect("started");
        assert!(matches!(n.finished(), Err(DriveError::HomingError { .. })));
    }

    #[test]
    fn cia402_csp_set_points_follow_each_sync() {
        let mut n = Net::new(AxisConfig::default());
        n.enable();
        n.mode(OpMode::CyclicSyncPosition);
        let cfg = StreamConfig {
            mode: CyclicMode::Position,
            rpdo: 0x200 + u16::from(NODE),
            with_controlword: true,
        };
        n.with(|m, now, out| m.start_stream(NODE, cfg, now, out))
            .expect("started");
        let s = n.finished().expect("streaming");
        assert_eq!(s.position, Some(1234));
        n.with(|m, now, _| {
            m.master_mut()
                .set_sync(Some((Duration::from_millis(1), 0)), now)
        })
        .expect("sync");
        n.master.move_cyclic(&[(NODE, 2234)], 10).expect("streams");
        let done = loop {
            match n.event(Duration::from_secs(1)) {
                Some((t, DriveEvent::TrajectoryDone { set_point, .. })) => break (t, set_point),
                Some(_) => {}
                None => panic!("no end"),
            }
        };
        assert_eq!(done.1, 2234);
        // Each SYNC is followed by the RPDO with the next set-point of the profile.
        let after: Vec<&str> = n
            .log
            .iter()
            .map(|(_, f)| f.as_str())
            .skip_while(|f| *f != "080#")
            .take(4)
            .collect();
        let traj = Trajectory {
            from: 1234,
            to: 2234,
            cycles: 10,
        };
        let rpdo = |k| {
            let mut d = vec![0x0F, 0x00];
            d.extend(traj.at(k).to_le_bytes());
            Frame::std(0x203, &d).expect("valid").to_string()
        };
        assert_eq!(after, ["080#", rpdo(1).as_str(), "080#", rpdo(2).as_str()]);
        // The drive applied the set-point at the SYNC after the one it came with.
        n.event(Duration::from_millis(3));
        assert_eq!(n.drive.position, 2234);
        // Moves are monotonic and symmetric.
        let pts: Vec<i32> = (0..=10).map(|k| traj.at(k)).collect();
        assert!(pts.windows(2).all(|w| w[0] <= w[1]), "{pts:?}");
        assert_eq!(traj.at(5), 1734);
    }

    #[test]
    fn cia402_a_silent_drive_times_out() {
        let mut n = Net::new(AxisConfig {
            step_timeout: Duration::from_millis(50),
            ..AxisConfig::default()
        });
        n.drive.silent = true;
        n.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
            .expect("started");
        // The SDO client's own timeout (1 s) ends the first read.
        assert!(matches!(
            n.finished(),
            Err(DriveError::Sdo { index: STATUSWORD, code, .. }) if code == AbortCode::TIMEOUT
        ));
        assert_eq!(
            n.with(|m, now, out| m.switch(99, PowerTarget::OperationEnabled, now, out)),
            Err(DriveError::NoAxis(99))
        );
    }

    #[test]
    fn a_second_job_on_a_busy_axis_is_refused() {
        let mut n = Net::new(AxisConfig::default());
        n.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
            .expect("started");
        assert_eq!(
            n.with(|m, now, out| m.set_mode(NODE, OpMode::Homing, now, out)),
            Err(DriveError::Busy(NODE))
        );
        assert!(n.finished().is_ok());
    }
}
