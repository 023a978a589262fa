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

/// The conversions in force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    /// Encoder increments per motor revolution.
    pub increments_per_revolution: f64,
    /// Encoder increments per position unit.
    pub increments_per_unit: f64,
    /// Rated torque, N·m.
    pub rated_torque: f64,
    /// Rated current, A.
    pub rated_current: f64,
    /// −1 when 0x607E bit 7 is set.
    pub position_sign: f64,
    /// −1 when 0x607E bit 6 is set.
    pub velocity_sign: f64,
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
        Units {
            increments_per_revolution: f64::from(increments.max(1)),
            increments_per_unit: 1.0,
            rated_torque,
            rated_current,
            position_sign: 1.0,
            velocity_sign: 1.0,
        }
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
        Units {
            increments_per_revolution: encoder,
            increments_per_unit: encoder * gear / feed,
            rated_torque: rated(MOTOR_RATED_TORQUE, fallback.rated_torque),
            rated_current: rated(MOTOR_RATED_CURRENT, fallback.rated_current),
            position_sign: if polarity & 0x80 != 0 { -1.0 } else { 1.0 },
            velocity_sign: if polarity & 0x40 != 0 { -1.0 } else { 1.0 },
        }
    }

    /// rad per position unit (without polarity).
    pub fn rad_per_unit(&self) -> f64 {
        self.increments_per_unit / self.increments_per_revolution * core::f64::consts::TAU
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

/// Rounds to the nearest integer and saturates to `i32` (an actual value object).
pub fn to_i32(v: f64) -> i32 {
    v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

/// Rounds to the nearest integer and saturates to `i16`.
pub fn to_i16(v: f64) -> i16 {
    v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
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
        assert_eq!(u.increments_per_unit, 1.0);
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
}
