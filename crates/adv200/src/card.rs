//! The drive with its EXP-CAN/DN-ADV card, as one [`Node`].
//!
//! * **Drive reset** ([`Node::on_power_up`] or [`Adv200::reset_drive`]) latches the fieldbus
//!   parameters 4000–4012 (§1.2: they act only after a reset), checks them (Opt Bus Fault
//!   FF01 wrong type, FF02 baud rate None, FF03 address outside 1–127), places the Process
//!   Data Channel (CANopen) and builds the card's CiA 301 device. With a configuration fault
//!   FF01–FF03 the card stays off the bus, as the real one does from the factory defaults.
//!   PAR 4000 = DeviceNet runs the [`crate::devicenet`] personality instead (chapter 3: bit
//!   rates 125k–500k, else FFC5; MAC ID 1–63, else FFC6; faults FFC7 bus-off, FFC9 duplicate
//!   MAC ID, 0 polled I/O timed out or enable without polled I/O; no EMCY, §3.7.2). The
//!   predefined explicit connection announces body format 8/16 in its Allocate response,
//!   so the manual's PAR 600 example reaches instance 600 on it (§3.4.1).
//! * **SDO** (§1.1 items 10–11, §1.4): the CiA 301 stack answers every request, with the
//!   services of a minimum-capability device: sub-index 0xFF is refused (0x06090011), and
//!   unless [`Adv200Config::expedited_only`] is off a segmented or block request is aborted
//!   with 0x05040001 and an upload of an object longer than 4 bytes with 0x06070012
//!   ([`SdoCapabilities`]). Drive parameters are served by the dictionary's hooks at
//!   0x2000 + PAR sub 1 in both directions ([`crate::station`]): a download of 1–4 bytes is
//!   accepted for any parameter, an upload returns the parameter's size.
//! * **Runtime faults** raise Opt Bus Fault (EMCY 0xFF11, sub-code in the manufacturer bytes)
//!   while the drive's enable command is on, or always with `Fieldbus alarm mode` = 1: 0
//!   bus loss (no SYNC within 0x1006 × 0x100D, §1.1.3, or enable while not Operational), 8130 guarding
//!   or heartbeat loss, 8110 receive overrun, FFC5 NMT message of the wrong length, FFC6
//!   invalid NMT command, FFC7 bus-off, 8100 bus-off again within [`BUS_OFF_REPEAT`] of
//!   recovering from the previous one. DeviceNet: FFC8 for a poll command whose length is not
//!   the PDC's Master→Slave size.
//! * **EMCY after boot-up** (CiA 301 §7.2.7.1: EMCY in PRE-OPERATIONAL and OPERATIONAL
//!   only): the alarms active when the boot-up message has been sent ([`Node::on_sent`]),
//!   a `Cfg` code found at the drive reset among them, are signalled then, one EMCY each,
//!   and again after every reset communication (which clears the stack's error register),
//!   so a master that starts later and resets the node learns them; 0x1001 and `Active
//!   alarm` (PAR 1072) show them meanwhile. The card has no 0x1003: table 1.1.5 does not
//!   list it (an upload is 0x06020000).
//! * **One alarm, one EMCY** (§1.1.3, §1.5): a guarding or heartbeat loss is Opt Bus Fault
//!   8130 alone (not also the stack's 0x8130); CiA 301's default reaction without 0x1029
//!   takes the card to PRE-OPERATIONAL (§7.5.2.32), and that is no second Bus Loss for a
//!   drive already tripped on the loss.
//! * **Two codes for one bus-off** (§1.5 lists FFC7 "CAN bus off — check line state for
//!   problems" and 8100 "CAN bus off — check line state for hardware problems"; the DeviceNet
//!   table of §3.7.1 only FFC7): a bus-off is FFC7; one that follows the recovery from the
//!   previous within [`BUS_OFF_REPEAT`] means the line cannot carry frames at all (a short,
//!   a missing terminator, a node at another bit rate) and raises 8100 as well.
//! * **Internal card errors** (FF04, FFB4..FFC3, "contact manufacturer"): a defect given to
//!   the card with [`Adv200::inject_card_fault`] is found at the next drive reset, like the
//!   other `Cfg` codes ([`CardFault`]).
//! * **LEDs** (§"Leds", §1.6.2.1): PWR and +5VC on while powered and the card active, OP on in
//!   Operational, AL on in any other NMT state or with Opt Bus Fault active.

use cantwin_can::{BitRate, ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::device::{Device, DeviceConfig, Event};
use cantwin_canopen::nmt::State;
use cantwin_canopen::od::{EntryId, ObjectDictionary, OdHooks};
use cantwin_canopen::sdo::SdoCapabilities;
use cantwin_cia402::objects as cia402;

use cantwin_devicenet::{Led, MacId, Slave, SlaveConfig, SlaveEvent};
use std::sync::Arc;

use crate::alarms::{Alarm, CardFault, opt_bus};
use crate::devicenet::{DnApp, identity};
use crate::drive::{AlarmEvent, Drive, ProfileCommands};
use crate::ds402::State as PowerState;
use crate::memory::Memory;
use crate::od::{CardInfo, Descriptions, Personality};
use crate::params::{ParamDb, ParamError, def, par};
use crate::pdc::{self, Pdc};
use crate::station::{Station, od_i64};

/// How the twin is set up besides its parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Adv200Config {
    /// Only expedited SDO transfers (§1.1 item 11). `false` lets the CiA 301 stack's segmented
    /// and block transfers through.
    pub expedited_only: bool,
    /// The bit rate of the bus the card is on; a card configured for another rate stays
    /// silent (it cannot decode the bus). `None`: not checked.
    pub bus_bit_rate: Option<u32>,
    /// 0x1018 sub 4 (CANopen) and Identity attribute 6 (DeviceNet).
    pub serial: u32,
    /// 0x1018 sub 1, the CiA vendor-ID ([`crate::od::VENDOR_ID`] by default: none sourced).
    pub vendor_id: u32,
    /// Identity attribute 1, the ODVA vendor ID ([`crate::devicenet::VENDOR_ID`] by
    /// default: none sourced).
    pub devicenet_vendor_id: u16,
}

