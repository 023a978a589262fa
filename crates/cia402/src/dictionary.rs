//! The objects of a servo drive (CiA 402-2: the factor group, profile position, profile
//! velocity, profile torque, homing, interpolated position and the cyclic synchronous
//! modes), beside the device control objects of [`crate::objects`]: [`servo_objects`] lists
//! them all, in index order, with the defaults of a [`MotionDefaults`].
//!
//! | index | object | type, access |
//! |---|---|---|
//! | 0x6062, 0x6063, 0x6064 | position demand value, position actual internal value, position actual value | INTEGER32 `ro`, mappable |
//! | 0x6065, 0x6066 | following error window, following error time out (ms) | UNSIGNED32, UNSIGNED16 `rw` |
//! | 0x6067, 0x6068 | position window, position window time (ms) | UNSIGNED32, UNSIGNED16 `rw` |
//! | 0x6069, 0x606B, 0x606C | velocity sensor actual value, velocity demand value, velocity actual value | INTEGER32 `ro`, mappable |
//! | 0x606D–0x6070 | velocity window, velocity window time, velocity threshold, velocity threshold time | UNSIGNED16 `rw` |
//! | 0x6071 | target torque | INTEGER16 `rw`, mappable |
//! | 0x6072, 0x6073 | max torque, max current (‰ of rated) | UNSIGNED16 `rw`, mappable |
//! | 0x6074 | torque demand | INTEGER16 `ro`, mappable |
//! | 0x6075, 0x6076 | motor rated current (mA), motor rated torque (mNm) | UNSIGNED32 `rw` |
//! | 0x6077, 0x6078 | torque actual value, current actual value | INTEGER16 `ro`, mappable |
//! | 0x6079 | DC link circuit voltage (mV) | UNSIGNED32 `ro`, mappable |
//! | 0x607A | target position | INTEGER32 `rw`, mappable |
//! | 0x607B, 0x607D | position range limit, software position limit: 1 min, 2 max | ARRAY of INTEGER32 `rw` |
//! | 0x607C | home offset | INTEGER32 `rw`, mappable |
//! | 0x607E | polarity: bit 7 position, bit 6 velocity | UNSIGNED8 `rw` |
//! | 0x607F, 0x6080 | max profile velocity, max motor speed (rpm) | UNSIGNED32 `rw`, mappable |
//! | 0x6081–0x6085 | profile velocity, end velocity, profile acceleration, profile deceleration, quick stop deceleration | UNSIGNED32 `rw`, mappable |
//! | 0x6086, 0x6088 | motion profile type, torque profile type (0: linear) | INTEGER16 `rw`, 0–0 |
//! | 0x6087 | torque slope (‰ per s) | UNSIGNED32 `rw`, mappable |
//! | 0x608F–0x6092 | position encoder resolution, velocity encoder resolution, gear ratio, feed constant | ARRAY of UNSIGNED32 `rw`, ≥ 1 |
//! | 0x6098 | homing method | INTEGER8 `rw`, mappable |
//! | 0x6099 | homing speeds: 1 search for switch, 2 search for zero | ARRAY of UNSIGNED32 `rw`, mappable |
//! | 0x609A | homing acceleration | UNSIGNED32 `rw`, mappable |
//! | 0x60B0, 0x60B1, 0x60B2 | position offset, velocity offset, torque offset | INTEGER32, INTEGER32, INTEGER16 `rw`, mappable |
//! | 0x60C0 | interpolation sub mode select (0: linear) | INTEGER16 `rw`, 0–0 |
//! | 0x60C1 | interpolation data record: 1 position set-point | ARRAY of INTEGER32 `rw`, mappable |
//! | 0x60C2 | interpolation time period: 1 ip time units, 2 ip time index (−6 … −3) | RECORD `rw` |
//! | 0x60F4 | following error actual value | INTEGER32 `ro`, mappable |
//! | 0x60FD | digital inputs | UNSIGNED32 `ro`, mappable |
//! | 0x60FF | target velocity | INTEGER32 `rw`, mappable |
//!
//! Units: position units are those of the factor group (CiA 402-2, factor group: one
//! position unit is `feed / (encoder increments per motor revolution × gear ratio)` of
//! a motor revolution, so with the defaults one position unit is one encoder increment);
//! velocities are position units per second, accelerations position units per second².

