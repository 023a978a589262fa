//! Velocity mode (vl, CiA 402-2 velocity mode): the target velocity 0x6042 goes through the
//! velocity limit function (0x6046 min max amount, 0x6047 min max) and the ramp function
//! (0x6048 acceleration, 0x6049 deceleration, 0x604A quick stop) to the velocity demand
//! 0x6043, in the way the power state says:
//!
//! | [`Motion`] | velocity demand |
//! |---|---|
//! | `Operate` | ramps to the limited target (acceleration while its amount rises, deceleration while it falls, through zero when the sign changes) |
//! | `Stop` on the slow down ramp (halt 0x605D = 1, quick stop 1/5, disable operation or shutdown option 1, fault reaction 1) | ramps to 0 with 0x6049 |
//! | `Stop` on the quick stop ramp (halt 2, quick stop 2/6, fault reaction 2) | ramps to 0 with 0x604A |
//! | `Stop` at the current or voltage limit | 0 at once: the drive's torque or DC link limits how fast the motor follows |
//! | `Disabled` | 0: the drive function is off and the motor coasts |
//!
//! With [`VlParams::rfg_bits`] the vl controlword bits 4–6 act as CiA 402-2 defines them in
//! `Operate`: bit 4 (rfg enable) 0 sets the demand to 0, bit 5 (rfg unlock) 0 holds the
//! ramp output where it is, bit 6 (rfg use ref) 0 ramps to 0 instead of the target. A drive
//! whose manual does not list them leaves them unused.
//!
//! The ramp is stepped by the caller with the time since the last step; the demand is kept
//! exact between steps and rounded for 0x6043.

use cantwin_can::Duration;
use cantwin_canopen::od::ObjectDictionary;

use crate::controlword::{VL_RFG_ENABLE, VL_RFG_UNLOCK, VL_RFG_USE_REF};
use crate::index;
use crate::options::StopRamp;
use crate::state::{Motion, PowerStage};

/// A vl ramp (0x6048, 0x6049, 0x604A): the velocity changes by `delta_speed` in
/// `delta_time` seconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Ramp {
    /// Sub-index 1, delta speed, in the velocity's units.
    pub delta_speed: u32,
    /// Sub-index 2, delta time, in seconds (0 is read as 1).
    pub delta_time: u16,
}

impl Ramp {
    /// A ramp of `delta_speed` per `delta_time` seconds.
    pub const fn new(delta_speed: u32, delta_time: u16) -> Ramp {
        Ramp {
            delta_speed,
            delta_time,
        }
    }

    /// The rate in velocity units per second.
    pub fn per_second(self) -> f64 {
        f64::from(self.delta_speed) / f64::from(self.delta_time.max(1))
    }
}

impl Default for Ramp {
    /// 1000 per second (CiA 402-2 leaves the default to the manufacturer).
    fn default() -> Self {
        Ramp::new(1000, 1)
    }
}

/// 0x6046 vl velocity min max amount: the amount of a non-zero target is kept between
/// `min` and `max`, whatever its sign.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MinMaxAmount {
    /// Sub-index 1, vl velocity min amount.
    pub min: u32,
    /// Sub-index 2, vl velocity max amount.
    pub max: u32,
}

impl Default for MinMaxAmount {
    /// 0 and 32767: no limit within 0x6042's range.
    fn default() -> Self {
        MinMaxAmount {
            min: 0,
            max: i16::MAX as u32,
        }
    }
}

/// 0x6047 vl velocity min max: the amounts of 0x6046, for each direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MinMax {
    /// Sub-index 1, min amount of a positive target.
    pub min_pos: u32,
    /// Sub-index 2, max amount of a positive target.
    pub max_pos: u32,
    /// Sub-index 3, min amount of a negative target.
    pub min_neg: u32,
    /// Sub-index 4, max amount of a negative target.
    pub max_neg: u32,
}

impl Default for MinMax {
    /// 0 and 32767 both ways: no limit within 0x6042's range.
    fn default() -> Self {
        MinMax {
            min_pos: 0,
            max_pos: i16::MAX as u32,
            min_neg: 0,
            max_neg: i16::MAX as u32,
        }
    }
}

