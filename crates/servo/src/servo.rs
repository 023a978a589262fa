//! The servo drive as a [`Node`]: a CiA 301 device over the dictionary of [`crate::od`]
//! whose CiA 402 objects a [`Drive`] reads and writes.
//!
//! * **One truth.** The master's commands and parameters are the dictionary's values; the
//!   device's hooks ([`ServoHooks`]) only note that a CiA 402 object was written, and the
//!   drive evaluates them once the frame that wrote them has been handled (an RPDO
//!   mapping the controlword and a target is taken as a whole).
//! * **Time.** Before the device handles a frame or a timer, the drive is brought to that
//!   bus time, so a TPDO sent at a SYNC carries the actual values of the last loop cycle
//!   before it. While the drive is active (high voltage applied or the motor turning) the
//!   node wakes when [`ServoConfig::status_period`] has passed without a frame to publish
//!   its statusword: a change goes out in the event-driven TPDOs mapping it at most one
//!   period after the loop cycle that made it.
//! * **SYNC.** At every SYNC the cyclic modes take the set-points received (those of
//!   synchronous RPDOs are applied by the device at that SYNC).
//! * **Refusals.** 0x6060 refuses a mode the drive does not support and 0x6098 a homing
//!   method it does not run, with 0x06090030 (value range of parameter exceeded).
//! * **Faults** raise an EMCY with the CiA 402 error code (0x603F); the fault reset clears
//!   it.
//! * **Power-up and reset application** start the drive afresh: motor at rest, SWITCH ON
//!   DISABLED.

use std::sync::Arc;

use cantwin_can::{ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::{Device, DeviceConfig, DeviceError, Event};
use cantwin_canopen::od::{ObjectDictionary, OdDescription, OdHooks};
use cantwin_cia402::drive::{Drive, DriveConfig, DriveEvent, InputSet};
use cantwin_cia402::index::*;
use cantwin_cia402::{Mode, SupportedModes, hm};

/// How a servo is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// The node-ID, 1..=127.
    pub node_id: u8,
    /// The drive: motor, load, inverter, gains, encoder, switches, modes.
    pub drive: DriveConfig,
    /// How often an active drive publishes its statusword.
    pub status_period: Duration,
    /// The SDO server's timeout.
    pub sdo_timeout: Duration,
    /// The default of 0x1017 producer heartbeat time (ms) of the built-in dictionary.
    pub heartbeat_ms: u16,
}

impl ServoConfig {
    /// A servo at `node_id` with the default drive, publishing every millisecond.
    pub fn new(node_id: u8) -> Self {
        ServoConfig {
            node_id,
            drive: DriveConfig::default(),
            status_period: Duration::from_millis(1),
            sdo_timeout: Duration::from_millis(1000),
            heartbeat_ms: 0,
        }
    }
}

/// The servo's hooks into its CiA 301 device: they check 0x6060 and 0x6098 and note
/// which CiA 402 objects were written: the drive's inputs (commands and set-points,
/// [`InputSet::of`]), which it evaluates at once and reads again one by one, or any
/// other object, a parameter change.
///
/// The notes are numbers of writes, which the servo compares with the last one it took:
/// it reads them through the device's shared access to its hooks, since asking for
/// mutable access tells the device that its timers may have changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServoHooks {
    modes: SupportedModes,
    /// The number of the last write noted: counting from 1 and wrapping past 0, which
    /// stands for none.
    writes: u32,
    /// The number of the last write of each input ([`InputSet::number`]).
    input_writes: [u32; InputSet::COUNT],
    /// The number of the last write of a parameter.
    param_writes: u32,
}

impl ServoHooks {
    /// The inputs written and whether a parameter was, after write number `seen`.
    fn notes_since(&self, seen: u32) -> (InputSet, bool) {
        let news = self.writes.wrapping_sub(seen);
        if news == 0 {
            return (InputSet::NONE, false);
        }
        let after = |n: u32| n != 0 && n.wrapping_sub(seen).wrapping_sub(1) < news;
        let mut inputs = InputSet::NONE;
        for (k, n) in self.input_writes.iter().enumerate() {
            if after(*n) {
                inputs = inputs.union(InputSet::single(k));
            }
        }
        (inputs, after(self.param_writes))
    }
}