use cantwin_canopen::od::{Access, DataType, ObjectCode, SubObject, Value};

use crate::index::*;
use crate::modes::{Mode, SupportedModes};
use crate::objects::{self, Object, Objects, OptionCodeObjects, VlObjects};
use crate::options::OptionCodes;

/// The defaults of a servo drive's motion objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MotionDefaults {
    /// 0x608F sub 1: encoder increments per motor revolution (sub 2 is 1).
    pub encoder_increments: u32,
    /// 0x6092 sub 1: the feed per shaft revolution (sub 2 is 1); with 0x6091 at 1:1 and
    /// the feed equal to the encoder increments, a position unit is an increment.
    pub feed: u32,
    /// 0x6075 motor rated current, mA.
    pub rated_current_ma: u32,
    /// 0x6076 motor rated torque, mNm.
    pub rated_torque_mnm: u32,
    /// 0x6072 max torque, ‰ of 0x6076.
    pub max_torque: u16,
    /// 0x6073 max current, ‰ of 0x6075.
    pub max_current: u16,
    /// 0x6080 max motor speed, rpm.
    pub max_motor_speed: u32,
    /// 0x607D software position limit (min, max).
    pub software_limit: (i32, i32),
    /// 0x607F max profile velocity.
    pub max_profile_velocity: u32,
    /// 0x6081 profile velocity.
    pub profile_velocity: u32,
    /// 0x6083 profile acceleration.
    pub profile_acceleration: u32,
    /// 0x6084 profile deceleration.
    pub profile_deceleration: u32,
    /// 0x6085 quick stop deceleration.
    pub quick_stop_deceleration: u32,
    /// 0x6087 torque slope, ‰ per second.
    pub torque_slope: u32,
    /// 0x6065 following error window.
    pub following_error_window: u32,
    /// 0x6066 following error time out, ms.
    pub following_error_time_out: u16,
    /// 0x6067 position window.
    pub position_window: u32,
    /// 0x6068 position window time, ms.
    pub position_window_time: u16,
    /// 0x606D velocity window.
    pub velocity_window: u16,
    /// 0x606E velocity window time, ms.
    pub velocity_window_time: u16,
    /// 0x606F velocity threshold.
    pub velocity_threshold: u16,
    /// 0x6070 velocity threshold time, ms.
    pub velocity_threshold_time: u16,
    /// 0x6098 homing method.
    pub homing_method: i8,
    /// 0x6099 homing speeds (search for switch, search for zero).
    pub homing_speeds: (u32, u32),
    /// 0x609A homing acceleration.
    pub homing_acceleration: u32,
    /// 0x60C2 interpolation time period (units, index): `(1, -3)` is 1 ms.
    pub interpolation_period: (u8, i8),
}

impl Default for MotionDefaults {
    /// A 4096-increment encoder, 1 position unit = 1 increment, a 1.27 Nm / 3 A motor
    /// limited to 300 % of rated torque, 3000 rpm, profiles of 10 revolutions per
    /// second at 100 revolutions per second², a following error window of half a
    /// revolution for 10 ms, position window 10 increments for 1 ms, 1 ms interpolation
    /// period, homing method 35 (current position).
    fn default() -> Self {
        MotionDefaults {
            encoder_increments: 4096,
            feed: 4096,
            rated_current_ma: 3000,
            rated_torque_mnm: 1270,
            max_torque: 3000,
            max_current: 3000,
            max_motor_speed: 3000,
            software_limit: (0, 0),
            max_profile_velocity: 204_800,
            profile_velocity: 40_960,
            profile_acceleration: 409_600,
            profile_deceleration: 409_600,
            quick_stop_deceleration: 819_200,
            torque_slope: 10_000,
            following_error_window: 2048,
            following_error_time_out: 10,
            position_window: 10,
            position_window_time: 1,
            velocity_window: 100,
            velocity_window_time: 1,
            velocity_threshold: 100,
            velocity_threshold_time: 1,
            homing_method: 35,
            homing_speeds: (20_480, 4096),
            homing_acceleration: 409_600,
            interpolation_period: (1, -3),
        }
    }
}