impl Default for Adv200Config {
    fn default() -> Self {
        Adv200Config {
            expedited_only: true,
            bus_bit_rate: None,
            serial: 1,
            vendor_id: crate::od::VENDOR_ID,
            devicenet_vendor_id: crate::devicenet::VENDOR_ID,
        }
    }
}

/// The card's LEDs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Leds {
    /// AL (red).
    pub al: bool,
    /// OP (green).
    pub op: bool,
    /// PWR (green).
    pub pwr: bool,
    /// +5VC (green).
    pub vc5: bool,
}

/// The card on the bus in a CANopen personality: its CiA 301 device, whose dictionary's
/// hooks hold the drive.
struct Card {
    dev: Device<Station>,
    personality: Personality,
    pdc: Pdc,
    last_sync: Option<Instant>,
    /// Where the dictionary keeps 0x1006 (communication cycle period), located once.
    cycle_period: Option<EntryId>,
    /// Where the dictionary keeps 0x100D (life time factor), for the same deadline.
    life_time_factor: Option<EntryId>,
    /// The bus-loss threshold with SYNC, 0x1006 × 0x100D (`None`: no SYNC watch), as of the
    /// last frame or device event: only a frame (an SDO write) or a reset communication
    /// changes those objects, and the deadline is asked for after every call of the bus.
    sync_timeout: Option<Duration>,
    /// The objects served by the drive that event-driven TPDOs (transmission type 0, 254,
    /// 255: §1.1.7 "254...255 if asynchronous") map, with the bytes they had at the last
    /// evaluation: a change is the application event that sends the TPDO.
    watched: Vec<(u16, u8, [u8; 4])>,
    /// The boot-up message of the last power-up or reset communication has not been sent
    /// yet: the drive's alarms wait for it (CiA 301 §7.2.7.1: EMCY in PRE-OPERATIONAL and
    /// OPERATIONAL only, and the boot-up ends initialisation).
    booting: bool,
}

/// The objects served by the drive that the event-driven TPDOs of `dev` map, with their
/// present bytes.
fn watch_list(dev: &Device<Station>) -> Vec<(u16, u8, [u8; 4])> {
    let od = dev.od();
    let mut watched: Vec<(u16, u8, [u8; 4])> = Vec::new();
    for n in 0..0x200u16 {
        let Some(ttype) = od.get_unsigned(0x1800 + n, 2) else {
            continue;
        };
        if !(ttype == 0 || ttype >= 254) {
            continue;
        }
        let count = od.get_unsigned(0x1A00 + n, 0).unwrap_or(0).min(64) as u8;
        for k in 1..=count {
            let entry = od.get_unsigned(0x1A00 + n, k).unwrap_or(0) as u32;
            let (index, sub) = ((entry >> 16) as u16, (entry >> 8) as u8);
            if watched.iter().any(|w| w.0 == index && w.1 == sub) {
                continue;
            }
            if let Some(Ok((bytes, _))) = dev.hooks().serve(index, sub) {
                watched.push((index, sub, bytes));
            }
        }
    }
    watched
}

/// The fieldbus parameters latched at the last drive reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Latched {
    ty: i64,
    baud: i64,
    address: i64,
    ms_enable: bool,
    alarm_mode: bool,
}

/// The vl objects of CiA 402 as the master last wrote them into the dictionary.
#[derive(Debug, Clone, Copy)]
struct VlCommand {
    controlword: u16,
    target: i64,
    min: i64,
    max: i64,
    acceleration: f64,
    deceleration: f64,
}

impl VlCommand {
    fn of(od: &ObjectDictionary) -> Self {
        let rate = |index: u16| {
            let dv = od_i64(od, index, 1).unwrap_or(1000) as f64;
            let dt = od_i64(od, index, 2).unwrap_or(1).max(1) as f64;
            dv / dt
        };
        VlCommand {
            controlword: od_i64(od, cia402::CONTROLWORD, 0).unwrap_or(0) as u16,
            target: od_i64(od, cia402::VL_TARGET_VELOCITY, 0).unwrap_or(0),
            min: od_i64(od, cia402::VL_VELOCITY_MIN_MAX_AMOUNT, 1).unwrap_or(0),
            max: od_i64(od, cia402::VL_VELOCITY_MIN_MAX_AMOUNT, 2).unwrap_or(i64::from(i16::MAX)),
            acceleration: rate(cia402::VL_VELOCITY_ACCELERATION),
            deceleration: rate(cia402::VL_VELOCITY_DECELERATION),
        }
    }
}

/// The ADV200 drive with its EXP-CAN/DN-ADV card. See the [module documentation](self).
pub struct Adv200 {
    config: Adv200Config,
    /// The drive while no CANopen card holds it (as its dictionary's hooks): fieldbus off,
    /// a card that could not start, DeviceNet.
    home: Station,
    card: Option<Card>,
    dnet: Option<Slave<DnApp>>,
    latched: Latched,
    powered: bool,
    sticky: Option<Alarm>,
    /// The time of the last call from the bus.
    last_now: Instant,
    /// An input changed outside a call from the bus: evaluate at once.
    dirty: bool,
    /// Defects of the card found at every drive reset.
    card_faults: std::collections::BTreeSet<CardFault>,
    /// When the controller last recovered from bus-off.
    bus_off_recovered: Option<Instant>,
    /// Where the card's dictionary description comes from at a drive reset.
    descriptions: Arc<Descriptions>,
    /// [`Node::next_deadline`] as of the end of the last call that could change it: the bus
    /// asks for it after every event; every other change of the drive sets `dirty`.
    deadline: Option<Instant>,
    /// Where "Save all parameters" keeps the parameters across power cycles
    /// ([`crate::memory`]): in memory unless [`Adv200::set_memory`] gave another store.
    memory: Option<Memory>,
    /// What was wrong with the memory at the last power-up or save.
    memory_error: Option<String>,
}