impl OdHooks for ServoHooks {
    fn validate(
        &mut self,
        _od: &ObjectDictionary,
        index: u16,
        _sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        let code = data.first().map_or(0, |b| *b as i8);
        let ok = match index {
            // CiA 402-2 object 6060h: 0 is "no mode"; other codes must be a supported mode.
            MODES_OF_OPERATION => {
                code == 0 || Mode::from_code(code).is_some_and(|m| self.modes.contains(m))
            }
            HOMING_METHOD => hm::supported(code),
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(AbortCode::INVALID_VALUE)
        }
    }

    fn written(&mut self, _od: &mut ObjectDictionary, index: u16, _sub: u8) {
        self.writes = self.writes.wrapping_add(1).max(1);
        match InputSet::number(index).and_then(|n| self.input_writes.get_mut(n)) {
            Some(n) => *n = self.writes,
            None => self.param_writes = self.writes,
        }
    }
}

/// Why a servo cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum ServoError {
    /// The dictionary could not be built.
    #[error("object dictionary: {0}")]
    Od(#[from] cantwin_canopen::od::OdBuildError),
    /// The node-ID is outside 1..=127.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The dictionary lacks an object every CiA 402 drive has.
    #[error("the dictionary has no object {0:#06x}, which every CiA 402 drive has")]
    Missing(u16),
}

/// A CiA 402 servo drive. See the [module documentation](self).
pub struct Servo {
    device: Device<ServoHooks>,
    drive: Drive,
    config: ServoConfig,
    powered: bool,
    powered_at: Instant,
    last: Instant,
    statusword: u16,
    mode_display: i64,
    /// The number of the last write the drive has taken of the hooks' notes.
    notes_seen: u32,
}

impl core::fmt::Debug for Servo {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Servo")
            .field("node_id", &self.device.node_id())
            .field("state", &self.drive.state())
            .field("mode", &self.drive.mode())
            .finish_non_exhaustive()
    }
}

impl Servo {
    /// A servo on the built-in dictionary of its configured modes
    /// ([`crate::od::description`]), unpowered until [`Node::on_power_up`].
    pub fn new(config: ServoConfig) -> Result<Self, ServoError> {
        let objects = cantwin_cia402::dictionary::ServoObjects {
            modes: config.drive.modes,
            mode: None,
            motion: cantwin_cia402::dictionary::MotionDefaults {
                encoder_increments: config.drive.encoder,
                feed: config.drive.encoder,
                rated_torque_mnm: (config.drive.mechanics.rated_torque * 1000.0).round() as u32,
                rated_current_ma: (config.drive.mechanics.rated_current * 1000.0).round() as u32,
                ..Default::default()
            },
        };
        let desc = Arc::new(crate::od::description(&objects, config.heartbeat_ms)?);
        Self::with_description(desc, config)
    }

