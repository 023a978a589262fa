//! The plant a servo drive controls, stepped in virtual time: a motor and its load
//! ([`Mechanics`]: inertia, viscous and Coulomb friction, torque and current limits, the
//! rated torque and current the per-mille objects 0x6071–0x6078 refer to), the encoder that
//! measures it ([`Encoder`]), the switches along the axis (limit and home switches, 0x60FD)
//! and the inverter ([`Inverter`]: DC link, over-current trip).
//!
//! Everything is SI inside (rad, rad/s, N·m, A, V); the objects' units are applied by
//! [`crate::units`]. The motor is integrated with semi-implicit Euler steps: torque →
//! acceleration → speed → angle, friction opposing the speed (Coulomb friction holds the
//! shaft while the driving torque is below it, as static friction does).

use cantwin_can::Duration;

/// The motor and its load as one rigid body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mechanics {
    /// Inertia of motor and load, kg·m².
    pub inertia: f64,
    /// Viscous friction, N·m per rad/s.
    pub viscous: f64,
    /// Coulomb friction, N·m.
    pub coulomb: f64,
    /// Rated torque, N·m (0x6076, the base of the torque objects' per-mille).
    pub rated_torque: f64,
    /// Rated current, A (0x6075).
    pub rated_current: f64,
    /// Torque constant, N·m per A.
    pub torque_constant: f64,
    /// The most torque the motor makes at its peak current, N·m.
    pub peak_torque: f64,
}

impl Default for Mechanics {
    /// A 400 W servo motor (1.27 N·m, 3 A rated, peak 3×) with a load of twice its own
    /// inertia.
    fn default() -> Self {
        Mechanics {
            inertia: 1.0e-4,
            viscous: 1.0e-4,
            coulomb: 0.02,
            rated_torque: 1.27,
            rated_current: 3.0,
            torque_constant: 1.27 / 3.0,
            peak_torque: 3.81,
        }
    }
}

/// The power stage: DC link and the current trip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverterParams {
    /// DC link voltage with mains present, V.
    pub dc_link_nominal: f64,
    /// Below this the drive faults with under-voltage (0x3220), V.
    pub dc_link_min: f64,
    /// Above this the drive faults with over-voltage (0x3210), V.
    pub dc_link_max: f64,
    /// A phase current above this trips the stage (0x2310), A.
    pub trip_current: f64,
}

impl Default for InverterParams {
    /// A 230 V drive: 325 V DC link, 200–400 V, tripping at 4× rated current.
    fn default() -> Self {
        InverterParams {
            dc_link_nominal: 325.0,
            dc_link_min: 200.0,
            dc_link_max: 400.0,
            trip_current: 12.0,
        }
    }
}

/// A fault of the power stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PowerFault {
    /// The phase current exceeded the trip level (CiA 402 error code 0x2310, continuous
    /// over current).
    OverCurrent,
    /// The DC link is below its minimum (0x3220, DC link under-voltage).
    UnderVoltage,
    /// The DC link is above its maximum (0x3210, DC link over-voltage).
    OverVoltage,
}

impl PowerFault {
    /// The CiA 402 error code (0x603F and the EMCY).
    pub const fn error_code(self) -> u16 {
        match self {
            PowerFault::OverCurrent => 0x2310,
            PowerFault::UnderVoltage => 0x3220,
            PowerFault::OverVoltage => 0x3210,
        }
    }
}

/// The power stage's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inverter {
    /// Its parameters.
    pub params: InverterParams,
    /// The DC link voltage now, V.
    pub dc_link: f64,
    /// A short between motor phases (an injected fault): the current rises past the trip
    /// level as soon as the bridge is switched on.
    pub phase_short: bool,
}

impl Inverter {
    /// A stage with its DC link at the nominal voltage.
    pub fn new(params: InverterParams) -> Self {
        Inverter {
            params,
            dc_link: params.dc_link_nominal,
            phase_short: false,
        }
    }

    /// The fault present with the bridge on (`bridge`) and phase current `current`, A.
    pub fn fault(&self, bridge: bool, current: f64) -> Option<PowerFault> {
        if self.dc_link > self.params.dc_link_max {
            Some(PowerFault::OverVoltage)
        } else if bridge && self.dc_link < self.params.dc_link_min {
            Some(PowerFault::UnderVoltage)
        } else if bridge && (self.phase_short || current.abs() > self.params.trip_current) {
            Some(PowerFault::OverCurrent)
        } else {
            None
        }
    }
}

/// The position encoder: increments per motor revolution, and an index pulse once a
/// revolution at angle 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Encoder {
    /// Increments per motor revolution.
    pub increments: u32,
}

