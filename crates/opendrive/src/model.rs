//! The drive: parameters, input logic, alarms and V/f physics, stepped at a fixed period.
//!
//! Everything here is deterministic: the same inputs at the same steps give the same
//! outputs. Quantities are floating point per-unit of the motor's ratings, the way a drive
//! firmware normalises them (currents in % of the motor's rated current, torques in % of its
//! rated torque, frequencies in Hz).

use cantwin_can::{Duration, Instant};

pub use crate::messages::Commands;
use crate::messages::{Code, CommandByte};
use crate::params::{self, C32, C35, C40, C47, C50, C52, P21, P22, P23, P24, P61, P68};
use crate::params::{P66, P70, P72, P73, P94, ParId, ParamError, Params};

/// The motor's data and the driven load's inertia.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorData {
    /// Rated frequency (Hz); the base of P68.
    pub rated_frequency_hz: f64,
    /// Rated power (kW): the scale of the power that flows back into the DC bus.
    pub rated_power_kw: f64,
    /// Magnetising current (% of rated current) at rated flux.
    pub magnetising_current_pct: f64,
    /// Mechanical starting time (s): how long rated torque takes to accelerate motor and
    /// load from standstill to rated frequency (the inertia in per-unit).
    pub starting_time_s: f64,
    /// Friction torque (% of rated torque) whenever the motor turns.
    pub friction_torque_pct: f64,
    /// Thermal time constant of the motor (s), for the I²t model.
    pub thermal_time_constant_s: f64,
}

impl Default for MotorData {
    fn default() -> Self {
        MotorData {
            rated_frequency_hz: 50.0,
            rated_power_kw: 4.0,
            magnetising_current_pct: 35.0,
            starting_time_s: 0.5,
            friction_torque_pct: 2.0,
            thermal_time_constant_s: 120.0,
        }
    }
}

/// The drive's hardware: limits and thermal data that are not parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveData {
    /// Mains voltage (V rms); the DC bus sits at 1.35 times this.
    pub mains_voltage_v: f64,
    /// DC bus capacitance (µF).
    pub dc_capacitance_uf: f64,
    /// Current limit (% of the drive's rated current): the current threshold of mux 0x18.
    pub current_limit_pct: f64,
    /// Instantaneous overcurrent trip (% of the drive's rated current): alarm A2.
    pub overcurrent_trip_pct: f64,
    /// DC bus overvoltage trip (V): alarm A11.
    pub overvoltage_trip_v: f64,
    /// DC bus voltage above which intelligent braking (C47) holds the deceleration (V).
    pub braking_threshold_v: f64,
    /// Heatsink temperature rise at the drive's rated current, steady state (K).
    pub heatsink_rise_k: f64,
    /// Heatsink thermal time constant (s).
    pub heatsink_time_constant_s: f64,
    /// Heatsink overtemperature trip (°C): alarm A4.
    pub heatsink_trip_c: f64,
    /// Power module (IGBT junction) temperature rise above the heatsink at the drive's rated
    /// current, steady state (K).
    pub module_rise_k: f64,
    /// Power module thermal time constant, junction to heatsink (s).
    pub module_time_constant_s: f64,
    /// Power module overtemperature trip (°C): alarm A5.
    pub module_trip_c: f64,
    /// Firmware version as read through mux 0x34.
    pub software_version: u16,
}

impl Default for DriveData {
    fn default() -> Self {
        DriveData {
            mains_voltage_v: 400.0,
            dc_capacitance_uf: 1000.0,
            current_limit_pct: 150.0,
            overcurrent_trip_pct: 220.0,
            overvoltage_trip_v: 780.0,
            braking_threshold_v: 720.0,
            heatsink_rise_k: 40.0,
            heatsink_time_constant_s: 60.0,
            heatsink_trip_c: 90.0,
            module_rise_k: 20.0,
            module_time_constant_s: 3.0,
            module_trip_c: 125.0,
            software_version: 0x0300,
        }
    }
}

/// A set of drive alarms, bit n = alarm An.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Alarms(pub u16);

/// Instantaneous overcurrent.
pub const A2: u8 = 2;
/// Motor overload (I²t thermal model, with C32 = 1).
pub const A3: u8 = 3;
/// Heatsink overtemperature.
pub const A4: u8 = 4;
/// Power module overtemperature: the estimated junction temperature of the output stage
/// (the second of the drive's overtemperature alarms in message 1 bit 6, manual §3.2).
pub const A5: u8 = 5;
/// DC bus overvoltage.
pub const A11: u8 = 11;

impl Alarms {
    /// No alarm.
    pub const NONE: Alarms = Alarms(0);

    /// Whether alarm `n` is active.
    pub fn contains(self, n: u8) -> bool {
        n < 16 && self.0 & (1 << n) != 0
    }

    /// Whether any alarm is active.
    pub fn any(self) -> bool {
        self.0 != 0
    }