    /// A servo on `desc` (a vendor's dictionary; its CiA 402 objects must be hooked, see
    /// [`crate::od::hooked`]). The profile's behaviour runs on whatever objects it has:
    /// where the dictionary states the encoder resolution (0x608F), the supported modes
    /// (0x6502), the rated torque (0x6076) or the rated current (0x6075), its defaults
    /// replace those of `config`; the factor group sets the units.
    pub fn with_description(
        desc: Arc<OdDescription>,
        mut config: ServoConfig,
    ) -> Result<Self, ServoError> {
        for index in [
            CONTROLWORD,
            STATUSWORD,
            MODES_OF_OPERATION,
            MODES_OF_OPERATION_DISPLAY,
        ] {
            if desc.object(index).is_none() {
                return Err(ServoError::Missing(index));
            }
        }
        let defaults = ObjectDictionary::new(Arc::clone(&desc), config.node_id);
        let get = |index: u16, sub: u8| defaults.get_unsigned(index, sub).filter(|v| *v > 0);
        if let (Some(inc), Some(rev)) = (
            get(POSITION_ENCODER_RESOLUTION, 1),
            get(POSITION_ENCODER_RESOLUTION, 2),
        ) {
            config.drive.encoder = u32::try_from((inc / rev).max(1)).unwrap_or(u32::MAX);
        }
        if let Some(m) = get(SUPPORTED_DRIVE_MODES, 0) {
            config.drive.modes = SupportedModes(m as u32);
        }
        let m = &mut config.drive.mechanics;
        if let Some(t) = get(MOTOR_RATED_TORQUE, 0) {
            let ratio = m.peak_torque / m.rated_torque;
            m.rated_torque = t as f64 / 1000.0;
            m.peak_torque = m.rated_torque * ratio;
        }
        if let Some(a) = get(MOTOR_RATED_CURRENT, 0) {
            m.rated_current = a as f64 / 1000.0;
        }
        m.torque_constant = m.rated_torque / m.rated_current;
        let hooks = ServoHooks {
            modes: config.drive.modes,
            ..ServoHooks::default()
        };
        let device_config = DeviceConfig {
            sdo_timeout: config.sdo_timeout,
            ..DeviceConfig::new(config.node_id)
        };
        let mut device = Device::with_hooks(desc, device_config, hooks)?;
        let drive = Drive::new(config.drive, device.od_mut());
        Ok(Servo {
            device,
            drive,
            config,
            powered: false,
            powered_at: Instant::ZERO,
            last: Instant::ZERO,
            statusword: 0,
            mode_display: 0,
            notes_seen: 0,
        })
    }

    /// The CiA 301 device inside.
    pub fn device(&self) -> &Device<ServoHooks> {
        &self.device
    }

    /// The CiA 301 device inside, mutably.
    pub fn device_mut(&mut self) -> &mut Device<ServoHooks> {
        &mut self.device
    }

    /// The drive.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The drive, mutably (to load the motor, fault the inverter, force a switch); call
    /// [`Servo::changed`] after a change so that it is evaluated at once.
    pub fn drive_mut(&mut self) -> &mut Drive {
        &mut self.drive
    }

    /// The configuration.
    pub fn config(&self) -> &ServoConfig {
        &self.config
    }

    /// Brings the drive to `now` (before a change made from outside).
    pub fn settle(&mut self, now: Instant) {
        if !self.powered {
            return;
        }
        let t = now.max(self.last);
        self.last = t;
        let elapsed = t.saturating_duration_since(self.powered_at);
        if self.drive.next_cycle() <= elapsed {
            self.drive.advance(&mut self.device, elapsed);
            self.publish();
        }
    }

    /// Evaluates the drive after a change made from outside at `now`.
    pub fn changed(&mut self, now: Instant) {
        self.settle(now);
        if self.powered {
            self.drive.evaluate(&mut self.device);
            self.publish();
        }
    }

    /// Passes the drive's news to the bus: EMCYs for its faults, event-driven TPDOs for
    /// a changed statusword or mode.
    fn publish(&mut self) {
        for e in self.drive.drain_events() {
            match e {
                DriveEvent::Fault(code) => {
                    self.device.emcy().raise(code, [0; 5]);
                }
                DriveEvent::Cleared(code) => {
                    self.device.emcy().clear(code);
                }
            }
        }
        let sw = self.drive.published_statusword();
        let mode = i64::from(self.drive.mode().map_or(0, Mode::code));
        if sw != self.statusword || mode != self.mode_display {
            self.statusword = sw;
            self.mode_display = mode;
            self.device.mark_changed(STATUSWORD, 0);
            self.device.mark_changed(MODES_OF_OPERATION_DISPLAY, 0);
        }
    }