impl Encoder {
    /// The increment count of `angle` (rad), truncated toward −∞ as a counter counts.
    pub fn count(&self, angle: f64) -> i64 {
        let x = angle / core::f64::consts::TAU * f64::from(self.increments);
        // `x.floor() as i64` without calling `floor`, a library function where the target
        // has no rounding instruction: truncate, then take one off a negative value that is
        // not an integer (the truncated value is exact: a double's integer part is one).
        let t = x as i64;
        t.saturating_sub(i64::from((t as f64) > x))
    }

    /// The angle of the index pulse crossed moving from `from` to `to` (rad), if any: the
    /// pulse sits at every whole revolution.
    pub fn index_between(&self, from: f64, to: f64) -> Option<f64> {
        let tau = core::f64::consts::TAU;
        let (a, b) = (from / tau, to / tau);
        if b > a {
            let k = a.floor() + 1.0;
            (k <= b).then_some(k * tau)
        } else if b < a {
            let k = a.ceil() - 1.0;
            (k >= b).then_some(k * tau)
        } else {
            None
        }
    }
}

/// Switches along the axis, by motor angle (rad): a negative limit switch active below
/// `negative_limit`, a positive one above `positive_limit`, and a home switch whose edge
/// is at `home`: active above it (a "positive home switch", CiA 402-2 homing methods 3, 4,
/// 19, 20) or, with `home_below`, below it (a "negative home switch", methods 5, 6, 21,
/// 22). Its edge is the home switch transition the methods search. With `home_end` the
/// home switch is a cam instead: active between `home` and `home_end` only, with an edge
/// on either side (methods 7–14, 23–30), and `home_below` does not apply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Switches {
    /// The negative limit switch is active at angles below this.
    pub negative_limit: Option<f64>,
    /// The positive limit switch is active at angles above this.
    pub positive_limit: Option<f64>,
    /// The home switch's edge.
    pub home: Option<f64>,
    /// The home switch is active below its edge rather than above.
    pub home_below: bool,
    /// The upper edge of a home switch that is a cam from `home` to here.
    pub home_end: Option<f64>,
}

/// 0x60FD bit 0: negative limit switch.
pub const NEGATIVE_LIMIT_SWITCH: u32 = 1 << 0;
/// 0x60FD bit 1: positive limit switch.
pub const POSITIVE_LIMIT_SWITCH: u32 = 1 << 1;
/// 0x60FD bit 2: home switch.
pub const HOME_SWITCH: u32 = 1 << 2;

impl Switches {
    /// No switches.
    pub const NONE: Switches = Switches {
        negative_limit: None,
        positive_limit: None,
        home: None,
        home_below: false,
        home_end: None,
    };

    /// The 0x60FD bits at `angle`.
    pub fn inputs(&self, angle: f64) -> u32 {
        let mut bits = 0;
        if self.negative_limit.is_some_and(|l| angle < l) {
            bits |= NEGATIVE_LIMIT_SWITCH;
        }
        if self.positive_limit.is_some_and(|l| angle > l) {
            bits |= POSITIVE_LIMIT_SWITCH;
        }
        if self.home.is_some_and(|h| {
            if let Some(end) = self.home_end {
                angle > h && angle < end
            } else if self.home_below {
                angle < h
            } else {
                angle > h
            }
        }) {
            bits |= HOME_SWITCH;
        }
        bits
    }
}

/// The motor's state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MotorState {
    /// Angle, rad.
    pub angle: f64,
    /// Speed, rad/s.
    pub speed: f64,
    /// The torque the motor makes, N·m.
    pub torque: f64,
    /// The phase current, A.
    pub current: f64,
}

/// The motor and load, integrated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motor {
    /// The mechanics.
    pub mechanics: Mechanics,
    /// The state.
    pub state: MotorState,
    /// A load torque acting on the shaft from outside (a process force), N·m.
    pub load_torque: f64,
    /// The shaft is jammed (a mechanical block, an injected fault): it does not move.
    pub jammed: bool,
}

impl Motor {
    /// A motor at rest at angle 0.
    pub fn new(mechanics: Mechanics) -> Self {
        Motor {
            mechanics,
            state: MotorState::default(),
            load_torque: 0.0,
            jammed: false,
        }
    }

    /// Advances by `dt` with the bridge making `torque` (N·m, `None`: the bridge is off and
    /// the motor coasts), limited to `limit` (N·m) and to the motor's peak torque.
    pub fn step(&mut self, torque: Option<f64>, limit: f64, dt: Duration) {
        self.step_seconds(torque, limit, dt.as_secs_f64());
    }