    fn insert(&mut self, n: u8) {
        if n < 16 {
            self.0 |= 1 << n;
        }
    }

    /// The alarms message 1 reports (A2, A3, A4, A5, A11).
    pub fn handled(self) -> Alarms {
        Alarms(self.0 & (1 << A2 | 1 << A3 | 1 << A4 | 1 << A5 | 1 << A11))
    }

    /// Message 1's alarm byte (manual §3.2): bit 7 overcurrent (A2, A3), bit 6
    /// overtemperature (A4, A5), bit 5 overvoltage (A11).
    pub fn error_flag(self) -> u8 {
        let mut b = 0;
        if self.contains(A2) || self.contains(A3) {
            b |= 0x80;
        }
        if self.contains(A4) || self.contains(A5) {
            b |= 0x40;
        }
        if self.contains(A11) {
            b |= 0x20;
        }
        b
    }
}

/// Logic input function 100 + code: start ("Marcia").
pub const FN_START: i32 = 0;
/// Logic input function 112: reverse the reference ("Inversione").
pub const FN_REVERSE: i32 = 12;
/// Logic input function 114: references from the field bus (the `114` of §2.2).
pub const FN_FIELDBUS: i32 = 14;

/// What survives a power cycle: the flash.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Flash {
    /// The saved parameters and connections.
    pub params: Params,
    /// The alarms active when power was lost (cleared at power-up with C35 = 1).
    pub alarms: Alarms,
    /// The position of DIP S1 at the last power-up (to detect its 0 → 1 change).
    pub dip_s1: bool,
}

/// A flash image that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("flash image line {line}: {message}")]
pub struct FlashError {
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl Flash {
    /// The image as text, one `KEY = value` per line in internal units: what a file keeps
    /// between runs.
    pub fn to_text(&self) -> String {
        let mut t = String::from("# OPEN DRIVE application 003 flash, internal units\n");
        for (def, value) in self.params.iter() {
            t.push_str(&format!("{} = {value}\n", def.id));
        }
        t.push_str(&format!("alarms = {}\n", self.alarms.0));
        t.push_str(&format!("dip_s1 = {}\n", u8::from(self.dip_s1)));
        t
    }

    /// Parse [`Flash::to_text`]'s format; keys absent keep their defaults.
    pub fn from_text(text: &str) -> Result<Flash, FlashError> {
        let mut flash = Flash::default();
        for (i, raw) in text.lines().enumerate() {
            let err = |message: String| FlashError {
                line: i + 1,
                message,
            };
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (key, value) = line
                .split_once('=')
                .ok_or_else(|| err(format!("expected KEY = value, got {line:?}")))?;
            let (key, value) = (key.trim(), value.trim());
            let number: i64 = value
                .parse()
                .map_err(|_| err(format!("{value:?} is not an integer")))?;
            match key {
                "alarms" => {
                    flash.alarms = Alarms(
                        u16::try_from(number).map_err(|_| err(format!("alarms = {number}")))?,
                    )
                }
                "dip_s1" => flash.dip_s1 = number != 0,
                _ => {
                    let id: ParId = key.parse().map_err(|e: ParamError| err(e.to_string()))?;
                    let v = i32::try_from(number).map_err(|_| err(format!("{key} = {number}")))?;
                    flash.params.set(id, v).map_err(|e| err(e.to_string()))?;
                }
            }
        }
        Ok(flash)
    }
}

/// The drive model.
#[derive(Debug, Clone)]
pub struct Drive {
    motor: MotorData,
    hw: DriveData,
    flash: Flash,
    params: Params,
    commands: Commands,
    can_reference: u16,
    inputs: [bool; 8],
    analog_reference_hz: f64,
    dip_s1: bool,
    s1_locked: bool,
    ambient_c: f64,
    load_torque_pct: f64,
    // Physics state.
    running: bool,
    output_hz: f64,
    motor_hz: f64,
    current_pct: f64,
    dc_bus_v: f64,
    heatsink_c: f64,
    module_c: f64,
    motor_thermal: f64,
    time_in_limit_s: f64,
    in_limit: bool,
    limit_stop: bool,
    /// Message 2 mux 0x18's code while C40 = 1: 1 STOP with the minimum delay, 2 STOP
    /// delayed by P94 (C40 = 1 for both, manual §3.3).
    stop_reaction: u16,
    needs_start_edge: bool,
    alarms: Alarms,
    thermal_warning: bool,
    last_step: Option<Instant>,
    powered: bool,
}

/// Message 2 error data (manual §3.3): undefined error.
pub const ERR_UNDEFINED: u16 = 0;
/// Message 2 error data: the multiplexor is not valid.
pub const ERR_INVALID_MUX: u16 = 1;
/// Message 2 error data: the value is not allowed.
pub const ERR_VALUE: u16 = 2;

impl Drive {
    /// A drive with the defaults of application 003 in its flash, switched off.
    pub fn new(motor: MotorData, hw: DriveData) -> Drive {
        let vdc = hw.mains_voltage_v * 1.35;
        Drive {
            motor,
            hw,
            flash: Flash::default(),
            params: Params::default(),
            commands: Commands::default(),
            can_reference: 0,
            inputs: [false; 8],
            analog_reference_hz: 0.0,
            dip_s1: false,
            s1_locked: false,
            ambient_c: 40.0,
            load_torque_pct: 0.0,
            running: false,
            output_hz: 0.0,
            motor_hz: 0.0,
            current_pct: 0.0,
            dc_bus_v: vdc,
            heatsink_c: 40.0,
            module_c: 40.0,
            motor_thermal: 0.0,
            time_in_limit_s: 0.0,
            in_limit: false,
            limit_stop: false,
            stop_reaction: 2,
            needs_start_edge: false,
            alarms: Alarms::NONE,
            thermal_warning: false,
            last_step: None,
            powered: false,
        }
    }

