//! The indices of the CiA 402 objects, and the profile number: what every module of the
//! profile names objects by. The objects themselves are built by [`crate::objects`].

/// 0x603F error code.
pub const ERROR_CODE: u16 = 0x603F;
/// 0x6040 controlword.
pub const CONTROLWORD: u16 = 0x6040;
/// 0x6041 statusword.
pub const STATUSWORD: u16 = 0x6041;
/// 0x6042 vl target velocity.
pub const VL_TARGET_VELOCITY: u16 = 0x6042;
/// 0x6043 vl velocity demand.
pub const VL_VELOCITY_DEMAND: u16 = 0x6043;
/// 0x6044 vl velocity actual value (DSP 402 V2.0: vl control effort).
pub const VL_VELOCITY_ACTUAL_VALUE: u16 = 0x6044;
/// 0x6046 vl velocity min max amount.
pub const VL_VELOCITY_MIN_MAX_AMOUNT: u16 = 0x6046;
/// 0x6047 vl velocity min max.
pub const VL_VELOCITY_MIN_MAX: u16 = 0x6047;
/// 0x6048 vl velocity acceleration.
pub const VL_VELOCITY_ACCELERATION: u16 = 0x6048;
/// 0x6049 vl velocity deceleration.
pub const VL_VELOCITY_DECELERATION: u16 = 0x6049;
/// 0x604A vl velocity quick stop.
pub const VL_VELOCITY_QUICK_STOP: u16 = 0x604A;
/// 0x605A quick stop option code.
pub const QUICK_STOP_OPTION_CODE: u16 = 0x605A;
/// 0x605B shutdown option code.
pub const SHUTDOWN_OPTION_CODE: u16 = 0x605B;
/// 0x605C disable operation option code.
pub const DISABLE_OPERATION_OPTION_CODE: u16 = 0x605C;
/// 0x605D halt option code.
pub const HALT_OPTION_CODE: u16 = 0x605D;
/// 0x605E fault reaction option code.
pub const FAULT_REACTION_OPTION_CODE: u16 = 0x605E;
/// 0x6060 modes of operation.
pub const MODES_OF_OPERATION: u16 = 0x6060;
/// 0x6061 modes of operation display.
pub const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
/// 0x6502 supported drive modes.
pub const SUPPORTED_DRIVE_MODES: u16 = 0x6502;

/// The CiA 402 profile number, 0x1000 bits 0–15.
pub const PROFILE_NUMBER: u32 = 402;
