//! The TM3BCCO coupler as a [`Node`]: the CiA 301 device of `cantwin-canopen` on the
//! dictionary of [`crate::od`], the CiA 401 I/O of the configured modules, and the
//! manual's diagnostics on top.
//!
//! What the coupler adds to the CiA 301 layer (manual: object 1002H, 1003H, 1016H, 1029H):
//!
//! * **EMCY contents.** Every EMCY carries 0x1002 in its manufacturer-specific bytes 3–6
//!   (little-endian, as read by SDO) and the module number in byte 7 (0 = coupler).
//! * **0x1003** entries hold the EMCY code (bits 0–15), the error register after the error
//!   (16–23) and the module number (24–31), newest first, 10 entries. Both forms come from
//!   the device's hooks ([`CouplerHooks`]): the CiA 301 layer asks them for the bytes of
//!   every EMCY it sends and for every entry it records. A module's error raised while the
//!   same code is active for another module is another occurrence of it: its own EMCY and
//!   entry, one active error.
//! * **0x1002** is stored when the module or bus status changes and again after every reset
//!   communication (which sets it back to its default).
//! * **Modules.** At power-up each configured position is compared with what is fitted: a
//!   missing or different module is a configuration error (EMCY 0x7002, status 1), a
//!   module that does not answer a configuration timeout (0x7001, status 1), an absent
//!   optional module is status 3 without an error. A module removed or failing at runtime
//!   is a runtime error (0x7003, status 2); its inputs freeze and its outputs are off.
//!   Module errors last until the next power-up and are raised again after every reset
//!   communication. Module errors set error register bit 7 (manual: 1001H, "problems of
//!   the bus coupler").
//! * **Failure state ("safe positions", CiA 401 error mode/value).** Entered on heartbeat
//!   or guarding loss (0x8130), bus-off, RPDO deadline (0x8250), SYNC timeout (0xF001) and
//!   an internal communication error (0x1000). Left when the device enters OPERATIONAL,
//!   or, while OPERATIONAL, at the first RPDO received once none of those causes is active.
//! * **0x1029** applies to SYNC timeout and RPDO deadline too (manual: 1029H lists SYNC
//!   timeout and PDO event time errors besides bus-off and error control).
//! * **SYNC timeout.** With 0x1006 ≠ 0, the watchdog is armed by the first SYNC and fires
//!   when no SYNC came for 1.5 cycle periods; the next SYNC clears 0xF001. While it is
//!   active the error register has bit 4 set (manual 1001H: communication error).
//! * **No EMCY before boot-up** (CiA 301 §7.3.2.2.1: EMCY is a service of PRE-OPERATIONAL
//!   and OPERATIONAL, entered with the boot-up message). The errors raised again by a
//!   power-up or reset communication wait in the CiA 301 device until the boot-up message
//!   was sent: queued together, the EMCY's lower identifier would win arbitration and
//!   reach the bus first.
//! * **RPDO length.** A received RPDO longer or shorter than its mapping is not processed
//!   and raises 0x8210 (manual, EMCY table: PDO_LENGTH); 0x8220 is not used.
//! * **Queues.** The firmware's receive queue (capacity and service time in
//!   [`CouplerConfig`]) overflows under overload: the frame is lost and 0x6101 raised until
//!   the queue is empty again. A frame the controller's transmit queue dropped raises
//!   0x6102, cleared by the next frame sent.
//! * **Rotary switches.** Moving them after power-up raises 0xFF03 (the node-ID changes at
//!   the next power-up); moving them back clears it.
//! * **Not configured.** A coupler without configuration (bus status 3) entering
//!   OPERATIONAL raises 0xFF04.
//! * **Analog interrupts.** Entering OPERATIONAL with analog inputs while 0x6423 is FALSE
//!   raises 0x0080 (TPDOs of analog inputs will only be sent by timer or SYNC); setting
//!   0x6423 to TRUE clears it.
//! * **Downloads the manual restricts** are refused with 0x06090030: 0x1006 outside 0 and
//!   10 000..=10 000 000 µs in 1 ms steps, 29-bit identifiers where "not supported" (0x1005,
//!   0x1014, 0x1201 sub 1/2, RPDOs, TPDOs), 0x1014 bits 30–31 ("reserved", 0), 0x1029
//!   sub 1 above 2 ("03h-FFh reserved"), TPDO bit 30, RPDO transmission types 241–254, TPDO
//!   transmission types 241–254 (manual: transmission type tables), 0x1016 sub 1 with bits
//!   24–31 set. Checked
//!   where the value is written ([`ManualLimits`], the device's object hooks), so expedited,
//!   segmented and block downloads are refused alike.
//! * **Changing a valid PDO** (bit 31 of its COB-ID 0). A download of the value an entry
//!   already holds is accepted (a configuration tool writing back a DCF); a change is
//!   refused as CiA 301 says, the entry keeping its value
//!   (`tests/manual_fidelity.rs`, one test per row):
//!
//!   | entry | CiA 301 | change refused with |
//!   |---|---|---|
//!   | 1400H–141CH sub 1, COB-ID (bits 0–29) | §7.5.2.35 | 0x06090030 |
//!   | 1800H–1837H sub 1, COB-ID (bits 0–29) | §7.5.2.37 | 0x06090030 |
//!   | 1800H–1837H sub 3, inhibit time | §7.5.2.37 | 0x06090030 |
//!   | 1600H–161CH sub 0, number of mapped objects | §7.5.2.36 | 0x06010000 |
//!   | 1600H–161CH sub 1–8, mapped object | §7.5.2.36 | 0x06010000 |
//!   | 1A00H–1A37H sub 0, number of mapped objects | §7.5.2.38 | 0x06010000 |
//!   | 1A00H–1A37H sub 1–8, mapped object | §7.5.2.38 | 0x06010000 |
//!   | transmission type (sub 2), event timer (sub 5) | §7.5.2.35, §7.5.2.37 | not refused: they may change on a valid PDO |
//!
//! * **1201H sub 3** (client node-ID) takes 0, its default, as well as 1–127, so a DCF of
//!   the defaults downloads.
//! * **Error register.** Besides the CiA 301 bits, bit 7 (manufacturer-specific) is set
//!   while a module error is active and bit 5 (device profile) while 0x0080 is.

