//! Profile velocity mode (pv, CiA 402-2 profile velocity mode): the demand velocity ramps
//! to 0x60FF target velocity with 0x6083 profile acceleration and 0x6084 profile
//! deceleration, within 0x607F max profile velocity.
//!
//! Statusword bits: 10 target reached — the actual velocity has been within 0x606D
//! velocity window of the target for 0x606E velocity window time (with halt: the axis has
//! stopped); 12 speed — the actual velocity has been within 0x606F velocity threshold of 0
//! for 0x6070 velocity threshold time (1: speed is 0); 13 max slippage error, which a
//! synchronous servo motor does not have (0).

use crate::profile::{Limits, Trajectory};

/// A window that must hold for a time: CiA 402-2's velocity window and threshold.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WindowTimer {
    inside_us: u64,
}

impl WindowTimer {
    /// One cycle of `dt_us`: whether `inside` has now held for at least `time_us`.
    pub fn step(&mut self, inside: bool, time_us: u64, dt_us: u64) -> bool {
        if inside {
            self.inside_us = self.inside_us.saturating_add(dt_us);
            self.inside_us >= time_us
        } else {
            self.inside_us = 0;
            false
        }
    }
}

/// The state of profile velocity mode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProfileVelocity {
    window: WindowTimer,
    threshold: WindowTimer,
    /// Statusword bit 10.
    pub target_reached: bool,
    /// Statusword bit 12 (speed = 0).
    pub speed_zero: bool,
}

/// The windows pv mode watches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Windows {
    /// 0x606D velocity window.
    pub velocity_window: f64,
    /// 0x606E, µs.
    pub velocity_window_time_us: u64,
    /// 0x606F velocity threshold.
    pub threshold: f64,
    /// 0x6070, µs.
    pub threshold_time_us: u64,
}

impl ProfileVelocity {
    /// One loop cycle: the demand ramps toward `target` (when `run`; a stop ramp moves the
    /// trajectory otherwise), and the windows are checked against `actual`.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        traj: &mut Trajectory,
        run: bool,
        target: f64,
        limits: &Limits,
        actual: f64,
        w: &Windows,
        dt_us: u64,
    ) {
        let dt = dt_us as f64 * 1e-6;
        let goal = if run {
            traj.step_velocity(target, limits, dt);
            target.clamp(-limits.velocity, limits.velocity)
        } else {
            0.0
        };
        self.target_reached = self.window.step(
            (actual - goal).abs() <= w.velocity_window,
            w.velocity_window_time_us,
            dt_us,
        );
        self.speed_zero =
            self.threshold
                .step(actual.abs() <= w.threshold, w.threshold_time_us, dt_us);
    }
}