    // ---- configuration and persistent storage ------------------------------------------

    /// The working value of a parameter or connection.
    pub fn param(&self, id: ParId) -> i32 {
        self.params.get(id)
    }

    /// The value stored in flash.
    pub fn saved_param(&self, id: ParId) -> i32 {
        self.flash.params.get(id)
    }

    /// Set a working value (keypad or serial line); [`Drive::save`] makes it survive a power
    /// cycle.
    pub fn set_param(&mut self, id: ParId, value: i32) -> Result<(), ParamError> {
        self.params.set(id, value)
    }

    /// Set a value both in the working set and in flash (factory or scenario setup).
    pub fn set_stored_param(&mut self, id: ParId, value: i32) -> Result<(), ParamError> {
        self.params.set(id, value)?;
        self.flash.params.set(id, value)
    }

    /// The flash.
    pub fn flash(&self) -> &Flash {
        &self.flash
    }

    /// Replace the flash (an image kept between runs); the working values follow at the
    /// next power-up.
    pub fn set_flash(&mut self, flash: Flash) {
        self.flash = flash;
    }

    /// Save the working values to flash (C63 = 1, message 2 mux 0x3A).
    pub fn save(&mut self) {
        self.flash.params = self.params.clone();
    }

    /// The working parameter set.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The motor data.
    pub fn motor(&self) -> &MotorData {
        &self.motor
    }

    /// The drive hardware data.
    pub fn hardware(&self) -> &DriveData {
        &self.hw
    }

    // ---- inputs --------------------------------------------------------------------------

    /// Logic input `n` (1–8) on the terminal board.
    pub fn set_input(&mut self, n: u8, on: bool) {
        if let Some(i) = self.inputs.get_mut(usize::from(n.wrapping_sub(1))) {
            *i = on;
        }
    }

    /// Logic input `n` (1–8).
    pub fn input(&self, n: u8) -> bool {
        self.inputs
            .get(usize::from(n.wrapping_sub(1)))
            .copied()
            .unwrap_or(false)
    }

    /// The frequency reference on the terminal board (Hz, magnitude).
    pub fn set_analog_reference_hz(&mut self, hz: f64) {
        self.analog_reference_hz = hz.max(0.0);
    }

    /// The frequency reference on the terminal board (Hz, magnitude).
    pub fn analog_reference_hz(&self) -> f64 {
        self.analog_reference_hz
    }

    /// Move DIP switch S1 on board CS6341 (read at power-up only, manual §2.3).
    pub fn set_dip_s1(&mut self, on: bool) {
        self.dip_s1 = on;
    }

    /// The position of DIP switch S1.
    pub fn dip_s1(&self) -> bool {
        self.dip_s1
    }

    /// The load torque (% of the motor's rated torque) opposing rotation.
    pub fn set_load_torque_pct(&mut self, pct: f64) {
        self.load_torque_pct = pct.max(0.0);
    }

    /// The ambient temperature around the heatsink (°C).
    pub fn set_ambient_c(&mut self, c: f64) {
        self.ambient_c = c;
    }

    /// The ambient temperature around the heatsink (°C).
    pub fn ambient_c(&self) -> f64 {
        self.ambient_c
    }

    /// The load torque (% of the motor's rated torque).
    pub fn load_torque_pct(&self) -> f64 {
        self.load_torque_pct
    }

    /// Reset the alarms (the keypad's or a terminal's reset).
    pub fn reset_alarms(&mut self) {
        self.alarms = Alarms::NONE;
        self.flash.alarms = Alarms::NONE;
    }

    // ---- outputs -------------------------------------------------------------------------

    /// Output frequency (Hz), positive clockwise (right), negative counter-clockwise.
    pub fn output_hz(&self) -> f64 {
        self.output_hz
    }

    /// Motor frequency (Hz): the output frequency while the drive runs, the coasting motor's
    /// otherwise.
    pub fn motor_hz(&self) -> f64 {
        self.motor_hz
    }