/// What velocity mode follows: the limits and ramps, as plain values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VlParams {
    /// 0x6046.
    pub min_max_amount: MinMaxAmount,
    /// 0x6047, where the drive has it.
    pub min_max: Option<MinMax>,
    /// 0x6048.
    pub acceleration: Ramp,
    /// 0x6049, also the slow down ramp.
    pub deceleration: Ramp,
    /// 0x604A, the quick stop ramp.
    pub quick_stop: Ramp,
    /// Whether controlword bits 4–6 (rfg enable, rfg unlock, rfg use ref) act.
    pub rfg_bits: bool,
}

impl Default for VlParams {
    /// No limits, ramps of [`Ramp::default`], the rfg bits acting.
    fn default() -> Self {
        VlParams {
            min_max_amount: MinMaxAmount::default(),
            min_max: None,
            acceleration: Ramp::default(),
            deceleration: Ramp::default(),
            quick_stop: Ramp::default(),
            rfg_bits: true,
        }
    }
}

fn unsigned(od: &ObjectDictionary, index: u16, sub: u8) -> Option<u32> {
    od.get_unsigned(index, sub)
        .and_then(|v| u32::try_from(v).ok())
}

fn ramp_of(od: &ObjectDictionary, index: u16, fallback: Ramp) -> Ramp {
    Ramp {
        delta_speed: unsigned(od, index, 1).unwrap_or(fallback.delta_speed),
        delta_time: unsigned(od, index, 2)
            .and_then(|v| u16::try_from(v).ok())
            .unwrap_or(fallback.delta_time),
    }
}

impl VlParams {
    /// The values `od` holds; objects the dictionary lacks keep `fallback`'s, and so does
    /// [`VlParams::rfg_bits`].
    pub fn from_od(od: &ObjectDictionary, fallback: VlParams) -> VlParams {
        let amount = index::VL_VELOCITY_MIN_MAX_AMOUNT;
        let min_max = index::VL_VELOCITY_MIN_MAX;
        VlParams {
            min_max_amount: MinMaxAmount {
                min: unsigned(od, amount, 1).unwrap_or(fallback.min_max_amount.min),
                max: unsigned(od, amount, 2).unwrap_or(fallback.min_max_amount.max),
            },
            min_max: match (
                unsigned(od, min_max, 1),
                unsigned(od, min_max, 2),
                unsigned(od, min_max, 3),
                unsigned(od, min_max, 4),
            ) {
                (Some(min_pos), Some(max_pos), Some(min_neg), Some(max_neg)) => Some(MinMax {
                    min_pos,
                    max_pos,
                    min_neg,
                    max_neg,
                }),
                _ => fallback.min_max,
            },
            acceleration: ramp_of(od, index::VL_VELOCITY_ACCELERATION, fallback.acceleration),
            deceleration: ramp_of(od, index::VL_VELOCITY_DECELERATION, fallback.deceleration),
            quick_stop: ramp_of(od, index::VL_VELOCITY_QUICK_STOP, fallback.quick_stop),
            rfg_bits: fallback.rfg_bits,
        }
    }

    /// The velocity limit function: `target` with its amount kept within 0x6046 (and, for
    /// its direction, 0x6047). A target of 0 stays 0, so the drive can stand still; a max
    /// below its min is read as the min.
    pub fn limit(&self, target: i16) -> i16 {
        if target == 0 {
            return 0;
        }
        let clamp = |amount: i64, min: u32, max: u32| {
            let (min, max) = (i64::from(min), i64::from(max));
            amount.clamp(min, max.max(min))
        };
        let mut amount = i64::from(target).abs();
        amount = clamp(amount, self.min_max_amount.min, self.min_max_amount.max);
        if let Some(m) = self.min_max {
            amount = if target > 0 {
                clamp(amount, m.min_pos, m.max_pos)
            } else {
                clamp(amount, m.min_neg, m.max_neg)
            };
        }
        let v = if target > 0 { amount } else { -amount };
        v.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16
    }

    /// Whether the limit function changes `target` (statusword bit 11, internal limit
    /// active).
    pub fn limits(&self, target: i16) -> bool {
        self.limit(target) != target
    }
}

