//! The drive: command sources, speed ramp, motor current, a first-order thermal model,
//! digital and analog I/O, WordComp/WordDecomp, and the alarm list.
//!
//! The control task runs every millisecond of bus time ([`STEP`]) while anything moves or
//! warms, and sleeps otherwise; inputs (a received PDO, a parameter write) are evaluated at
//! once. Choices the manual leaves open, each pinned by a test:
//!
//! * **Commands**: `Commands remote sel` = Digital takes enable and start from `Dig enable
//!   src` / `Dig start src`; Terminals takes them from digital inputs 1 and 2. A fieldbus
//!   profile (CiA 402) may take over both.
//! * **Ramp**: linear, `Acceleration 0` when the speed magnitude grows, `Deceleration 0` when
//!   it shrinks, `Fast stop decel` for a fast (quick) stop; the reference is clamped to
//!   ±`Full scale speed`. The speed loop is ideal: motor speed = ramp output. Without
//!   enable the motor coasts down at the deceleration rate.
//! * **Current**: 30 % of rated (magnetising) + the load torque sim (% of rated) + 50 % while
//!   ramping, only while enabled.
//! * **Thermal**: θ' = ((I/In)² − θ)/τ with τ = `Motor thermal tc`; `Motor thermal load` =
//!   100·θ %; Motor overload trips at 110 %.
//! * **Alarms** trip the drive (enable drops, motor coasts); `Alarm reset` (write 1) clears
//!   them, except Motor overload while the motor is still above 100 %.

use cantwin_can::{Duration, Instant};

use crate::alarms::Alarm;
use cantwin_cia402::units::to_i64;
use std::sync::LazyLock;

use crate::params::{ParamDb, Slot, par};

/// The control task period.
pub const STEP: Duration = Duration::from_millis(1);

/// Enable/start/fast stop from a fieldbus profile instead of the command source.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProfileCommands {
    /// Power stage enabled.
    pub enable: bool,
    /// Run (follow the reference).
    pub start: bool,
    /// Fast stop: ramp to zero at the fast stop deceleration.
    pub fast_stop: bool,
    /// Speed reference, rpm (replaces `Ramp ref 1`).
    pub reference: i64,
    /// Acceleration and deceleration, rpm/s (replace `Acceleration 0`/`Deceleration 0`).
    pub rates: Option<(f64, f64)>,
}

/// A change of the alarm list, for the fieldbus card to report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlarmEvent {
    /// An alarm became active.
    Raised(Alarm),
    /// An alarm was reset.
    Cleared(Alarm),
}

/// The drive model. See the [module documentation](self).
#[derive(Debug, Clone, Default)]
pub struct Drive {
    speed: f64,
    current: f64,
    thermal: f64,
    ramping: bool,
    alarms: Vec<Alarm>,
    events: Vec<AlarmEvent>,
    inputs: u16,
    analog: [i64; 2],
    profile: Option<ProfileCommands>,
    next_step: Option<Instant>,
    /// Whether no source the control task reads names a parameter it sets later in the
    /// same step, for the settings generation it was found for (see [`Drive::advance`]).
    feedback_free: Option<(u64, bool)>,
}

/// Whether the boolean source the parameter in slot `src` names is on.
fn bit(db: &ParamDb, src: Slot) -> bool {
    let s = db.at(src) as u16;
    s != 0 && db.value(s) != 0
}

/// The slots of the parameters the control task reads and sets every step.
struct Slots {
    digital_input_mon: Slot,
    digital_inputs: [Slot; 8],
    analog_inputs: [Slot; 2],
    word_decomp_src: Slot,
    word_decomp_mon: Slot,
    word_decomp_bits: [Slot; 16],
    alarm_reset: Slot,
    commands_remote_sel: Slot,
    dig_enable_src: Slot,
    dig_start_src: Slot,
    full_scale_speed: Slot,
    ramp_ref_1_src: Slot,
    acceleration: Slot,
    deceleration: Slot,
    fast_stop_decel: Slot,
    rated_current: Slot,
    load: Slot,
    thermal_tc: Slot,
    ramp_output: Slot,
    motor_speed: Slot,
    output_current: Slot,
    motor_thermal: Slot,
    speed_zero_thr: Slot,
    speed_is_zero: Slot,
    enable_state: Slot,
    drive_ok: Slot,
    run_state: Slot,
    active_alarm: Slot,
    digital_output_srcs: [Slot; 4],
    digital_output_mon: Slot,
    word_comp_bit_srcs: [Slot; 16],
    word_comp_mon: Slot,
}