    /// Motor current (% of the motor's rated current).
    pub fn current_pct(&self) -> f64 {
        self.current_pct
    }

    /// Output voltage (% of Vmax) from the V/f characteristic (P66, P72, P73).
    pub fn output_voltage_pct(&self) -> f64 {
        if !self.running {
            return 0.0;
        }
        let fmax = self.fmax_hz();
        let f1 = fmax * f64::from(self.params.get(P73)) / 1000.0;
        let v1 = f64::from(self.params.get(P72)) / 10.0;
        let boost = f64::from(self.params.get(P66)) / 10.0 * self.current_pct / 100.0;
        let f = self.output_hz.abs();
        let v = if f1 <= 0.0 || f >= f1 {
            v1
        } else {
            v1 * f / f1
        };
        (v + boost).min(100.0)
    }

    /// DC bus voltage (V).
    pub fn dc_bus_v(&self) -> f64 {
        self.dc_bus_v
    }

    /// Heatsink temperature (°C).
    pub fn heatsink_c(&self) -> f64 {
        self.heatsink_c
    }

    /// The power module's estimated junction temperature (°C).
    pub fn module_c(&self) -> f64 {
        self.module_c
    }

    /// The motor's I²t thermal state: 1.0 is the trip level.
    pub fn motor_thermal(&self) -> f64 {
        self.motor_thermal
    }

    /// Whether the motor thermal model is past its level with C32 = 0 (warning only).
    pub fn thermal_warning(&self) -> bool {
        self.thermal_warning
    }

    /// Whether the output stage is enabled.
    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Whether the current is at the threshold (current limit).
    pub fn in_limit(&self) -> bool {
        self.in_limit
    }

    /// Whether a stop after P94 seconds in limit (C40 = 1) is holding the drive stopped
    /// until the start command is removed.
    pub fn limit_stopped(&self) -> bool {
        self.limit_stop
    }

    /// The active alarms.
    pub fn alarms(&self) -> Alarms {
        self.alarms
    }

    /// The command bits received on message 0.
    pub fn commands(&self) -> Commands {
        self.commands
    }

    /// The reference last received on message 0 (0.01 Hz).
    pub fn can_reference(&self) -> u16 {
        self.can_reference
    }

    /// Whether the drive ignores CAN since DIP S1 was on at power-up (manual §2.3).
    pub fn can_locked(&self) -> bool {
        self.s1_locked
    }

    // ---- input logic (manual §2.2) -------------------------------------------------------

    fn function_active(&self, code: i32) -> bool {
        (1..=8u8).any(|n| self.input(n) && self.params.get(params::input_connection(n)) == code)
    }

    fn fieldbus_enabled(&self) -> bool {
        self.params.get(C52) == 1 || self.function_active(FN_FIELDBUS)
    }

    /// `[(C52 or 114) and CAN_remote_control and /DIP S1]`: whether start and reverse come
    /// from CAN (functions 100 and 112) rather than from the terminals.
    pub fn can_control(&self) -> bool {
        self.fieldbus_enabled() && self.commands.command_remote && !self.s1_locked
    }

    /// (start, reverse) from CAN or from the terminals.
    pub fn start_reverse(&self) -> (bool, bool) {
        if self.can_control() {
            (self.commands.can_start, self.commands.can_reverse)
        } else {
            (
                self.function_active(FN_START),
                self.function_active(FN_REVERSE),
            )
        }
    }

    /// The maximum frequency fMAX (Hz): P68 of the motor's rated frequency.
    pub fn fmax_hz(&self) -> f64 {
        f64::from(self.params.get(P68)) / 1000.0 * self.motor.rated_frequency_hz
    }

    /// The frequency reference in use (Hz, magnitude): the CAN reference with the
    /// "reference remote" bit and references enabled from the field bus, the terminal's
    /// otherwise; limited to fMAX (P68).
    pub fn reference_hz(&self) -> f64 {
        let r = if self.commands.reference_remote && self.fieldbus_enabled() && !self.s1_locked {
            f64::from(self.can_reference) / 100.0
        } else {
            self.analog_reference_hz
        };
        r.min(self.fmax_hz())
    }

    // ---- power ---------------------------------------------------------------------------