impl core::fmt::Debug for Adv200 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Adv200")
            .field("powered", &self.powered)
            .field("alarms", &self.st().drive.alarms())
            .finish_non_exhaustive()
    }
}

/// A bus-off within this time of the recovery from the previous one raises 8100 (hardware
/// problem) besides FFC7 (§1.5; see the [module documentation](self)). ISO 11898-1 recovery
/// takes 128 × 11 bit times (2.8 ms at 500 kbit/s): a line that sends the card bus-off again
/// within a second of recovering keeps failing.
pub const BUS_OFF_REPEAT: Duration = Duration::from_secs(1);

const BAUDS: [u32; 5] = [0, 125_000, 250_000, 500_000, 1_000_000];

impl Adv200 {
    /// A drive with factory parameters, not powered.
    pub fn new(config: Adv200Config) -> Self {
        Self::with_descriptions(config, Arc::new(Descriptions::new()))
    }

    /// Like [`Adv200::new`], sharing the dictionary descriptions of `descriptions` with
    /// the other drives given it: drives whose card runs the same personality, PDC layout
    /// and serial number then hold one description between them.
    pub fn with_descriptions(config: Adv200Config, descriptions: Arc<Descriptions>) -> Self {
        Adv200 {
            config,
            home: Station::default(),
            card: None,
            dnet: None,
            latched: Latched::default(),
            powered: false,
            sticky: None,
            last_now: Instant::ZERO,
            dirty: false,
            card_faults: std::collections::BTreeSet::new(),
            bus_off_recovered: None,
            descriptions,
            deadline: None,
            // §1.1 object table: 0x1010 is the card's; a drive given no other memory keeps
            // what it saves in memory, for as long as the twin exists (across its power
            // cycles), in the stack's storage.
            memory: Some(Memory::new(Box::new(
                cantwin_canopen::storage::MemoryStorage::new(),
            ))),
            memory_error: None,
        }
    }

    /// Keeps what "Save all parameters" (0x1010 sub 1) stores in `memory` from now on, and
    /// loads the drive parameters from it at every power-up ([`crate::memory`]).
    pub fn set_memory(&mut self, memory: Memory) {
        self.memory = Some(memory);
    }

    /// What was wrong with the parameter memory at the last power-up or save (the drive
    /// then raised Param error), if anything.
    pub fn memory_error(&self) -> Option<&str> {
        self.memory_error.as_deref()
    }

    /// Loads the saved parameters at power-up; whether the memory could not be read.
    fn load_memory(&mut self) -> bool {
        let Some(m) = self.memory.clone() else {
            return false;
        };
        match m.load_params(&mut self.st_mut().params) {
            Ok(_) => false,
            Err(e) => {
                self.memory_error = Some(crate::memory::describe(&e));
                true
            }
        }
    }

    /// Completes a store the card's device was asked for; Param error if it fails.
    fn flush_memory(&mut self) {
        let Some(m) = &self.memory else {
            return;
        };
        if let Err(e) = m.flush(&self.st().params) {
            self.memory_error = Some(e.to_string());
            self.st_mut().drive.raise(Alarm::ParamError);
        }
    }

    /// The drive, wherever it is held.
    fn st(&self) -> &Station {
        match &self.card {
            Some(c) => c.dev.hooks(),
            None => &self.home,
        }
    }

