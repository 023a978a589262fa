//! A servo drive over its object dictionary: the power drive state machine, every operating
//! mode, the cascaded controller and the plant, stepped in virtual time. Sans-IO: the
//! owner (a twin) calls [`Drive::evaluate`] after every write of the dictionary's CiA 402
//! objects ([`Drive::evaluate_written`] when it knows which inputs were written),
//! [`Drive::advance`] to bring the drive to a bus time, and [`Drive::sync`] at every SYNC;
//! the drive reads its inputs and parameters from the dictionary and writes its actual
//! values and statusword back. It keeps no copy of what the dictionary holds beyond a
//! write: the parameters are read again after any write of them, an input after a write
//! of it (after any write, for an owner that does not say which).
//!
//! The control loop runs every [`DriveConfig::loop_period`] on a fixed grid from power-up;
//! the values in the dictionary are those of the last loop cycle.
//!
//! What the drive does beside the modes (each with the modes' modules):
//!
//! * **Stopping** ([`Motion::Stop`]): the demand velocity ramps to 0 with 0x6084 profile
//!   deceleration (slow down ramp; 0x609A in homing), 0x6085 quick stop deceleration
//!   (quick stop ramp), or at once at the torque limit (current and voltage limit). The
//!   torque modes stop the same way, under velocity control. The stop is complete when
//!   the actual velocity is within 0x606F velocity threshold of 0.
//! * **Limit switches** (0x60FD bits 0, 1): while one is active, a demand moving into it is
//!   stopped with 0x6085 quick stop deceleration and statusword bit 11 (internal limit
//!   active) is set; a demand moving away from it is followed. Homing looks for them
//!   itself.
//! * **Software position limits** (0x607D, in force when min < max): pp targets are
//!   limited to them, the csp and ip demand is held within them, and pv, csv and the
//!   torque modes stop at them as at a limit switch; bit 11 while so.
//! * **Following error** (position modes pp, ip, hm, csp): 0x60F4 is demand minus actual
//!   position. Beyond 0x6065 following error window (FFFF FFFFh: off) for longer than
//!   0x6066 following error time out, statusword bit 13 is set, and the drive faults
//!   with error code 0x8611 (following error), taking the 0x605E fault reaction.
//! * **Power stage**: over-current (0x2310) and DC link under- and over-voltage (0x3220,
//!   0x3210) switch the bridge off at once and fault the drive; the motor coasts.
//!   Statusword bit 4 (voltage enabled) is set while high voltage is applied and the DC
//!   link is up.
//! * **Fault reset**: a rising edge of controlword bit 7 clears the faults whose cause is
//!   gone (the following error always), then transition 15 follows.

use cantwin_can::Duration;
use cantwin_canopen::device::Device;
use cantwin_canopen::od::{EntryId, ObjectDictionary, OdHooks};

use crate::control::{Controller, Demand, Gains};
use crate::cyclic::{self, Interpolator};
use crate::hm::{self, Homing, Outcome, Phase};
use crate::index::*;
use crate::modes::{Mode, SupportedModes};
use crate::options::{OptionCodes, StopRamp};
use crate::physics::{
    Encoder, Inverter, InverterParams, Mechanics, Motor, NEGATIVE_LIMIT_SWITCH,
    POSITIVE_LIMIT_SWITCH, PowerFault, Switches,
};
use crate::pp::{self, ProfilePosition};
use crate::profile::{Limits, Trajectory};
use crate::pt::ProfileTorque;
use crate::pv::{ProfileVelocity, WindowTimer, Windows};
use crate::state::{Facts, Motion, PowerStateMachine, State, StopReason};
use crate::statusword::{StatusFlags, Statusword};
use crate::units::{Units, to_i16, to_i32, to_u32};
use crate::vl::{VelocityMode, VlParams};

/// CiA 402 error code of a following error (0x603F, EMCY).
pub const FOLLOWING_ERROR: u16 = 0x8611;

/// How a drive is built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveConfig {
    /// The motor and load.
    pub mechanics: Mechanics,
    /// The inverter.
    pub inverter: InverterParams,
    /// The controller gains.
    pub gains: Gains,
    /// Encoder increments per motor revolution.
    pub encoder: u32,
    /// The switches along the axis.
    pub switches: Switches,
    /// The modes the drive runs (0x6502).
    pub modes: SupportedModes,
    /// The control loop period.
    pub loop_period: Duration,
}

impl Default for DriveConfig {
    /// The default mechanics, inverter and gains, a 4096-increment encoder, no switches,
    /// every mode, a 250 µs loop.
    fn default() -> Self {
        DriveConfig {
            mechanics: Mechanics::default(),
            inverter: InverterParams::default(),
            gains: Gains::default(),
            encoder: 4096,
            switches: Switches::NONE,
            modes: SupportedModes::of(&Mode::ALL),
            loop_period: Duration::from_micros(250),
        }
    }
}

/// Something the owner passes on to the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriveEvent {
    /// A fault with this CiA 402 error code appeared (an EMCY to raise).
    Fault(u16),
    /// The fault with this code was reset (its EMCY to clear).
    Cleared(u16),
}

/// The parameters, as plain values in the drive's units (position units, per second).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Params {
    units: Units,
    options: OptionCodes,
    vl: VlParams,
    profile_velocity: f64,
    end_velocity: f64,
    profile_acceleration: f64,
    profile_deceleration: f64,
    quick_stop_deceleration: f64,
    max_profile_velocity: f64,
    max_motor_speed: f64,
    max_torque: f64,
    /// 0x6072 max torque in N·m, the limit of every loop cycle.
    torque_limit: f64,
    torque_slope: f64,
    following_error_window: Option<f64>,
    following_error_time_out_us: u64,
    position_window: Option<f64>,
    position_window_time_us: u64,
    windows: Windows,
    software_limit: Option<(f64, f64)>,
    homing_method: i8,
    homing_speeds: (f64, f64),
    homing_acceleration: f64,
    home_offset: f64,
    interpolation_us: u64,
}

/// What the master commands, read at every evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Inputs {
    controlword: u16,
    mode: i8,
    target_position: f64,
    target_velocity: f64,
    target_torque: f64,
    ip_data: f64,
    vl_target: i16,
    position_offset: f64,
    velocity_offset: f64,
    torque_offset: f64,
}

/// A set of the drive's input objects (the controlword, 0x6060, the set-points and the
/// offsets): those written since the drive last read them. An owner that learns of each
/// write (the device's hooks) passes them to [`Drive::evaluate_written`], and the drive
/// reads only those; the others hold what it read before.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InputSet(u16);

impl InputSet {
    /// No input.
    pub const NONE: InputSet = InputSet(0);
    /// How many inputs there are.
    pub const COUNT: usize = 10;
    /// Every input.
    pub const ALL: InputSet = InputSet((1 << InputSet::COUNT) - 1);

    /// The input object `index` (any sub-index of it), or `None` when the object is not
    /// one of the drive's inputs (a parameter, an actual value).
    pub const fn of(index: u16) -> Option<InputSet> {
        match InputSet::number(index) {
            Some(n) => Some(InputSet::single(n)),
            None => None,
        }
    }