/// A servo drive's objects: the device control objects of `modes` and every motion
/// object of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ServoObjects {
    /// The supported modes (0x6502; vl objects when it holds vl).
    pub modes: SupportedModes,
    /// 0x6060's default.
    pub mode: Option<Mode>,
    /// The motion objects' defaults.
    pub motion: MotionDefaults,
}

impl ServoObjects {
    /// Every mode CiA 402-2 defines, starting in no mode, with `motion`.
    pub fn all_modes(motion: MotionDefaults) -> ServoObjects {
        ServoObjects {
            modes: SupportedModes::of(&Mode::ALL),
            mode: None,
            motion,
        }
    }
}

fn var(index: u16, name: &str, ty: DataType, access: Access, v: Value, mappable: bool) -> Object {
    let mut sub = SubObject::new(name, ty, access).default(v);
    if mappable {
        sub = sub.mappable();
    }
    Object {
        index,
        name: name.into(),
        code: ObjectCode::Var,
        subs: vec![(0, sub)],
    }
}

fn i32_ro(index: u16, name: &str) -> Object {
    var(
        index,
        name,
        DataType::Integer32,
        Access::Ro,
        Value::Integer32(0),
        true,
    )
}

fn u32_rw(index: u16, name: &str, v: u32) -> Object {
    var(
        index,
        name,
        DataType::Unsigned32,
        Access::Rw,
        Value::Unsigned32(v),
        true,
    )
}

fn u16_rw(index: u16, name: &str, v: u16) -> Object {
    var(
        index,
        name,
        DataType::Unsigned16,
        Access::Rw,
        Value::Unsigned16(v),
        true,
    )
}

fn pair_u32(index: u16, name: &str, names: [&str; 2], v: (u32, u32)) -> Object {
    // A zero would divide by zero in the factor group: both start at 1.
    let sub = |n: &str, x: u32| {
        SubObject::new(n, DataType::Unsigned32, Access::Rw)
            .default(Value::Unsigned32(x))
            .limits(Value::Unsigned32(1), Value::Unsigned32(u32::MAX))
    };
    Object {
        index,
        name: name.into(),
        code: ObjectCode::Array,
        subs: vec![(1, sub(names[0], v.0)), (2, sub(names[1], v.1))],
    }
}

fn pair_i32(index: u16, name: &str, names: [&str; 2], v: (i32, i32)) -> Object {
    let sub = |n: &str, x: i32| {
        SubObject::new(n, DataType::Integer32, Access::Rw)
            .default(Value::Integer32(x))
            .mappable()
    };
    Object {
        index,
        name: name.into(),
        code: ObjectCode::Array,
        subs: vec![(1, sub(names[0], v.0)), (2, sub(names[1], v.1))],
    }
}

fn linear_only(index: u16, name: &str) -> Object {
    Object {
        index,
        name: name.into(),
        code: ObjectCode::Var,
        subs: vec![(
            0,
            SubObject::new(name, DataType::Integer16, Access::Rw)
                .default(Value::Integer16(0))
                .limits(Value::Integer16(0), Value::Integer16(0)),
        )],
    }
}