    /// Mains applied at `now` (the CAN node's power-up): the motor coasted while the drive
    /// was off; working values come back from flash; DIP S1 switched 0 → 1 while off loads
    /// the defaults except the reserved ones and saves them, and from then on CAN is ignored
    /// until S1 is back at 0 at a power-up (§2.3); alarms clear with C35 = 1.
    pub fn power_up(&mut self, now: Instant) {
        if let Some(last) = self.last_step {
            let off = now.saturating_duration_since(last).as_secs_f64();
            self.coast(off);
            self.cool(off);
        }
        self.powered = true;
        self.last_step = Some(now);
        self.params = self.flash.params.clone();
        if self.dip_s1 && !self.flash.dip_s1 {
            self.params.load_free_defaults();
            self.flash.params = self.params.clone();
        }
        self.flash.dip_s1 = self.dip_s1;
        self.s1_locked = self.dip_s1;
        // The flash holds C40 and P94, not the code written to mux 0x18: after mains
        // return a STOP reaction with P94 = 1 s reads as 1 (the minimum delay).
        self.stop_reaction = if self.params.get(P94) == 10 { 1 } else { 2 };
        self.alarms = if self.params.get(C35) == 1 {
            Alarms::NONE
        } else {
            self.flash.alarms
        };
        self.flash.alarms = self.alarms;
        self.commands = Commands::default();
        self.can_reference = 0;
        self.running = false;
        self.output_hz = 0.0;
        self.current_pct = 0.0;
        self.dc_bus_v = self.vdc_nominal();
        self.time_in_limit_s = 0.0;
        self.in_limit = false;
        self.limit_stop = false;
        self.needs_start_edge = false;
    }

    fn vdc_nominal(&self) -> f64 {
        self.hw.mains_voltage_v * 1.35
    }

    fn coast(&mut self, secs: f64) {
        // Friction and load brake the freewheeling motor: dω/dt = −T / starting time.
        let decel = (self.load_torque_pct + self.motor.friction_torque_pct) / 100.0
            * self.motor.rated_frequency_hz
            / self.motor.starting_time_s.max(1e-3);
        let f = (self.motor_hz.abs() - decel * secs).max(0.0);
        self.motor_hz = f.copysign(self.motor_hz);
    }

    fn cool(&mut self, secs: f64) {
        let k = (-secs / self.motor.thermal_time_constant_s.max(1e-3)).exp();
        self.motor_thermal *= k;
        let k = (-secs / self.hw.heatsink_time_constant_s.max(1e-3)).exp();
        self.heatsink_c = self.ambient_c + (self.heatsink_c - self.ambient_c) * k;
        let k = (-secs / self.hw.module_time_constant_s.max(1e-3)).exp();
        self.module_c = self.heatsink_c + (self.module_c - self.heatsink_c) * k;
    }

    fn trip(&mut self, n: u8) {
        self.alarms.insert(n);
        self.flash.alarms = self.alarms;
        self.running = false;
        self.needs_start_edge = true;
        self.current_pct = 0.0;
    }

    // ---- physics -------------------------------------------------------------------------