    /// The set of input number `n` (of [`InputSet::number`]); empty beyond
    /// [`InputSet::COUNT`].
    pub const fn single(n: usize) -> InputSet {
        if n < InputSet::COUNT {
            InputSet(1 << n)
        } else {
            InputSet::NONE
        }
    }

    /// The number, below [`InputSet::COUNT`], of input object `index`, or `None` when the
    /// object is not one of the drive's inputs.
    pub const fn number(index: u16) -> Option<usize> {
        let bit = match index {
            CONTROLWORD => 0,
            MODES_OF_OPERATION => 1,
            TARGET_POSITION => 2,
            TARGET_VELOCITY => 3,
            TARGET_TORQUE => 4,
            INTERPOLATION_DATA_RECORD => 5,
            VL_TARGET_VELOCITY => 6,
            POSITION_OFFSET => 7,
            VELOCITY_OFFSET => 8,
            TORQUE_OFFSET => 9,
            _ => return None,
        };
        Some(bit)
    }

    /// Both sets.
    pub const fn union(self, other: InputSet) -> InputSet {
        InputSet(self.0 | other.0)
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Whether input object `index` is in the set.
    pub const fn contains(self, index: u16) -> bool {
        match InputSet::of(index) {
            Some(input) => self.0 & input.0 != 0,
            None => false,
        }
    }
}

fn int(od: &ObjectDictionary, index: u16, sub: u8) -> Option<i64> {
    od.get(index, sub)
        .ok()?
        .as_i128()
        .and_then(|v| i64::try_from(v).ok())
}

/// Where the drive reads its inputs: located once, read as raw bytes at every evaluation.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct InputIds {
    controlword: Input,
    mode: Input,
    target_position: Input,
    target_velocity: Input,
    target_torque: Input,
    ip_data: Input,
    vl_target: Input,
    position_offset: Input,
    velocity_offset: Input,
    torque_offset: Input,
}

/// An input entry and whether its data type is signed (a vendor's dictionary may give an
/// object another integer type than the profile's).
type Input = Option<(EntryId, bool)>;

impl InputIds {
    fn locate(od: &ObjectDictionary) -> InputIds {
        use cantwin_canopen::od::DataType::*;
        let at = |index: u16, sub: u8| {
            let id = od.locate(index, sub).ok()?;
            let signed = matches!(
                od.sub_object(id).data_type,
                Integer8
                    | Integer16
                    | Integer24
                    | Integer32
                    | Integer40
                    | Integer48
                    | Integer56
                    | Integer64
            );
            Some((id, signed))
        };
        InputIds {
            controlword: at(CONTROLWORD, 0),
            mode: at(MODES_OF_OPERATION, 0),
            target_position: at(TARGET_POSITION, 0),
            target_velocity: at(TARGET_VELOCITY, 0),
            target_torque: at(TARGET_TORQUE, 0),
            ip_data: at(INTERPOLATION_DATA_RECORD, 1),
            vl_target: at(VL_TARGET_VELOCITY, 0),
            position_offset: at(POSITION_OFFSET, 0),
            velocity_offset: at(VELOCITY_OFFSET, 0),
            torque_offset: at(TORQUE_OFFSET, 0),
        }
    }
}

/// The integer value of input `input` as its data type reads it; 0 for none.
fn raw_int(od: &ObjectDictionary, input: Input) -> i64 {
    let Some((id, signed)) = input else { return 0 };
    let bytes = od.raw(id);
    // The sizes of the profile's own types, read whole rather than through a buffer: the
    // drive reads inputs at every evaluation, two a communication cycle under a cyclic
    // master.
    match (bytes, signed) {
        (&[b], true) => return i64::from(b as i8),
        (&[b], false) => return i64::from(b),
        (&[a, b], true) => return i64::from(i16::from_le_bytes([a, b])),
        (&[a, b], false) => return i64::from(u16::from_le_bytes([a, b])),
        (&[a, b, c, d], true) => return i64::from(i32::from_le_bytes([a, b, c, d])),
        (&[a, b, c, d], false) => return i64::from(u32::from_le_bytes([a, b, c, d])),
        _ => {}
    }
    let n = bytes.len().min(8);
    let mut b = [0u8; 8];
    b[..n].copy_from_slice(&bytes[..n]);
    let v = i64::from_le_bytes(b);
    if signed && n > 0 && n < 8 {
        let shift = 64 - 8 * n as u32;
        (v << shift) >> shift
    } else {
        v
    }
}

/// Where a drive finds its objects: a dictionary, or the CiA 301 device holding one. The
/// drive reads through [`DriveOd::od`] and asks for [`DriveOd::od_mut`] only to store a
/// value that changed: a device takes write access to its dictionary as a sign that its
/// timers may have changed and works out its next deadline again, and at a steady
/// statusword an evaluation changes nothing.
pub trait DriveOd {
    /// The dictionary, to read.
    fn od(&self) -> &ObjectDictionary;
    /// The dictionary, to write.
    fn od_mut(&mut self) -> &mut ObjectDictionary;
}

impl DriveOd for ObjectDictionary {
    fn od(&self) -> &ObjectDictionary {
        self
    }

    fn od_mut(&mut self) -> &mut ObjectDictionary {
        self
    }
}

impl<H: OdHooks> DriveOd for Device<H> {
    fn od(&self) -> &ObjectDictionary {
        Device::od(self)
    }

    fn od_mut(&mut self) -> &mut ObjectDictionary {
        Device::od_mut(self)
    }
}

/// Writes `bytes` to `id` unless it holds them already: most actual values stand still
/// most of the time, and a write is dearer than the comparison.
#[inline]
fn put<D: DriveOd + ?Sized, const N: usize>(od: &mut D, id: Option<EntryId>, bytes: [u8; N]) {
    if let Some(id) = id
        && od.od().raw(id) != bytes
    {
        let _ = od.od_mut().set_raw(id, &bytes);
    }
}

/// Where the drive writes its actual values.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct Outputs {
    statusword: Option<EntryId>,
    mode_display: Option<EntryId>,
    error_code: Option<EntryId>,
    position_demand: Option<EntryId>,
    position_internal: Option<EntryId>,
    position_actual: Option<EntryId>,
    velocity_sensor: Option<EntryId>,
    velocity_demand: Option<EntryId>,
    velocity_actual: Option<EntryId>,
    torque_demand: Option<EntryId>,
    torque_actual: Option<EntryId>,
    current_actual: Option<EntryId>,
    dc_link: Option<EntryId>,
    following_error: Option<EntryId>,
    digital_inputs: Option<EntryId>,
    vl_demand: Option<EntryId>,
    vl_actual: Option<EntryId>,
}

