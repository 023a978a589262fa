//! The drive on the CAN bus: the model behind a CAL CMS server with the three messages of
//! application 003 (manual §3).

use cantwin_cal::{Application, CmsServer, Mux, ObjectIndex, Payload};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};

pub use crate::messages::cms_objects;
use crate::model::{Alarms, Drive, DriveData, ERR_UNDEFINED, Flash, MotorData};
use crate::params::{C48, ParId, ParamError};

/// Message 0: commands and frequency reference (Read/Write basic variable).
pub const MESSAGE_0: ObjectIndex = ObjectIndex(0);
/// Message 1: alarm notification (controlled event).
pub const MESSAGE_1: ObjectIndex = ObjectIndex(1);
/// Message 2: parameters and connections (Read/Write multiplexed variable).
pub const MESSAGE_2: ObjectIndex = ObjectIndex(2);

/// The default physics period.
pub const DEFAULT_PHYSICS_PERIOD: Duration = Duration::from_millis(1);

/// The bit rate of C48 (manual §1.2: 0 = 1M, 1 = 500k … 7 = 10k).
pub fn bit_rate_of_c48(c48: i32) -> Option<BitRate> {
    Some(match c48 {
        0 => BitRate::R1M,
        1 => BitRate::R500K,
        2 => BitRate::R250K,
        3 => BitRate::R125K,
        4 => BitRate::R100K,
        5 => BitRate::R50K,
        6 => BitRate::R20K,
        7 => BitRate::R10K,
        _ => return None,
    })
}

/// Where the drive's flash goes between runs (a file, for `--state-dir`).
pub trait FlashStorage: Send {
    /// Keep this image (see [`Flash::to_text`]); called whenever the flash changed.
    fn store(&mut self, image: &str) -> Result<(), String>;
}

/// The twin of an OPEN DRIVE with application 003.
pub struct OpenDrive {
    drive: Drive,
    server: Option<CmsServer>,
    period: Duration,
    next_step: Option<Instant>,
    reported: Alarms,
    storage: Option<Box<dyn FlashStorage>>,
    stored: Option<Flash>,
    storage_error: Option<String>,
}

impl core::fmt::Debug for OpenDrive {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("OpenDrive")
            .field("drive", &self.drive)
            .field("server", &self.server)
            .field("period", &self.period)
            .field("next_step", &self.next_step)
            .field("storage", &self.storage.is_some())
            .finish()
    }
}

impl OpenDrive {
    /// A drive with this motor and hardware, application 003's defaults in flash, and a
    /// physics step of [`DEFAULT_PHYSICS_PERIOD`].
    pub fn new(motor: MotorData, hardware: DriveData) -> Self {
        OpenDrive {
            drive: Drive::new(motor, hardware),
            server: None,
            period: DEFAULT_PHYSICS_PERIOD,
            next_step: None,
            reported: Alarms::NONE,
            storage: None,
            stored: None,
            storage_error: None,
        }
    }

    /// Keep the flash in `storage` from now on (it receives the image whenever it changes,
    /// starting with the current one at the next callback).
    pub fn with_storage(mut self, storage: Box<dyn FlashStorage>) -> Self {
        self.storage = Some(storage);
        self.stored = None;
        self
    }

    /// The last error the storage reported, if any.
    pub fn storage_error(&self) -> Option<&str> {
        self.storage_error.as_deref()
    }

    fn persist(&mut self) {
        let Some(storage) = &mut self.storage else {
            return;
        };
        if self.stored.as_ref() != Some(self.drive.flash()) {
            let flash = self.drive.flash().clone();
            self.storage_error = storage.store(&flash.to_text()).err();
            self.stored = Some(flash);
        }
    }

    /// With another physics period (at least 1 µs).
    pub fn with_physics_period(mut self, period: Duration) -> Self {
        self.period = period.max(Duration::from_micros(1));
        self
    }