    /// The drive, mutably.
    fn st_mut(&mut self) -> &mut Station {
        match &mut self.card {
            Some(c) => c.dev.hooks_mut(),
            None => &mut self.home,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ParamDb {
        &self.st().params
    }

    /// The value of parameter `par`.
    pub fn param(&self, par: u16) -> Result<i64, ParamError> {
        self.params().get(par)
    }

    /// Writes parameter `par` from the keypad (checked like an SDO write).
    pub fn set_param(&mut self, par: u16, value: i64) -> Result<(), ParamError> {
        self.dirty = true;
        self.st_mut().params.set(par, value)
    }

    /// Writes parameter `par` by enumeration name or number from the keypad.
    pub fn set_param_str(&mut self, par: u16, value: &str) -> Result<(), ParamError> {
        let d = def(par).ok_or(ParamError::Missing)?;
        let v = match d.enum_value(value) {
            Some(v) => v,
            None => value.trim().parse().map_err(|_| ParamError::Invalid)?,
        };
        self.set_param(par, v)
    }

    /// The value of object `index`/`sub` as an SDO upload would give it (hooked objects
    /// served from the drive), without the SDO server's transfer rules. Drive parameters
    /// (0x2000 + PAR sub 1) answer in every personality; other objects while the card runs
    /// CANopen or DS402.
    pub fn object_bytes(&self, index: u16, sub: u8) -> Result<Vec<u8>, cantwin_canopen::AbortCode> {
        let Some(c) = &self.card else {
            if (crate::station::PARAMS_FIRST..=crate::station::PARAMS_LAST).contains(&index)
                && sub == 1
            {
                let (bytes, len) = self
                    .home
                    .params
                    .encode(index - crate::station::PARAMS_FIRST)
                    .map_err(|e| e.abort_code())?;
                return Ok(bytes[..len].to_vec());
            }
            return Err(cantwin_canopen::AbortCode::NO_OBJECT);
        };
        let od = c.dev.od();
        let id = od.locate(index, sub)?;
        if od.description().is_hooked(index)
            && let Some(r) = c.dev.hooks().serve(index, sub)
        {
            let (bytes, len) = r?;
            return Ok(bytes[..len].to_vec());
        }
        Ok(od.raw(id).to_vec())
    }

    /// The drive model.
    pub fn drive(&self) -> &Drive {
        &self.st().drive
    }

    /// Sets digital input k (1..=8), effective at the next event.
    pub fn set_digital_input(&mut self, k: u8, on: bool) {
        self.dirty = true;
        self.st_mut().drive.set_digital_input(k, on);
    }

    /// Sets analog input k (1..=2) in volts.
    pub fn set_analog_input(&mut self, k: u8, volts: f64) {
        self.dirty = true;
        self.st_mut().drive.set_analog_input(k, volts);
    }

    /// Raises a drive alarm (an outside cause: overvoltage, external fault, …).
    pub fn raise_alarm(&mut self, alarm: Alarm) {
        self.dirty = true;
        self.st_mut().drive.raise(alarm);
    }

    /// Gives the card an internal defect (FF04, FFB4..FFC3, "Internal error, contact
    /// manufacturer"). Like every `Cfg` code of the §1.5/§3.7.1 tables the card finds it
    /// when it configures itself, at the next drive reset, and at every reset after until
    /// [`Adv200::clear_card_faults`].
    pub fn inject_card_fault(&mut self, fault: CardFault) {
        self.card_faults.insert(fault);
    }

    /// Repairs the card (effective at the next drive reset).
    pub fn clear_card_faults(&mut self) {
        self.card_faults.clear();
    }

    /// The defects given to the card.
    pub fn card_faults(&self) -> impl Iterator<Item = CardFault> + '_ {
        self.card_faults.iter().copied()
    }

    /// The first internal database error of the card, if any (FFB4..FFC3).
    fn database_fault(&self) -> Option<u16> {
        self.card_faults
            .iter()
            .find(|f| matches!(f, CardFault::Database(_)))
            .map(|f| f.code())
    }

    /// Digital output k (1..=4).
    pub fn digital_output(&self, k: u8) -> bool {
        Drive::digital_output(self.params(), k)
    }

    /// The card's NMT state, if it is on the bus.
    pub fn nmt_state(&self) -> Option<State> {
        self.card.as_ref().map(|c| c.dev.state())
    }

    /// The CiA 402 state (DS402 personality).
    pub fn power_state(&self) -> Option<PowerState> {
        self.card
            .as_ref()
            .filter(|c| c.personality == Personality::Ds402)
            .map(|c| c.dev.hooks().ds402.state())
    }

    /// The CANopen device of the card, if it is on the bus.
    pub fn device(&self) -> Option<&Device<impl OdHooks>> {
        self.card.as_ref().map(|c| &c.dev)
    }

    /// The PDC layout placed at the last drive reset (CANopen personality).
    pub fn pdc(&self) -> Option<&Pdc> {
        self.card
            .as_ref()
            .filter(|c| c.personality == Personality::CanOpen)
            .map(|c| &c.pdc)
    }

    /// The Opt Bus Fault sub-codes active.
    pub fn opt_bus_faults(&self) -> Vec<u16> {
        self.st()
            .drive
            .alarms()
            .iter()
            .filter_map(|a| match a {
                Alarm::OptBusFault(s) => Some(*s),
                _ => None,
            })
            .collect()
    }

    /// The LEDs.
    pub fn leds(&self) -> Leds {
        if !self.powered {
            return Leds::default();
        }
        let fault = !self.opt_bus_faults().is_empty();
        match &self.card {
            Some(c) => {
                let op = c.dev.state() == State::Operational;
                Leds {
                    al: fault || !op,
                    op,
                    pwr: true,
                    vc5: true,
                }
            }
            None => Leds {
                al: fault,
                op: false,
                pwr: self.latched.ty != 0,
                vc5: self.latched.ty != 0,
            },
        }
    }

    /// Runs the drive held at home to `now` (no card holds it).
    fn advance_home(&mut self, now: Instant) {
        let st = &mut self.home;
        st.drive.advance(&mut st.params, now);
    }

    /// A drive reset (power cycle of the drive with its parameters kept): latches the
    /// fieldbus parameters and restarts the card.
    pub fn reset_drive(&mut self, now: Instant, out: &mut Outbox) {
        self.restart(now, out);
        self.deadline = self.compute_deadline();
    }

    fn restart(&mut self, now: Instant, out: &mut Outbox) {
        self.powered = true;
        self.last_now = now;
        // The previous card is kept until the reset is over so that a card rebuilt alike
        // finds its description still in use, instead of building it again; the drive comes
        // home from it first.
        let mut previous = self.card.take();
        if let Some(c) = &mut previous {
            self.home = core::mem::take(c.dev.hooks_mut());
        }
        self.dnet = None;
        self.home.drive.restart();
        self.sticky = None;
        self.bus_off_recovered = None;
        let p = &self.home.params;
        self.latched = Latched {
            ty: p.value(par::FIELDBUS_TYPE),
            baud: p.value(par::FIELDBUS_BAUDRATE),
            address: p.value(par::FIELDBUS_ADDRESS),
            ms_enable: p.value(par::FIELDBUS_MS_ENABLE) != 0,
            alarm_mode: p.value(par::FIELDBUS_ALARM_MODE) != 0,
        };
        let _ = self.home.params.force(par::FIELDBUS_STATE, 0);
        // The process data the master sent lives in the card's memory: a restart starts from
        // zero, so a control word received before a power loss cannot enable the drive
        // before the master sends one again.
        for n in 1..=crate::params::CHANNELS {
            let _ = self.home.params.force(par::m2s_mon(n), 0);
        }
        let personality = match self.latched.ty {
            1 => Personality::CanOpen,
            3 => Personality::Ds402,
            2 => return self.reset_devicenet(now, out),
            0 => return self.advance_home(now),
            _ => return self.config_fault(0xFF01, now),
        };
        if self.latched.baud == 0 {
            return self.config_fault(0xFF02, now);
        }
        if !(1..=127).contains(&self.latched.address) {
            return self.config_fault(0xFF03, now);
        }
        if self.card_faults.contains(&CardFault::CanInit) {
            return self.config_fault(opt_bus::CAN_INIT, now);
        }
        let bps = BAUDS.get(self.latched.baud as usize).copied().unwrap_or(0);
        if self.config.bus_bit_rate.is_some_and(|b| b != bps) {
            return self.advance_home(now);
        }
        let (pdc, fault) = if personality == Personality::CanOpen {
            match pdc::configure(&mut self.home.params) {
                Ok(p) => (p, None),
                Err(e) => (Pdc::default(), Some(e.code())),
            }
        } else {
            (Pdc::default(), None)
        };
        let fault = fault.or(self.database_fault());
        let node = self.latched.address as u8;
        let built = self
            .descriptions
            .get(
                personality,
                &pdc,
                CardInfo {
                    serial: self.config.serial,
                    vendor_id: self.config.vendor_id,
                    expedited_only: self.config.expedited_only,
                },
            )
            .ok()
            .and_then(|d| {
                let mut c = DeviceConfig::new(node);
                c.sync_producer = false;
                c.time_producer = false;
                // §1.1 item 11: expedited transfers only (unless the limit is lifted);
                // item 10: no object-structure sub-index 0xFF.
                let services = if self.config.expedited_only {
                    SdoCapabilities::EXPEDITED_ONLY
                } else {
                    SdoCapabilities::FULL
                };
                c.sdo = services.with_sub_index_ff_refused();
                // Memory that cannot be read is the drive's Param error (§1.5), not the
                // generic 0x5000.
                c.storage_fault = None;
                // A guarding or heartbeat loss is Opt Bus Fault 8130 (§1.5), raised by the
                // drive's rule (only while enabled, or with alarm mode 1), not the stack's
                // own 0x8130: one alarm, one EMCY.
                c.error_control_fault = None;
                let mut dev = Device::with_hooks(d, c, Station::default()).ok()?;
                if let Some(m) = &self.memory {
                    dev.set_storage(m.card_storage());
                }
                Some(dev)
            });
        let Some(mut dev) = built else {
            return self.config_fault(0xFF04, now);
        };
        self.home.ds402 = Default::default();
        self.home.configure(&pdc, self.latched.ms_enable);
        core::mem::swap(dev.hooks_mut(), &mut self.home);
        dev.on_power_up(now, out);
        let cycle_period = dev.od().locate(0x1006, 0).ok();
        let life_time_factor = dev.od().locate(0x100D, 0).ok();
        dev.hooks_mut().remapped = true;
        self.card = Some(Card {
            dev,
            personality,
            pdc,
            last_sync: None,
            cycle_period,
            life_time_factor,
            sync_timeout: None,
            watched: Vec::new(),
            booting: true,
        });
        self.refresh_sync_timeout();
        if let Some(code) = fault {
            self.sticky = Some(Alarm::OptBusFault(code));
            self.st_mut().drive.raise(Alarm::OptBusFault(code));
        }
        self.settle(now);
        drop(previous);
    }

    /// Chapter 3: the DeviceNet personality. Bit rates 125k/250k/500k (else FFC5), MAC ID
    /// 1–63 (else FFC6), then the PDC (§3.8) as polled I/O.
    fn reset_devicenet(&mut self, now: Instant, out: &mut Outbox) {
        let rate = match self.latched.baud {
            1 => BitRate::R125K,
            2 => BitRate::R250K,
            3 => BitRate::R500K,
            _ => return self.config_fault(0xFFC5, now),
        };
        let Some(mac) = u8::try_from(self.latched.address)
            .ok()
            .filter(|a| (1..=63).contains(a))
            .and_then(|a| MacId::new(a).ok())
        else {
            return self.config_fault(0xFFC6, now);
        };
        if self.card_faults.contains(&CardFault::CanInit) {
            return self.config_fault(opt_bus::CAN_INIT, now);
        }
        if self
            .config
            .bus_bit_rate
            .is_some_and(|b| b != rate.bits_per_second())
        {
            return self.advance_home(now);
        }
        let (pdc, fault) = match pdc::configure(&mut self.home.params) {
            Ok(p) => (p, None),
            Err(e) => (Pdc::default(), Some(e.code())),
        };
        let fault = fault.or(self.database_fault());
        let app = DnApp {
            params: ParamDb::new(),
            pdc,
            ms_enable: self.latched.ms_enable,
            events: Vec::new(),
        };
        let mut config = SlaveConfig::new(
            mac,
            rate,
            identity(self.config.serial, self.config.devicenet_vendor_id),
        );
        // §3.4.1/§3.4.2 address the Parameter object and Drive Parameter Access by PAR as
        // the instance (PAR 600, PAR 4000–4014: above 255), and the manual names no other
        // body format: the predefined explicit connection announces 8/16 in the Allocate
        // response, so its requests carry 16-bit instance IDs (DeviceNet Vol. 3 §5-5.4.2).
        config.allocate_format = cantwin_devicenet::wire::BodyFormat::F8_16;
        let Ok(slave) = Slave::new(config, app) else {
            return self.config_fault(0xFF04, now);
        };
        self.dnet = Some(slave);
        self.with_dnet(|s| s.on_power_up(now, out));
        if let Some(code) = fault {
            self.sticky = Some(Alarm::OptBusFault(code));
            self.home.drive.raise(Alarm::OptBusFault(code));
        }
        self.dnet_events(now);
    }

    /// Runs `f` on the DeviceNet slave with the parameters lent to it.
    fn with_dnet(&mut self, f: impl FnOnce(&mut Slave<DnApp>)) -> bool {
        let Some(slave) = &mut self.dnet else {
            return false;
        };
        core::mem::swap(&mut self.home.params, &mut slave.app_mut().params);
        f(slave);
        core::mem::swap(&mut self.home.params, &mut slave.app_mut().params);
        true
    }

    /// DeviceNet events: Fieldbus state (§3.6: Stop, Pre-Operational while the master
    /// recognises the node, Operational with polled I/O), faults (§3.7.1), the drive.
    fn dnet_events(&mut self, now: Instant) {
        let Some(slave) = &mut self.dnet else { return };
        let events: Vec<SlaveEvent> = slave.app_mut().events.drain(..).collect();
        let io = slave.poll_connection().is_some();
        let mut state = self.home.params.value(par::FIELDBUS_STATE);
        for e in events {
            match e {
                SlaveEvent::Allocated { .. } if state == 0 => state = 1,
                SlaveEvent::Released { choice: 0 } => state = 0,
                SlaveEvent::IoEstablished => state = 2,
                SlaveEvent::IoTimedOut => {
                    state = 1;
                    self.bus_fault(opt_bus::BUS_LOSS);
                }
                SlaveEvent::DuplicateMac => self.bus_fault(opt_bus::DUPLICATE_MAC),
                SlaveEvent::BusOff => self.bus_fault(opt_bus::BUS_OFF),
                SlaveEvent::IoLengthMismatch { .. } => self.bus_fault(opt_bus::CONNECTION),
                _ => {}
            }
        }
        if state == 2 && !io {
            state = 1;
        }
        let _ = self.home.params.force(par::FIELDBUS_STATE, state);
        self.advance_home(now);
        if state != 2 && self.drive_enable_cmd() {
            self.bus_fault(opt_bus::BUS_LOSS);
        }
        if let Some(sticky) = self.sticky
            && !self.home.drive.alarms().contains(&sticky)
        {
            self.home.drive.raise(sticky);
        }
        self.advance_home(now);
        while self.home.drive.poll_event().is_some() {}
        self.last_now = self.last_now.max(now);
        self.dirty = false;
    }

    /// The DeviceNet (OP green, AL red) LEDs (manual "LEDs" table), if the card is set to
    /// DeviceNet. A card that could not start for a configuration fault (FFC5, FFC6) or an
    /// internal error (FF04) shows OP off, AL on: "Fault grave (errore di configurazione,
    /// errore interno)".
    pub fn devicenet_leds(&self) -> Option<(Led, Led)> {
        match &self.dnet {
            Some(slave) => Some(slave.network_status().leds()),
            None if self.powered && self.latched.ty == 2 && self.sticky.is_some() => {
                Some((Led::Off, Led::On))
            }
            None => None,
        }
    }

    /// The DeviceNet slave, if the card runs DeviceNet.
    pub fn devicenet(&self) -> Option<&Slave<DnApp>> {
        self.dnet.as_ref()
    }

    fn config_fault(&mut self, code: u16, now: Instant) {
        self.sticky = Some(Alarm::OptBusFault(code));
        self.home.drive.raise(Alarm::OptBusFault(code));
        self.advance_home(now);
    }

    /// A runtime fieldbus fault (only while enabled unless alarm mode is on).
    fn bus_fault(&mut self, sub: u16) {
        let enabled = self.drive_enable_cmd();
        if enabled || self.latched.alarm_mode {
            self.st_mut().drive.raise(Alarm::OptBusFault(sub));
        }
    }

    fn drive_enable_cmd(&self) -> bool {
        match &self.card {
            Some(c) if c.personality == Personality::Ds402 => c.dev.hooks().ds402.power(),
            _ => {
                let p = self.params();
                if p.value(par::COMMANDS_REMOTE_SEL) == 1 {
                    let s = p.value(par::DIG_ENABLE_SRC) as u16;
                    s != 0 && p.value(s) != 0
                } else {
                    p.value(par::DIGITAL_INPUT_MON) & 1 != 0
                }
            }
        }
    }

    /// Whether the drive's control task is due at `now` or an input changed since the last
    /// evaluation: then the drive is evaluated before the stack reads its parameters.
    fn stale(&self, now: Instant) -> bool {
        self.dirty || self.st().drive.next_deadline().is_some_and(|d| d <= now)
    }

    /// Evaluates the drive at `now`: runs it, applies the NMT state and the fieldbus
    /// faults, and reports alarm changes as EMCY.
    fn settle(&mut self, now: Instant) {
        self.last_now = self.last_now.max(now);
        self.dirty = false;
        self.profile_in();
        let st = self.st_mut();
        st.touched = false;
        st.drive.advance(&mut st.params, now);
        let mut not_operational = false;
        let mut ds402 = false;
        if let Some(c) = &mut self.card {
            let state = c.dev.state();
            let st = c.dev.hooks_mut();
            if c.personality == Personality::Ds402 {
                let fault = !st.drive.alarms().is_empty();
                let stopped = st.drive.speed() == 0.0;
                st.ds402.refresh(fault, stopped);
                ds402 = true;
            }
            let fieldbus_state = match state {
                State::Operational => 2,
                State::PreOperational => 1,
                _ => 0,
            };
            let _ = st.params.force(par::FIELDBUS_STATE, fieldbus_state);
            not_operational = state != State::Operational;
        }
        // Enable outside Operational is bus loss (§1.5), unless the drive has already
        // tripped on a guarding or heartbeat loss: that loss takes the card out of
        // Operational itself (CiA 301 §7.5.2.32), and one loss is one alarm (§1.1.3).
        if not_operational
            && self.drive_enable_cmd()
            && !self.opt_bus_faults().contains(&opt_bus::GUARDING)
        {
            self.bus_fault(opt_bus::BUS_LOSS);
        }
        let sticky = self.sticky;
        let st = self.st_mut();
        if let Some(sticky) = sticky
            && !st.drive.alarms().contains(&sticky)
        {
            st.drive.raise(sticky);
        }
        if ds402 || !st.drive.alarms().is_empty() {
            // The power state or the alarms changed what the drive is commanded to do.
            self.profile_in();
            let st = self.st_mut();
            st.drive.advance(&mut st.params, now);
        }
        self.report_alarms();
        let Some(c) = &mut self.card else { return };
        match c.personality {
            Personality::CanOpen => {
                // The S2M channels' monitors show what the TPDOs carry (§1.3).
                let st = c.dev.hooks_mut();
                for item in c.pdc.s2m.items() {
                    let v = pdc::s2m_value(&st.params, item.channel);
                    let _ = st.params.force(par::s2m_mon(item.channel), v);
                }
            }
            Personality::Ds402 => {
                let target = od_i64(c.dev.od(), cia402::VL_TARGET_VELOCITY, 0).unwrap_or(0);
                c.dev.hooks_mut().update_statusword(target);
            }
        }
        if c.dev.hooks().remapped {
            c.dev.hooks_mut().remapped = false;
            c.watched = watch_list(&c.dev);
        }
        for w in &mut c.watched {
            if let Some(Ok((bytes, _))) = c.dev.hooks().serve(w.0, w.1)
                && bytes != w.2
            {
                w.2 = bytes;
                c.dev.mark_changed(w.0, w.1);
            }
        }
    }

    fn report_alarms(&mut self) {
        let Some(c) = &mut self.card else {
            while self.home.drive.poll_event().is_some() {}
            return;
        };
        if c.booting {
            // The alarms active when the boot-up has gone are sent then ([`Adv200::booted`]).
            while c.dev.hooks_mut().drive.poll_event().is_some() {}
            return;
        }
        while let Some(e) = c.dev.hooks_mut().drive.poll_event() {
            match e {
                AlarmEvent::Raised(a) => {
                    // Every Opt Bus Fault sub-code is its own occurrence of 0xFF11 (§1.5):
                    // each one is sent, one alarm reset clears them all.
                    c.dev.emcy().signal(a.emcy_code(), a.manufacturer_bytes());
                }
                AlarmEvent::Cleared(a) => {
                    let code = a.emcy_code();
                    if !c
                        .dev
                        .hooks()
                        .drive
                        .alarms()
                        .iter()
                        .any(|b| b.emcy_code() == code)
                    {
                        c.dev.emcy().clear(code);
                    }
                }
            }
        }
    }

    /// CiA 402: the control word and the vl objects command the drive.
    fn profile_in(&mut self) {
        let Some(c) = &mut self.card else { return };
        if c.personality != Personality::Ds402 {
            return;
        }
        let vl = VlCommand::of(c.dev.od());
        let sticky = self.sticky;
        let st = c.dev.hooks_mut();
        let cw = vl.controlword;
        // The fault reset clears the drive's alarms first, so that transition 15 sees them
        // gone in the same evaluation.
        if st.ds402.reset_requested(cw) && !st.drive.alarms().is_empty() {
            st.drive.reset_alarms();
            if let Some(sticky) = sticky
                && !st.drive.alarms().contains(&sticky)
            {
                st.drive.raise(sticky);
            }
        }
        let fault = !st.drive.alarms().is_empty();
        let stopped = st.drive.speed() == 0.0;
        st.ds402.update(cw, fault, stopped);
        let mag = vl.target.abs();
        let clamped = if mag == 0 {
            0
        } else {
            mag.clamp(vl.min, vl.max.max(vl.min))
        };
        let reference = if vl.target < 0 { -clamped } else { clamped };
        st.drive.set_profile(Some(ProfileCommands {
            enable: st.ds402.power(),
            start: st.ds402.running(),
            fast_stop: st.ds402.quick_stopping(),
            reference,
            rates: Some((vl.acceleration, vl.deceleration)),
        }));
    }

    /// §1.1.3 table: with SYNC the Bus Loss threshold is SYNC_PERIOD (0x1006) ×
    /// LIFE_TIME_FACTOR (0x100D), the factor 3 "if not indicated by the master": a factor
    /// of 0 is taken as not indicated (0 would trip at every SYNC).
    fn sync_deadline(&self) -> Option<Instant> {
        let c = self.card.as_ref()?;
        let timeout = c.sync_timeout?;
        if c.dev.state() == State::Stopped {
            return None;
        }
        c.last_sync?.checked_add(timeout)
    }

    /// Reads the bus-loss threshold of [`Adv200::sync_deadline`] from the dictionary.
    fn refresh_sync_timeout(&mut self) {
        let Some(c) = &mut self.card else { return };
        let od = c.dev.od();
        let read = |id: Option<EntryId>| {
            id.map_or(0, |id| {
                let raw = od.raw(id);
                let mut b = [0u8; 4];
                let n = raw.len().min(4);
                b[..n].copy_from_slice(&raw[..n]);
                u64::from(u32::from_le_bytes(b))
            })
        };
        let period = read(c.cycle_period);
        let factor = match read(c.life_time_factor) {
            0 => 3,
            f => f,
        };
        c.sync_timeout = (period != 0).then(|| Duration::from_micros(period * factor));
    }

    /// Takes the device's events; returns whether there were any.
    fn card_events(&mut self, now: Instant) -> bool {
        let mut faults = Vec::new();
        let mut any = false;
        let mut memory_fault = false;
        if let Some(c) = &mut self.card {
            while let Some(e) = c.dev.poll_event() {
                any = true;
                match e {
                    Event::Sync { .. } => c.last_sync = Some(now),
                    Event::LifeGuardingLost | Event::HeartbeatLost { .. } => {
                        faults.push(opt_bus::GUARDING)
                    }
                    Event::StateChanged {
                        to: State::Operational,
                        ..
                    } => c.last_sync = Some(now),
                    // The TPDO parameters are back at their power-on values; the errors
                    // the stack recorded are cleared and the boot-up is on its way.
                    Event::ResetCommunication => {
                        c.dev.hooks_mut().remapped = true;
                        c.booting = true;
                    }
                    Event::StorageLoadFailed(_) => memory_fault = true,
                    _ => {}
                }
            }
        }
        // A frame (an SDO write of 0x1006 or 0x100D) or a reset communication came before.
        self.refresh_sync_timeout();
        for f in faults {
            self.bus_fault(f);
        }
        if memory_fault {
            self.memory_error
                .get_or_insert_with(|| "the saved communication parameters cannot be read".into());
            self.st_mut().drive.raise(Alarm::ParamError);
        }
        any
    }

    fn check_nmt(&mut self, frame: &Frame) {
        if frame.id().as_raw() != 0 || frame.is_remote() {
            return;
        }
        let Some(c) = &self.card else { return };
        let node = c.dev.node_id();
        let d = frame.data_bytes();
        if d.len() != 2 {
            self.bus_fault(0xFFC5);
        } else if (d[1] == 0 || d[1] == node) && !matches!(d[0], 1 | 2 | 128 | 129 | 130) {
            self.bus_fault(0xFFC6);
        }
    }
}

impl Adv200 {
    fn frame_in(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if self.powered && self.dnet.is_some() {
            self.dnet_events(now);
            self.with_dnet(|s| s.on_frame(frame, now, out));
            return self.dnet_events(now);
        }
        if !self.powered || self.card.is_none() {
            return;
        }
        // The stack reads parameters while it handles the frame (a TPDO at SYNC): the
        // drive is brought to `now` first.
        if self.stale(now) {
            self.settle(now);
        }
        self.last_now = self.last_now.max(now);
        self.check_nmt(frame);
        if let Some(c) = &mut self.card {
            c.dev.on_frame(frame, now, out);
        }
        self.flush_memory();
        let events = self.card_events(now);
        let st = self.st();
        if events || st.touched || st.remapped || st.drive.has_events() {
            self.settle(now);
        }
    }