impl Outputs {
    fn locate(od: &ObjectDictionary) -> Outputs {
        let at = |index: u16| od.locate(index, 0).ok();
        Outputs {
            statusword: at(STATUSWORD),
            mode_display: at(MODES_OF_OPERATION_DISPLAY),
            error_code: at(ERROR_CODE),
            position_demand: at(POSITION_DEMAND_VALUE),
            position_internal: at(POSITION_ACTUAL_INTERNAL_VALUE),
            position_actual: at(POSITION_ACTUAL_VALUE),
            velocity_sensor: at(VELOCITY_SENSOR_ACTUAL_VALUE),
            velocity_demand: at(VELOCITY_DEMAND_VALUE),
            velocity_actual: at(VELOCITY_ACTUAL_VALUE),
            torque_demand: at(TORQUE_DEMAND),
            torque_actual: at(TORQUE_ACTUAL_VALUE),
            current_actual: at(CURRENT_ACTUAL_VALUE),
            dc_link: at(DC_LINK_CIRCUIT_VOLTAGE),
            following_error: at(FOLLOWING_ERROR_ACTUAL_VALUE),
            digital_inputs: at(DIGITAL_INPUTS),
            vl_demand: at(VL_VELOCITY_DEMAND),
            vl_actual: at(VL_VELOCITY_ACTUAL_VALUE),
        }
    }
}

/// The statusword bits a loop cycle decided.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct ModeStatus {
    target_reached: bool,
    internal_limit: bool,
    bit12: bool,
    bit13: bool,
}

/// A servo drive. See the [module documentation](self).
#[derive(Debug, Clone)]
pub struct Drive {
    config: DriveConfig,
    fsa: PowerStateMachine,
    motor: Motor,
    inverter: Inverter,
    encoder: Encoder,
    controller: Controller,
    params: Params,
    params_stale: bool,
    inputs: Inputs,
    input_ids: InputIds,
    outputs: Outputs,
    mode: Option<Mode>,
    traj: Trajectory,
    pp: ProfilePosition,
    pv: ProfileVelocity,
    pt: ProfileTorque,
    hm: Homing,
    vl: VelocityMode,
    interpolator: Interpolator,
    ip_enabled: bool,
    /// Position units added to the encoder's position (set by homing).
    offset: f64,
    /// Inputs forced active by the owner (a stuck switch), 0x60FD bits.
    forced_inputs: u32,
    demand: Demand,
    following_error: f64,
    following_us: u64,
    following_flag: bool,
    stopped: WindowTimer,
    at_rest: bool,
    status: ModeStatus,
    power_fault: Option<PowerFault>,
    following_fault: bool,
    reported: Option<u16>,
    events: Vec<DriveEvent>,
    /// The loop cycles run since power-up.
    cycles: u64,
    /// An evaluation changed something a loop cycle has not yet shown.
    pending: bool,
    /// The statusword last written.
    last_statusword: u16,
    /// The loop period in seconds, the motor's time step.
    loop_seconds: f64,
}

impl Drive {
    /// A drive at rest over `od` (which holds the objects of
    /// [`crate::dictionary::servo_objects`] or a vendor's subset of them), in SWITCH ON
    /// DISABLED after transitions 0 and 1.
    pub fn new(config: DriveConfig, od: &mut ObjectDictionary) -> Drive {
        let units = Units::increments(
            config.encoder,
            config.mechanics.rated_torque,
            config.mechanics.rated_current,
        );
        let mut drive = Drive {
            config,
            fsa: PowerStateMachine::switch_on_disabled(),
            motor: Motor::new(config.mechanics),
            inverter: Inverter::new(config.inverter),
            encoder: Encoder {
                increments: config.encoder.max(1),
            },
            controller: Controller::default(),
            params: Params {
                units,
                options: OptionCodes::STANDARD,
                vl: VlParams::default(),
                profile_velocity: 0.0,
                end_velocity: 0.0,
                profile_acceleration: 1.0,
                profile_deceleration: 1.0,
                quick_stop_deceleration: 1.0,
                max_profile_velocity: f64::MAX,
                max_motor_speed: f64::MAX,
                max_torque: 1000.0,
                torque_limit: units.torque_to_nm(1000.0),
                torque_slope: 1000.0,
                following_error_window: None,
                following_error_time_out_us: 0,
                position_window: None,
                position_window_time_us: 0,
                windows: Windows {
                    velocity_window: 0.0,
                    velocity_window_time_us: 0,
                    threshold: 0.0,
                    threshold_time_us: 0,
                },
                software_limit: None,
                homing_method: 35,
                homing_speeds: (1.0, 1.0),
                homing_acceleration: 1.0,
                home_offset: 0.0,
                interpolation_us: 1000,
            },
            params_stale: true,
            inputs: Inputs::default(),
            input_ids: InputIds::locate(od),
            outputs: Outputs::locate(od),
            mode: None,
            traj: Trajectory::default(),
            pp: ProfilePosition::default(),
            pv: ProfileVelocity::default(),
            pt: ProfileTorque::default(),
            hm: Homing::default(),
            vl: VelocityMode::new(),
            interpolator: Interpolator::at(0.0),
            ip_enabled: false,
            offset: 0.0,
            forced_inputs: 0,
            demand: Demand::Torque(0.0),
            following_error: 0.0,
            following_us: 0,
            following_flag: false,
            stopped: WindowTimer::default(),
            at_rest: true,
            status: ModeStatus::default(),
            power_fault: None,
            following_fault: false,
            reported: None,
            events: Vec::new(),
            cycles: 0,
            pending: false,
            last_statusword: 0,
            loop_seconds: config.loop_period.as_secs_f64(),
        };
        drive.read(od, InputSet::ALL);
        drive.mode = Mode::from_code(drive.inputs.mode).filter(|m| config.modes.contains(*m));
        drive.publish(od);
        drive
    }

    /// The configuration.
    pub fn config(&self) -> &DriveConfig {
        &self.config
    }

    /// The state of the power drive state machine.
    pub fn state(&self) -> State {
        self.fsa.state()
    }

    /// The mode in effect (0x6061).
    pub fn mode(&self) -> Option<Mode> {
        self.mode
    }

    /// The motor.
    pub fn motor(&self) -> &Motor {
        &self.motor
    }

    /// The motor, to load or jam it.
    pub fn motor_mut(&mut self) -> &mut Motor {
        &mut self.motor
    }

    /// The inverter.
    pub fn inverter(&self) -> &Inverter {
        &self.inverter
    }

    /// The inverter, to change its DC link or short a phase.
    pub fn inverter_mut(&mut self) -> &mut Inverter {
        &mut self.inverter
    }

    /// Forces 0x60FD inputs active (a switch stuck or pressed by hand), on top of the
    /// switches along the axis.
    pub fn force_inputs(&mut self, bits: u32) {
        self.forced_inputs = bits;
    }

    /// The inputs forced active.
    pub fn forced_inputs(&self) -> u32 {
        self.forced_inputs
    }

    /// 0x60FD now.
    pub fn digital_inputs(&self) -> u32 {
        self.config.switches.inputs(self.motor.state.angle) | self.forced_inputs
    }

    /// The actual position, position units.
    pub fn position(&self) -> f64 {
        self.params.units.rad_to_position(self.motor.state.angle) + self.offset
    }

    /// The actual velocity, velocity units.
    pub fn velocity(&self) -> f64 {
        self.params.units.rad_to_velocity(self.motor.state.speed)
    }

    /// The actual torque, ‰ of rated torque.
    pub fn torque(&self) -> f64 {
        self.params.units.nm_to_torque(self.motor.state.torque)
    }

    /// 0x60F4 following error, position units.
    pub fn following_error(&self) -> f64 {
        self.following_error
    }

