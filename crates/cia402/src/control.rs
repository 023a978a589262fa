//! The drive's cascaded controller: a position loop (proportional, with velocity feed
//! forward) feeding a velocity loop (proportional-integral, with torque feed forward and
//! anti-windup at the torque limit). The gains are the model's, so the following error
//! 0x60F4 is what a real loop of these gains would leave.

/// The controller gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Position loop gain, 1/s (velocity demand per rad of position error).
    pub position_kp: f64,
    /// Velocity loop proportional gain, N·m per rad/s.
    pub velocity_kp: f64,
    /// Velocity loop integral gain, N·m per rad.
    pub velocity_ki: f64,
}

impl Default for Gains {
    /// A stiff loop for the default [`crate::physics::Mechanics`]: 100/s position gain, a
    /// velocity loop of about 80 Hz bandwidth.
    fn default() -> Self {
        Gains {
            position_kp: 100.0,
            velocity_kp: 0.05,
            velocity_ki: 5.0,
        }
    }
}

/// What the controller is asked to follow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Demand {
    /// A position (rad) with velocity (rad/s) and torque (N·m) feed forward.
    Position {
        /// The position demand.
        position: f64,
        /// Velocity feed forward.
        velocity: f64,
        /// Torque feed forward.
        torque: f64,
    },
    /// A velocity (rad/s) with torque feed forward (N·m).
    Velocity {
        /// The velocity demand.
        velocity: f64,
        /// Torque feed forward.
        torque: f64,
    },
    /// A torque, N·m.
    Torque(f64),
}

/// The controller's state: the velocity loop's integral.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Controller {
    integral: f64,
    /// The last velocity demand, rad/s.
    pub velocity_demand: f64,
    /// The last torque demand before the limit, N·m.
    pub torque_demand: f64,
}

impl Controller {
    /// Forgets the integral (the drive function was disabled).
    pub fn reset(&mut self) {
        *self = Controller::default();
    }

    /// One loop cycle of `dt` seconds: the torque (N·m) to make for `demand`, given the
    /// measured `position` (rad) and `speed` (rad/s), within ±`limit`.
    pub fn step(
        &mut self,
        gains: &Gains,
        demand: Demand,
        position: f64,
        speed: f64,
        limit: f64,
        dt: f64,
    ) -> f64 {
        let (velocity, feed) = match demand {
            Demand::Torque(t) => {
                self.integral = 0.0;
                self.velocity_demand = speed;
                self.torque_demand = t;
                return t.clamp(-limit, limit);
            }
            Demand::Velocity { velocity, torque } => (velocity, torque),
            Demand::Position {
                position: p,
                velocity,
                torque,
            } => (velocity + gains.position_kp * (p - position), torque),
        };
        self.velocity_demand = velocity;
        let error = velocity - speed;
        let unclamped = gains.velocity_kp * error + self.integral + feed;
        let torque = unclamped.clamp(-limit, limit);
        // Anti-windup: integrate only while the output is not held at the limit in the
        // error's direction.
        if torque == unclamped || (unclamped > limit) != (error > 0.0) {
            self.integral += gains.velocity_ki * error * dt;
            self.integral = self.integral.clamp(-limit, limit);
        }
        self.torque_demand = unclamped;
        torque
    }
}
