//! The cyclic synchronous modes (CiA 402-2: csp cyclic synchronous position, csv cyclic
//! synchronous velocity, cst cyclic synchronous torque) and interpolated position mode
//! (ip, linear interpolation, 0x60C0 = 0).
//!
//! The master sends a set-point every communication cycle and a SYNC ends the cycle: at
//! each SYNC the drive takes the set-point received (0x607A, 0x60FF, 0x6071, or in ip
//! 0x60C1 sub 1) together with the offsets 0x60B0–0x60B2. Between two SYNCs the position
//! demand moves linearly from the previous set-point to the new one over the
//! interpolation time period 0x60C2 (units × 10^index s), with the slope as velocity feed
//! forward; csv and cst take the set-point as it is. When no SYNC comes, the demand stops
//! at the last set-point and stays there (the drive does not extrapolate); a set-point
//! received after its SYNC is taken at the next.
//!
//! Statusword bit 12 in csp, csv and cst: 1 the drive follows the command value, 0 the
//! target is ignored (halt, a quick stop or any stop ramp, not OPERATION ENABLED).
//! In ip, bit 12 is "ip mode active": controlword bit 4 (enable ip mode) is set in
//! OPERATION ENABLED; bit 10 is target reached (the demand at the last set-point and the
//! actual position within the position window).

/// The cyclic set-point interpolator.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Interpolator {
    from: f64,
    to: f64,
    /// Time since the last SYNC, µs.
    since_us: u64,
    /// The interpolation period, µs (0: take set-points at once).
    period_us: u64,
    started: bool,
    /// A loop cycle ran after the segment ended: no SYNC came in time.
    ended: bool,
}

impl Interpolator {
    /// Starts at `position`, holding it.
    pub fn at(position: f64) -> Self {
        Interpolator {
            from: position,
            to: position,
            since_us: 0,
            period_us: 0,
            started: true,
            ended: true,
        }
    }

    /// A SYNC with set-point `target`; the next segment lasts `period_us`.
    pub fn sync(&mut self, target: f64, period_us: u64) {
        let now = self.value();
        self.from = if self.started { now } else { target };
        self.to = target;
        self.since_us = 0;
        self.period_us = period_us;
        self.started = true;
        self.ended = false;
    }

    /// Advances by `dt_us`.
    pub fn step(&mut self, dt_us: u64) {
        if self.since_us >= self.period_us {
            self.ended = true;
        }
        self.since_us = self.since_us.saturating_add(dt_us).min(self.period_us);
    }

    /// The interpolated value now.
    pub fn value(&self) -> f64 {
        if self.period_us == 0 || self.since_us >= self.period_us {
            self.to
        } else {
            self.from + (self.to - self.from) * (self.since_us as f64 / self.period_us as f64)
        }
    }

    /// The slope of the present segment per second, through the cycle that ends it; 0
    /// once a cycle ran past it.
    pub fn slope(&self) -> f64 {
        if self.period_us == 0 || self.ended {
            0.0
        } else {
            (self.to - self.from) / (self.period_us as f64 * 1e-6)
        }
    }

    /// The set-point of the present segment.
    pub fn target(&self) -> f64 {
        self.to
    }
}

/// 0x60C2 interpolation time period as µs: `units × 10^index` s, for the indices −6 to −3
/// the dictionary allows; `None` for another index.
pub fn period_us(units: u8, index: i8) -> Option<u64> {
    let scale = match index {
        -6 => 1,
        -5 => 10,
        -4 => 100,
        -3 => 1000,
        _ => return None,
    };
    Some(u64::from(units) * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_60c2h_interpolation_period() {
        assert_eq!(period_us(1, -3), Some(1000));
        assert_eq!(period_us(250, -6), Some(250));
        assert_eq!(period_us(2, -4), Some(200));
        assert_eq!(period_us(1, 0), None);
    }

    #[test]
    fn linear_interpolation_between_syncs() {
        let mut i = Interpolator::at(0.0);
        i.sync(100.0, 1000);
        assert_eq!(i.value(), 0.0);
        i.step(250);
        assert_eq!(i.value(), 25.0);
        assert_eq!(i.slope(), 100_000.0);
        i.step(750);
        assert_eq!(i.value(), 100.0);
        assert_eq!(i.slope(), 100_000.0);
        i.step(5000);
        assert_eq!(i.value(), 100.0);
        assert_eq!(i.slope(), 0.0);
    }
}