/// The motion objects of the [module table](self), in index order.
pub fn motion_objects(m: &MotionDefaults) -> Vec<Object> {
    use DataType::*;
    let mut out = vec![
        i32_ro(POSITION_DEMAND_VALUE, "Position demand value"),
        i32_ro(
            POSITION_ACTUAL_INTERNAL_VALUE,
            "Position actual internal value",
        ),
        i32_ro(POSITION_ACTUAL_VALUE, "Position actual value"),
        u32_rw(
            FOLLOWING_ERROR_WINDOW,
            "Following error window",
            m.following_error_window,
        ),
        u16_rw(
            FOLLOWING_ERROR_TIME_OUT,
            "Following error time out",
            m.following_error_time_out,
        ),
        u32_rw(POSITION_WINDOW, "Position window", m.position_window),
        u16_rw(
            POSITION_WINDOW_TIME,
            "Position window time",
            m.position_window_time,
        ),
        i32_ro(VELOCITY_SENSOR_ACTUAL_VALUE, "Velocity sensor actual value"),
        i32_ro(VELOCITY_DEMAND_VALUE, "Velocity demand value"),
        i32_ro(VELOCITY_ACTUAL_VALUE, "Velocity actual value"),
        u16_rw(VELOCITY_WINDOW, "Velocity window", m.velocity_window),
        u16_rw(
            VELOCITY_WINDOW_TIME,
            "Velocity window time",
            m.velocity_window_time,
        ),
        u16_rw(
            VELOCITY_THRESHOLD,
            "Velocity threshold",
            m.velocity_threshold,
        ),
        u16_rw(
            VELOCITY_THRESHOLD_TIME,
            "Velocity threshold time",
            m.velocity_threshold_time,
        ),
        var(
            TARGET_TORQUE,
            "Target torque",
            Integer16,
            Access::Rw,
            Value::Integer16(0),
            true,
        ),
        u16_rw(MAX_TORQUE, "Max torque", m.max_torque),
        u16_rw(MAX_CURRENT, "Max current", m.max_current),
        var(
            TORQUE_DEMAND,
            "Torque demand",
            Integer16,
            Access::Ro,
            Value::Integer16(0),
            true,
        ),
        u32_rw(
            MOTOR_RATED_CURRENT,
            "Motor rated current",
            m.rated_current_ma,
        ),
        u32_rw(MOTOR_RATED_TORQUE, "Motor rated torque", m.rated_torque_mnm),
        var(
            TORQUE_ACTUAL_VALUE,
            "Torque actual value",
            Integer16,
            Access::Ro,
            Value::Integer16(0),
            true,
        ),
        var(
            CURRENT_ACTUAL_VALUE,
            "Current actual value",
            Integer16,
            Access::Ro,
            Value::Integer16(0),
            true,
        ),
        var(
            DC_LINK_CIRCUIT_VOLTAGE,
            "DC link circuit voltage",
            Unsigned32,
            Access::Ro,
            Value::Unsigned32(0),
            true,
        ),
        var(
            TARGET_POSITION,
            "Target position",
            Integer32,
            Access::Rw,
            Value::Integer32(0),
            true,
        ),
        pair_i32(
            POSITION_RANGE_LIMIT,
            "Position range limit",
            ["Min position range limit", "Max position range limit"],
            (i32::MIN, i32::MAX),
        ),
        var(
            HOME_OFFSET,
            "Home offset",
            Integer32,
            Access::Rw,
            Value::Integer32(0),
            true,
        ),
        pair_i32(
            SOFTWARE_POSITION_LIMIT,
            "Software position limit",
            ["Min position limit", "Max position limit"],
            m.software_limit,
        ),
        var(
            POLARITY,
            "Polarity",
            Unsigned8,
            Access::Rw,
            Value::Unsigned8(0),
            false,
        ),
        u32_rw(
            MAX_PROFILE_VELOCITY,
            "Max profile velocity",
            m.max_profile_velocity,
        ),
        u32_rw(MAX_MOTOR_SPEED, "Max motor speed", m.max_motor_speed),
        u32_rw(PROFILE_VELOCITY, "Profile velocity", m.profile_velocity),
        u32_rw(END_VELOCITY, "End velocity", 0),
        u32_rw(
            PROFILE_ACCELERATION,
            "Profile acceleration",
            m.profile_acceleration,
        ),
        u32_rw(
            PROFILE_DECELERATION,
            "Profile deceleration",
            m.profile_deceleration,
        ),
        u32_rw(
            QUICK_STOP_DECELERATION,
            "Quick stop deceleration",
            m.quick_stop_deceleration,
        ),
        linear_only(MOTION_PROFILE_TYPE, "Motion profile type"),
        u32_rw(TORQUE_SLOPE, "Torque slope", m.torque_slope),
        linear_only(TORQUE_PROFILE_TYPE, "Torque profile type"),
        pair_u32(
            POSITION_ENCODER_RESOLUTION,
            "Position encoder resolution",
            ["Encoder increments", "Motor revolutions"],
            (m.encoder_increments, 1),
        ),
        pair_u32(
            VELOCITY_ENCODER_RESOLUTION,
            "Velocity encoder resolution",
            [
                "Encoder increments per second",
                "Motor revolutions per second",
            ],
            (m.encoder_increments, 1),
        ),
        pair_u32(
            GEAR_RATIO,
            "Gear ratio",
            ["Motor revolutions", "Shaft revolutions"],
            (1, 1),
        ),
        pair_u32(
            FEED_CONSTANT,
            "Feed constant",
            ["Feed", "Shaft revolutions"],
            (m.feed, 1),
        ),
        var(
            HOMING_METHOD,
            "Homing method",
            Integer8,
            Access::Rw,
            Value::Integer8(m.homing_method),
            true,
        ),
    ];
    let speed = |n: &str, v: u32| SubObject::unsigned32(n, Access::Rw, v).mappable();
    out.push(Object {
        index: HOMING_SPEEDS,
        name: "Homing speeds".into(),
        code: ObjectCode::Array,
        subs: vec![
            (
                1,
                speed("Speed during search for switch", m.homing_speeds.0),
            ),
            (2, speed("Speed during search for zero", m.homing_speeds.1)),
        ],
    });
    out.extend([
        u32_rw(
            HOMING_ACCELERATION,
            "Homing acceleration",
            m.homing_acceleration,
        ),
        var(
            POSITION_OFFSET,
            "Position offset",
            Integer32,
            Access::Rw,
            Value::Integer32(0),
            true,
        ),
        var(
            VELOCITY_OFFSET,
            "Velocity offset",
            Integer32,
            Access::Rw,
            Value::Integer32(0),
            true,
        ),
        var(
            TORQUE_OFFSET,
            "Torque offset",
            Integer16,
            Access::Rw,
            Value::Integer16(0),
            true,
        ),
        linear_only(
            INTERPOLATION_SUB_MODE_SELECT,
            "Interpolation sub mode select",
        ),
        Object {
            index: INTERPOLATION_DATA_RECORD,
            name: "Interpolation data record".into(),
            code: ObjectCode::Array,
            subs: vec![(
                1,
                SubObject::new("Interpolation data record 1", Integer32, Access::Rw)
                    .default(Value::Integer32(0))
                    .mappable(),
            )],
        },
        Object {
            index: INTERPOLATION_TIME_PERIOD,
            name: "Interpolation time period".into(),
            code: ObjectCode::Record,
            subs: vec![
                (
                    1,
                    SubObject::new("Interpolation time period value", Unsigned8, Access::Rw)
                        .default(Value::Unsigned8(m.interpolation_period.0)),
                ),
                (
                    2,
                    // CiA 402-2, object 60C2h: the index is −128 … 63; a drive supports
                    // periods from 1 µs (10^-6 s) to 255 ms (10^-3 s × 255).
                    SubObject::new("Interpolation time index", Integer8, Access::Rw)
                        .default(Value::Integer8(m.interpolation_period.1))
                        .limits(Value::Integer8(-6), Value::Integer8(-3)),
                ),
            ],
        },
        i32_ro(FOLLOWING_ERROR_ACTUAL_VALUE, "Following error actual value"),
        var(
            DIGITAL_INPUTS,
            "Digital inputs",
            Unsigned32,
            Access::Ro,
            Value::Unsigned32(0),
            true,
        ),
        var(
            TARGET_VELOCITY,
            "Target velocity",
            Integer32,
            Access::Rw,
            Value::Integer32(0),
            true,
        ),
    ]);
    out
}

