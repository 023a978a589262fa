//! Profile torque mode (pt, CiA 402-2 profile torque mode): the torque demand 0x6074 ramps
//! to 0x6071 target torque with 0x6087 torque slope (‰ of rated torque per second, torque
//! profile type 0: linear), within 0x6072 max torque.
//!
//! Statusword bits: 10 target reached — the torque demand equals the (limited) target; 11
//! internal limit active — 0x6072 limits the target, or the motor is at 0x6080 max motor
//! speed and the drive holds the torque back (a torque-controlled axis would otherwise
//! run away).

/// The state of profile torque mode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProfileTorque {
    /// The torque demand, ‰ of rated torque.
    pub demand: f64,
}

impl ProfileTorque {
    /// Starts from `torque` (the torque the motor makes as the mode is entered).
    pub fn at(torque: f64) -> Self {
        ProfileTorque { demand: torque }
    }

    /// One loop cycle of `dt` s toward `target` (‰) at `slope` ‰/s within ±`max`.
    /// Returns whether the demand equals the limited target, and whether the target was
    /// limited.
    pub fn step(&mut self, target: f64, slope: f64, max: f64, dt: f64) -> (bool, bool) {
        let goal = target.clamp(-max, max);
        let step = slope.abs() * dt;
        if (goal - self.demand).abs() <= step {
            self.demand = goal;
        } else {
            self.demand += step * (goal - self.demand).signum();
        }
        (self.demand == goal, goal != target)
    }
}
