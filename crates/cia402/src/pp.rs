//! Profile position mode (pp, CiA 402-2 profile position mode): the set-point handshake
//! and the move to each set-point.
//!
//! Controlword bits: 4 new set-point (acts on its rising edge), 5 change set immediately,
//! 6 relative (1) or absolute (0), 8 halt, 9 change on set-point. Statusword bits: 10
//! target reached, 12 set-point acknowledge, 13 following error (kept by the drive).
//!
//! * **Single set-point** (bit 5 = 1): a new set-point replaces the one being moved to at
//!   once; the axis moves from where its demand is.
//! * **Set of set-points** (bit 5 = 0): a new set-point while a move is in progress is
//!   buffered (one deep) and started when the present one is reached; with bit 9 (change
//!   on set-point) the axis passes through the present set-point without stopping, at the
//!   new set-point's profile velocity. A third set-point while the buffer is full is not
//!   acknowledged.
//! * **Set-point acknowledge** (bit 12) is set at the rising edge of bit 4 that the drive
//!   took, and cleared once bit 4 is 0 again and the buffer is free: the master may then
//!   send the next set-point.
//! * **Relative** set-points add to the target of the set-point before (the last one
//!   taken); absolute ones replace it. Targets beyond 0x607D software position limit are
//!   limited to it (statusword bit 11 while such a target is the one being moved to).
//! * **Target reached** (bit 10): the demand is at the last set-point and the actual
//!   position has stayed within 0x6067 position window of it for 0x6068 position window
//!   time; with halt, the axis has stopped.

use crate::profile::{Limits, Trajectory};

/// A set-point the drive took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetPoint {
    /// The target, position units (after the software position limit).
    pub target: f64,
    /// The profile velocity, acceleration and deceleration of the move.
    pub limits: Limits,
    /// The target was limited by 0x607D.
    pub limited: bool,
}

/// Controlword bit 4: new set-point.
pub const NEW_SET_POINT: u16 = 1 << 4;
/// Controlword bit 5: change set immediately.
pub const CHANGE_SET_IMMEDIATELY: u16 = 1 << 5;
/// Controlword bit 6: relative.
pub const RELATIVE: u16 = 1 << 6;
/// Controlword bit 9: change on set-point.
pub const CHANGE_ON_SET_POINT: u16 = 1 << 9;

/// The state of profile position mode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProfilePosition {
    active: Option<SetPoint>,
    buffered: Option<SetPoint>,
    /// The target of the last set-point taken (the base of a relative one).
    last_target: Option<f64>,
    acknowledge: bool,
    bit4: bool,
    /// How long the actual position has been within the position window, µs.
    in_window_us: u64,
    arrived: bool,
}

/// What the drive knows when a controlword is evaluated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Request {
    /// 0x607A target position.
    pub target: f64,
    /// The move's limits.
    pub limits: Limits,
    /// 0x607D, when the limits are in force.
    pub software_limit: Option<(f64, f64)>,
}

impl ProfilePosition {
    /// Forgets every set-point (the mode was entered, the drive enabled).
    pub fn reset(&mut self, bit4: bool) {
        *self = ProfilePosition {
            bit4,
            ..ProfilePosition::default()
        };
    }

    /// Evaluates controlword `cw`; `demand` is where the trajectory is now.
    pub fn controlword(&mut self, cw: u16, req: &Request, demand: f64) {
        let bit4 = cw & NEW_SET_POINT != 0;
        let edge = bit4 && !self.bit4;
        self.bit4 = bit4;
        if edge {
            let base = self.last_target.unwrap_or(demand);
            let raw = if cw & RELATIVE != 0 {
                base + req.target
            } else {
                req.target
            };
            let (target, limited) = match req.software_limit {
                Some((lo, _)) if raw < lo => (lo, true),
                Some((_, hi)) if raw > hi => (hi, true),
                _ => (raw, false),
            };
            let sp = SetPoint {
                target,
                limits: req.limits,
                limited,
            };
            let moving = self.active.is_some() && !self.arrived;
            if cw & CHANGE_SET_IMMEDIATELY != 0 || !moving {
                self.active = Some(sp);
                self.buffered = None;
                self.arrived = false;
                self.in_window_us = 0;
                self.last_target = Some(target);
                self.acknowledge = true;
            } else if self.buffered.is_none() {
                self.buffered = Some(sp);
                self.last_target = Some(target);
                self.acknowledge = true;
            }
        }
        if !bit4 && self.buffered.is_none() {
            self.acknowledge = false;
        }
    }

    /// Statusword bit 12.
    pub fn set_point_acknowledge(&self) -> bool {
        self.acknowledge
    }

    /// The set-point being moved to.
    pub fn active(&self) -> Option<&SetPoint> {
        self.active.as_ref()
    }

    /// One loop cycle of `dt_us` µs: moves `traj`; `actual` is the actual position,
    /// `window` 0x6067 and `window_time_us` 0x6068. `cw` gives bit 9. Returns whether the
    /// target is reached (bit 10).
    pub fn step(
        &mut self,
        traj: &mut Trajectory,
        cw: u16,
        actual: f64,
        window: Option<f64>,
        window_time_us: u64,
        dt_us: u64,
    ) -> bool {
        let dt = dt_us as f64 * 1e-6;
        let Some(sp) = self.active else {
            // No set-point yet: hold where the demand is.
            traj.step_velocity(
                0.0,
                &Limits {
                    velocity: 0.0,
                    acceleration: 1.0,
                    deceleration: 1.0,
                },
                dt,
            );
            return true;
        };
        if !self.arrived {
            let blend = cw & CHANGE_ON_SET_POINT != 0
                && self
                    .buffered
                    .is_some_and(|b| (b.target - sp.target) * (sp.target - traj.position) >= 0.0);
            let end = match (blend, self.buffered) {
                (true, Some(b)) => b.limits.velocity,
                _ => 0.0,
            };
            if traj.step_position(sp.target, end, &sp.limits, dt) {
                self.arrived = true;
                self.in_window_us = 0;
            }
        }
        if self.arrived
            && let Some(next) = self.buffered.take()
        {
            self.active = Some(next);
            self.arrived = false;
            if !self.bit4 {
                self.acknowledge = false;
            }
            return false;
        }
        if !self.arrived {
            return false;
        }
        let inside = window.is_none_or(|w| (actual - sp.target).abs() <= w);
        if inside {
            self.in_window_us = self.in_window_us.saturating_add(dt_us);
        } else {
            self.in_window_us = 0;
        }
        inside && self.in_window_us >= window_time_us
    }

    /// Whether a move to a set-point is in progress (bit 10 is 0 from the set-point's
    /// acceptance on).
    pub fn moving(&self) -> bool {
        self.active.is_some() && !self.arrived
    }

    /// Whether the set-point being moved to was limited by 0x607D (statusword bit 11).
    pub fn limited(&self) -> bool {
        self.active.is_some_and(|s| s.limited)
    }
}