    fn tick(&mut self, now: Instant, out: &mut Outbox) {
        if !self.powered {
            return;
        }
        if self.dnet.is_some() {
            self.dnet_events(now);
            if self
                .dnet
                .as_ref()
                .and_then(|s| s.next_deadline())
                .is_some_and(|d| d <= now)
            {
                self.with_dnet(|s| s.on_tick(now, out));
            }
            return self.dnet_events(now);
        }
        if self.stale(now) {
            self.settle(now);
        }
        self.last_now = self.last_now.max(now);
        let mut again = false;
        if self.sync_deadline().is_some_and(|d| d <= now) {
            if let Some(c) = &mut self.card {
                c.last_sync = Some(now);
            }
            self.bus_fault(opt_bus::BUS_LOSS);
            again = true;
        }
        if let Some(c) = &mut self.card
            && c.dev.next_deadline().is_some_and(|d| d <= now)
        {
            c.dev.on_tick(now, out);
            again = true;
        }
        if again {
            self.card_events(now);
            self.settle(now);
            if let Some(c) = &mut self.card
                && c.dev.next_deadline().is_some_and(|d| d <= now)
            {
                c.dev.on_tick(now, out);
            }
        }
    }

    /// The next deadline of the drive, its card and the bus-loss watch, as of now.
    fn compute_deadline(&self) -> Option<Instant> {
        // Folded one by one: the bus asks after every call (an array through an iterator
        // does not always fold away).
        let mut next = self.st().drive.next_deadline();
        next = Instant::earliest(next, self.card.as_ref().and_then(|c| c.dev.next_deadline()));
        next = Instant::earliest(next, self.dnet.as_ref().and_then(|s| s.next_deadline()));
        Instant::earliest(next, self.sync_deadline())
    }

