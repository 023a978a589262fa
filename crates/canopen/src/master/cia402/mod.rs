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

mod driver;
pub use driver::DriveMaster;

#[cfg(test)]
mod tests;