    /// The CiA 402 error code of the fault present (0x603F), 0 without one.
    pub fn error_code(&self) -> u16 {
        if let Some(f) = self.power_fault {
            f.error_code()
        } else if self.following_fault {
            FOLLOWING_ERROR
        } else {
            0
        }
    }

    /// The events since the last call, oldest first.
    pub fn take_events(&mut self) -> Vec<DriveEvent> {
        std::mem::take(&mut self.events)
    }

    /// [`Drive::take_events`], keeping the drive's buffer (for an owner that asks after
    /// every frame).
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, DriveEvent> {
        self.events.drain(..)
    }

    /// The parameters must be read again (a parameter object was written).
    pub fn parameters_changed(&mut self) {
        self.params_stale = true;
    }

    /// The time of loop cycle `n`.
    fn cycle_time(&self, n: u64) -> Duration {
        Duration::from_nanos(self.config.loop_period.as_nanos().saturating_mul(n))
    }

    /// The bus time of the next loop cycle, as a time since power-up.
    pub fn next_cycle(&self) -> Duration {
        self.cycle_time(self.cycles + 1)
    }

    /// Whether the drive needs loop cycles to run without anything happening on the bus:
    /// the motor moves, the power stage is on, or an evaluation awaits a cycle.
    pub fn active(&self) -> bool {
        self.pending
            || self.fsa.power_stage().voltage
            || self.motor.state.speed != 0.0
            || self.fsa.state() == State::FaultReactionActive
    }

    fn read_params(&mut self, od: &ObjectDictionary) {
        let fallback = self.params;
        let u = Units::from_od(od, &fallback.units);
        let get = |index: u16, sub: u8, fb: f64| int(od, index, sub).map_or(fb, |v| v as f64);
        let ms = |index: u16, fb: u64| int(od, index, 0).map_or(fb, |v| v.max(0) as u64 * 1000);
        let window = |index: u16| match int(od, index, 0) {
            Some(0xFFFF_FFFF) => None,
            Some(v) => Some(v as f64),
            None => None,
        };
        let limit = match (
            int(od, SOFTWARE_POSITION_LIMIT, 1),
            int(od, SOFTWARE_POSITION_LIMIT, 2),
        ) {
            (Some(lo), Some(hi)) if lo < hi => Some((lo as f64, hi as f64)),
            _ => None,
        };
        let rpm = get(MAX_MOTOR_SPEED, 0, f64::MAX);
        let max_motor_speed = if rpm == f64::MAX {
            f64::MAX
        } else {
            u.rad_to_velocity(rpm * core::f64::consts::TAU / 60.0).abs()
        };
        let period = match (
            int(od, INTERPOLATION_TIME_PERIOD, 1),
            int(od, INTERPOLATION_TIME_PERIOD, 2),
        ) {
            (Some(n), Some(i)) => cyclic::period_us(n as u8, i as i8).unwrap_or(1000),
            _ => fallback.interpolation_us,
        };
        let max_torque = get(MAX_TORQUE, 0, 1000.0);
        self.params = Params {
            units: u,
            options: OptionCodes::from_od(od, fallback.options),
            vl: VlParams::from_od(od, VlParams::default()),
            profile_velocity: get(PROFILE_VELOCITY, 0, fallback.profile_velocity),
            end_velocity: get(END_VELOCITY, 0, 0.0),
            profile_acceleration: get(PROFILE_ACCELERATION, 0, 1.0),
            profile_deceleration: get(PROFILE_DECELERATION, 0, 1.0),
            quick_stop_deceleration: get(QUICK_STOP_DECELERATION, 0, 1.0),
            max_profile_velocity: get(MAX_PROFILE_VELOCITY, 0, f64::MAX),
            max_motor_speed,
            max_torque,
            torque_limit: u.torque_to_nm(max_torque),
            torque_slope: get(TORQUE_SLOPE, 0, 1000.0),
            following_error_window: window(FOLLOWING_ERROR_WINDOW),
            following_error_time_out_us: ms(FOLLOWING_ERROR_TIME_OUT, 0),
            position_window: window(POSITION_WINDOW),
            position_window_time_us: ms(POSITION_WINDOW_TIME, 0),
            windows: Windows {
                velocity_window: get(VELOCITY_WINDOW, 0, 0.0),
                velocity_window_time_us: ms(VELOCITY_WINDOW_TIME, 0),
                threshold: get(VELOCITY_THRESHOLD, 0, 0.0),
                threshold_time_us: ms(VELOCITY_THRESHOLD_TIME, 0),
            },
            software_limit: limit,
            homing_method: int(od, HOMING_METHOD, 0).map_or(35, |v| v as i8),
            homing_speeds: (get(HOMING_SPEEDS, 1, 1.0), get(HOMING_SPEEDS, 2, 1.0)),
            homing_acceleration: get(HOMING_ACCELERATION, 0, 1.0),
            home_offset: get(HOME_OFFSET, 0, 0.0),
            interpolation_us: period,
        };
        self.params_stale = false;
    }

    /// Reads the parameters if they are stale and the inputs in `which`.
    fn read(&mut self, od: &ObjectDictionary, which: InputSet) {
        if self.params_stale {
            self.read_params(od);
        }
        let ids = &self.input_ids;
        let i = &mut self.inputs;
        let get = |input: Input| raw_int(od, input);
        if which.contains(CONTROLWORD) {
            i.controlword = get(ids.controlword) as u16;
        }
        if which.contains(MODES_OF_OPERATION) {
            i.mode = get(ids.mode) as i8;
        }
        if which.contains(TARGET_POSITION) {
            i.target_position = get(ids.target_position) as f64;
        }
        if which.contains(TARGET_VELOCITY) {
            i.target_velocity = get(ids.target_velocity) as f64;
        }
        if which.contains(TARGET_TORQUE) {
            i.target_torque = get(ids.target_torque) as f64;
        }
        if which.contains(INTERPOLATION_DATA_RECORD) {
            i.ip_data = get(ids.ip_data) as f64;
        }
        if which.contains(VL_TARGET_VELOCITY) {
            i.vl_target = get(ids.vl_target) as i16;
        }
        if which.contains(POSITION_OFFSET) {
            i.position_offset = get(ids.position_offset) as f64;
        }
        if which.contains(VELOCITY_OFFSET) {
            i.velocity_offset = get(ids.velocity_offset) as f64;
        }
        if which.contains(TORQUE_OFFSET) {
            i.torque_offset = get(ids.torque_offset) as f64;
        }
    }

    fn facts(&self) -> Facts {
        let stage = self.fsa.power_stage();
        Facts {
            fault: self.error_code() != 0,
            fault_reaction_done: !stage.enabled() || self.power_fault.is_some() || self.at_rest,
            stopped: self.at_rest,
        }
    }

    fn profile_limits(&self) -> Limits {
        let p = &self.params;
        Limits {
            velocity: p
                .profile_velocity
                .min(p.max_profile_velocity)
                .min(p.max_motor_speed),
            acceleration: p.profile_acceleration,
            deceleration: p.profile_deceleration,
        }
    }