/// Moves `v` towards `target` for `dt` seconds, at `acc` while its amount rises and `dec`
/// while it falls; a change of sign first brakes to zero.
fn ramp(mut v: f64, target: f64, acc: f64, dec: f64, mut dt: f64) -> f64 {
    // At most two phases: brake to zero, then accelerate the other way.
    for _ in 0..2 {
        if v == target || dt <= 0.0 {
            break;
        }
        let crossing = v != 0.0 && target != 0.0 && (v > 0.0) != (target > 0.0);
        let goal = if crossing { 0.0 } else { target };
        let falling = goal.abs() < v.abs();
        let rate = if falling { dec } else { acc };
        if rate <= 0.0 {
            break;
        }
        let need = (goal - v).abs() / rate;
        if need > dt {
            v += (goal - v).signum() * rate * dt;
            break;
        }
        v = goal;
        dt -= need;
    }
    v
}

/// The state of velocity mode: the ramp function's output.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct VelocityMode {
    demand: f64,
}

impl VelocityMode {
    /// At standstill.
    pub const fn new() -> Self {
        VelocityMode { demand: 0.0 }
    }

    /// 0x6043 vl velocity demand: the ramp output rounded to the nearest unit.
    pub fn demand(&self) -> i16 {
        self.demand
            .round()
            .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }

    /// The ramp output before rounding.
    pub fn demand_exact(&self) -> f64 {
        self.demand
    }

    /// Runs the ramp function for `dt` with target velocity `target` (0x6042), controlword
    /// `controlword`, the power state's `stage` and `params`; returns the new
    /// [`Self::demand`].
    pub fn step(
        &mut self,
        target: i16,
        controlword: u16,
        stage: &PowerStage,
        params: &VlParams,
        dt: Duration,
    ) -> i16 {
        let dt = dt.as_secs_f64();
        let to_zero = |v: f64, r: Ramp| ramp(v, 0.0, r.per_second(), r.per_second(), dt);
        self.demand = match stage.motion {
            Motion::Disabled => 0.0,
            Motion::Stop { ramp: r, .. } => match r {
                StopRamp::SlowDown => to_zero(self.demand, params.deceleration),
                StopRamp::QuickStop => to_zero(self.demand, params.quick_stop),
                StopRamp::CurrentLimit | StopRamp::VoltageLimit => 0.0,
            },
            Motion::Operate => {
                let cw = controlword;
                let input = if params.rfg_bits && cw & VL_RFG_USE_REF == 0 {
                    0.0
                } else {
                    f64::from(params.limit(target))
                };
                if params.rfg_bits && cw & VL_RFG_ENABLE == 0 {
                    0.0
                } else if params.rfg_bits && cw & VL_RFG_UNLOCK == 0 {
                    self.demand
                } else {
                    ramp(
                        self.demand,
                        input,
                        params.acceleration.per_second(),
                        params.deceleration.per_second(),
                        dt,
                    )
                }
            }
        };
        self.demand()
    }