/// The vl objects beside those of [`crate::objects`] (CiA 402-2, velocity mode): 0x6045
/// and the factors and references 0x604B–0x604F, which a vl drive uses to scale its
/// set-points (a servo twin keeps them at their neutral values: factors 1/1).
fn vl_objects() -> Vec<Object> {
    use DataType::*;
    let pair = |index: u16, name: &str, ty: DataType, one: Value| Object {
        index,
        name: name.into(),
        code: ObjectCode::Array,
        subs: vec![
            (
                1,
                SubObject::new("Numerator", ty, Access::Rw)
                    .default(one.clone())
                    .mappable(),
            ),
            (
                2,
                SubObject::new("Denominator", ty, Access::Rw)
                    .default(one)
                    .mappable(),
            ),
        ],
    };
    vec![
        var(
            VL_MANIPULATED_VELOCITY,
            "vl velocity manipulated value",
            Integer16,
            Access::Ro,
            Value::Integer16(0),
            true,
        ),
        pair(
            VL_SET_POINT_FACTOR,
            "vl set-point factor",
            Integer16,
            Value::Integer16(1),
        ),
        pair(
            VL_DIMENSION_FACTOR,
            "vl dimension factor",
            Integer32,
            Value::Integer32(1),
        ),
        var(
            VL_POLE_NUMBER,
            "vl pole number",
            Unsigned8,
            Access::Rw,
            Value::Unsigned8(4),
            false,
        ),
        var(
            VL_VELOCITY_REFERENCE,
            "vl velocity reference",
            Unsigned32,
            Access::Rw,
            Value::Unsigned32(3000),
            true,
        ),
        var(
            VL_RAMP_FUNCTION_TIME,
            "vl ramp function time",
            Unsigned32,
            Access::Rw,
            Value::Unsigned32(1000),
            true,
        ),
    ]
}