    /// Advance the physics by `dt` (one physics step).
    pub fn step(&mut self, dt: Duration, now: Instant) {
        self.last_step = Some(now);
        let dt = dt.as_secs_f64();
        if dt <= 0.0 {
            return;
        }
        let fnom = self.motor.rated_frequency_hz;
        let h = self.motor.starting_time_s.max(1e-3);
        let (start, reverse) = self.start_reverse();
        if !start {
            self.limit_stop = false;
            self.needs_start_edge = false;
        }
        let want_run = start && !self.limit_stop && !self.needs_start_edge && !self.alarms.any();
        if want_run && !self.running {
            // Start: with C50 the drive searches the rotating motor and starts from its
            // frequency; without it, it starts from 0 Hz, which a motor still turning above
            // a tenth of its rated frequency answers with an overcurrent (A2).
            self.running = true;
            if self.params.get(C50) == 1 {
                self.output_hz = self.motor_hz;
            } else if self.motor_hz.abs() > 0.1 * fnom {
                self.trip(A2);
            } else {
                self.output_hz = 0.0;
            }
        }
        if !self.running {
            self.current_pct = 0.0;
            self.in_limit = false;
            self.time_in_limit_s = 0.0;
            self.coast(dt);
            self.output_hz = 0.0;
            // With the output off the DC bus settles back to the rectified mains.
            let vn = self.vdc_nominal();
            self.dc_bus_v = vn + (self.dc_bus_v - vn) * (-dt).exp();
            self.thermal(dt);
            return;
        }

        let target = if want_run {
            let r = self.reference_hz();
            if reverse { -r } else { r }
        } else {
            0.0
        };
        let f = self.output_hz;
        let fmax = self.fmax_hz().max(1e-6);
        // Ramp times run from 0 to fmax (P21–P24); which applies depends on the direction of
        // rotation and whether |f| grows.
        let cw = f > 0.0 || (f == 0.0 && target >= 0.0);
        let towards_zero = (target - f).signum() != f.signum() && f != 0.0;
        let time = |id| f64::from(self.params.get(id)) / 100.0;
        let ramp_s = match (cw, towards_zero) {
            (true, false) => time(P21),
            (true, true) => time(P22),
            (false, false) => time(P23),
            (false, true) => time(P24),
        };
        let step = fmax / ramp_s.max(1e-3) * dt;
        let mut next = approach(f, target, step);
        if f != 0.0 && next != 0.0 && next.signum() != f.signum() {
            // Reversal passes through zero within a step: stop at zero first.
            next = 0.0;
        }
        // Intelligent braking (C47) holds the deceleration while the DC bus is high.
        if towards_zero && self.params.get(C47) == 1 && self.dc_bus_v >= self.hw.braking_threshold_v
        {
            next = f;
        }

        let p61 = f64::from(self.params.get(P61)) / 1000.0;
        let to_motor_pct = |drive_pct: f64| drive_pct / p61.max(1e-3);
        let limit = to_motor_pct(self.hw.current_limit_pct);
        let trip_level = to_motor_pct(self.hw.overcurrent_trip_pct);

        let load_pct = self.load_torque_pct + self.motor.friction_torque_pct;
        let magnetising = self.motor.magnetising_current_pct;
        let current = |next: f64| {
            let accel = (next.abs() - f.abs()) / dt / fnom * h * 100.0;
            let turning = next != 0.0 || f != 0.0;
            let load = if turning { load_pct } else { 0.0 };
            let torque = load + accel;
            let flux = if next.abs() <= fnom {
                1.0
            } else {
                fnom / next.abs()
            };
            let im = magnetising * flux;
            let it = torque / flux;
            ((im * im + it * it).sqrt(), torque)
        };
        let (mut i, mut torque) = current(next);
        if i > trip_level {
            self.trip(A2);
            return;
        }
        self.in_limit = i > limit;
        if self.in_limit {
            // At the threshold the drive stops accelerating, and if the load alone is too
            // much it lowers the frequency at the deceleration rate (stall prevention).
            if next.abs() > f.abs() {
                next = f;
            }
            (i, torque) = current(next);
            if i > limit {
                next = approach(f, 0.0, step);
                (i, torque) = current(next);
            }
            i = i.min(limit);
            self.time_in_limit_s += dt;
            let p94 = f64::from(self.params.get(P94)) / 10.0;
            if self.params.get(C40) == 1 && self.time_in_limit_s + 1e-9 >= p94 {
                self.limit_stop = true;
            }
        } else {
            self.time_in_limit_s = 0.0;
        }

        // DC bus: the power the motor sends back charges the capacitors; the mains only
        // ever supplies.
        let speed = (f.abs() + next.abs()) / 2.0 / fnom;
        let p_mech = torque / 100.0 * speed * self.motor.rated_power_kw * 1000.0;
        let p_loss = self.motor.rated_power_kw * 1000.0 * (0.02 + 0.04 * (i / 100.0).powi(2));
        let p = p_mech + p_loss;
        let c = self.hw.dc_capacitance_uf * 1e-6;
        let vn = self.vdc_nominal();
        let v2 = self.dc_bus_v * self.dc_bus_v - 2.0 * p * dt / c;
        self.dc_bus_v = v2.max(vn * vn).sqrt();

        self.output_hz = next;
        self.motor_hz = next;
        self.current_pct = i;
        if self.dc_bus_v > self.hw.overvoltage_trip_v {
            self.trip(A11);
            return;
        }
        if !want_run && next == 0.0 {
            self.running = false;
            self.current_pct = 0.0;
        }
        self.thermal(dt);
    }

    fn thermal(&mut self, dt: f64) {
        // Motor I²t: first order towards (I / P70)², trip at 1.
        let p70 = f64::from(self.params.get(P70)) / 10.0;
        let ratio = self.current_pct / p70.max(1.0);
        let tau = self.motor.thermal_time_constant_s.max(1e-3);
        self.motor_thermal += (ratio * ratio - self.motor_thermal) * (dt / tau).min(1.0);
        if self.motor_thermal >= 1.0 {
            if self.params.get(C32) == 1 {
                if !self.alarms.contains(A3) {
                    self.trip(A3);
                }
            } else {
                self.thermal_warning = true;
            }
        } else {
            self.thermal_warning = false;
        }
        // Heatsink: first order towards ambient + rise × (I_drive / I_rated)².
        let p61 = f64::from(self.params.get(P61)) / 1000.0;
        let drive_pu = self.current_pct / 100.0 * p61;
        let target = self.ambient_c + self.hw.heatsink_rise_k * drive_pu * drive_pu;
        let tau = self.hw.heatsink_time_constant_s.max(1e-3);
        self.heatsink_c += (target - self.heatsink_c) * (dt / tau).min(1.0);
        if self.heatsink_c >= self.hw.heatsink_trip_c && !self.alarms.contains(A4) {
            self.trip(A4);
        }
        // Power module: its junctions sit above the heatsink by the losses of the current
        // they carry, with a time constant of seconds where the heatsink's is a minute. An
        // overload the heatsink would carry for a minute (150 % at the current limit) heats
        // the junctions to their limit first: A5, while the heatsink is still below A4's.
        let target = self.heatsink_c + self.hw.module_rise_k * drive_pu * drive_pu;
        let tau = self.hw.module_time_constant_s.max(1e-3);
        self.module_c += (target - self.module_c) * (dt / tau).min(1.0);
        if self.module_c >= self.hw.module_trip_c && !self.alarms.contains(A5) {
            self.trip(A5);
        }
    }

