//! The factor group (CiA 402-2, objects 608Fh–6092h) and the per-mille torque units:
//! conversions between the objects' units and the SI units of [`crate::physics`].
//!
//! * position unit → increments: `× (encoder increments / motor revolutions) × (motor
//!   revolutions / shaft revolutions) / (feed / shaft revolutions)`, from 0x608F, 0x6091
//!   and 0x6092;
//! * increments → rad: `× 2π / (encoder increments per motor revolution)`;
//! * velocity units are position units per second, acceleration units position units per
//!   second²;
//! * torque: ‰ of 0x6076 motor rated torque; current: ‰ of 0x6075 motor rated current;
//! * 0x607E polarity: bit 7 negates position set-points and actual positions, bit 6
//!   velocity set-points and actual velocities.

use cantwin_canopen::od::ObjectDictionary;

use crate::index::*;

/// The conversions in force. Built whole ([`Units::increments`], [`Units::from_od`]) and
/// read through its methods, so the scale every conversion uses is worked out once: the
/// drive converts positions and velocities several times a loop cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    /// Encoder increments per motor revolution.
    increments_per_revolution: f64,
    /// Encoder increments per position unit.
    increments_per_unit: f64,
    /// Rated torque, N·m.
    rated_torque: f64,
    /// Rated current, A.
    rated_current: f64,
    /// −1 when 0x607E bit 7 is set.
    position_sign: f64,
    /// −1 when 0x607E bit 6 is set.
    velocity_sign: f64,
    /// rad per position unit, of the two ratios above.
    rad_per_unit: f64,
}

fn ratio(od: &ObjectDictionary, index: u16, fallback: f64) -> f64 {
    match (od.get_unsigned(index, 1), od.get_unsigned(index, 2)) {
        (Some(n), Some(d)) if n > 0 && d > 0 => n as f64 / d as f64,
        _ => fallback,
    }
}

impl Units {
    /// One position unit per increment of an encoder of `increments` per revolution, and
    /// the rated torque and current given.
    pub fn increments(increments: u32, rated_torque: f64, rated_current: f64) -> Units {
        Units::new(
            f64::from(increments.max(1)),
            1.0,
            rated_torque,
            rated_current,
            0,
        )
    }

    /// The units of an encoder of `increments_per_revolution`, `increments_per_unit`, the
    /// rated torque and current given, and 0x607E polarity `polarity`.
    fn new(
        increments_per_revolution: f64,
        increments_per_unit: f64,
        rated_torque: f64,
        rated_current: f64,
        polarity: u64,
    ) -> Units {
        Units {
            increments_per_revolution,
            increments_per_unit,
            rated_torque,
            rated_current,
            position_sign: if polarity & 0x80 != 0 { -1.0 } else { 1.0 },
            velocity_sign: if polarity & 0x40 != 0 { -1.0 } else { 1.0 },
            rad_per_unit: increments_per_unit / increments_per_revolution * core::f64::consts::TAU,
        }
    }

    /// Encoder increments per motor revolution.
    pub fn increments_per_revolution(&self) -> f64 {
        self.increments_per_revolution
    }

    /// Encoder increments per position unit.
    pub fn increments_per_unit(&self) -> f64 {
        self.increments_per_unit
    }

    /// Rated torque, N·m (0x6076).
    pub fn rated_torque(&self) -> f64 {
        self.rated_torque
    }

    /// Rated current, A (0x6075).
    pub fn rated_current(&self) -> f64 {
        self.rated_current
    }

    /// −1 when 0x607E bit 7 (position polarity) is set, else 1.
    pub fn position_sign(&self) -> f64 {
        self.position_sign
    }

    /// −1 when 0x607E bit 6 (velocity polarity) is set, else 1.
    pub fn velocity_sign(&self) -> f64 {
        self.velocity_sign
    }

