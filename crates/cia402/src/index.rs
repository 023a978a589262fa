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

/// 0x6045 vl velocity manipulated value (vl manipulated velocity).
pub const VL_MANIPULATED_VELOCITY: u16 = 0x6045;
/// 0x604B vl set-point factor: 1 numerator, 2 denominator.
pub const VL_SET_POINT_FACTOR: u16 = 0x604B;
/// 0x604C vl dimension factor: 1 numerator, 2 denominator.
pub const VL_DIMENSION_FACTOR: u16 = 0x604C;
/// 0x604D vl pole number.
pub const VL_POLE_NUMBER: u16 = 0x604D;
/// 0x604E vl velocity reference.
pub const VL_VELOCITY_REFERENCE: u16 = 0x604E;
/// 0x604F vl ramp function time.
pub const VL_RAMP_FUNCTION_TIME: u16 = 0x604F;
/// 0x6062 position demand value (position units).
pub const POSITION_DEMAND_VALUE: u16 = 0x6062;
/// 0x6063 position actual internal value (increments).
pub const POSITION_ACTUAL_INTERNAL_VALUE: u16 = 0x6063;
/// 0x6064 position actual value (position units).
pub const POSITION_ACTUAL_VALUE: u16 = 0x6064;
/// 0x6065 following error window.
pub const FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
/// 0x6066 following error time out (ms).
pub const FOLLOWING_ERROR_TIME_OUT: u16 = 0x6066;
/// 0x6067 position window.
pub const POSITION_WINDOW: u16 = 0x6067;
/// 0x6068 position window time (ms).
pub const POSITION_WINDOW_TIME: u16 = 0x6068;
/// 0x6069 velocity sensor actual value (increments per second).
pub const VELOCITY_SENSOR_ACTUAL_VALUE: u16 = 0x6069;
/// 0x606B velocity demand value.
pub const VELOCITY_DEMAND_VALUE: u16 = 0x606B;
/// 0x606C velocity actual value.
pub const VELOCITY_ACTUAL_VALUE: u16 = 0x606C;
/// 0x606D velocity window.
pub const VELOCITY_WINDOW: u16 = 0x606D;
/// 0x606E velocity window time (ms).
pub const VELOCITY_WINDOW_TIME: u16 = 0x606E;
/// 0x606F velocity threshold.
pub const VELOCITY_THRESHOLD: u16 = 0x606F;
/// 0x6070 velocity threshold time (ms).
pub const VELOCITY_THRESHOLD_TIME: u16 = 0x6070;
/// 0x6071 target torque (per mille of 0x6076).
pub const TARGET_TORQUE: u16 = 0x6071;
/// 0x6072 max torque (per mille of 0x6076).
pub const MAX_TORQUE: u16 = 0x6072;
/// 0x6073 max current (per mille of 0x6075).
pub const MAX_CURRENT: u16 = 0x6073;
/// 0x6074 torque demand (per mille of 0x6076).
pub const TORQUE_DEMAND: u16 = 0x6074;
/// 0x6075 motor rated current (mA).
pub const MOTOR_RATED_CURRENT: u16 = 0x6075;
/// 0x6076 motor rated torque (mNm).
pub const MOTOR_RATED_TORQUE: u16 = 0x6076;
/// 0x6077 torque actual value (per mille of 0x6076).
pub const TORQUE_ACTUAL_VALUE: u16 = 0x6077;
/// 0x6078 current actual value (per mille of 0x6075).
pub const CURRENT_ACTUAL_VALUE: u16 = 0x6078;
/// 0x6079 DC link circuit voltage (mV).
pub const DC_LINK_CIRCUIT_VOLTAGE: u16 = 0x6079;
/// 0x607A target position.
pub const TARGET_POSITION: u16 = 0x607A;
/// 0x607B position range limit: 1 min, 2 max.
pub const POSITION_RANGE_LIMIT: u16 = 0x607B;
/// 0x607C home offset.
pub const HOME_OFFSET: u16 = 0x607C;
/// 0x607D software position limit: 1 min, 2 max.
pub const SOFTWARE_POSITION_LIMIT: u16 = 0x607D;
/// 0x607E polarity.
pub const POLARITY: u16 = 0x607E;
/// 0x607F max profile velocity.
pub const MAX_PROFILE_VELOCITY: u16 = 0x607F;
/// 0x6080 max motor speed (rpm).
pub const MAX_MOTOR_SPEED: u16 = 0x6080;
/// 0x6081 profile velocity.
pub const PROFILE_VELOCITY: u16 = 0x6081;
/// 0x6082 end velocity.
pub const END_VELOCITY: u16 = 0x6082;
/// 0x6083 profile acceleration.
pub const PROFILE_ACCELERATION: u16 = 0x6083;
/// 0x6084 profile deceleration.
pub const PROFILE_DECELERATION: u16 = 0x6084;
/// 0x6085 quick stop deceleration.
pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
/// 0x6086 motion profile type.
pub const MOTION_PROFILE_TYPE: u16 = 0x6086;
/// 0x6087 torque slope (per mille per second).
pub const TORQUE_SLOPE: u16 = 0x6087;
/// 0x6088 torque profile type.
pub const TORQUE_PROFILE_TYPE: u16 = 0x6088;
/// 0x608F position encoder resolution: 1 encoder increments, 2 motor revolutions.
pub const POSITION_ENCODER_RESOLUTION: u16 = 0x608F;
/// 0x6090 velocity encoder resolution: 1 encoder increments per second, 2 motor
/// revolutions per second.
pub const VELOCITY_ENCODER_RESOLUTION: u16 = 0x6090;
/// 0x6091 gear ratio: 1 motor revolutions, 2 shaft revolutions.
pub const GEAR_RATIO: u16 = 0x6091;
/// 0x6092 feed constant: 1 feed, 2 shaft revolutions.
pub const FEED_CONSTANT: u16 = 0x6092;
/// 0x6098 homing method.
pub const HOMING_METHOD: u16 = 0x6098;
/// 0x6099 homing speeds: 1 during search for switch, 2 during search for zero.
pub const HOMING_SPEEDS: u16 = 0x6099;
/// 0x609A homing acceleration.
pub const HOMING_ACCELERATION: u16 = 0x609A;
/// 0x60B0 position offset.
pub const POSITION_OFFSET: u16 = 0x60B0;
/// 0x60B1 velocity offset.
pub const VELOCITY_OFFSET: u16 = 0x60B1;
/// 0x60B2 torque offset.
pub const TORQUE_OFFSET: u16 = 0x60B2;
/// 0x60C0 interpolation sub mode select.
pub const INTERPOLATION_SUB_MODE_SELECT: u16 = 0x60C0;
/// 0x60C1 interpolation data record: sub 1, the position set-point.
pub const INTERPOLATION_DATA_RECORD: u16 = 0x60C1;
/// 0x60C2 interpolation time period: 1 ip time units, 2 ip time index (10^index s).
pub const INTERPOLATION_TIME_PERIOD: u16 = 0x60C2;
/// 0x60F4 following error actual value.
pub const FOLLOWING_ERROR_ACTUAL_VALUE: u16 = 0x60F4;
/// 0x60FD digital inputs: bit 0 negative limit switch, 1 positive limit switch, 2 home
/// switch, 3 interlock.
pub const DIGITAL_INPUTS: u16 = 0x60FD;
/// 0x60FF target velocity.
pub const TARGET_VELOCITY: u16 = 0x60FF;