use crate::diag::{self, Status};
use crate::island::{Island, MAX_MODULES};
use crate::od::IslandDescription;
use cantwin_can::{ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::{Device, DeviceConfig, DeviceError, Event};
use cantwin_canopen::nmt::State;
use cantwin_canopen::od::{ObjectDictionary, OdBuildError, OdDescription, OdHooks, Value};
use cantwin_canopen::pdo::PdoEvent;
use cantwin_cia401::inputs::{self, AnalogTriggers};
use cantwin_cia401::{objects as cia401, outputs};
use std::sync::Arc;

/// How the coupler is set up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CouplerConfig {
    /// The rotary switches' node-ID at power-up, 1..=127.
    pub node_id: u8,
    /// The configured modules.
    pub island: Island,
    /// Whether the coupler holds a configuration (bus status 3 otherwise).
    pub configured: bool,
    /// Frames the firmware's receive queue holds.
    pub rx_queue_capacity: u32,
    /// Time the firmware takes per received frame.
    pub rx_service_time: Duration,
}

impl CouplerConfig {
    /// A configured coupler at `node_id` carrying `island`, with a 64-frame receive queue
    /// served at 50 µs a frame.
    pub fn new(node_id: u8, island: Island) -> Self {
        CouplerConfig {
            node_id,
            island,
            configured: true,
            rx_queue_capacity: 64,
            rx_service_time: Duration::from_micros(50),
        }
    }
}

/// Why a coupler cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum CouplerError {
    /// The dictionary could not be built.
    #[error("object dictionary: {0}")]
    Od(#[from] OdBuildError),
    /// The node-ID is outside 1..=127.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// A shared description built for other modules than the configured island's.
    #[error("the object dictionary description was built for another island")]
    OtherIsland,
}

/// A wrong channel or module number in an I/O call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IoError {
    /// No module at that position (1-based).
    #[error("no module {0}")]
    NoModule(usize),
    /// The module has no such channel of that kind.
    #[error("module {module} has no channel {channel} of that kind")]
    NoChannel {
        /// The module (1-based).
        module: usize,
        /// The channel (0-based).
        channel: u8,
    },
}

/// What is physically fitted at a module position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fitted {
    /// The module of this reference, working.
    Module(&'static crate::catalogue::ModuleSpec),
    /// Nothing.
    Empty,
    /// A module that does not answer on the expansion bus.
    Unresponsive,
}

/// The value restrictions of the manual's object tables, checked on every write of the
/// object whatever the SDO transfer that carries it (the CiA 301 layer's own checks run
/// first). Refusals are 0x06090030 "value range of parameter exceeded".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ManualLimits;