    /// The units `od`'s factor group, rated values and polarity say; what the dictionary
    /// lacks keeps `fallback`'s.
    pub fn from_od(od: &ObjectDictionary, fallback: &Units) -> Units {
        let encoder = ratio(
            od,
            POSITION_ENCODER_RESOLUTION,
            fallback.increments_per_revolution,
        );
        let gear = ratio(od, GEAR_RATIO, 1.0);
        let feed = ratio(
            od,
            FEED_CONSTANT,
            encoder * gear / fallback.increments_per_unit,
        );
        let rated = |index: u16, fallback: f64| {
            od.get_unsigned(index, 0)
                .filter(|v| *v > 0)
                .map_or(fallback, |v| v as f64 / 1000.0)
        };
        let polarity = od.get_unsigned(POLARITY, 0).unwrap_or(0);
        Units::new(
            encoder,
            encoder * gear / feed,
            rated(MOTOR_RATED_TORQUE, fallback.rated_torque),
            rated(MOTOR_RATED_CURRENT, fallback.rated_current),
            polarity,
        )
    }

    /// rad per position unit (without polarity).
    pub fn rad_per_unit(&self) -> f64 {
        self.rad_per_unit
    }

    /// A position in position units as a motor angle, rad.
    pub fn position_to_rad(&self, units: f64) -> f64 {
        units * self.position_sign * self.rad_per_unit()
    }

    /// A motor angle as a position in position units.
    pub fn rad_to_position(&self, rad: f64) -> f64 {
        rad / self.rad_per_unit() * self.position_sign
    }

    /// A velocity in velocity units as a motor speed, rad/s.
    pub fn velocity_to_rad(&self, units: f64) -> f64 {
        units * self.velocity_sign * self.rad_per_unit()
    }

    /// A motor speed as a velocity in velocity units.
    pub fn rad_to_velocity(&self, rad: f64) -> f64 {
        rad / self.rad_per_unit() * self.velocity_sign
    }

    /// An acceleration in acceleration units as rad/s² (no polarity: it is an amount).
    pub fn acceleration_to_rad(&self, units: f64) -> f64 {
        units * self.rad_per_unit()
    }

    /// A torque in ‰ of rated torque as N·m.
    pub fn torque_to_nm(&self, permille: f64) -> f64 {
        permille * self.rated_torque / 1000.0
    }

    /// A torque in N·m as ‰ of rated torque.
    pub fn nm_to_torque(&self, nm: f64) -> f64 {
        nm / self.rated_torque * 1000.0
    }

    /// A current in A as ‰ of rated current.
    pub fn a_to_current(&self, a: f64) -> f64 {
        a / self.rated_current * 1000.0
    }
}

/// The largest double below one half, 0.5 − 2⁻⁵⁴.
const BELOW_HALF: f64 = f64::from_bits(0x3FDF_FFFF_FFFF_FFFF);

/// `v` moved so that truncating it (`as`, which saturates and takes NaN to 0) rounds it
/// to the nearest integer, halves away from zero, exactly as [`f64::round`] does: a
/// fraction of one half reaches the next integer only through the rounding of the sum
/// (ties to even lands on it), a smaller one never does, and from 2⁵² on, where every
/// double is an integer, the sum rounds back to `v`. Done this way because the drive
/// rounds a dozen actual values at every publication and `f64::round` is a library call
/// where the target has no rounding instruction.
fn nearest(v: f64) -> f64 {
    v + BELOW_HALF.copysign(v)
}

/// Rounds to the nearest integer and saturates to `i32` (an actual value object).
pub fn to_i32(v: f64) -> i32 {
    nearest(v) as i32
}

/// Rounds to the nearest integer and saturates to `i64` (a drive's monitor value).
pub fn to_i64(v: f64) -> i64 {
    nearest(v) as i64
}

/// Rounds to the nearest integer and saturates to `i16`.
pub fn to_i16(v: f64) -> i16 {
    nearest(v) as i16
}