    /// [`Motor::step`] by `dt` seconds (a loop period converted once, not every cycle).
    pub fn step_seconds(&mut self, torque: Option<f64>, limit: f64, dt: f64) {
        let m = &self.mechanics;
        let limit = limit.min(m.peak_torque).max(0.0);
        let t = torque.map_or(0.0, |t| t.clamp(-limit, limit));
        self.state.torque = t;
        self.state.current = t / m.torque_constant;
        if self.jammed {
            self.state.speed = 0.0;
            return;
        }
        let drive = t + self.load_torque;
        let speed = self.state.speed;
        let mut accel = (drive - m.viscous * speed) / m.inertia;
        let coulomb = m.coulomb / m.inertia;
        if speed == 0.0 && drive.abs() <= m.coulomb {
            // Static friction holds the shaft.
            return;
        }
        accel -= coulomb
            * if speed != 0.0 {
                speed.signum()
            } else {
                drive.signum()
            };
        let next = speed + accel * dt;
        // Friction brings the shaft to rest; it never reverses it.
        let next = if speed != 0.0 && next.signum() != speed.signum() && drive.abs() <= m.coulomb {
            0.0
        } else {
            next
        };
        self.state.speed = next;
        self.state.angle += next * dt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motor_accelerates_with_torque_over_inertia() {
        let mut m = Motor::new(Mechanics {
            viscous: 0.0,
            coulomb: 0.0,
            ..Mechanics::default()
        });
        for _ in 0..1000 {
            m.step(Some(0.1), 10.0, Duration::from_micros(100));
        }
        // 0.1 N·m / 1e-4 kg·m² = 1000 rad/s² for 0.1 s.
        assert!((m.state.speed - 100.0).abs() < 1e-6, "{}", m.state.speed);
        assert!((m.state.current - 0.1 * 3.0 / 1.27).abs() < 1e-9);
    }

    #[test]
    fn coulomb_friction_holds_and_stops_the_shaft() {
        let mut m = Motor::new(Mechanics::default());
        m.step(Some(0.01), 10.0, Duration::from_millis(1));
        assert_eq!(m.state.speed, 0.0);
        m.state.speed = 10.0;
        for _ in 0..1000 {
            m.step(None, 10.0, Duration::from_millis(1));
        }
        assert_eq!(m.state.speed, 0.0);
        assert!(m.state.angle > 0.0);
    }

    #[test]
    fn torque_is_limited_to_the_limit_and_the_peak() {
        let mut m = Motor::new(Mechanics::default());
        m.step(Some(100.0), 1.0, Duration::from_millis(1));
        assert_eq!(m.state.torque, 1.0);
        m.step(Some(-100.0), 100.0, Duration::from_millis(1));
        assert_eq!(m.state.torque, -3.81);
    }

    #[test]
    fn encoder_counts_and_finds_index_pulses() {
        let e = Encoder { increments: 4096 };
        let tau = core::f64::consts::TAU;
        assert_eq!(e.count(tau), 4096);
        assert_eq!(e.count(-0.0001), -1);
        assert_eq!(e.count(-tau), -4096);
        assert_eq!(e.count(-0.0), 0);
        assert_eq!(e.count(f64::NAN), 0);
        assert_eq!(e.count(f64::INFINITY), i64::MAX);
        assert_eq!(e.count(f64::NEG_INFINITY), i64::MIN);
        for k in -40_000..40_000 {
            let angle = f64::from(k) * 1.0e-3;
            let floor = (angle / tau * 4096.0).floor() as i64;
            assert_eq!(e.count(angle), floor, "{angle}");
        }
        assert_eq!(e.index_between(0.5, 7.0), Some(tau));
        assert_eq!(e.index_between(7.0, 0.5), Some(tau));
        assert_eq!(e.index_between(0.5, 0.6), None);
        assert_eq!(e.index_between(-0.1, 0.1), Some(0.0));
    }

    #[test]
    fn switches_and_power_stage_faults() {
        let s = Switches {
            negative_limit: Some(-10.0),
            positive_limit: Some(10.0),
            home: Some(0.0),
            home_below: false,
            home_end: None,
        };
        assert_eq!(s.inputs(-11.0), NEGATIVE_LIMIT_SWITCH);
        assert_eq!(s.inputs(11.0), POSITIVE_LIMIT_SWITCH | HOME_SWITCH);
        assert_eq!(s.inputs(1.0), HOME_SWITCH);
        let cam = Switches {
            home_end: Some(2.0),
            ..s
        };
        assert_eq!(cam.inputs(1.0), HOME_SWITCH);
        assert_eq!(cam.inputs(3.0), 0);
        assert_eq!(cam.inputs(-1.0), 0);
        let mut p = Inverter::new(InverterParams::default());
        assert_eq!(p.fault(true, 3.0), None);
        assert_eq!(p.fault(true, 13.0), Some(PowerFault::OverCurrent));
        assert_eq!(p.fault(false, 13.0), None);
        p.dc_link = 0.0;
        assert_eq!(p.fault(false, 0.0), None);
        assert_eq!(p.fault(true, 0.0).map(PowerFault::error_code), Some(0x3220));
        p.dc_link = 450.0;
        assert_eq!(p.fault(false, 0.0), Some(PowerFault::OverVoltage));
    }
}