impl ManualLimits {
    /// Whether the manual refuses `value` (little-endian, up to 4 bytes) for `index`/`sub`.
    pub fn refuses(index: u16, sub: u8, value: u32) -> bool {
        let ttype = value as u8;
        match (index, sub) {
            // Manual 1006H: at least 10 ms, in 1 ms steps, at most 10 000 ms; 0 = unused.
            (0x1006, 0) => {
                value != 0 && (!(10_000..=10_000_000).contains(&value) || value % 1000 != 0)
            }
            // Manual 1005H: 29-bit identifiers are not supported.
            (0x1005, 0) => value & (1 << 29) != 0,
            // Manual 1014H: bits 31 and 30 are reserved (0), 29-bit identifiers are not
            // supported.
            (0x1014, 0) => value & (7 << 29) != 0,
            // Manual 1029H: 00h-02h; 03h-FFh are reserved (including CiA 301's
            // manufacturer-specific 80h-FFh).
            (0x1029, 1) => value > 2,
            // Manual 1200H/1201H: 29-bit identifiers are not supported.
            (0x1201, 1 | 2) => value & (1 << 29) != 0,
            // Manual 1016H: bits 31-24 are 0.
            (0x1016, 1) => value >> 24 != 0,
            // Manual 1400H-141CH: 29-bit identifiers are not supported; transmission types
            // 0-240 and 255.
            (0x1400..=0x141C, 1) => value & (1 << 29) != 0,
            (0x1400..=0x141C, 2) => (241..=254).contains(&ttype),
            // Manual 1800H-1837H: 29-bit identifiers and "no RTR" are not supported;
            // transmission types 0-240 and 255.
            (0x1800..=0x1837, 1) => value & (3 << 29) != 0,
            (0x1800..=0x1837, 2) => (241..=254).contains(&ttype),
            _ => false,
        }
    }
}

impl OdHooks for ManualLimits {
    fn validate(
        &mut self,
        _od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        let mut b = [0u8; 4];
        let n = data.len().min(4);
        b[..n].copy_from_slice(&data[..n]);
        if Self::refuses(index, sub, u32::from_le_bytes(b)) {
            Err(AbortCode::INVALID_VALUE)
        } else {
            Ok(())
        }
    }
}

/// The coupler's hooks into its CiA 301 device: the manual's value restrictions
/// ([`ManualLimits`]), and the manual's forms of the EMCY and of 0x1003. An error is raised
/// with the module number (0 = coupler) as its fifth manufacturer-specific byte; the EMCY
/// then carries 0x1002 as it is when the EMCY is sent in bytes 3–6 and the module in
/// byte 7, and the 0x1003 entry is [`diag::history_entry`] of code, error register and
/// module.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CouplerHooks {
    /// 0x1002 as the coupler last published it.
    status: u32,
}

impl CouplerHooks {
    /// 0x1002 as the EMCYs carry it.
    pub fn manufacturer_status(&self) -> u32 {
        self.status
    }
}

impl OdHooks for CouplerHooks {
    fn validate(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        ManualLimits.validate(od, index, sub, data)
    }

    fn emcy_manufacturer(&mut self, _: &ObjectDictionary, _: u16, _: u8, info: [u8; 5]) -> [u8; 5] {
        let s = self.status.to_le_bytes();
        [s[0], s[1], s[2], s[3], info[4]]
    }

    fn error_entry(&mut self, _: &ObjectDictionary, code: u16, register: u8, info: [u8; 5]) -> u32 {
        diag::history_entry(code, register, info[4])
    }
}

/// The TM3 CANopen bus coupler. See the [module documentation](self).
pub struct Tm3Coupler {
    device: Device<CouplerHooks>,
    desc: Arc<OdDescription>,
    config: CouplerConfig,
    fitted: Vec<Fitted>,
    status: Vec<Status>,
    /// Physical digital inputs per module, bit n = channel n.
    di: Vec<u32>,
    /// Physical analog inputs, by 0x6401 channel (0-based).
    ai: Vec<i16>,
    triggers: AnalogTriggers,
    failure: bool,
    internal_error: bool,
    switch: u8,
    /// An EMCY was raised or cleared outside the CiA 301 layer's own processing: it must
    /// run once more to send it.
    flush: bool,
    /// The (code, module) pairs raised and still active.
    raised: Vec<(u16, u8)>,
    sync_seen: Option<Instant>,
    sync_timed_out: bool,
    rx_level: u64,
    rx_last: Instant,
    now: Instant,
    /// The CiA 301 layer's events, passed on to [`Tm3Coupler::poll_event`].
    events: std::collections::VecDeque<Event>,
}