    /// Starts every mode afresh from where the axis is.
    fn restart_modes(&mut self) {
        let pos = self.position();
        self.traj = Trajectory {
            position: pos,
            velocity: self.velocity(),
        };
        let cw = self.inputs.controlword;
        self.pp.reset(cw & pp::NEW_SET_POINT != 0);
        self.hm.enter(cw & hm::HOMING_OPERATION_START != 0);
        self.pt = ProfileTorque::at(self.torque());
        self.interpolator = Interpolator::at(pos);
        self.ip_enabled = false;
    }

    /// Evaluates the controlword, the mode of operation and the set-points the dictionary
    /// holds now (after a write of them), and writes the statusword back.
    pub fn evaluate<D: DriveOd + ?Sized>(&mut self, od: &mut D) {
        self.evaluate_written(od, InputSet::ALL);
    }

    /// [`Drive::evaluate`] after writes of the inputs in `written` only (and of parameters,
    /// if [`Drive::parameters_changed`] said so): the other inputs are taken as the drive
    /// last read them. A cyclic master writes two or three objects a cycle.
    pub fn evaluate_written<D: DriveOd + ?Sized>(&mut self, od: &mut D, written: InputSet) {
        self.read(od.od(), written);
        let cw = self.inputs.controlword;
        if self.fsa.fault_reset_edge(cw) {
            self.reset_faults();
        }
        self.fsa.set_options(self.params.options);
        let facts = self.facts();
        let step = self.fsa.update(cw, facts);
        if step.transitions.contains(&4) || step.transitions.contains(&16) {
            self.controller.reset();
            self.restart_modes();
        }
        // Mode switching (CiA 402-2, object 6061h): the drive switches to a supported mode
        // at once and 0x6061 shows it from then on; an unsupported code is not taken.
        let wanted = Mode::from_code(self.inputs.mode).filter(|m| self.config.modes.contains(*m));
        if let Some(m) = wanted
            && Some(m) != self.mode
        {
            self.mode = Some(m);
            self.restart_modes();
        }
        let run = self.fsa.power_stage().motion == Motion::Operate;
        match self.mode {
            Some(Mode::ProfilePosition) => {
                let req = pp::Request {
                    target: self.inputs.target_position,
                    limits: self.profile_limits(),
                    software_limit: self.params.software_limit,
                };
                if run {
                    self.pp.controlword(cw, &req, self.traj.position);
                } else {
                    self.pp.reset(cw & pp::NEW_SET_POINT != 0);
                }
            }
            Some(Mode::Homing) => {
                let wired = self.wired_inputs();
                if self
                    .hm
                    .controlword(cw, self.params.homing_method, wired, run)
                {
                    let here = self.position();
                    self.home_at(here);
                }
            }
            Some(Mode::InterpolatedPosition) => {
                let enable = run && cw & (1 << 4) != 0;
                if enable && !self.ip_enabled {
                    self.interpolator = Interpolator::at(self.traj.position);
                }
                self.ip_enabled = enable;
            }
            _ => {}
        }
        self.pending = true;
        self.publish_status(od);
    }

    /// Writes what an evaluation changes: the statusword, 0x6061 and 0x603F.
    fn publish_status<D: DriveOd + ?Sized>(&mut self, od: &mut D) {
        self.last_statusword = self.statusword();
        let o = &self.outputs;
        put(od, o.statusword, self.last_statusword.to_le_bytes());
        put(od, o.mode_display, [self.mode.map_or(0, Mode::code) as u8]);
        put(od, o.error_code, self.error_code().to_le_bytes());
    }

    fn wired_inputs(&self) -> u32 {
        let s = &self.config.switches;
        let mut bits = self.forced_inputs;
        if s.negative_limit.is_some() {
            bits |= NEGATIVE_LIMIT_SWITCH;
        }
        if s.positive_limit.is_some() {
            bits |= POSITIVE_LIMIT_SWITCH;
        }
        if s.home.is_some() {
            bits |= crate::physics::HOME_SWITCH;
        }
        bits
    }

    /// A SYNC: the cyclic modes take the set-points of the last evaluation (the owner
    /// evaluates the writes a SYNC applied, those of synchronous RPDOs, before it).
    pub fn sync<D: DriveOd + ?Sized>(&mut self, od: &mut D) {
        if self.params_stale {
            self.read(od.od(), InputSet::ALL);
        }
        let i = self.inputs;
        let period = self.params.interpolation_us;
        match self.mode {
            Some(Mode::CyclicSyncPosition) => self
                .interpolator
                .sync(i.target_position + i.position_offset, period),
            Some(Mode::InterpolatedPosition) if self.ip_enabled => {
                self.interpolator.sync(i.ip_data, period)
            }
            _ => {}
        }
        self.pending = true;
    }

    fn reset_faults(&mut self) {
        if self.following_fault {
            self.following_fault = false;
            self.following_us = 0;
            self.following_flag = false;
        }
        if self
            .power_fault
            .is_some_and(|_| self.inverter.fault(false, 0.0).is_none())
        {
            self.power_fault = None;
        }
        let now = self.error_code();
        if let Some(old) = self.reported
            && now != old
        {
            self.events.push(DriveEvent::Cleared(old));
            self.reported = (now != 0).then_some(now);
        }
    }

    fn home_at(&mut self, home: f64) {
        let delta = self.params.home_offset - home;
        self.offset += delta;
        self.traj.position += delta;
        self.interpolator = Interpolator::at(self.traj.position);
    }

    /// Runs the loop cycles due by `elapsed` (the time since power-up) and writes the
    /// actual values and statusword of the last one.
    pub fn advance<D: DriveOd + ?Sized>(&mut self, od: &mut D, elapsed: Duration) {
        if self.params_stale {
            self.read(od.od(), InputSet::ALL);
        }
        let mut ran = false;
        while self.next_cycle() <= elapsed {
            self.cycle();
            ran = true;
            if !self.active() {
                // At rest with the power off nothing changes: skip to `elapsed`.
                let period = self.config.loop_period.as_nanos().max(1);
                self.cycles = self.cycles.max(elapsed.as_nanos() / period);
            }
        }
        if ran {
            self.publish(od);
        }
    }

    fn stop_deceleration(&self, ramp: StopRamp) -> Option<f64> {
        match ramp {
            StopRamp::SlowDown if self.mode == Some(Mode::Homing) => {
                Some(self.params.homing_acceleration)
            }
            StopRamp::SlowDown => Some(self.params.profile_deceleration),
            StopRamp::QuickStop => Some(self.params.quick_stop_deceleration),
            StopRamp::CurrentLimit | StopRamp::VoltageLimit => None,
        }
    }

    fn ramp_down(&mut self, deceleration: Option<f64>, dt: f64) -> Demand {
        match deceleration {
            Some(d) => {
                let l = Limits {
                    velocity: f64::MAX,
                    acceleration: d,
                    deceleration: d,
                };
                self.traj.step_velocity(0.0, &l, dt);
                self.position_demand(0.0)
            }
            None => {
                self.traj = Trajectory {
                    position: self.position(),
                    velocity: 0.0,
                };
                Demand::Velocity {
                    velocity: 0.0,
                    torque: 0.0,
                }
            }
        }
    }