    // ---- message 0 (manual §3.1) ---------------------------------------------------------

    /// Message 0's answer data: command state byte (`10` set, `01` reset per bit pair) and
    /// the frequency reference in use in 0.01 Hz, little-endian.
    pub fn message0_state(&self) -> [u8; 3] {
        let pair = |b: bool| if b { 0b10 } else { 0b01 };
        let c = self.commands;
        let state = pair(c.reference_remote) << 6
            | pair(c.command_remote) << 4
            | pair(c.can_start) << 2
            | pair(c.can_reverse);
        let r = (self.reference_hz() * 100.0).round().clamp(0.0, 65535.0) as u16;
        let [lo, hi] = r.to_le_bytes();
        [state, lo, hi]
    }

    /// Apply message 0's write data: command byte and reference. Errors are message 2's
    /// error data codes.
    pub fn message0_write(&mut self, data: &[u8]) -> Result<[u8; 3], u16> {
        let [cmd, lo, hi] = <[u8; 3]>::try_from(data).map_err(|_| ERR_UNDEFINED)?;
        // Manual §3.1 gives message 0 no error data: a reference above fMAX is taken and
        // limited to fMAX where it is used (`reference_hz`), and the answer carries the
        // reference in use.
        let reference = u16::from_le_bytes([lo, hi]);
        let codes = CommandByte::decode(cmd);
        let apply = |bit: &mut bool, code: Code| match code {
            Code::Set => *bit = true,
            Code::Reset => *bit = false,
            Code::NoChange => {}
        };
        let c = &mut self.commands;
        apply(&mut c.reference_remote, codes.reference_remote);
        apply(&mut c.command_remote, codes.command_remote);
        if c.command_remote {
            // CAN-Start and CAN-Reverse are valid only with "comando Remote" set.
            apply(&mut c.can_start, codes.can_start);
            apply(&mut c.can_reverse, codes.can_reverse);
        } else {
            // Back to the terminals: a later switch to remote must not restart the motor.
            c.can_start = false;
            c.can_reverse = false;
        }
        self.can_reference = reference;
        Ok(self.message0_state())
    }

    // ---- message 2 (manual §3.3) ---------------------------------------------------------

    /// Read multiplexor `mux`.
    pub fn mux_read(&self, mux: u8) -> Result<u16, u16> {
        let fnom_centi = (self.motor.rated_frequency_hz * 100.0).round();
        Ok(match mux {
            0x00 => (f64::from(self.params.get(P68)) * fnom_centi / 1000.0)
                .round()
                .min(65535.0) as u16,
            0x18 => match self.params.get(C40) {
                0 => 0,
                _ => self.stop_reaction,
            },
            0x19 => (f64::from(self.params.get(P70)) * 256.0 / 2000.0).round() as u16,
            0x1B => self.params.get(P94) as u16,
            0x34 => self.hw.software_version,
            0x3A => 0,
            _ => return Err(ERR_INVALID_MUX),
        })
    }