static SLOTS: LazyLock<Slots> = LazyLock::new(|| Slots {
    digital_input_mon: Slot::of(par::DIGITAL_INPUT_MON),
    digital_inputs: core::array::from_fn(|k| Slot::of(par::digital_input(k as u16 + 1))),
    analog_inputs: [Slot::of(par::ANALOG_INPUT_1), Slot::of(par::ANALOG_INPUT_2)],
    word_decomp_src: Slot::of(par::WORD_DECOMP_SRC),
    word_decomp_mon: Slot::of(par::WORD_DECOMP_MON),
    word_decomp_bits: core::array::from_fn(|k| Slot::of(par::word_decomp_bit(k as u16))),
    alarm_reset: Slot::of(par::ALARM_RESET),
    commands_remote_sel: Slot::of(par::COMMANDS_REMOTE_SEL),
    dig_enable_src: Slot::of(par::DIG_ENABLE_SRC),
    dig_start_src: Slot::of(par::DIG_START_SRC),
    full_scale_speed: Slot::of(par::FULL_SCALE_SPEED),
    ramp_ref_1_src: Slot::of(par::RAMP_REF_1_SRC),
    acceleration: Slot::of(par::ACCELERATION),
    deceleration: Slot::of(par::DECELERATION),
    fast_stop_decel: Slot::of(par::FAST_STOP_DECEL),
    rated_current: Slot::of(par::RATED_CURRENT),
    load: Slot::of(par::LOAD),
    thermal_tc: Slot::of(par::THERMAL_TC),
    ramp_output: Slot::of(par::RAMP_OUTPUT),
    motor_speed: Slot::of(par::MOTOR_SPEED),
    output_current: Slot::of(par::OUTPUT_CURRENT),
    motor_thermal: Slot::of(par::MOTOR_THERMAL),
    speed_zero_thr: Slot::of(par::SPEED_ZERO_THR),
    speed_is_zero: Slot::of(par::SPEED_IS_ZERO),
    enable_state: Slot::of(par::ENABLE_STATE),
    drive_ok: Slot::of(par::DRIVE_OK),
    run_state: Slot::of(par::RUN_STATE),
    active_alarm: Slot::of(par::ACTIVE_ALARM),
    digital_output_srcs: core::array::from_fn(|k| Slot::of(par::digital_output_src(k as u16 + 1))),
    digital_output_mon: Slot::of(par::DIGITAL_OUTPUT_MON),
    word_comp_bit_srcs: core::array::from_fn(|k| Slot::of(par::word_comp_bit_src(k as u16))),
    word_comp_mon: Slot::of(par::WORD_COMP_MON),
});

impl Drive {
    /// A drive at rest, cold, without alarms.
    pub fn new() -> Self {
        Drive::default()
    }

    /// A drive reset: the motor stops, alarms and the profile are gone; the inputs (wired
    /// terminals) keep their state.
    pub fn restart(&mut self) {
        *self = Drive {
            inputs: self.inputs,
            analog: self.analog,
            ..Drive::default()
        };
    }

    /// Motor speed, rpm.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Motor current, A.
    pub fn current(&self) -> f64 {
        self.current
    }

    /// Thermal load, 1.0 = rated.
    pub fn thermal(&self) -> f64 {
        self.thermal
    }

    /// Active alarms, oldest first.
    pub fn alarms(&self) -> &[Alarm] {
        &self.alarms
    }

    /// Sets digital input k (1..=8).
    pub fn set_digital_input(&mut self, k: u8, on: bool) {
        if (1..=8).contains(&k) {
            let m = 1u16 << (k - 1);
            self.inputs = if on {
                self.inputs | m
            } else {
                self.inputs & !m
            };
        }
    }

    /// Digital input k (1..=8); `false` for other k.
    pub fn digital_input(&self, k: u8) -> bool {
        (1..=8).contains(&k) && self.inputs & (1 << (k - 1)) != 0
    }

    /// Analog input k (1..=2) in volts, as quantised by the converter; 0 for other k.
    pub fn analog_input(&self, k: u8) -> f64 {
        match k {
            1 | 2 => self.analog[usize::from(k - 1)] as f64 / 1638.4,
            _ => 0.0,
        }
    }

