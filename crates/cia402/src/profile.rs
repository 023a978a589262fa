//! The trajectory generator of the profile modes (CiA 402-2, motion profile type 0, linear
//! ramp, i.e. a trapezoidal velocity profile): it moves a demand position toward a target
//! position, or a demand velocity toward a target velocity, within a velocity limit and
//! with an acceleration and a deceleration. All in one unit system (the caller's).

/// The generator's demand: position and velocity.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Trajectory {
    /// Demand position.
    pub position: f64,
    /// Demand velocity.
    pub velocity: f64,
}

/// The limits of a move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// The most velocity (an amount).
    pub velocity: f64,
    /// Acceleration (an amount, > 0).
    pub acceleration: f64,
    /// Deceleration (an amount, > 0).
    pub deceleration: f64,
}

impl Limits {
    fn sane(self) -> Limits {
        Limits {
            velocity: self.velocity.abs(),
            acceleration: self.acceleration.abs().max(1e-9),
            deceleration: self.deceleration.abs().max(1e-9),
        }
    }
}

/// Changes `v` toward `want` by at most the acceleration when its amount grows in its
/// direction, the deceleration otherwise, over `dt`.
fn approach(v: f64, want: f64, l: &Limits, dt: f64) -> f64 {
    let speeding_up = want.abs() > v.abs() && (v == 0.0 || want.signum() == v.signum());
    let rate = if speeding_up {
        l.acceleration
    } else {
        l.deceleration
    };
    let step = rate * dt;
    if (want - v).abs() <= step {
        want
    } else {
        v + step * (want - v).signum()
    }
}

impl Trajectory {
    /// A demand at rest at `position`.
    pub fn at(position: f64) -> Self {
        Trajectory {
            position,
            velocity: 0.0,
        }
    }

    /// One step of `dt` toward the velocity `target` (profile velocity mode, the stop
    /// ramps). Returns whether the demand velocity equals the target.
    pub fn step_velocity(&mut self, target: f64, limits: &Limits, dt: f64) -> bool {
        let l = limits.sane();
        let target = target.clamp(-l.velocity, l.velocity);
        self.velocity = approach(self.velocity, target, &l, dt);
        self.position += self.velocity * dt;
        self.velocity == target
    }

    /// One step of `dt` toward `target` with `end` velocity (an amount, in the direction of
    /// the move; 0 stops there). Returns whether the demand has arrived (position equal to
    /// the target and, for `end = 0`, at rest).
    pub fn step_position(&mut self, target: f64, end: f64, limits: &Limits, dt: f64) -> bool {
        let l = limits.sane();
        let distance = target - self.position;
        if distance == 0.0 && self.velocity.abs() <= end.abs() + l.deceleration * dt {
            self.velocity = if end == 0.0 { 0.0 } else { self.velocity };
            return true;
        }
        let dir = if distance != 0.0 {
            distance.signum()
        } else {
            -self.velocity.signum()
        };
        let end = end.abs().min(l.velocity);
        // The fastest velocity that, moved for this step and then decelerated, still reaches
        // the end velocity at the target: v·dt + (v² − end²)/2d ≤ distance.
        let ddt = l.deceleration * dt;
        let reach = -ddt + (ddt * ddt + end * end + 2.0 * l.deceleration * distance.abs()).sqrt();
        let want = dir * reach.min(l.velocity);
        let v = if self.velocity != 0.0 && self.velocity.signum() != dir {
            // Moving away from the target: brake first.
            approach(self.velocity, 0.0, &l, dt)
        } else {
            approach(self.velocity, want, &l, dt)
        };
        let next = self.position + v * dt;
        if (target - next) * dir <= 0.0 && v.signum() == dir {
            // This step reaches the target.
            self.position = target;
            self.velocity = if end == 0.0 { 0.0 } else { dir * end };
            return true;
        }
        self.velocity = v;
        self.position = next;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: Limits = Limits {
        velocity: 100.0,
        acceleration: 1000.0,
        deceleration: 500.0,
    };

    #[test]
    fn a_position_move_is_trapezoidal_and_arrives_exactly() {
        let mut t = Trajectory::at(0.0);
        let mut peak: f64 = 0.0;
        let mut steps = 0;
        let mut last = 0.0;
        while !t.step_position(50.0, 0.0, &L, 0.001) {
            peak = peak.max(t.velocity);
            last = t.velocity;
            steps += 1;
            assert!(steps < 10_000);
            assert!(t.position <= 50.0);
        }
        assert_eq!(t.position, 50.0);
        assert_eq!(t.velocity, 0.0);
        assert_eq!(peak, 100.0);
        // The last step before arriving is within two steps of deceleration of rest.
        assert!(last <= 2.0 * 500.0 * 0.001, "{last}");
        // 0.1 s accelerating (5 units), 0.2 s decelerating (10), 0.35 s at 100 (35).
        assert!((640..=660).contains(&steps), "{steps}");
    }

    #[test]
    fn a_reversal_brakes_with_the_deceleration() {
        let mut t = Trajectory {
            position: 0.0,
            velocity: 100.0,
        };
        t.step_position(-10.0, 0.0, &L, 0.001);
        assert_eq!(t.velocity, 99.5);
        let mut steps = 0;
        while !t.step_position(-10.0, 0.0, &L, 0.001) {
            steps += 1;
            assert!(steps < 10_000);
        }
        assert_eq!(t.position, -10.0);
    }

    #[test]
    fn a_velocity_ramp_reaches_the_target() {
        let mut t = Trajectory::at(0.0);
        for _ in 0..99 {
            assert!(!t.step_velocity(100.0, &L, 0.001));
        }
        assert!(t.step_velocity(100.0, &L, 0.001));
        assert!(!t.step_velocity(-100.0, &L, 0.001));
        assert_eq!(t.velocity, 99.5);
        assert!(t.step_velocity(500.0, &L, 0.001));
        assert_eq!(t.velocity, 100.0);
    }
}