    /// The physics period.
    pub fn physics_period(&self) -> Duration {
        self.period
    }

    /// The model: outputs, parameters.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The model, mutably: inputs, DIP S1, load, parameters.
    pub fn drive_mut(&mut self) -> &mut Drive {
        &mut self.drive
    }

    /// Store a parameter in flash, as at commissioning (takes effect now; COB-IDs and C48 at
    /// the next power-up).
    pub fn set_stored_param(&mut self, id: ParId, value: i32) -> Result<(), ParamError> {
        self.drive.set_stored_param(id, value)
    }

    /// The bit rate the drive's CAN controller uses (C48 in flash).
    pub fn bit_rate(&self) -> BitRate {
        bit_rate_of_c48(self.drive.saved_param(C48)).unwrap_or(BitRate::R500K)
    }

    /// Whether a client has enabled message 1.
    pub fn events_enabled(&self) -> bool {
        self.server
            .as_ref()
            .is_some_and(|s| s.event_enabled(MESSAGE_1))
    }

    fn notify_changes(&mut self, out: &mut Outbox) {
        let now = self.drive.alarms().handled();
        if now != self.reported {
            self.reported = now;
            if let Some(server) = &self.server
                && !self.drive.can_locked()
            {
                // Data: warnings (not handled: 0), then the alarm byte (manual §3.2).
                server.notify(MESSAGE_1, &[0x00, now.error_flag()], out);
            }
        }
    }
}

impl Application for Drive {
    fn read_basic(&mut self, _: ObjectIndex, _: Instant) -> Result<Payload, Payload> {
        Ok(Payload::new(&self.message0_state()).unwrap_or_default())
    }

    fn write_basic(&mut self, _: ObjectIndex, data: &[u8], _: Instant) -> Result<Payload, Payload> {
        self.message0_write(data)
            .map(|d| Payload::new(&d).unwrap_or_default())
            .map_err(Payload::u16)
    }

    fn read_mux(&mut self, _: ObjectIndex, mux: Mux, _: Instant) -> Result<Payload, Payload> {
        self.mux_read(mux.raw())
            .map(Payload::u16)
            .map_err(Payload::u16)
    }

    fn write_mux(
        &mut self,
        _: ObjectIndex,
        mux: Mux,
        data: &[u8],
        _: Instant,
    ) -> Result<Payload, Payload> {
        let [lo, hi] = <[u8; 2]>::try_from(data).map_err(|_| Payload::u16(ERR_UNDEFINED))?;
        self.mux_write(mux.raw(), u16::from_le_bytes([lo, hi]))
            .map(Payload::u16)
            .map_err(Payload::u16)
    }

    fn malformed(&mut self, _: ObjectIndex) -> Payload {
        Payload::u16(ERR_UNDEFINED)
    }
}

impl Node for OpenDrive {
    fn on_power_up(&mut self, now: Instant, _out: &mut Outbox) {
        self.drive.power_up(now);
        // COB-IDs come from flash at power-up; a table with two messages on one COB-ID
        // leaves the drive mute on CAN, as a misconfigured drive is.
        self.server = cms_objects(|id| self.drive.param(id))
            .ok()
            .and_then(|objs| CmsServer::new(objs.to_vec()).ok());
        self.reported = self.drive.alarms().handled();
        self.next_step = Some(now + self.period);
        self.persist();
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if self.drive.can_locked() {
            return;
        }
        if let Some(server) = &mut self.server {
            server.handle(frame, &mut self.drive, now, out);
        }
        self.persist();
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while let Some(t) = self.next_step.filter(|t| *t <= now) {
            self.drive.step(self.period, t);
            self.notify_changes(out);
            self.next_step = Some(t + self.period);
        }
        self.persist();
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.next_step
    }

    fn accepts(&self, id: Id) -> bool {
        !self.drive.can_locked() && self.server.as_ref().is_some_and(|s| s.accepts(id))
    }
}