impl core::fmt::Debug for Tm3Coupler {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Tm3Coupler")
            .field("node_id", &self.device.node_id())
            .field("state", &self.device.state())
            .field("status", &self.status)
            .finish_non_exhaustive()
    }
}

fn device_config(node_id: u8) -> DeviceConfig {
    DeviceConfig {
        // Manual 1005H: bit 30 "device creates SYNC" is not supported.
        sync_producer: false,
        time_producer: false,
        ..DeviceConfig::new(node_id)
    }
}

/// Whether `f` is the boot-up message on `id` (CiA 301 §7.2.8.3.3: one byte, 0; a node
/// guarding answer on the same identifier never carries 0).
/// The CiA 301 device of a coupler at `node_id`.
fn coupler_device(
    desc: Arc<OdDescription>,
    node_id: u8,
) -> Result<Device<CouplerHooks>, DeviceError> {
    let mut device = Device::with_hooks(desc, device_config(node_id), CouplerHooks::default())?;
    // Manual, EMCY table, 0x8210 PDO_LENGTH: "PDO not processed because the length of the
    // received data does not match the expected one" — too long as well as too short
    // (CiA 301 §7.2.2.2 leaves the longer case to the device).
    if let Some(p) = device.pdo_mut() {
        p.set_excess_length_processed(false);
    }
    Ok(device)
}

impl Tm3Coupler {
    /// A coupler with every configured module fitted. It is unpowered until
    /// [`Node::on_power_up`].
    pub fn new(config: CouplerConfig) -> Result<Self, CouplerError> {
        let shared = IslandDescription::new(&config.island)?;
        Self::with_description(config, &shared)
    }

    /// Like [`Tm3Coupler::new`], on a description built once for couplers carrying the
    /// same modules: the description is most of a coupler's memory, and couplers of one
    /// island differ only in their values.
    pub fn with_description(
        config: CouplerConfig,
        shared: &IslandDescription,
    ) -> Result<Self, CouplerError> {
        if !shared.fits(&config.island) {
            return Err(CouplerError::OtherIsland);
        }
        let desc = Arc::clone(shared.description());
        let device = coupler_device(desc.clone(), config.node_id)?;
        let n = config.island.modules().len();
        let fitted = config
            .island
            .modules()
            .iter()
            .map(|m| Fitted::Module(m.spec))
            .collect();
        Ok(Tm3Coupler {
            device,
            desc,
            fitted,
            status: vec![Status::Ok; n],
            di: vec![0; n],
            ai: vec![0; usize::from(config.island.layout().analog_inputs)],
            triggers: AnalogTriggers::new(config.island.layout().analog_inputs),
            failure: false,
            internal_error: false,
            switch: config.node_id,
            flush: false,
            raised: Vec::new(),
            sync_seen: None,
            sync_timed_out: false,
            rx_level: 0,
            rx_last: Instant::ZERO,
            now: Instant::ZERO,
            events: std::collections::VecDeque::new(),
            config,
        })
    }

    /// The CiA 301 device inside.
    pub fn device(&self) -> &Device<CouplerHooks> {
        &self.device
    }

    /// The CiA 301 device inside, mutably.
    pub fn device_mut(&mut self) -> &mut Device<CouplerHooks> {
        &mut self.device
    }

    /// The next event of the CiA 301 layer (state changes, lost heartbeats, PDOs, SYNC...),
    /// oldest first; at most [`cantwin_canopen::device::MAX_EVENTS`] are kept.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// The configuration.
    pub fn config(&self) -> &CouplerConfig {
        &self.config
    }

    /// The dictionary description (for EDS generation).
    pub fn description(&self) -> &Arc<OdDescription> {
        &self.desc
    }

    /// The NMT state.
    pub fn state(&self) -> State {
        self.device.state()
    }

    /// Whether the outputs are in their failure state (safe positions).
    pub fn in_failure_state(&self) -> bool {
        self.failure
    }

    /// The status of module `module` (1-based) as in 0x1002.
    pub fn module_status(&self, module: usize) -> Option<Status> {
        module
            .checked_sub(1)
            .and_then(|i| self.status.get(i))
            .copied()
    }

    /// The bus status, bits 30–31 of 0x1002.
    pub fn bus_status(&self) -> Status {
        if !self.config.configured {
            Status::NotConfigured
        } else if self.internal_error || self.status.contains(&Status::RuntimeError) {
            Status::RuntimeError
        } else if self.status.contains(&Status::ConfigurationError) {
            Status::ConfigurationError
        } else {
            Status::Ok
        }
    }