    /// Write multiplexor `mux` with `value`.
    pub fn mux_write(&mut self, mux: u8, value: u16) -> Result<u16, u16> {
        let v = f64::from(value);
        let set = |p: &mut Params, id, x: i32| p.set(id, x).map_err(|_| ERR_VALUE);
        match mux {
            0x00 => {
                // fMAX: P68 = data / (fnom × 100), in % of the rated frequency. The data's
                // range is P68's printed 20.0–400.0 % in 0.01 Hz (1000–20000 at 50 Hz),
                // checked on the data itself so that no value outside rounds into it.
                let fnom_centi = (self.motor.rated_frequency_hz * 100.0).round();
                let def = params::def(P68).ok_or(ERR_UNDEFINED)?;
                let lo = (f64::from(def.min) * fnom_centi / 1000.0).ceil();
                let hi = (f64::from(def.max) * fnom_centi / 1000.0).floor();
                if v < lo || v > hi {
                    return Err(ERR_VALUE);
                }
                let p68 = (v * 1000.0 / fnom_centi).round() as i32;
                set(&mut self.params, P68, p68.clamp(def.min, def.max))?;
            }
            0x18 => {
                // 0 none, 1 STOP with the minimum delay (P94 = 1 s), 2 STOP delayed by P94,
                // 3 and 4 as 0.
                if value > 4 {
                    return Err(ERR_VALUE);
                }
                let stop = matches!(value, 1 | 2);
                set(&mut self.params, C40, i32::from(stop))?;
                if value == 1 {
                    set(&mut self.params, P94, 10)?;
                }
                if stop {
                    self.stop_reaction = value;
                }
            }
            0x19 => {
                // Base 256 = 200 % of the motor's rated current.
                if value > 256 {
                    return Err(ERR_VALUE);
                }
                let p70 = (v * 2000.0 / 256.0).round() as i32;
                set(&mut self.params, P70, p70)?;
            }
            0x1B => set(&mut self.params, P94, i32::from(value))?,
            0x34 => return Err(ERR_INVALID_MUX),
            0x3A => {
                if value != 1 {
                    return Err(ERR_VALUE);
                }
                self.save();
            }
            _ => return Err(ERR_INVALID_MUX),
        }
        Ok(value)
    }
}

fn approach(from: f64, to: f64, step: f64) -> f64 {
    if (to - from).abs() <= step + 1e-9 {
        to
    } else if to > from {
        from + step
    } else {
        from - step
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive() -> Drive {
        let mut d = Drive::new(MotorData::default(), DriveData::default());
        d.power_up(Instant::ZERO);
        d
    }

    #[test]
    fn message0_codes_and_validity() {
        let mut d = drive();
        // Start and reverse "set" without command remote: ignored.
        assert_eq!(d.message0_write(&[0b00_00_10_10, 0, 0]), Ok([0x55, 0, 0]));
        // Reference remote, command remote, start set; reverse unchanged (11).
        assert_eq!(
            d.message0_write(&[0b10_10_10_11, 0x88, 0x13]),
            Ok([0b10_10_10_01, 0x88, 0x13])
        );
        // Command remote reset clears start and reverse.
        assert_eq!(
            d.message0_write(&[0b00_01_00_00, 0x88, 0x13]),
            Ok([0b10_01_01_01, 0x88, 0x13])
        );
        // Above fMAX (60.00 Hz): taken, the state carries the reference in use.
        assert_eq!(
            d.message0_write(&[0, 0x10, 0x27]),
            Ok([0b10_01_01_01, 0x70, 0x17])
        );
        assert_eq!(d.message0_write(&[0, 0]), Err(ERR_UNDEFINED));
    }

    #[test]
    fn mux_normalisations() {
        let mut d = drive();
        assert_eq!(d.mux_read(0x00), Ok(6000));
        assert_eq!(d.mux_write(0x00, 5000), Ok(5000));
        assert_eq!(d.param(P68), 1000);
        assert_eq!(d.mux_write(0x19, 256), Ok(256));
        assert_eq!(d.param(P70), 2000);
        assert_eq!(d.mux_write(0x19, 128), Ok(128));
        assert_eq!(d.param(P70), 1000);
        assert_eq!(d.mux_write(0x1B, 250), Ok(250));
        assert_eq!(d.param(P94), 250);
        assert_eq!(d.mux_write(0x18, 1), Ok(1));
        assert_eq!((d.param(C40), d.param(P94)), (1, 10));
    }
}

#[cfg(test)]
mod flash_tests {
    use super::*;
    use crate::params::{P21, P180};

    #[test]
    fn flash_image_round_trip_and_errors() {
        let mut f = Flash::default();
        f.params.set(P21, 123).unwrap();
        f.alarms = Alarms(1 << A3);
        f.dip_s1 = true;
        let text = f.to_text();
        assert!(text.contains("P21 = 123\n") && text.contains("alarms = 8\n"));
        assert_eq!(Flash::from_text(&text), Ok(f));
        assert_eq!(Flash::from_text("P180 = 5\n").unwrap().params.get(P180), 5);
        let e = Flash::from_text("# x\nP180 = 1761\n").unwrap_err();
        assert_eq!(e.line, 2);
        assert!(Flash::from_text("P99 = 1").is_err());
        assert!(Flash::from_text("P21").is_err());
        assert!(Flash::from_text("P21 = x").is_err());
    }
}

#[cfg(test)]
mod vf_tests {
    use super::*;

    #[test]
    fn output_voltage_follows_the_vf_characteristic_p72_p73_with_p66_boost() {
        let mut d = Drive::new(MotorData::default(), DriveData::default());
        d.power_up(Instant::ZERO);
        assert_eq!(d.output_voltage_pct(), 0.0);
        d.set_analog_reference_hz(25.0);
        d.set_input(4, true);
        let mut t = Instant::ZERO;
        for _ in 0..2000 {
            t += Duration::from_millis(1);
            d.step(Duration::from_millis(1), t);
        }
        assert_eq!(d.output_hz(), 25.0);
        // Point 1 at 83.3 % of fMAX (P68 = 120 % of 50 Hz: point 1 falls at the rated
        // frequency) and 100 % voltage; boost 5.7 % at rated current.
        let expected = 100.0 * 25.0 / (60.0 * 0.833) + 5.7 * d.current_pct() / 100.0;
        assert!((d.output_voltage_pct() - expected).abs() < 1e-9);
        d.set_analog_reference_hz(50.0);
        for _ in 0..2000 {
            t += Duration::from_millis(1);
            d.step(Duration::from_millis(1), t);
        }
        // Above point 1 the voltage stays at P72 (capped at 100 %).
        assert_eq!(d.output_voltage_pct(), 100.0);
    }
}