    fn position_demand(&self, torque: f64) -> Demand {
        Demand::Position {
            position: self.traj.position,
            velocity: self.traj.velocity,
            torque,
        }
    }

    /// One loop cycle.
    fn cycle(&mut self) {
        self.cycles += 1;
        self.pending = false;
        let dt_us = self.config.loop_period.as_micros();
        let dt = dt_us as f64 * 1e-6;
        let stage = self.fsa.power_stage();
        let actual = self.position();
        let velocity = self.velocity();
        let inputs_before = self.digital_inputs();
        let angle_before = self.motor.state.angle;
        let mut status = ModeStatus::default();
        let bridge = stage.enabled() && self.power_fault.is_none();
        let vl_mode = self.mode == Some(Mode::Velocity);
        let demand = if !bridge {
            self.controller.reset();
            self.traj = Trajectory {
                position: actual,
                velocity,
            };
            self.vl = VelocityMode::new();
            self.hm.interrupt();
            None
        } else if vl_mode {
            let target = self.inputs.vl_target;
            let cw = self.inputs.controlword;
            self.vl
                .step(target, cw, &stage, &self.params.vl, self.config.loop_period);
            status.target_reached = self.vl.target_reached(target, &stage, &self.params.vl);
            status.internal_limit =
                stage.motion == Motion::Operate && self.params.vl.limits(target);
            let rad = self.vl.demand_exact() * core::f64::consts::TAU / 60.0;
            Some(Demand::Velocity {
                velocity: rad,
                torque: 0.0,
            })
        } else {
            match stage.motion {
                Motion::Disabled => None,
                Motion::Stop { ramp, reason } => {
                    self.hm.interrupt();
                    let d = self.stop_deceleration(ramp);
                    let demand = self.ramp_down(d, dt);
                    if reason == StopReason::Halt {
                        status.target_reached = self.at_rest;
                        if let Some(Mode::ProfilePosition) = self.mode {
                            status.bit12 = self.pp.set_point_acknowledge();
                        }
                        if self.mode == Some(Mode::Homing) {
                            let (t, a, e) = self.hm.status(self.at_rest);
                            status = ModeStatus {
                                target_reached: t,
                                bit12: a,
                                bit13: e,
                                ..status
                            };
                        }
                    }
                    Some(demand)
                }
                Motion::Operate => Some(self.operate(&mut status, actual, velocity, dt_us)),
            }
        };
        // Limit switches and software position limits (not in homing, which looks for the
        // switches itself).
        let demand = demand.map(|d| self.limit(d, &mut status, actual, dt));
        let torque_limit = self.params.torque_limit;
        let torque = demand.map(|d| {
            let u = &self.params.units;
            let d = match d {
                Demand::Position {
                    position,
                    velocity,
                    torque,
                } => Demand::Position {
                    position: u.position_to_rad(position - self.offset),
                    velocity: u.velocity_to_rad(velocity),
                    torque: u.torque_to_nm(torque),
                },
                Demand::Velocity { velocity, torque } if vl_mode => Demand::Velocity {
                    velocity,
                    torque: u.torque_to_nm(torque),
                },
                Demand::Velocity { velocity, torque } => Demand::Velocity {
                    velocity: u.velocity_to_rad(velocity),
                    torque: u.torque_to_nm(torque),
                },
                Demand::Torque(t) => Demand::Torque(u.torque_to_nm(t)),
            };
            self.controller.step(
                &self.config.gains,
                d,
                self.motor.state.angle,
                self.motor.state.speed,
                torque_limit,
                dt,
            )
        });
        if torque.is_some_and(|t| t.abs() >= torque_limit && torque_limit > 0.0)
            && self.controller.torque_demand.abs() > torque_limit
        {
            status.internal_limit = true;
        }
        self.demand = demand.unwrap_or(Demand::Torque(0.0));
        self.motor
            .step_seconds(torque, torque_limit, self.loop_seconds);
        // Homing events.
        if self.mode == Some(Mode::Homing) && bridge && stage.motion == Motion::Operate {
            let now_actual = self.position();
            let index = self
                .encoder
                .index_between(angle_before, self.motor.state.angle)
                .map(|a| self.params.units.rad_to_position(a) + self.offset);
            let sample = hm::Sample {
                inputs_before,
                inputs: self.digital_inputs(),
                position: now_actual,
                index,
            };
            if let Phase::Searching { .. } = self.hm.phase {
                if let Outcome::Home(home) = self.hm.step(&sample) {
                    self.home_at(home);
                }
            }
        }
        // Following error in the position modes.
        self.following_error = match self.demand {
            Demand::Position { .. } if !vl_mode && bridge => self.traj_demand() - self.position(),
            _ => 0.0,
        };
        match self.params.following_error_window {
            Some(w) if self.following_error.abs() > w => {
                self.following_us = self.following_us.saturating_add(dt_us);
                if self.following_us > self.params.following_error_time_out_us {
                    self.following_flag = true;
                    self.following_fault = true;
                }
            }
            _ if !self.following_fault => {
                self.following_us = 0;
                self.following_flag = false;
            }
            _ => {}
        }
        if matches!(
            self.mode,
            Some(Mode::ProfilePosition | Mode::CyclicSyncPosition | Mode::InterpolatedPosition)
        ) && self.following_flag
        {
            status.bit13 = true;
        }
        // The power stage.
        if self.power_fault.is_none() {
            self.power_fault = self.inverter.fault(bridge, self.motor.state.current);
        }
        let threshold = self.params.windows.threshold.max(1.0);
        self.at_rest = self.stopped.step(
            self.velocity().abs() <= threshold && self.traj.velocity == 0.0,
            0,
            dt_us,
        ) || !bridge && self.motor.state.speed == 0.0;
        if self.mode == Some(Mode::Homing) && self.at_rest {
            self.hm.stopped();
        }
        let code = self.error_code();
        if code != 0 && self.reported != Some(code) {
            self.reported = Some(code);
            self.events.push(DriveEvent::Fault(code));
        }
        self.status = status;
        let facts = self.facts();
        let step = self.fsa.refresh(facts);
        if step.transitions.contains(&13) && facts.fault_reaction_done {
            self.fsa.refresh(self.facts());
        }
    }

    fn traj_demand(&self) -> f64 {
        match self.demand {
            Demand::Position { position, .. } => position,
            _ => self.position(),
        }
    }