    /// 0x1002.
    pub fn manufacturer_status(&self) -> u32 {
        diag::manufacturer_status(&self.status, self.bus_status())
    }

    /// The life time factor advice for the current 0x100C/0x100D.
    pub fn life_time_warning(&self) -> Option<diag::LifeTimeWarning> {
        let od = self.device.od();
        diag::check_life_time(
            od.get_unsigned(0x100C, 0).unwrap_or(0) as u16,
            od.get_unsigned(0x100D, 0).unwrap_or(0) as u8,
        )
    }

    fn slot(
        &self,
        module: usize,
    ) -> Result<(usize, &'static crate::catalogue::ModuleSpec), IoError> {
        let i = module.checked_sub(1).ok_or(IoError::NoModule(module))?;
        let m = self
            .config
            .island
            .modules()
            .get(i)
            .ok_or(IoError::NoModule(module))?;
        Ok((i, m.spec))
    }

    /// The position of module `module` (1-based) and the sub-index of its analog input
    /// `channel` (0-based) in 0x6401 (CiA 401 read analog input 16-bit), the island's
    /// analog inputs numbered in module order.
    fn analog_input_sub(&self, module: usize, channel: u8) -> Result<(usize, u8), IoError> {
        let (i, spec) = self.slot(module)?;
        if channel >= spec.analog_inputs {
            return Err(IoError::NoChannel { module, channel });
        }
        let sub = self
            .config
            .island
            .offsets(i)
            .map_or(1, |o| o.analog_input + channel + 1);
        Ok((i, sub))
    }

    fn working(&self, i: usize) -> bool {
        matches!(self.fitted.get(i), Some(Fitted::Module(_)))
            && self.status.get(i) == Some(&Status::Ok)
    }

    /// Sets digital input `channel` (0-based) of module `module` (1-based). The new state
    /// reaches 0x6000 only while the module works; a change selected by 0x6005–0x6008
    /// makes the event-driven TPDOs mapping the byte due.
    pub fn set_digital_input(
        &mut self,
        module: usize,
        channel: u8,
        on: bool,
    ) -> Result<(), IoError> {
        let (i, spec) = self.slot(module)?;
        if channel >= spec.digital_inputs {
            return Err(IoError::NoChannel { module, channel });
        }
        let bit = 1u32 << channel;
        if on {
            self.di[i] |= bit;
        } else {
            self.di[i] &= !bit;
        }
        if self.working(i) {
            self.apply_digital_inputs(i);
        }
        Ok(())
    }

    fn apply_digital_inputs(&mut self, i: usize) {
        let (Some(o), Some(m)) = (
            self.config.island.offsets(i),
            self.config.island.modules().get(i),
        ) else {
            return;
        };
        for b in 0..m.spec.input_bytes() {
            let sub = o.input_byte + b + 1;
            let byte = (self.di[i] >> (8 * b)) as u8;
            if inputs::set_digital_input_byte(self.device.od_mut(), sub, byte) {
                self.device.mark_changed(cia401::READ_INPUT_8, sub);
            }
        }
    }

    /// Writes the physical inputs of the working modules into 0x6000/0x6401 again (after
    /// the application objects went back to their defaults).
    fn reapply_inputs(&mut self) {
        self.triggers.reset();
        for i in 0..self.di.len() {
            if !self.working(i) {
                continue;
            }
            self.apply_digital_inputs(i);
            let (Some(o), Some(m)) = (
                self.config.island.offsets(i),
                self.config.island.modules().get(i),
            ) else {
                continue;
            };
            for ch in 0..m.spec.analog_inputs {
                let sub = o.analog_input + ch + 1;
                let v = self.ai.get(usize::from(sub) - 1).copied().unwrap_or(0);
                self.triggers.set_input(self.device.od_mut(), sub, v);
            }
        }
    }

    /// Sets analog input `channel` (0-based) of module `module` (1-based) to `value`
    /// (raw 16-bit). A 0x6421 trigger that fires makes the event-driven TPDOs mapping the
    /// channel due.
    pub fn set_analog_input(
        &mut self,
        module: usize,
        channel: u8,
        value: i16,
    ) -> Result<(), IoError> {
        let (i, sub) = self.analog_input_sub(module, channel)?;
        if let Some(v) = self.ai.get_mut(usize::from(sub) - 1) {
            *v = value;
        }
        if !self.working(i) {
            return Ok(());
        }
        if self.triggers.set_input(self.device.od_mut(), sub, value) != 0 {
            self.device.mark_changed(cia401::READ_ANALOG_INPUT_16, sub);
        }
        Ok(())
    }