    /// Sets analog input k (1..=2) in volts (±10 V = ±16384 counts).
    pub fn set_analog_input(&mut self, k: u8, volts: f64) {
        if (1..=2).contains(&k) {
            let counts = (volts.clamp(-10.0, 10.0) * 1638.4).round() as i64;
            self.analog[usize::from(k - 1)] = counts;
        }
    }

    /// Lets a fieldbus profile command the drive (or gives the command back with `None`).
    pub fn set_profile(&mut self, p: Option<ProfileCommands>) {
        self.profile = p;
    }

    /// Raises `alarm` (nothing if it is already active).
    pub fn raise(&mut self, alarm: Alarm) {
        if !self.alarms.contains(&alarm) {
            self.alarms.push(alarm);
            self.events.push(AlarmEvent::Raised(alarm));
        }
    }

    /// Resets the alarms whose cause is gone; returns whether none is left.
    pub fn reset_alarms(&mut self) -> bool {
        let hot = self.thermal >= 1.0;
        let mut kept = Vec::new();
        for a in self.alarms.drain(..) {
            if a == Alarm::MotorOverload && hot {
                kept.push(a);
            } else {
                self.events.push(AlarmEvent::Cleared(a));
            }
        }
        self.alarms = kept;
        self.alarms.is_empty()
    }

    /// Whether alarm changes wait for [`Drive::poll_event`].
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The next alarm change, oldest first.
    pub fn poll_event(&mut self) -> Option<AlarmEvent> {
        if self.events.is_empty() {
            None
        } else {
            Some(self.events.remove(0))
        }
    }

    fn idle(&self) -> bool {
        self.speed == 0.0 && self.current == 0.0 && self.thermal < 1e-4 && !self.ramping
    }

    /// Runs the control task up to `now`, then evaluates the inputs at `now`.
    ///
    /// A control step that ran at `now` already evaluated the inputs at `now`: the
    /// evaluation is not repeated unless a source reads a parameter the step sets after the
    /// source is read (the evaluation then carries that value one stage further, as it
    /// always did).
    pub fn advance(&mut self, db: &mut ParamDb, now: Instant) {
        let mut stepped_now = false;
        while let Some(t) = self.next_step {
            if t > now {
                break;
            }
            self.step(db, STEP.as_secs_f64());
            stepped_now = t == now;
            self.next_step = if self.idle() && !self.wants_motion(db) {
                None
            } else {
                Some(t + STEP)
            };
        }
        if !(stepped_now && self.is_feedback_free(db)) {
            self.step(db, 0.0);
        }
        if self.next_step.is_none() && (!self.idle() || self.wants_motion(db)) {
            let ms = STEP.as_nanos();
            self.next_step = Some(Instant::from_nanos((now.as_nanos() / ms + 1) * ms));
        }
    }

    /// Whether every source the step reads names a parameter set before it in the step (or
    /// not set by the step at all); cached per settings generation.
    fn is_feedback_free(&mut self, db: &ParamDb) -> bool {
        let generation = db.generation();
        if let Some((g, free)) = self.feedback_free
            && g == generation
        {
            return free;
        }
        let s: &Slots = &SLOTS;
        // What the step sets after the commands and the ramp reference are read, and
        // after the digital outputs and WordComp read theirs.
        let monitors = [
            par::RAMP_OUTPUT,
            par::MOTOR_SPEED,
            par::OUTPUT_CURRENT,
            par::MOTOR_THERMAL,
            par::SPEED_IS_ZERO,
            par::ENABLE_STATE,
            par::DRIVE_OK,
            par::RUN_STATE,
            par::ACTIVE_ALARM,
            par::DIGITAL_OUTPUT_MON,
            par::WORD_COMP_MON,
        ];
        let late = [par::DIGITAL_OUTPUT_MON, par::WORD_COMP_MON];
        let names = |slot: Slot, set: &[u16]| set.contains(&(db.at(slot) as u16));
        let early = [
            s.word_decomp_src,
            s.dig_enable_src,
            s.dig_start_src,
            s.ramp_ref_1_src,
        ];
        let free = !early.iter().any(|x| names(*x, &monitors))
            && !s
                .digital_output_srcs
                .iter()
                .chain(&s.word_comp_bit_srcs)
                .any(|x| names(*x, &late));
        self.feedback_free = Some((generation, free));
        free
    }