    /// The boot-up message has been sent: every alarm active now is signalled, one EMCY
    /// each, and recorded in 0x1001, so that a configuration fault found at the drive reset
    /// (§1.5, `Cfg` codes) reaches the bus after the boot-up and again after every reset
    /// communication, where a master starting later resets the nodes it finds.
    fn booted(&mut self) {
        let Some(c) = &mut self.card else { return };
        c.booting = false;
        while c.dev.hooks_mut().drive.poll_event().is_some() {}
        let active: Vec<Alarm> = c.dev.hooks().drive.alarms().to_vec();
        for a in active {
            c.dev.emcy().signal(a.emcy_code(), a.manufacturer_bytes());
        }
    }

    fn sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let mut booted = false;
        if let Some(c) = &mut self.card {
            c.dev.on_sent(frame, now, out);
            let boot_up = u32::from(0x700 + u16::from(c.dev.node_id()));
            booted = c.booting
                && !frame.is_remote()
                && frame.id().as_raw() == boot_up
                && frame.data_bytes() == [0x00];
        }
        if booted {
            self.booted();
        }
        if self.with_dnet(|s| s.on_sent(frame, now, out)) {
            self.dnet_events(now);
        }
    }

    fn controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        if self.dnet.is_none() {
            match event {
                ControllerEvent::BusOff => {
                    self.bus_fault(opt_bus::BUS_OFF);
                    if self
                        .bus_off_recovered
                        .is_some_and(|t| now.saturating_duration_since(t) <= BUS_OFF_REPEAT)
                    {
                        self.bus_fault(opt_bus::BUS_OFF_HARDWARE);
                    }
                }
                ControllerEvent::BusOffRecovered => self.bus_off_recovered = Some(now),
                ControllerEvent::RxOverrun => self.bus_fault(opt_bus::OVERFLOW),
                _ => {}
            }
        } else if event == ControllerEvent::RxOverrun {
            self.bus_fault(opt_bus::OVERFLOW);
        }
        if let Some(c) = &mut self.card {
            c.dev.on_controller_event(event, now, out);
        }
        if self.with_dnet(|s| s.on_controller_event(event, now, out)) {
            return self.dnet_events(now);
        }
        self.card_events(now);
        self.settle(now);
    }
}

impl Node for Adv200 {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.memory_error = None;
        let unreadable = self.load_memory();
        self.reset_drive(now, out);
        let events = self.card_events(now);
        if unreadable {
            self.st_mut().drive.raise(Alarm::ParamError);
        }
        if unreadable || events {
            self.settle(now);
            self.deadline = self.compute_deadline();
        }
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.frame_in(frame, now, out);
        self.deadline = self.compute_deadline();
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.tick(now, out);
        self.deadline = self.compute_deadline();
    }

    fn next_deadline(&self) -> Option<Instant> {
        if !self.powered {
            return None;
        }
        if self.dirty {
            return Some(self.last_now);
        }
        self.deadline
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.sent(frame, now, out);
        self.deadline = self.compute_deadline();
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.controller_event(event, now, out);
        self.deadline = self.compute_deadline();
    }
}