    /// The physical state of digital input `channel` (0-based) of module `module` (the
    /// wired terminal, whether or not the module works).
    pub fn digital_input(&self, module: usize, channel: u8) -> Result<bool, IoError> {
        let (i, spec) = self.slot(module)?;
        if channel >= spec.digital_inputs {
            return Err(IoError::NoChannel { module, channel });
        }
        Ok(self.di.get(i).is_some_and(|d| d >> channel & 1 != 0))
    }

    /// The physical value of analog input `channel` (0-based) of module `module` (raw
    /// 16-bit, whether or not the module works).
    pub fn analog_input(&self, module: usize, channel: u8) -> Result<i16, IoError> {
        let (_, sub) = self.analog_input_sub(module, channel)?;
        Ok(self.ai.get(usize::from(sub) - 1).copied().unwrap_or(0))
    }

    /// The physical state of digital output `channel` (0-based) of module `module`.
    pub fn digital_output(&self, module: usize, channel: u8) -> Result<bool, IoError> {
        let (i, spec) = self.slot(module)?;
        if channel >= spec.digital_outputs {
            return Err(IoError::NoChannel { module, channel });
        }
        if !self.working(i) {
            return Ok(false);
        }
        let o = self.config.island.offsets(i).unwrap_or_default();
        let sub = o.output_byte + channel / 8 + 1;
        let byte = outputs::digital_output_byte(self.device.od(), sub, self.failure);
        Ok(byte >> (channel % 8) & 1 != 0)
    }

    /// The physical value of analog output `channel` (0-based) of module `module`.
    pub fn analog_output(&self, module: usize, channel: u8) -> Result<i16, IoError> {
        let (i, spec) = self.slot(module)?;
        if channel >= spec.analog_outputs {
            return Err(IoError::NoChannel { module, channel });
        }
        if !self.working(i) {
            return Ok(0);
        }
        let o = self.config.island.offsets(i).unwrap_or_default();
        Ok(outputs::analog_output(
            self.device.od(),
            o.analog_output + channel + 1,
            self.failure,
        ))
    }

    /// Fits `what` at module position `module` (1-based). Takes effect at the next
    /// power-up, except removing a working module, which is a runtime error at once.
    pub fn fit(
        &mut self,
        module: usize,
        what: Fitted,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), IoError> {
        let (i, _) = self.slot(module)?;
        let was_working = self.working(i) && self.state() != State::Initialising;
        self.fitted[i] = what;
        if was_working
            && !matches!(what, Fitted::Module(s) if Some(s) == self.config.island.modules().get(i).map(|m| m.spec))
        {
            self.status[i] = Status::RuntimeError;
            self.publish_status();
            self.run(now, out, |c, _| c.raise(diag::RUNTIME_ERROR, (i + 1) as u8));
        }
        Ok(())
    }

    /// An internal communication error on the expansion bus starts (`true`, EMCY 0x1000,
    /// failure state) or ends (`false`).
    pub fn set_internal_error(&mut self, on: bool, now: Instant, out: &mut Outbox) {
        if on == self.internal_error {
            return;
        }
        self.internal_error = on;
        self.publish_status();
        self.run(now, out, |c, _| {
            if on {
                c.failure = true;
                c.raise(diag::GENERIC_ERROR, 0);
            } else {
                c.clear(diag::GENERIC_ERROR);
            }
        });
    }

    /// The rotary switches are turned to `node_id`. The node-ID is read at power-up only;
    /// a position different from the one at power-up raises 0xFF03.
    pub fn set_rotary_switch(&mut self, node_id: u8, now: Instant, out: &mut Outbox) {
        self.switch = node_id;
        let changed = node_id != self.device.node_id();
        self.run(now, out, |c, _| {
            if changed {
                c.raise(diag::ROTARY_SWITCH_CHANGED, 0);
            } else {
                c.clear(diag::ROTARY_SWITCH_CHANGED);
            }
        });
    }