    /// When the control task runs next.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.next_step
    }

    fn commands(&self, db: &ParamDb, s: &Slots) -> (bool, bool, bool) {
        if let Some(p) = self.profile {
            return (p.enable, p.start, p.fast_stop);
        }
        if db.at(s.commands_remote_sel) == 1 {
            (bit(db, s.dig_enable_src), bit(db, s.dig_start_src), false)
        } else {
            (self.inputs & 1 != 0, self.inputs & 2 != 0, false)
        }
    }

    fn wants_motion(&self, db: &ParamDb) -> bool {
        let (enable, _, _) = self.commands(db, &SLOTS);
        enable && self.alarms.is_empty()
    }

    fn step(&mut self, db: &mut ParamDb, dt: f64) {
        let s: &Slots = &SLOTS;
        // Inputs.
        db.force_at(s.digital_input_mon, i64::from(self.inputs));
        db.force_bits_at(&s.digital_inputs, i64::from(self.inputs));
        db.force_at(s.analog_inputs[0], self.analog[0]);
        db.force_at(s.analog_inputs[1], self.analog[1]);
        // WordDecomp.
        let src = db.at(s.word_decomp_src) as u16;
        let word = if src == 0 { 0 } else { db.value(src) & 0xFFFF };
        db.force_at(s.word_decomp_mon, word);
        db.force_bits_at(&s.word_decomp_bits, word);
        // Commands.
        if db.at(s.alarm_reset) != 0 {
            db.force_at(s.alarm_reset, 0);
            self.reset_alarms();
        }
        let (enable, start, fast_stop) = self.commands(db, s);
        let enabled = enable && self.alarms.is_empty();
        let run = enabled && start && !fast_stop;
        // Ramp.
        let fs = db.at(s.full_scale_speed) as f64;
        let (reference, rates) = match self.profile {
            Some(p) => (p.reference as f64, p.rates),
            None => {
                let src = db.at(s.ramp_ref_1_src) as u16;
                let r = if src == 0 { 0 } else { db.value(src) };
                (r as f64, None)
            }
        };
        let target = if run { reference.clamp(-fs, fs) } else { 0.0 };
        let (acc, dec) =
            rates.unwrap_or((db.at(s.acceleration) as f64, db.at(s.deceleration) as f64));
        let rate = if fast_stop && enabled {
            db.at(s.fast_stop_decel) as f64
        } else if target.abs() > self.speed.abs() && target * self.speed >= 0.0 {
            acc
        } else {
            dec
        };
        let before = self.speed;
        if dt > 0.0 {
            let max = rate * dt;
            let delta = (target - self.speed).clamp(-max, max);
            self.speed += delta;
            if (self.speed - target).abs() < 1e-9 {
                self.speed = target;
            }
        }
        self.ramping = (self.speed - target).abs() > 0.0 || (dt > 0.0 && before != self.speed);
        // Current and temperature.
        let rated = db.at(s.rated_current) as f64 / 10.0;
        self.current = if enabled {
            let load = (db.at(s.load) as f64 / 100.0).abs();
            let accel = if self.speed != target { 0.5 } else { 0.0 };
            rated * (0.3 + load + accel)
        } else {
            0.0
        };
        if dt > 0.0 {
            let tau = db.at(s.thermal_tc) as f64;
            let ratio = if rated > 0.0 {
                self.current / rated
            } else {
                0.0
            };
            self.thermal += dt / tau * (ratio * ratio - self.thermal);
            if self.thermal < 1e-6 && self.current == 0.0 {
                self.thermal = 0.0;
            }
            if self.thermal >= 1.1 {
                self.raise(Alarm::MotorOverload);
            }
        }
        // Monitors.
        let speed = to_i64(self.speed);
        db.force_at(s.ramp_output, speed);
        db.force_at(s.motor_speed, speed);
        db.force_at(s.output_current, to_i64(self.current * 10.0));
        db.force_at(s.motor_thermal, to_i64(self.thermal * 100.0));
        let zero = speed.abs() <= db.at(s.speed_zero_thr);
        db.force_at(s.speed_is_zero, i64::from(zero));
        let enabled = enable && self.alarms.is_empty();
        db.force_at(s.enable_state, i64::from(enabled));
        db.force_at(s.drive_ok, i64::from(self.alarms.is_empty()));
        db.force_at(s.run_state, i64::from(enabled && start));
        let active = self.alarms.first().map_or(0, |a| a.emcy_code());
        db.force_at(s.active_alarm, i64::from(active));
        // Digital outputs and WordComp.
        let mut outputs = 0;
        for (k, slot) in s.digital_output_srcs.iter().enumerate() {
            if bit(db, *slot) {
                outputs |= 1 << k;
            }
        }
        db.force_at(s.digital_output_mon, outputs);
        let mut comp = 0;
        for (k, slot) in s.word_comp_bit_srcs.iter().enumerate() {
            if bit(db, *slot) {
                comp |= 1 << k;
            }
        }
        db.force_at(s.word_comp_mon, comp);
    }

    /// Digital output k (1..=4).
    pub fn digital_output(db: &ParamDb, k: u8) -> bool {
        (1..=4).contains(&k) && db.value(par::DIGITAL_OUTPUT_MON) >> (k - 1) & 1 != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_ms(ms: u64) -> Instant {
        Instant::from_nanos(ms * 1_000_000)
    }

    #[test]
    fn bit_monitors_hold_0_and_1_so_the_control_task_sets_them_unclamped() {
        let bits = (1..=8)
            .map(par::digital_input)
            .chain((0..16).map(par::word_decomp_bit));
        for p in bits {
            let d = crate::params::def(p).expect("a bit monitor of the catalogue");
            let (lo, hi) = d.ty.range();
            assert!(lo <= 0 && hi >= 1, "parameter {p}: {lo}..={hi}");
        }
        // And they read back what the task set.
        let mut db = ParamDb::new();
        let mut d = Drive::new();
        d.set_digital_input(1, true);
        d.set_digital_input(8, true);
        d.advance(&mut db, at_ms(0));
        assert_eq!(db.value(par::digital_input(1)), 1);
        assert_eq!(db.value(par::digital_input(2)), 0);
        assert_eq!(db.value(par::digital_input(8)), 1);
    }

    #[test]
    fn terminals_enable_and_start_ramp_at_the_acceleration() {
        let mut db = ParamDb::new();
        db.set(par::DIG_RAMP_REF_1, 500).unwrap();
        let mut d = Drive::new();
        d.set_digital_input(1, true);
        d.set_digital_input(2, true);
        d.advance(&mut db, at_ms(0));
        assert_eq!(d.next_deadline(), Some(at_ms(1)));
        d.advance(&mut db, at_ms(100));
        assert_eq!(db.value(par::MOTOR_SPEED), 100);
        d.advance(&mut db, at_ms(1000));
        assert_eq!(db.value(par::MOTOR_SPEED), 500);
        assert_eq!(db.value(par::ENABLE_STATE), 1);
        assert_eq!(db.value(par::SPEED_IS_ZERO), 0);
        assert_eq!(
            db.value(par::OUTPUT_CURRENT),
            30,
            "30 % of 10 A at constant speed"
        );
        d.set_digital_input(2, false);
        d.advance(&mut db, at_ms(1250));
        assert_eq!(db.value(par::MOTOR_SPEED), 250);
        d.advance(&mut db, at_ms(2000));
        assert_eq!(db.value(par::SPEED_IS_ZERO), 1);
    }

    #[test]
    fn thermal_model_trips_motor_overload_and_reset_waits_for_cooling() {
        let mut db = ParamDb::new();
        db.set(par::LOAD, 120).unwrap();
        db.set(par::THERMAL_TC, 1).unwrap();
        let mut d = Drive::new();
        d.set_digital_input(1, true);
        d.advance(&mut db, at_ms(0));
        // (0.3 + 1.2)² = 2.25 steady state: 110 % after τ·ln(2.25 / 1.15) ≈ 671 ms.
        d.advance(&mut db, at_ms(670));
        assert!(d.alarms().is_empty());
        d.advance(&mut db, at_ms(672));
        assert_eq!(d.alarms(), [Alarm::MotorOverload]);
        assert_eq!(
            d.poll_event(),
            Some(AlarmEvent::Raised(Alarm::MotorOverload))
        );
        assert_eq!(db.value(par::ENABLE_STATE), 0);
        assert!(!d.reset_alarms(), "still hot");
        d.advance(&mut db, at_ms(10000));
        assert!(d.reset_alarms());
        assert_eq!(
            d.poll_event(),
            Some(AlarmEvent::Cleared(Alarm::MotorOverload))
        );
    }
}