    /// Whether the demand has reached what the drive is asked for: the limited target in
    /// `Operate`, standstill when stopping or disabled (statusword bit 10).
    pub fn target_reached(&self, target: i16, stage: &PowerStage, params: &VlParams) -> bool {
        let goal = match stage.motion {
            Motion::Operate => params.limit(target),
            _ => 0,
        };
        self.demand() == goal && self.demand == f64::from(goal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::StopReason;

    const RUN: u16 = 0x007F;
    const MS: Duration = Duration::from_millis(1);

    fn operate() -> PowerStage {
        PowerStage {
            voltage: true,
            motion: Motion::Operate,
        }
    }

    #[test]
    fn vl_ramp_accelerates_and_decelerates_at_their_rates() {
        let p = VlParams {
            acceleration: Ramp::new(1000, 1),
            deceleration: Ramp::new(3000, 2),
            ..VlParams::default()
        };
        let mut vl = VelocityMode::new();
        for _ in 0..500 {
            vl.step(1500, RUN, &operate(), &p, MS);
        }
        assert_eq!(vl.demand(), 500);
        assert!(!vl.target_reached(1500, &operate(), &p));
        vl.step(1500, RUN, &operate(), &p, Duration::from_secs(2));
        assert_eq!(vl.demand(), 1500);
        assert!(vl.target_reached(1500, &operate(), &p));
        // 1500 per second down: 100 ms takes 150.
        vl.step(0, RUN, &operate(), &p, Duration::from_millis(100));
        assert_eq!(vl.demand(), 1350);
    }

    #[test]
    fn vl_ramp_brakes_through_zero_on_a_sign_change() {
        let p = VlParams {
            acceleration: Ramp::new(100, 1),
            deceleration: Ramp::new(1000, 1),
            ..VlParams::default()
        };
        let mut vl = VelocityMode::new();
        vl.step(100, RUN, &operate(), &p, Duration::from_secs(1));
        assert_eq!(vl.demand(), 100);
        // 100 ms braking to zero at 1000/s, then 900 ms accelerating at 100/s.
        vl.step(-500, RUN, &operate(), &p, Duration::from_secs(1));
        assert_eq!(vl.demand(), -90);
    }

    #[test]
    fn vl_limit_function_keeps_amounts_within_6046_and_6047() {
        let p = VlParams {
            min_max_amount: MinMaxAmount {
                min: 100,
                max: 3000,
            },
            min_max: Some(MinMax {
                min_pos: 0,
                max_pos: 2000,
                min_neg: 200,
                max_neg: 32767,
            }),
            ..VlParams::default()
        };
        assert_eq!(p.limit(0), 0);
        assert_eq!(p.limit(50), 100);
        assert_eq!(p.limit(2500), 2000);
        assert_eq!(p.limit(-150), -200);
        assert_eq!(p.limit(-5000), -3000);
        assert_eq!(p.limit(i16::MIN), -3000);
        assert!(p.limits(2500));
        assert!(!p.limits(1000));
    }

    #[test]
    fn vl_stops_follow_the_power_stage() {
        let p = VlParams {
            deceleration: Ramp::new(1000, 1),
            quick_stop: Ramp::new(5000, 1),
            ..VlParams::default()
        };
        let start = |v: i16| {
            let mut vl = VelocityMode::new();
            vl.step(v, RUN, &operate(), &p, Duration::from_secs(10));
            vl
        };
        let stop = |ramp, reason| PowerStage {
            voltage: true,
            motion: Motion::Stop { ramp, reason },
        };
        let mut vl = start(1000);
        vl.step(
            1000,
            RUN,
            &stop(StopRamp::SlowDown, StopReason::Halt),
            &p,
            Duration::from_millis(100),
        );
        assert_eq!(vl.demand(), 900);
        let mut vl = start(1000);
        vl.step(
            1000,
            RUN,
            &stop(StopRamp::QuickStop, StopReason::QuickStop),
            &p,
            Duration::from_millis(100),
        );
        assert_eq!(vl.demand(), 500);
        let mut vl = start(1000);
        vl.step(
            1000,
            RUN,
            &stop(StopRamp::CurrentLimit, StopReason::FaultReaction),
            &p,
            MS,
        );
        assert_eq!(vl.demand(), 0);
        let mut vl = start(-1000);
        let off = PowerStage {
            voltage: true,
            motion: Motion::Disabled,
        };
        vl.step(-1000, RUN, &off, &p, MS);
        assert_eq!(vl.demand(), 0);
        assert!(vl.target_reached(-1000, &off, &p));
    }

    #[test]
    fn vl_rfg_bits_enable_unlock_and_use_ref() {
        let p = VlParams::default();
        let mut vl = VelocityMode::new();
        vl.step(1000, RUN, &operate(), &p, Duration::from_millis(500));
        assert_eq!(vl.demand(), 500);
        // rfg unlock = 0: held.
        vl.step(
            1000,
            RUN & !VL_RFG_UNLOCK,
            &operate(),
            &p,
            Duration::from_millis(500),
        );
        assert_eq!(vl.demand(), 500);
        // rfg use ref = 0: ramps to zero.
        vl.step(
            1000,
            RUN & !VL_RFG_USE_REF,
            &operate(),
            &p,
            Duration::from_millis(100),
        );
        assert_eq!(vl.demand(), 400);
        // rfg enable = 0: zero at once.
        vl.step(1000, RUN & !VL_RFG_ENABLE, &operate(), &p, MS);
        assert_eq!(vl.demand(), 0);
        // A drive without the bits ramps with 0x000F.
        let plain = VlParams {
            rfg_bits: false,
            ..p
        };
        vl.step(1000, 0x000F, &operate(), &plain, Duration::from_millis(100));
        assert_eq!(vl.demand(), 100);
    }
}