/// Every object of a servo drive described by `spec`: the device control objects (with
/// 0x603F, all five option codes, 0x6502, the vl objects when vl is supported) and the
/// motion objects, in index order.
pub fn servo_objects(spec: &ServoObjects) -> Vec<Object> {
    let control = Objects {
        error_code: true,
        modes: spec.modes,
        supported_drive_modes: true,
        mode: spec.mode,
        option_codes: OptionCodeObjects::all(OptionCodes::STANDARD),
        vl: spec.modes.contains(Mode::Velocity).then(VlObjects::default),
        ..Objects::minimal()
    };
    let mut all = objects::objects(&control);
    if control.vl.is_some() {
        all.extend(vl_objects());
    }
    all.extend(motion_objects(&spec.motion));
    all.sort_by_key(|o| o.index);
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::od::{ObjectDictionary, OdBuilder};
    use std::sync::Arc;

    #[test]
    fn cia402_servo_objects_cover_the_profile_objects() {
        let spec = ServoObjects::all_modes(MotionDefaults::default());
        let desc = objects::add(OdBuilder::new(), servo_objects(&spec))
            .build()
            .unwrap();
        let od = ObjectDictionary::new(Arc::new(desc), 1);
        let mut need: Vec<u16> = vec![0x603F, 0x6040, 0x6041];
        need.extend(0x6042..=0x6044);
        need.extend([0x6046, 0x6047, 0x6048, 0x6049, 0x604A]);
        need.extend(0x6045..=0x604F);
        need.extend(0x605A..=0x605E);
        need.extend(0x6060..=0x6069);
        need.extend(0x606B..=0x6087);
        need.extend(0x608F..=0x6092);
        need.extend(0x6098..=0x609A);
        need.extend(0x60B0..=0x60B2);
        need.extend([0x60C1, 0x60C2, 0x60F4, 0x60FD, 0x60FF, 0x6502]);
        for index in need {
            assert!(od.description().object(index).is_some(), "{index:#06x}");
        }
        assert_eq!(
            od.get(SUPPORTED_DRIVE_MODES, 0),
            Ok(Value::Unsigned32(0x03EF))
        );
        assert_eq!(
            od.get(POSITION_ENCODER_RESOLUTION, 1),
            Ok(Value::Unsigned32(4096))
        );
        assert_eq!(
            od.get(INTERPOLATION_TIME_PERIOD, 2),
            Ok(Value::Integer8(-3))
        );
    }
}