/// Rounds to the nearest integer and saturates to `u32` (negative: 0).
pub fn to_u32(v: f64) -> u32 {
    nearest(v) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dictionary::{MotionDefaults, ServoObjects, servo_objects};
    use cantwin_canopen::od::{OdBuilder, Value};
    use std::sync::Arc;

    #[test]
    fn cia402_factor_group_position_units() {
        let spec = ServoObjects::all_modes(MotionDefaults::default());
        let desc = crate::objects::add(OdBuilder::new(), servo_objects(&spec))
            .build()
            .unwrap();
        let mut od = ObjectDictionary::new(Arc::new(desc), 1);
        let base = Units::increments(4096, 1.27, 3.0);
        let u = Units::from_od(&od, &base);
        assert_eq!(u.increments_per_unit(), 1.0);
        assert!((u.position_to_rad(4096.0) - core::f64::consts::TAU).abs() < 1e-12);
        // Gear 10:1 and a feed of 5 mm per shaft revolution, in µm: one unit is 1 µm, and
        // 5000 units are one shaft revolution, ten motor revolutions.
        od.set(GEAR_RATIO, 1, &Value::Unsigned32(10)).unwrap();
        od.set(FEED_CONSTANT, 1, &Value::Unsigned32(5000)).unwrap();
        let u = Units::from_od(&od, &base);
        assert!((u.position_to_rad(5000.0) - 10.0 * core::f64::consts::TAU).abs() < 1e-9);
        od.set(POLARITY, 0, &Value::Unsigned8(0xC0)).unwrap();
        let u = Units::from_od(&od, &base);
        assert!(u.position_to_rad(5000.0) < 0.0);
        assert!(u.rad_to_velocity(1.0) < 0.0);
        assert!((u.torque_to_nm(1000.0) - 1.27).abs() < 1e-12);
        assert_eq!(to_i16(1e9), i16::MAX);
    }

    #[test]
    fn actual_values_round_as_f64_round_and_saturate() {
        let cases = [
            0.0,
            -0.0,
            0.49999999999999994,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.4999,
            1e15 + 0.5,
            4_503_599_627_370_497.0,
            -9.3e18,
            9.3e18,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN_POSITIVE,
        ];
        for v in cases {
            let want = v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
            assert_eq!(to_i32(v), want, "{v}");
            let want = v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
            assert_eq!(to_i16(v), want, "{v}");
            let want = v.round().clamp(0.0, f64::from(u32::MAX)) as u32;
            assert_eq!(to_u32(v), want, "{v}");
            // `as` saturates i64 as it saturates the others.
            assert_eq!(to_i64(v), v.round() as i64, "{v}");
        }
        assert_eq!(to_i32(f64::NAN), 0);
        assert_eq!(to_i16(f64::NAN), 0);
        assert_eq!(to_u32(f64::NAN), 0);
        assert_eq!(to_i64(f64::NAN), 0);
        // Every quarter from -3 to 3 and the edges of i32.
        for k in -12..=12 {
            let v = f64::from(k) * 0.25;
            assert_eq!(to_i32(v), v.round() as i32, "{v}");
        }
        assert_eq!(to_i32(2_147_483_647.5), i32::MAX);
        assert_eq!(to_i32(-2_147_483_648.5), i32::MIN);
        assert_eq!(to_i32(-2_147_483_647.5), i32::MIN);
    }

    /// `to_i32`, `to_i16`, `to_u32` and `to_i64` of `v` are `f64::round` of it, saturated.
    fn rounds_as_f64_round(v: f64) -> Result<(), proptest::test_runner::TestCaseError> {
        let r = v.round();
        proptest::prop_assert_eq!(
            to_i32(v),
            r.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
        );
        proptest::prop_assert_eq!(
            to_i16(v),
            r.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
        );
        proptest::prop_assert_eq!(to_u32(v), r.clamp(0.0, f64::from(u32::MAX)) as u32);
        proptest::prop_assert_eq!(to_i64(v), r as i64);
        Ok(())
    }

    proptest::proptest! {
        #[test]
        fn actual_values_round_as_f64_round_for_any_double(bits in proptest::num::u64::ANY) {
            rounds_as_f64_round(f64::from_bits(bits))?;
        }

        #[test]
        fn actual_values_round_as_f64_round_near_halves(
            n in -(1i64 << 53)..(1i64 << 53),
            shift in 0i32..24,
            step in -2i64..=2,
        ) {
            // Halves, quarters … of every magnitude, and their neighbouring doubles.
            let exact = n as f64 * 2f64.powi(-shift);
            rounds_as_f64_round(f64::from_bits(exact.to_bits().wrapping_add_signed(step)))?;
            let small = (n % 100_000) as f64 * 2f64.powi(-shift);
            let v = f64::from_bits(small.to_bits().wrapping_add_signed(step));
            proptest::prop_assert_eq!(to_i32(v), v.round() as i32);
        }
    }
}