    /// Raises `code` for `module` (0 = coupler) through the CiA 301 layer: a new error,
    /// or, while the code is active for another module, another occurrence of it with its
    /// own EMCY and 0x1003 entry. A code already active for that module is not raised again.
    fn raise(&mut self, code: u16, module: u8) {
        if self.raised.contains(&(code, module)) && self.device.emcy_active(code) {
            return;
        }
        if matches!(code, 0x7000..=0x7FFF) {
            self.device.emcy().set_register_bits(0x80, true);
        }
        if code == diag::ANALOG_DISABLE {
            // Manual 1001H bit 5: problems related to the device profile.
            self.device.emcy().set_register_bits(0x20, true);
        }
        if code == diag::SYNC_TIMEOUT {
            // Manual 1001H bit 4: communication error (the SYNC is a communication object).
            self.device.emcy().set_register_bits(0x10, true);
        }
        self.raised.push((code, module));
        self.device.emcy().report(code, [0, 0, 0, 0, module]);
        self.flush = true;
    }

    /// Clears `code` (error reset EMCY if it was active).
    fn clear(&mut self, code: u16) {
        if code == diag::ANALOG_DISABLE {
            self.device.emcy().set_register_bits(0x20, false);
        } else if code == diag::SYNC_TIMEOUT && self.device.emcy_active(code) {
            self.device.emcy().set_register_bits(0x10, false);
        } else if !self.device.emcy_active(code) {
            // Nothing to clear (the common case, e.g. 0x6102 after every frame sent): asked
            // without `emcy()`, which would make the device recompute its timers.
            return;
        }
        if self.device.emcy().clear(code) {
            self.flush = true;
        }
    }

    /// Publishes 0x1002 after the module or bus status changed, or after a reset
    /// communication set it back to its default: into the dictionary, and to the hooks for
    /// the EMCYs.
    fn publish_status(&mut self) {
        let status = self.manufacturer_status();
        self.device.hooks_mut().status = status;
        let od = self.device.od_mut();
        if od.get_unsigned(0x1002, 0) != Some(u64::from(status)) {
            let _ = od.set(0x1002, 0, &Value::Unsigned32(status));
        }
    }

    fn module_check(&mut self) {
        for (i, m) in self.config.island.modules().iter().enumerate() {
            self.status[i] = match self.fitted[i] {
                Fitted::Module(s) if s == m.spec => Status::Ok,
                Fitted::Empty if m.optional => Status::NotConfigured,
                Fitted::Empty | Fitted::Module(_) | Fitted::Unresponsive => {
                    Status::ConfigurationError
                }
            };
        }
    }

    fn raise_module_errors(&mut self) {
        for i in 0..self.status.len().min(MAX_MODULES) {
            let code = match (self.status[i], self.fitted[i]) {
                (Status::ConfigurationError, Fitted::Unresponsive) => diag::CONFIGURATION_TIMEOUT,
                (Status::ConfigurationError, _) => diag::CONFIGURATION_ERROR,
                (Status::RuntimeError, _) => diag::RUNTIME_ERROR,
                _ => continue,
            };
            self.raise(code, (i + 1) as u8);
        }
        if self.internal_error {
            self.raise(diag::GENERIC_ERROR, 0);
        }
        if self.switch != self.device.node_id() {
            self.raise(diag::ROTARY_SWITCH_CHANGED, 0);
        }
    }

    /// Runs `f` on the coupler and then everything that follows a call into the device.
    fn run(&mut self, now: Instant, out: &mut Outbox, f: impl FnOnce(&mut Self, &mut Outbox)) {
        self.now = now;
        let timed_out = self.device.emcy_active(diag::RPDO_TIMEOUT);
        f(self, out);
        if !timed_out && self.device.emcy_active(diag::RPDO_TIMEOUT) {
            // Manual 1029H: an RPDO deadline is handled like a communication error.
            self.failure = true;
            self.device.error_detected(1, now, out);
        }
        self.events(now, out);
        // Send the EMCYs raised or cleared above.
        if core::mem::take(&mut self.flush) {
            self.device.on_tick(now, out);
        }
        let device = &mut self.device;
        self.raised.retain(|&(c, _)| device.emcy_active(c));
    }