    /// The demand of the mode in effect, in OPERATION ENABLED without halt.
    fn operate(
        &mut self,
        status: &mut ModeStatus,
        actual: f64,
        velocity: f64,
        dt_us: u64,
    ) -> Demand {
        let dt = dt_us as f64 * 1e-6;
        let i = self.inputs;
        match self.mode {
            None | Some(Mode::Velocity) => Demand::Velocity {
                velocity: 0.0,
                torque: 0.0,
            },
            Some(Mode::ProfilePosition) => {
                status.target_reached = self.pp.step(
                    &mut self.traj,
                    i.controlword,
                    actual,
                    self.params.position_window,
                    self.params.position_window_time_us,
                    dt_us,
                );
                status.bit12 = self.pp.set_point_acknowledge();
                status.internal_limit = self.pp.limited();
                self.position_demand(0.0)
            }
            Some(Mode::ProfileVelocity) => {
                let limits = self.profile_limits();
                let limits = Limits {
                    velocity: self
                        .params
                        .max_profile_velocity
                        .min(self.params.max_motor_speed),
                    ..limits
                };
                self.pv.step(
                    &mut self.traj,
                    true,
                    i.target_velocity,
                    &limits,
                    velocity,
                    &self.params.windows,
                    dt_us,
                );
                status.target_reached = self.pv.target_reached;
                status.bit12 = self.pv.speed_zero;
                status.internal_limit = i.target_velocity.abs() > limits.velocity;
                Demand::Velocity {
                    velocity: self.traj.velocity,
                    torque: 0.0,
                }
            }
            Some(Mode::ProfileTorque) => {
                let (reached, limited) = self.pt.step(
                    i.target_torque,
                    self.params.torque_slope,
                    self.params.max_torque,
                    dt,
                );
                status.target_reached = reached;
                status.internal_limit = limited;
                self.torque_demand(status, velocity, self.pt.demand)
            }
            Some(Mode::Homing) => {
                let (t, a, e) = self.hm.status(self.at_rest);
                *status = ModeStatus {
                    target_reached: t,
                    bit12: a,
                    bit13: e,
                    ..*status
                };
                let (fast, slow) = self.params.homing_speeds;
                let acc = self.params.homing_acceleration;
                let target = match self.hm.phase {
                    hm::Phase::Searching { .. } => {
                        // The direction of the present search step (its outcome of the
                        // last cycle is applied in the same cycle it is seen).
                        self.hm_velocity(fast, slow)
                    }
                    _ => 0.0,
                };
                let l = Limits {
                    velocity: f64::MAX,
                    acceleration: acc,
                    deceleration: acc,
                };
                self.traj.step_velocity(target, &l, dt);
                self.position_demand(0.0)
            }
            Some(Mode::InterpolatedPosition) => {
                status.bit12 = self.ip_enabled;
                if self.ip_enabled {
                    self.interpolator.step(dt_us);
                    let p = self.hold_within_limits(self.interpolator.value(), status);
                    self.traj = Trajectory {
                        position: p,
                        velocity: self.interpolator.slope(),
                    };
                    status.target_reached = self.interpolator.slope() == 0.0
                        && self
                            .params
                            .position_window
                            .is_none_or(|w| (actual - self.interpolator.target()).abs() <= w);
                } else {
                    self.traj.velocity = 0.0;
                }
                self.position_demand(0.0)
            }
            Some(Mode::CyclicSyncPosition) => {
                status.bit12 = true;
                self.interpolator.step(dt_us);
                let p = self.hold_within_limits(self.interpolator.value(), status);
                self.traj = Trajectory {
                    position: p,
                    velocity: self.interpolator.slope() + i.velocity_offset,
                };
                self.position_demand(i.torque_offset)
            }
            Some(Mode::CyclicSyncVelocity) => {
                status.bit12 = true;
                let v = i.target_velocity + i.velocity_offset;
                let limit = self
                    .params
                    .max_profile_velocity
                    .min(self.params.max_motor_speed);
                status.internal_limit = v.abs() > limit;
                let v = v.clamp(-limit, limit);
                self.traj = Trajectory {
                    position: actual,
                    velocity: v,
                };
                Demand::Velocity {
                    velocity: v,
                    torque: i.torque_offset,
                }
            }
            Some(Mode::CyclicSyncTorque) => {
                status.bit12 = true;
                let t = i.target_torque + i.torque_offset;
                let max = self.params.max_torque;
                status.internal_limit = t.abs() > max;
                self.torque_demand(status, velocity, t.clamp(-max, max))
            }
        }
    }

    /// The homing search velocity of the step the procedure is at.
    fn hm_velocity(&mut self, fast: f64, slow: f64) -> f64 {
        // Ask the procedure without a new sample: the step's direction and speed.
        let probe = hm::Sample {
            inputs_before: self.digital_inputs(),
            inputs: self.digital_inputs(),
            position: self.position(),
            index: None,
        };
        let mut copy = self.hm.clone();
        match copy.step(&probe) {
            Outcome::Move { direction, fast: f } => direction * if f { fast } else { slow },
            _ => 0.0,
        }
    }

    /// A torque demand, held back at 0x6080 max motor speed.
    fn torque_demand(&mut self, status: &mut ModeStatus, velocity: f64, torque: f64) -> Demand {
        let max = self.params.max_motor_speed;
        self.traj = Trajectory {
            position: self.position(),
            velocity,
        };
        if velocity.abs() >= max && torque.signum() == velocity.signum() {
            status.internal_limit = true;
            return Demand::Velocity {
                velocity: max * velocity.signum(),
                torque: 0.0,
            };
        }
        Demand::Torque(torque)
    }

    fn hold_within_limits(&self, p: f64, status: &mut ModeStatus) -> f64 {
        match self.params.software_limit {
            Some((lo, hi)) if p < lo || p > hi => {
                status.internal_limit = true;
                p.clamp(lo, hi)
            }
            _ => p,
        }
    }

    /// Stops a demand that moves into an active limit switch or beyond a software position
    /// limit.
    fn limit(&mut self, d: Demand, status: &mut ModeStatus, actual: f64, dt: f64) -> Demand {
        if self.mode == Some(Mode::Homing) {
            return d;
        }
        let inputs = self.digital_inputs();
        let dir = match d {
            Demand::Position { velocity, .. } | Demand::Velocity { velocity, .. } => {
                velocity.signum()
            }
            Demand::Torque(t) => t.signum(),
        };
        let beyond = self
            .params
            .software_limit
            .is_some_and(|(lo, hi)| (actual >= hi && dir > 0.0) || (actual <= lo && dir < 0.0))
            && !matches!(
                self.mode,
                Some(Mode::ProfilePosition | Mode::CyclicSyncPosition | Mode::InterpolatedPosition)
            );
        let switch = (dir > 0.0 && inputs & POSITIVE_LIMIT_SWITCH != 0)
            || (dir < 0.0 && inputs & NEGATIVE_LIMIT_SWITCH != 0);
        if !(switch || beyond) {
            return d;
        }
        status.internal_limit = true;
        if self.mode == Some(Mode::Velocity) {
            return Demand::Velocity {
                velocity: 0.0,
                torque: 0.0,
            };
        }
        if matches!(d, Demand::Torque(_)) || matches!(d, Demand::Velocity { .. }) {
            self.traj = Trajectory {
                position: actual,
                velocity: self.traj.velocity,
            };
        }
        let decel = self.params.quick_stop_deceleration;
        let demand = self.ramp_down(Some(decel), dt);
        if self.mode == Some(Mode::ProfilePosition) {
            // The move into the switch is given up: the axis stays where it stops.
            let here = self.traj.position;
            let req = pp::Request {
                target: here,
                limits: self.profile_limits(),
                software_limit: None,
            };
            self.pp.reset(false);
            self.pp
                .controlword(pp::NEW_SET_POINT | pp::CHANGE_SET_IMMEDIATELY, &req, here);
            self.pp
                .controlword(self.inputs.controlword & !pp::NEW_SET_POINT, &req, here);
            self.pp
                .reset(self.inputs.controlword & pp::NEW_SET_POINT != 0);
        }
        if matches!(
            self.mode,
            Some(Mode::CyclicSyncPosition | Mode::InterpolatedPosition)
        ) {
            self.interpolator = Interpolator::at(self.traj.position);
        }
        demand
    }