    /// Takes the device's events and the hooks' notes, and has the drive evaluate them.
    pub(crate) fn after_device(&mut self) {
        let mut sync = false;
        while let Some(e) = self.device.poll_event() {
            match e {
                Event::Sync { .. } => sync = true,
                Event::ResetApplication => {
                    self.drive = Drive::new(self.config.drive, self.device.od_mut());
                }
                _ => {}
            }
        }
        let hooks = self.device.hooks();
        let (inputs, params) = hooks.notes_since(self.notes_seen);
        self.notes_seen = hooks.writes;
        if params {
            self.drive.parameters_changed();
        }
        if !inputs.is_empty() || params {
            self.drive.evaluate_written(&mut self.device, inputs);
        }
        if sync {
            self.drive.sync(&mut self.device);
        }
        self.publish();
    }

    /// While the drive is active, [`ServoConfig::status_period`] after the drive was last
    /// brought up to date: a frame (a SYNC, an RPDO) settles it too, so a drive under a
    /// cyclic master needs no wake-ups of its own.
    fn drive_deadline(&self) -> Option<Instant> {
        if !self.powered || !self.drive.active() {
            return None;
        }
        self.last.checked_add(self.config.status_period)
    }
}

impl Node for Servo {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.powered = true;
        self.powered_at = now;
        self.last = now;
        self.notes_seen = self.device.hooks().writes;
        self.device.on_power_up(now, out);
        self.drive = Drive::new(self.config.drive, self.device.od_mut());
        while self.device.poll_event().is_some() {}
        self.statusword = 0;
        self.publish();
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.settle(now);
        self.device.on_frame(frame, now, out);
        self.after_device();
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.settle(now);
        if self.device.next_deadline().is_some_and(|d| d <= now) {
            self.device.on_tick(now, out);
        }
        self.after_device();
        if self.device.next_deadline().is_some_and(|d| d <= now) {
            self.device.on_tick(now, out);
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        // Asked after every frame and timer: no iterator over the two.
        Instant::earliest(self.device.next_deadline(), self.drive_deadline())
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.device.on_sent(frame, now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.settle(now);
        self.device.on_controller_event(event, now, out);
        self.after_device();
    }

    fn accepts(&self, id: Id) -> bool {
        self.device.accepts(id)
    }

    fn acceptance_version(&self) -> Option<u64> {
        self.device.acceptance_version()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noted(hooks: &mut ServoHooks, od: &mut ObjectDictionary, index: u16) {
        hooks.written(od, index, 0);
    }

    #[test]
    fn the_hooks_notes_name_the_writes_after_the_last_taken_across_a_wrap() {
        let desc = Arc::new(
            crate::od::description(
                &cantwin_cia402::dictionary::ServoObjects::all_modes(Default::default()),
                0,
            )
            .expect("the built-in dictionary"),
        );
        let mut od = ObjectDictionary::new(desc, 1);
        let cw = InputSet::of(CONTROLWORD).expect("an input");
        let target = InputSet::of(TARGET_POSITION).expect("an input");
        let mut hooks = ServoHooks {
            writes: u32::MAX - 1,
            ..ServoHooks::default()
        };
        let seen = hooks.writes;
        assert_eq!(hooks.notes_since(seen), (InputSet::NONE, false));
        noted(&mut hooks, &mut od, CONTROLWORD);
        noted(&mut hooks, &mut od, TARGET_POSITION);
        noted(&mut hooks, &mut od, PROFILE_VELOCITY);
        assert_eq!(hooks.writes, 2);
        assert_eq!(hooks.notes_since(seen), (cw.union(target), true));
        // Taken up to the controlword: the target and the parameter remain.
        assert_eq!(hooks.notes_since(u32::MAX), (target, true));
        assert_eq!(hooks.notes_since(hooks.writes), (InputSet::NONE, false));
        noted(&mut hooks, &mut od, CONTROLWORD);
        assert_eq!(hooks.notes_since(2), (cw, false));
    }
}