    fn events(&mut self, now: Instant, out: &mut Outbox) {
        while let Some(e) = self.device.poll_event() {
            if self.events.len() >= cantwin_canopen::device::MAX_EVENTS {
                self.events.pop_front();
            }
            self.events.push_back(e);
            match e {
                Event::ResetCommunication => {
                    self.raised.clear();
                    self.publish_status();
                    self.sync_seen = None;
                    self.sync_timed_out = false;
                    self.raise_module_errors();
                }
                Event::ResetApplication => self.reapply_inputs(),
                Event::StateChanged {
                    to: State::Operational,
                    ..
                } => {
                    self.failure = self.internal_error;
                    if !self.config.configured {
                        self.raise(diag::NOT_CONFIGURED_IN_OP, 0);
                    }
                    let ai = self.config.island.layout().analog_inputs > 0;
                    let enabled = matches!(
                        self.device
                            .od()
                            .get(cia401::ANALOG_GLOBAL_INTERRUPT_ENABLE, 0),
                        Ok(Value::Boolean(true))
                    );
                    if ai && !enabled {
                        self.raise(diag::ANALOG_DISABLE, 0);
                    }
                }
                Event::HeartbeatLost { .. } | Event::LifeGuardingLost | Event::BusOff => {
                    self.failure = true;
                }
                Event::Sync { .. } => {
                    self.sync_seen = Some(now);
                    self.sync_timed_out = false;
                    self.clear(diag::SYNC_TIMEOUT);
                }
                Event::Pdo(PdoEvent::Received { .. })
                    if self.failure && self.can_leave_failure() =>
                {
                    self.failure = false;
                }
                _ => {}
            }
        }
        if self.device.emcy_active(diag::ANALOG_DISABLE)
            && matches!(
                self.device
                    .od()
                    .get(cia401::ANALOG_GLOBAL_INTERRUPT_ENABLE, 0),
                Ok(Value::Boolean(true))
            )
        {
            self.clear(diag::ANALOG_DISABLE);
        }
        if let Some(t) = self.sync_deadline()
            && now >= t
        {
            self.sync_timed_out = true;
            self.raise(diag::SYNC_TIMEOUT, 0);
            self.failure = true;
            self.device.error_detected(1, now, out);
        }
    }

    fn can_leave_failure(&mut self) -> bool {
        self.state() == State::Operational
            && !self.internal_error
            && ![
                diag::GUARD_OR_HEARTBEAT,
                diag::RPDO_TIMEOUT,
                diag::SYNC_TIMEOUT,
            ]
            .iter()
            .any(|&c| self.device.emcy_active(c))
    }

    fn sync_period(&self) -> Duration {
        Duration::from_micros(self.device.od().get_unsigned(0x1006, 0).unwrap_or(0))
    }

    fn sync_deadline(&self) -> Option<Instant> {
        let period = self.sync_period();
        if period.is_zero() || !matches!(self.state(), State::PreOperational | State::Operational) {
            return None;
        }
        let last = self.sync_seen?;
        if self.sync_timed_out {
            return None;
        }
        Some(last + period + Duration::from_nanos(period.as_nanos() / 2))
    }

    /// The firmware's receive queue takes `frame`; false if it overflowed.
    fn rx_queue(&mut self, now: Instant) -> bool {
        let service = self.config.rx_service_time.as_nanos().max(1);
        let served = now.saturating_duration_since(self.rx_last).as_nanos() / service;
        if served > 0 {
            self.rx_level = self.rx_level.saturating_sub(served);
            self.rx_last += Duration::from_nanos(served * service);
        }
        if self.rx_level == 0 {
            self.rx_last = now;
            if self.device.emcy_active(diag::RX_QUEUE_OVERRUN) {
                self.clear(diag::RX_QUEUE_OVERRUN);
            }
        }
        if self.rx_level >= u64::from(self.config.rx_queue_capacity) {
            self.raise(diag::RX_QUEUE_OVERRUN, 0);
            return false;
        }
        self.rx_level += 1;
        true
    }
}

impl Node for Tm3Coupler {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        if self.switch != self.device.node_id()
            && let Ok(mut d) = coupler_device(self.desc.clone(), self.switch)
        {
            // The stored parameters belong to the coupler, not to its node-ID.
            d.set_storage(self.device.take_storage());
            self.device = d;
        }
        self.internal_error = false;
        self.failure = false;
        self.rx_level = 0;
        self.rx_last = now;
        self.module_check();
        self.publish_status();
        self.run(now, out, |c, o| {
            c.device.on_power_up(now, o);
            c.reapply_inputs();
        });
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.run(now, out, |c, o| {
            if !c.rx_queue(now) {
                return;
            }
            c.device.on_frame(frame, now, o);
        });
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.run(now, out, |c, o| c.device.on_tick(now, o));
    }

    fn next_deadline(&self) -> Option<Instant> {
        Instant::earliest(self.device.next_deadline(), self.sync_deadline())
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.run(now, out, |c, o| {
            c.device.on_sent(frame, now, o);
            c.clear(diag::TX_QUEUE_OVERRUN);
        });
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.run(now, out, |c, o| {
            if event == ControllerEvent::TxDropped {
                c.raise(diag::TX_QUEUE_OVERRUN, 0);
            }
            c.device.on_controller_event(event, now, o);
        });
    }
}