    fn statusword(&self) -> u16 {
        let state = self.fsa.state();
        let voltage = state.voltage() && self.inverter.dc_link >= self.config.inverter.dc_link_min;
        let op = state == State::OperationEnabled || state == State::QuickStopActive;
        let mut s = if op {
            self.status
        } else {
            ModeStatus::default()
        };
        // The handshake bits answer the controlword at once, not at the next loop cycle.
        match self.mode {
            Some(Mode::ProfilePosition) if op => {
                s.bit12 = self.pp.set_point_acknowledge();
                s.target_reached &= !self.pp.moving();
            }
            Some(Mode::Homing) if op => {
                let (t, a, e) = self.hm.status(self.at_rest);
                s.target_reached = t;
                s.bit12 = a;
                s.bit13 = e;
            }
            Some(Mode::InterpolatedPosition) if op => s.bit12 = self.ip_enabled,
            _ => {}
        }
        // A following error stays shown while it is the fault.
        if self.following_flag
            && matches!(
                self.mode,
                Some(Mode::ProfilePosition | Mode::CyclicSyncPosition | Mode::InterpolatedPosition)
            )
        {
            s.bit13 = true;
        }
        let mut bits = 0;
        if s.bit12 {
            bits |= 1;
        }
        if s.bit13 {
            bits |= 2;
        }
        let flags = StatusFlags {
            voltage_enabled: voltage,
            remote: true,
            target_reached: s.target_reached || (state == State::QuickStopActive && self.at_rest),
            internal_limit_active: s.internal_limit,
            mode_specific: bits,
            ..StatusFlags::default()
        };
        Statusword::encode(state, flags).0
    }

    /// Writes the statusword, 0x6061 and the actual values into `od`.
    fn publish<D: DriveOd + ?Sized>(&mut self, od: &mut D) {
        self.publish_status(od);
        let o = &self.outputs;
        let u = &self.params.units;
        let demand = match self.demand {
            Demand::Position { position, .. } => position,
            _ => self.position(),
        };
        put(od, o.position_demand, to_i32(demand).to_le_bytes());
        let count = self.encoder.count(self.motor.state.angle);
        let count = count.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
        put(od, o.position_internal, count.to_le_bytes());
        put(od, o.position_actual, to_i32(self.position()).to_le_bytes());
        let inc_per_s =
            self.motor.state.speed / core::f64::consts::TAU * f64::from(self.encoder.increments);
        put(od, o.velocity_sensor, to_i32(inc_per_s).to_le_bytes());
        let vdemand = u.rad_to_velocity(self.controller.velocity_demand);
        put(od, o.velocity_demand, to_i32(vdemand).to_le_bytes());
        put(od, o.velocity_actual, to_i32(self.velocity()).to_le_bytes());
        let tdemand = u.nm_to_torque(self.motor.state.torque);
        put(od, o.torque_demand, to_i16(tdemand).to_le_bytes());
        put(od, o.torque_actual, to_i16(self.torque()).to_le_bytes());
        let current = u.a_to_current(self.motor.state.current);
        put(od, o.current_actual, to_i16(current).to_le_bytes());
        let mv = to_u32(self.inverter.dc_link * 1000.0);
        put(od, o.dc_link, mv.to_le_bytes());
        put(
            od,
            o.following_error,
            to_i32(self.following_error).to_le_bytes(),
        );
        put(od, o.digital_inputs, self.digital_inputs().to_le_bytes());
        let rpm = self.motor.state.speed * 60.0 / core::f64::consts::TAU;
        put(od, o.vl_demand, self.vl.demand().to_le_bytes());
        put(od, o.vl_actual, to_i16(rpm).to_le_bytes());
    }

    /// The statusword the dictionary holds (as last published).
    pub fn published_statusword(&self) -> u16 {
        self.last_statusword
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dictionary::{MotionDefaults, ServoObjects, servo_objects};
    use cantwin_canopen::od::{OdBuilder, Value};
    use std::sync::Arc;

    fn dictionary() -> ObjectDictionary {
        let spec = ServoObjects::all_modes(MotionDefaults::default());
        let desc = crate::objects::add(OdBuilder::new(), servo_objects(&spec))
            .build()
            .expect("the profile's dictionary");
        ObjectDictionary::new(Arc::new(desc), 1)
    }

    #[test]
    fn input_sets_name_the_commands_and_set_points_only() {
        let inputs = [
            CONTROLWORD,
            MODES_OF_OPERATION,
            TARGET_POSITION,
            TARGET_VELOCITY,
            TARGET_TORQUE,
            INTERPOLATION_DATA_RECORD,
            VL_TARGET_VELOCITY,
            POSITION_OFFSET,
            VELOCITY_OFFSET,
            TORQUE_OFFSET,
        ];
        let mut all = InputSet::NONE;
        for (k, index) in inputs.into_iter().enumerate() {
            assert_eq!(InputSet::number(index), Some(k));
            let one = InputSet::of(index).expect("an input");
            assert!(one.contains(index) && !one.is_empty());
            assert!(!InputSet::NONE.contains(index));
            all = all.union(one);
        }
        assert_eq!(all, InputSet::ALL);
        assert_eq!(InputSet::single(InputSet::COUNT), InputSet::NONE);
        for index in [STATUSWORD, PROFILE_VELOCITY, POSITION_ACTUAL_VALUE, 0x1017] {
            assert_eq!(InputSet::of(index), None);
            assert!(!InputSet::ALL.contains(index));
        }
    }

    #[test]
    fn cia402_6040h_an_evaluation_reads_again_the_inputs_written_only() {
        let mut od = dictionary();
        let mut drive = Drive::new(DriveConfig::default(), &mut od);
        let cw = InputSet::of(CONTROLWORD).expect("an input");
        // Shutdown (transition 2).
        od.set(CONTROLWORD, 0, &Value::Unsigned16(0x06)).unwrap();
        drive.evaluate_written(&mut od, cw);
        assert_eq!(drive.state(), State::ReadyToSwitchOn);
        // A mode stored but not said to be written is not taken; said, it is.
        od.set(MODES_OF_OPERATION, 0, &Value::Integer8(8)).unwrap();
        drive.evaluate_written(&mut od, cw);
        assert_eq!(drive.mode(), None);
        let mode = InputSet::of(MODES_OF_OPERATION).expect("an input");
        drive.evaluate_written(&mut od, mode);
        assert_eq!(drive.mode(), Some(Mode::CyclicSyncPosition));
        // Switch on + enable operation (transitions 3 and 4), the controlword read again by
        // an evaluation of every input.
        od.set(CONTROLWORD, 0, &Value::Unsigned16(0x0F)).unwrap();
        drive.evaluate(&mut od);
        assert_eq!(drive.state(), State::OperationEnabled);
        assert_eq!(
            od.get(STATUSWORD, 0).unwrap(),
            Value::Unsigned16(drive.published_statusword())
        );
    }
}
