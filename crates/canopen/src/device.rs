//! The composite CiA 301 device: object dictionary, NMT slave, error control, EMCY, SYNC,
//! TIME, SDO servers, PDOs and parameter storage behind one [`Node`].
//!
//! A [`Device`] is driven entirely through [`Node`]; it implements [`ObjectAccess`] with
//! the rules of the communication objects on top of the dictionary's own checks, so a
//! test, a device model or the SDO servers write through the same path.
//!
//! Behaviour chosen where CiA 301 leaves room (each pinned by a test in `tests/`):
//!
//! * **Boot-up** (§7.3.2.2.1): [`Node::on_power_up`] sets every object to its default,
//!   applies the stored parameters, sends the boot-up message and enters pre-operational in
//!   the same instant. Reset node and reset communication do the same for their areas.
//! * **Stored parameters** (§7.5.2.10, §7.5.2.11): a device keeps what "save" stores in
//!   memory for as long as it exists (resets and power cycles restore it) unless it is
//!   given a backend ([`Device::set_storage`], e.g. files that outlive the process); so
//!   "save" and "load" always work, and 0x0606 0000 means the backend failed.
//! * **Reset communication** restores 0x1000–0x1FFF to the power-on values (defaults, then
//!   stored communication parameters); this empties 0x1003, clears active errors, resets
//!   the guarding toggle bit and aborts SDO transfers silently. **Reset node** restores
//!   0x2000–0x9FFF first (stored manufacturer and application parameters on top of the
//!   defaults), reports [`Event::ResetApplication`], then resets communication.
//! * **COB-ID entries** (0x1005, 0x1012, 0x1014, 0x1028, 0x1200–0x12FF, the PDOs) follow
//!   one rule, [`crate::cob_id`]: restricted CAN-IDs (CiA 301 §7.3.5), the frame bits and
//!   each entry's reserved bits, answered with 0x0609 0030.
//! * **0x1003**: an entry above the number of errors recorded reads as 0x0800 0024 "no data
//!   available" (§7.5.2.4).
//! * **Communication errors** (heartbeat consumer timeout, life guarding event, bus-off)
//!   apply 0x1029 sub 1 (without 0x1029: its default 0, OPERATIONAL → PRE-OPERATIONAL
//!   only, §7.5.2.32). The heartbeat and guarding losses raise EMCY 0x8130, with the
//!   lost producer's node-ID in the first manufacturer-specific byte (0 for life
//!   guarding); it is cleared (EMCY 0x0000) once no partner is lost any more.
//! * **Controller events**: receive overrun raises 0x8110, cleared by the next frame
//!   received; error passive raises 0x8120, cleared when the controller is error-active
//!   again; recovery from bus-off raises 0x8140, cleared when the next frame of the device
//!   is confirmed sent ([`Node::on_sent`]) — the bus works again.
//! * **Stopped**: only NMT, node guarding and heartbeat; EMCYs queued at the transition are
//!   dropped (errors are still recorded in 0x1001/0x1003), SDO transfers end silently. The
//!   EMCY of an error whose 0x1029 reaction stops the device is sent before it stops.
//! * **Acceptance filter**: [`Node::accepts`] passes only the identifiers a frame can
//!   change the device on (NMT, SYNC, consumed TIME, its own node guarding requests, the
//!   heartbeats 0x1016 monitors, the EMCYs 0x1028 consumes, its SDO servers' requests, its
//!   runnable RPDOs, and its TPDOs for remote requests), rebuilt whenever one of those
//!   COB-IDs changes; [`Node::on_frame`] skips any other frame at once (a driver that does
//!   not filter only runs the timers already due). While a receive overrun waits for the
//!   next frame to clear 0x8110 every identifier passes. [`DeviceConfig::acceptance_filter`]
//!   turns the filter off. The next deadline is kept from the end of each call and computed
//!   afresh only after a change through a `&mut` accessor that can move a timer (the hooks
//!   cannot: they serve objects).
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_can::{Frame, Instant, Node, Outbox};
//! use cantwin_canopen::device::{Device, DeviceConfig};
//! use cantwin_canopen::nmt::State;
//! use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
//! use cantwin_canopen::od::OdBuilder;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let options = Cia301Options { heartbeat_time: 100, ..Cia301Options::default() };
//! let desc = cia301_defaults(OdBuilder::new(), &options).build()?;
//! let mut dev = Device::new(Arc::new(desc), DeviceConfig::new(5))?;
//! let mut out = Outbox::new();
//! dev.on_power_up(Instant::ZERO, &mut out);
//! assert_eq!(out.frames(), [Frame::std(0x705, &[0x00])?]); // boot-up
//! out.clear();
//! // NMT "start remote node 5" at 1 ms.
//! dev.on_frame(&Frame::std(0x000, &[0x01, 0x05])?, Instant::from_nanos(1_000_000), &mut out);
//! assert_eq!(dev.state(), State::Operational);
//! // The first heartbeat is due one period after the boot-up.
//! assert_eq!(dev.next_deadline(), Some(Instant::from_nanos(100_000_000)));
//! dev.on_tick(Instant::from_nanos(100_000_000), &mut out);
//! assert_eq!(out.frames(), [Frame::std(0x705, &[0x05])?]);
//! # Ok(())
//! # }
//! ```

use crate::abort::AbortCode;
use crate::cob_id;
use crate::emcy;
use crate::error_behaviour::Reaction;
use crate::guarding::Guarding;
use crate::heartbeat::{self, Heard};
use crate::nmt::{self, Service, State, Transition};
use crate::od::{
    Hooked, ObjectAccess, ObjectDictionary, OdDescription, OdHooks, ReadInfo, TimeOfDay, Value,
};
use crate::pdo::{PdoEngine, PdoEvent};
use crate::sdo::{SdoCapabilities, SdoServer};
use crate::storage::{self, Group, MemoryStorage, Storage, StorageError};
use crate::sync::SyncService;
use crate::time::TimeService;
use crate::wire::{self, CobId, ErrorControl, NmtCommand};
use cantwin_can::{ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};
use std::collections::VecDeque;
use std::sync::Arc;

/// EMCY 0x8110: CAN overrun, objects lost (CiA 301 table 21).
pub const EMCY_CAN_OVERRUN: u16 = 0x8110;
/// EMCY 0x8120: CAN in error passive mode.
pub const EMCY_ERROR_PASSIVE: u16 = 0x8120;
/// EMCY 0x8130: life guard error or heartbeat error.
pub const EMCY_LIFE_GUARD_HEARTBEAT: u16 = 0x8130;
/// EMCY 0x8140: recovered from bus off.
pub const EMCY_BUS_OFF_RECOVERED: u16 = 0x8140;
/// EMCY 0x5000: device hardware (CiA 301 table 21), raised with the generic bit of the
/// error register when stored parameters cannot be loaded (the memory that keeps them
/// failed): see [`DeviceConfig::storage_fault`].
pub const EMCY_STORED_PARAMETERS: u16 = 0x5000;

/// At most this many unpolled [`Event`]s are kept; older ones are dropped.
pub const MAX_EVENTS: usize = 32;

/// Device hooks that do nothing: every application object is a plain stored value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoHooks;

impl OdHooks for NoHooks {}

/// What a device cannot be built with.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// Node-IDs are 1..=127 (CiA 301 §7.3.2.1).
    #[error("node-ID {0} is outside 1..=127")]
    NodeId(u8),
}

/// How a device is set up besides its dictionary.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceConfig {
    /// The node-ID, 1..=127.
    pub node_id: u8,
    /// The SDO servers' timeout.
    pub sdo_timeout: Duration,
    /// Whether the device can produce SYNC (0x1005 bit 30 may be set).
    pub sync_producer: bool,
    /// Whether the device can produce TIME (0x1012 bit 30 may be set).
    pub time_producer: bool,
    /// Whether the device filters received frames by its own COB-IDs, as firmware programs
    /// a controller's acceptance filter: [`Node::accepts`] then passes only the identifiers
    /// the device reacts to, and [`Node::on_frame`] skips any other frame at once. Without
    /// it every frame goes through the whole stack (same behaviour, more work).
    pub acceptance_filter: bool,
    /// The services the SDO servers offer, and what they answer to the others
    /// ([`SdoCapabilities`]; [`SdoCapabilities::EXPEDITED_ONLY`] for a CiA 301
    /// minimum-capability device).
    pub sdo: SdoCapabilities,
    /// The error raised when stored parameters (0x1010) cannot be loaded at a reset: the
    /// device runs on its defaults for the group and reports it with this EMCY code once
    /// boot-up is done, its first manufacturer byte the 0x1010 sub-indices of the groups
    /// that failed as bits (bit 2 communication, 3 application, 4 manufacturer). `None`
    /// for a device whose application reports it its own way ([`Event::StorageLoadFailed`]).
    pub storage_fault: Option<u16>,
    /// The error raised when a monitored heartbeat producer or the life guarding master is
    /// lost (§7.2.7.1): [`EMCY_LIFE_GUARD_HEARTBEAT`]. `None` for a device whose
    /// application reports it its own way ([`Event::HeartbeatLost`],
    /// [`Event::LifeGuardingLost`]); the communication error reaction is applied either way.
    pub error_control_fault: Option<u16>,
}

impl DeviceConfig {
    /// A device with node-ID `node_id`, a 1 s SDO timeout, every SDO service, able to
    /// produce SYNC and TIME, filtering received frames by its COB-IDs.
    pub const fn new(node_id: u8) -> Self {
        DeviceConfig {
            node_id,
            sdo_timeout: crate::sdo::server::DEFAULT_TIMEOUT,
            sync_producer: true,
            time_producer: true,
            acceptance_filter: true,
            sdo: SdoCapabilities::FULL,
            storage_fault: Some(EMCY_STORED_PARAMETERS),
            error_control_fault: Some(EMCY_LIFE_GUARD_HEARTBEAT),
        }
    }
}

/// Something the application (device model, test) may want to know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The NMT state changed.
    StateChanged {
        /// The previous state.
        from: State,
        /// The new state.
        to: State,
    },
    /// Reset node: application parameters are back at their power-on values; the device
    /// model should restart its application.
    ResetApplication,
    /// Reset communication (also part of reset node and power-up).
    ResetCommunication,
    /// A monitored heartbeat producer timed out.
    HeartbeatLost {
        /// Its node-ID.
        node: u8,
    },
    /// A monitored heartbeat producer is heard again after a timeout.
    HeartbeatRecovered {
        /// Its node-ID.
        node: u8,
    },
    /// A monitored heartbeat producer sent a boot-up message.
    RemoteBootUp {
        /// Its node-ID.
        node: u8,
    },
    /// The NMT master stopped guarding within the life time.
    LifeGuardingLost,
    /// Guarding resumed after a life guarding event.
    LifeGuardingRecovered,
    /// The controller went bus-off.
    BusOff,
    /// A SYNC was received or produced.
    Sync {
        /// Its counter.
        counter: Option<u8>,
    },
    /// A TIME message was received.
    Time(TimeOfDay),
    /// An EMCY from a consumed COB-ID (0x1028).
    Emcy {
        /// The identifier it came on.
        id: Id,
        /// The message.
        emcy: wire::Emcy,
    },
    /// Something the PDO engine reported.
    Pdo(PdoEvent),
    /// Stored parameters could not be loaded (damaged blob or backend failure); the
    /// defaults stay in effect for the group.
    StorageLoadFailed(Group),
}

/// Everything but the SDO servers, so that a server can borrow it as [`ObjectAccess`].
struct Core<H> {
    config: DeviceConfig,
    od: ObjectDictionary,
    hooks: H,
    state: State,
    now: Instant,
    heartbeat: heartbeat::Producer,
    consumer: heartbeat::Consumer,
    guarding: Guarding,
    emcy: emcy::Producer,
    emcy_rx: Vec<Id>,
    sync: SyncService,
    time: TimeService,
    reaction: Reaction,
    pdo: Option<PdoEngine>,
    /// RPDO faults whose EMCY is active: (RPDO slot, error code).
    pdo_faults: Vec<(u16, u16)>,
    /// Where 0x1010/0x1011 keep the parameters: in memory unless the device was given a
    /// backend.
    storage: Box<dyn Storage>,
    /// The 0x1010 sub-indices, as bits, of the groups whose stored parameters could not be
    /// loaded at the last reset that loaded them.
    storage_faults: u8,
    /// The boot-up message is queued but not yet confirmed sent: EMCYs wait behind it
    /// (CiA 301 §7.2.7.1: EMCY is a service of PRE-OPERATIONAL and OPERATIONAL, which the
    /// boot-up message announces; an EMCY's identifier outranks the boot-up's, so queued
    /// together the EMCY would reach the bus first).
    boot_up_unsent: bool,
    /// The last frame of an SDO answer that the bus has not confirmed yet. EMCYs raised
    /// while the request was served (an object write that reports an error) wait for it:
    /// a device serves the request, answers it and produces the EMCY in its next cycle
    /// (CiA 301 §7.2.7: the EMCY is produced once, after the event; §7.2.4.3: the answer
    /// belongs to the request), so a master sees the answer first. Queued together, the
    /// EMCY's lower identifier would win arbitration.
    sdo_answer_unsent: Option<Frame>,
    events: VecDeque<Event>,
    error_passive: bool,
    overrun: bool,
    bus_off_recovered: bool,
    /// The SDO server parameters changed: the servers must be reconfigured.
    sdo_changed: bool,
    /// SDO transfers must end silently (stopped, reset).
    sdo_reset: bool,
    /// The identifiers the device reacts to, as [`frame_key`]s, sorted: its acceptance
    /// filter.
    accept: Vec<u32>,
    /// A COB-ID may have changed since `accept` was built: accept everything until it is
    /// built again.
    accept_stale: bool,
    /// Counts the changes of `accept`'s contents, for [`Node::acceptance_version`].
    accept_generation: u64,
    /// The previous `accept`, kept for its allocation: a rebuild compares the new list with
    /// the old one.
    accept_spare: Vec<u32>,
}

/// A CiA 301 device. See the [module documentation](self).
pub struct Device<H = NoHooks> {
    core: Core<H>,
    sdo: Vec<SdoServer>,
    /// [`Node::next_deadline`] as of the end of the last call; `None` when something
    /// changed since through a `&mut` accessor, so it must be computed afresh.
    deadline: Option<Option<Instant>>,
}

impl<H> core::fmt::Debug for Device<H> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Device")
            .field("node_id", &self.core.config.node_id)
            .field("state", &self.core.state)
            .finish_non_exhaustive()
    }
}

impl Device<NoHooks> {
    /// A device on `desc` with no device hooks.
    pub fn new(desc: Arc<OdDescription>, config: DeviceConfig) -> Result<Self, DeviceError> {
        Device::with_hooks(desc, config, NoHooks)
    }
}

fn u32_of(data: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    u32::from_le_bytes(b)
}

impl<H: OdHooks> Device<H> {
    /// A device on `desc` whose objects in hooked ranges are served by `hooks`. It is not
    /// powered: nothing happens until [`Node::on_power_up`].
    pub fn with_hooks(
        desc: Arc<OdDescription>,
        config: DeviceConfig,
        hooks: H,
    ) -> Result<Self, DeviceError> {
        if !(1..=127).contains(&config.node_id) {
            return Err(DeviceError::NodeId(config.node_id));
        }
        let od = ObjectDictionary::new(desc, config.node_id);
        let history = od
            .description()
            .object(0x1003)
            .map_or(0, |o| o.sub_number().saturating_sub(1) as u8);
        let consumers = od
            .description()
            .object(0x1016)
            .map_or(0, |o| o.sub_number().saturating_sub(1) as u8);
        // A PDO whose stored configuration cannot run (a mapping of an object the
        // dictionary lacks) stays off and the others run, as a device that boots with a bad
        // stored mapping does (CiA 301 §7.5.2.36: the mapping is refused, not the device).
        let (pdo, _) = PdoEngine::load(&od);
        let pdo = Some(pdo).filter(|p| p.rpdo_slots() + p.tpdo_slots() > 0);
        let mut core = Core {
            config,
            od,
            hooks,
            state: State::Initialising,
            now: Instant::ZERO,
            heartbeat: heartbeat::Producer::default(),
            consumer: heartbeat::Consumer::new(consumers),
            guarding: Guarding::default(),
            emcy: emcy::Producer::new(history),
            emcy_rx: Vec::new(),
            sync: SyncService::default(),
            time: TimeService::default(),
            reaction: Reaction::PreOperational,
            pdo,
            pdo_faults: Vec::new(),
            storage: Box::new(MemoryStorage::new()),
            storage_faults: 0,
            boot_up_unsent: false,
            sdo_answer_unsent: None,
            events: VecDeque::new(),
            error_passive: false,
            overrun: false,
            bus_off_recovered: false,
            sdo_changed: true,
            sdo_reset: false,
            accept: Vec::new(),
            accept_stale: true,
            accept_generation: 0,
            accept_spare: Vec::new(),
        };
        core.configure();
        let mut device = Device {
            core,
            sdo: Vec::new(),
            deadline: None,
        };
        device.apply_sdo_config();
        device.refresh();
        Ok(device)
    }

    /// Uses `storage` for 0x1010/0x1011 and for the power-on values of every reset,
    /// instead of the in-memory store a device starts with.
    pub fn set_storage(&mut self, storage: Box<dyn Storage>) {
        self.deadline = None;
        self.core.storage = storage;
    }

    /// Hands over the parameter storage (to a device that replaces this one, e.g. at a
    /// power-up with another node-ID), leaving this one an empty in-memory store.
    pub fn take_storage(&mut self) -> Box<dyn Storage> {
        self.deadline = None;
        core::mem::replace(&mut self.core.storage, Box::new(MemoryStorage::new()))
    }

    /// The node-ID.
    pub fn node_id(&self) -> u8 {
        self.core.config.node_id
    }

    /// The NMT state.
    pub fn state(&self) -> State {
        self.core.state
    }

    /// The dictionary.
    pub fn od(&self) -> &ObjectDictionary {
        &self.core.od
    }

    /// The dictionary, for the device model. Communication objects changed here take
    /// effect at the next reset communication; use [`ObjectAccess::write`] for immediate
    /// effect.
    pub fn od_mut(&mut self) -> &mut ObjectDictionary {
        self.deadline = None;
        &mut self.core.od
    }

    /// Sets an application value as the device itself would (no access check) and tells
    /// the PDO engine it changed (event-driven TPDOs mapping it are sent).
    pub fn set_value(&mut self, index: u16, sub: u8, value: &Value) -> Result<(), AbortCode> {
        self.deadline = None;
        self.core.od.set(index, sub, value)?;
        if let Some(p) = &mut self.core.pdo {
            p.mark_changed(index, sub);
        }
        Ok(())
    }

    /// The device hooks.
    pub fn hooks(&self) -> &H {
        &self.core.hooks
    }

    /// The device hooks, mutably. The hooks take no part in the device's timers (they serve
    /// objects; the services keep their own deadlines), so the next deadline the device keeps
    /// stays valid: a device model that runs its application through its hooks every
    /// millisecond pays no recomputation of the services' timers for it. A value the hooks
    /// serve that changed is told with [`Device::mark_changed`].
    pub fn hooks_mut(&mut self) -> &mut H {
        &mut self.core.hooks
    }

    /// The PDO engine, if the dictionary has PDOs.
    pub fn pdo(&self) -> Option<&PdoEngine> {
        self.core.pdo.as_ref()
    }

    /// An application value changed outside [`ObjectAccess::write`] (served by the hooks, or
    /// set through [`Device::od_mut`]): an application event for every TPDO of type 0, 254
    /// or 255 that maps it ([`PdoEngine::mark_changed`], CiA 301 §7.2.2.4). Unlike
    /// [`Device::pdo_mut`] it leaves the acceptance filter as it is: no COB-ID changes.
    pub fn mark_changed(&mut self, index: u16, sub: u8) {
        if let Some(p) = &mut self.core.pdo {
            self.deadline = None;
            p.mark_changed(index, sub);
        }
    }

    /// The PDO engine, mutably (to trigger event-driven TPDOs).
    pub fn pdo_mut(&mut self) -> Option<&mut PdoEngine> {
        self.deadline = None;
        self.core.accept_stale = true;
        self.core.pdo.as_mut()
    }

    /// The device detected a serious error of the kind 0x1029 sub-index `sub` configures
    /// (1 communication error, 2.. device- or profile-specific): applies the reaction
    /// stored there (§7.5.2.32). Returns the state entered, if it changed. A missing
    /// sub-index or a reserved value leaves the state alone.
    pub fn error_detected(&mut self, sub: u8, now: Instant, out: &mut Outbox) -> Option<State> {
        let reaction = self
            .core
            .u32(0x1029, sub)
            .and_then(|v| Reaction::from_u8(v as u8))?;
        self.core.now = now;
        self.core.send_emcys(now, out);
        let to = reaction.apply(self.core.state)?;
        self.core.enter(to, now);
        self.after(now, out);
        Some(to)
    }

    /// The error register (0x1001).
    pub fn error_register(&self) -> u8 {
        self.core.emcy.register()
    }

    /// Raising and clearing the device's own errors.
    pub fn emcy(&mut self) -> Emcy<'_, H> {
        self.deadline = None;
        Emcy {
            core: &mut self.core,
        }
    }

    /// Whether EMCY error `code` is active. Unlike [`Device::emcy`] it changes nothing, so
    /// the next deadline the device keeps stays valid: a device model that only asks pays
    /// no recomputation of its timers.
    pub fn emcy_active(&self, code: u16) -> bool {
        self.core.emcy.is_active(code)
    }

    /// Queues a TIME message with `time` into `out`, if the device is a TIME producer
    /// (0x1012 bit 30) and TIME is allowed in its NMT state. Returns whether it did.
    pub fn publish_time(&mut self, time: TimeOfDay, out: &mut Outbox) -> bool {
        if !self.core.state.allows(Service::Time) {
            return false;
        }
        match self.core.time.produce(time) {
            Some(f) => {
                out.push(f);
                true
            }
            None => false,
        }
    }

    /// The next event for the application, oldest first.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.core.events.pop_front()
    }

    /// Bytes of heap this device uses: its values, SDO servers, services and queues. The
    /// shared description and the PDO engine's tables are not counted.
    pub fn heap_bytes(&self) -> usize {
        self.core.od.heap_bytes()
            + self.sdo.capacity() * core::mem::size_of::<SdoServer>()
            + self.core.emcy_rx.capacity() * core::mem::size_of::<Id>()
            + self.core.events.capacity() * core::mem::size_of::<Event>()
            + self.core.emcy.heap_bytes()
            + self.core.consumer.heap_bytes()
            + self.core.pdo_faults.capacity() * 4
            + (self.core.accept.capacity() + self.core.accept_spare.capacity())
                * core::mem::size_of::<u32>()
    }

    fn apply_sdo_config(&mut self) {
        if !self.core.sdo_changed {
            return;
        }
        self.core.sdo_changed = false;
        let od = &self.core.od;
        let mut wanted: Vec<(u32, u32)> = Vec::new();
        if od.description().object(0x1200).is_none() {
            let n = u32::from(self.core.config.node_id);
            wanted.push((0x600 + n, 0x580 + n));
        }
        for k in 0..0x80u16 {
            let index = 0x1200 + k;
            if od.description().object(index).is_none() {
                continue;
            }
            let rx = od.get_unsigned(index, 1).unwrap_or(0x8000_0000) as u32;
            let tx = od.get_unsigned(index, 2).unwrap_or(0x8000_0000) as u32;
            wanted.push((rx, tx));
        }
        if self.sdo.len() != wanted.len() {
            self.core.accept_stale = true;
        }
        self.sdo
            .resize_with(wanted.len(), || SdoServer::for_node(0));
        for (server, (rx, tx)) in self.sdo.iter_mut().zip(wanted) {
            let want = (wire::CobId(rx), wire::CobId(tx));
            let now = (
                server.rx_id().map(|i| i.as_raw()),
                server.tx_id().map(|i| i.as_raw()),
            );
            let new = (
                crate::sdo::server::cob_id(want.0.0).map(|i| i.as_raw()),
                crate::sdo::server::cob_id(want.1.0).map(|i| i.as_raw()),
            );
            if now != new {
                server.set_cob_ids(rx, tx);
                self.core.accept_stale = true;
            }
            server.set_timeout(self.core.config.sdo_timeout);
            server.set_capabilities(self.core.config.sdo);
        }
    }

    fn after(&mut self, now: Instant, out: &mut Outbox) {
        if self.core.sdo_reset {
            self.core.sdo_reset = false;
            for s in &mut self.sdo {
                s.reset(&mut self.core);
            }
        }
        self.apply_sdo_config();
        self.core.run_timers(now, out);
        if self.core.state.allows(Service::Sdo) {
            for s in &mut self.sdo {
                s.on_tick(now, &mut self.core, out);
            }
        }
        self.core.mirror_errors();
        self.refresh();
    }

    /// Brings the caches up to date after a change: the acceptance filter, if a COB-ID may
    /// have changed, and the next deadline.
    fn refresh(&mut self) {
        if self.core.accept_stale {
            self.rebuild_acceptance();
        }
        self.deadline = Some(self.compute_deadline());
    }

    /// Collects every identifier a received frame can change the device on (see
    /// `Core::on_frame`, the SDO servers and [`PdoEngine::on_frame`]): NMT (CiA 301
    /// §7.2.8.3.1), SYNC (0x1005), TIME when consumed (0x1012 bit 31), node guarding
    /// requests for this node and the heartbeats of the producers 0x1016 monitors
    /// (§7.2.8.3.2), the EMCYs 0x1028 consumes, the requests of every valid SDO server
    /// channel (0x1200..0x127F sub 1), and every runnable RPDO and TPDO (data and remote
    /// requests, 0x1400..0x15FF and 0x1800..0x19FF sub 1).
    fn rebuild_acceptance(&mut self) {
        let core = &mut self.core;
        let mut keys = core::mem::take(&mut core.accept_spare);
        keys.clear();
        let guard = |node: u8| u32::from(wire::ERROR_CONTROL_BASE) + u32::from(node);
        keys.push(u32::from(wire::NMT_COB_ID));
        keys.push(frame_key(core.sync.id()));
        if core.time.consumer() {
            keys.push(frame_key(core.time.id()));
        }
        keys.push(guard(core.config.node_id));
        keys.extend(core.consumer.nodes().map(guard));
        keys.extend(core.emcy_rx.iter().copied().map(frame_key));
        keys.extend(self.sdo.iter().filter_map(SdoServer::rx_id).map(frame_key));
        if let Some(p) = &core.pdo {
            keys.extend(p.cob_ids().map(frame_key));
        }
        keys.sort_unstable();
        keys.dedup();
        if keys != core.accept {
            core.accept_generation += 1;
            core::mem::swap(&mut core.accept, &mut keys);
        }
        core.accept_spare = keys;
        core.accept_stale = false;
    }

    fn compute_deadline(&self) -> Option<Instant> {
        let sdo = if self.core.state.allows(Service::Sdo) {
            self.sdo.iter().filter_map(SdoServer::next_deadline).min()
        } else {
            None
        };
        Instant::earliest(self.core.next_deadline(), sdo)
    }

    /// Whether a frame on `id` can change the device: always while the filter is off or
    /// out of date, and while a receive overrun waits for the next frame to clear it.
    fn filter_passes(&self, id: Id) -> bool {
        !self.core.config.acceptance_filter
            || self.core.accept_stale
            || self.core.overrun
            || self.core.accept.binary_search(&frame_key(id)).is_ok()
    }
}

/// An identifier as one sortable number: the raw identifier, bit 31 set for the extended
/// format (as a CiA 301 COB-ID keeps the format in bit 29, a 29-bit identifier needs room
/// above its own bits).
fn frame_key(id: Id) -> u32 {
    id.as_raw() | if id.is_extended() { 1 << 31 } else { 0 }
}

/// Raises and clears the device's errors; see [`Device::emcy`].
pub struct Emcy<'a, H> {
    core: &'a mut Core<H>,
}

impl<H: OdHooks> Emcy<'_, H> {
    /// Raises error `code` with five manufacturer-specific bytes: recorded in 0x1001 and
    /// 0x1003 (the entry from [`OdHooks::error_entry`]) and sent as EMCY (subject to the
    /// inhibit time, its bytes from [`OdHooks::emcy_manufacturer`]) at the next
    /// [`Node::on_tick`] if EMCY is allowed in the NMT state. Raising an active code again
    /// does nothing.
    pub fn raise(&mut self, code: u16, manufacturer: [u8; 5]) -> bool {
        let r = self.core.raise(code, manufacturer);
        self.core.mirror_errors();
        r
    }

    /// Signals another occurrence of error `code` with other manufacturer-specific bytes
    /// (one active entry, one EMCY per occurrence); raises it if it is not active.
    pub fn signal(&mut self, code: u16, manufacturer: [u8; 5]) -> bool {
        let send = self.core.state.allows(Service::Emcy);
        let Core {
            emcy, hooks, od, ..
        } = &mut *self.core;
        let r = if emcy.is_active(code) {
            emcy.signal(code, manufacturer, send)
        } else {
            emcy.raise_with(code, manufacturer, send, |register| {
                hooks.error_entry(od, code, register, manufacturer)
            })
        };
        self.core.mirror_errors();
        r
    }

    /// Reports error `code` with `manufacturer` bytes: raises it if it is not active,
    /// otherwise records another occurrence with its own 0x1003 entry and EMCY (a second
    /// module failing with the same code), still one active error that one clear ends.
    pub fn report(&mut self, code: u16, manufacturer: [u8; 5]) -> bool {
        let send = self.core.state.allows(Service::Emcy);
        let Core {
            emcy, hooks, od, ..
        } = &mut *self.core;
        let r = emcy.report_with(code, manufacturer, send, |register| {
            hooks.error_entry(od, code, register, manufacturer)
        });
        self.core.mirror_errors();
        r
    }

    /// Clears error `code` (sends EMCY 0x0000 with the new error register).
    pub fn clear(&mut self, code: u16) -> bool {
        let send = self.core.state.allows(Service::Emcy);
        let r = self.core.emcy.clear(code, send);
        self.core.mirror_errors();
        r
    }

    /// Whether `code` is active.
    pub fn is_active(&self, code: u16) -> bool {
        self.core.emcy.is_active(code)
    }

    /// The error register.
    pub fn register(&self) -> u8 {
        self.core.emcy.register()
    }

    /// Sets or clears error register bits the application owns (bit 5 device profile,
    /// bit 7 manufacturer-specific).
    pub fn set_register_bits(&mut self, mask: u8, on: bool) {
        self.core.emcy.set_register_bits(mask, on);
        self.core.mirror_errors();
    }
}

impl<H: OdHooks> Core<H> {
    fn push_event(&mut self, e: Event) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events.push_back(e);
    }

    fn running(&self) -> bool {
        matches!(self.state, State::PreOperational | State::Operational)
    }

    fn u32(&self, index: u16, sub: u8) -> Option<u32> {
        self.od.get_unsigned(index, sub).map(|v| v as u32)
    }

    /// Reads every communication parameter from the dictionary into the services.
    fn configure(&mut self) {
        let now = self.now;
        let running = self.running();
        let node = self.config.node_id;
        self.heartbeat
            .set_time(self.u32(0x1017, 0).unwrap_or(0) as u16, now, false);
        let n = self
            .od
            .description()
            .object(0x1016)
            .map_or(0, |o| o.sub_number());
        for sub in 1..n.min(256) as u16 {
            let v = self.u32(0x1016, sub as u8).unwrap_or(0);
            self.consumer.set(sub as u8, v);
        }
        self.guarding.set_life_time(
            self.u32(0x100C, 0).unwrap_or(0) as u16,
            self.u32(0x100D, 0).unwrap_or(0) as u8,
        );
        self.emcy
            .set_cob_id(CobId(self.u32(0x1014, 0).unwrap_or(0x80 + u32::from(node))));
        self.emcy
            .set_inhibit(self.u32(0x1015, 0).unwrap_or(0) as u16);
        self.sync
            .set_overflow(self.u32(0x1019, 0).unwrap_or(0) as u8);
        self.sync.set_window(self.u32(0x1007, 0).unwrap_or(0));
        self.sync
            .set_cob_id(CobId(self.u32(0x1005, 0).unwrap_or(0x80)), now, false);
        self.sync
            .set_period(self.u32(0x1006, 0).unwrap_or(0), now, running);
        self.time = TimeService::new(CobId(self.u32(0x1012, 0).unwrap_or(0x100)));
        self.reaction = self
            .u32(0x1029, 1)
            .and_then(|v| Reaction::from_u8(v as u8))
            .unwrap_or(Reaction::PreOperational);
        self.configure_emcy_consumers();
        self.sdo_changed = true;
        self.accept_stale = true;
    }

    fn configure_emcy_consumers(&mut self) {
        self.accept_stale = true;
        self.emcy_rx.clear();
        let n = self
            .od
            .description()
            .object(0x1028)
            .map_or(0, |o| o.sub_number());
        for sub in 1..n.min(256) {
            let c = CobId(self.u32(0x1028, sub as u8).unwrap_or(0x8000_0000));
            if !c.bit31() {
                self.emcy_rx.push(c.can_id());
            }
        }
    }

    /// Mirrors the error register and the error history into 0x1001 and 0x1003.
    fn mirror_errors(&mut self) {
        if !self.emcy.take_changed() {
            return;
        }
        let _ = self
            .od
            .set(0x1001, 0, &Value::Unsigned8(self.emcy.register()));
        if let Some(o) = self.od.description().object(0x1003) {
            let n = o.sub_number().saturating_sub(1);
            let history = self.emcy.history();
            let count = history.len().min(n) as u8;
            let _ = self.od.set(0x1003, 0, &Value::Unsigned8(count));
            for k in 0..n {
                let v = history.get(k).copied().unwrap_or(0);
                let _ = self.od.set(0x1003, (k + 1) as u8, &Value::Unsigned32(v));
            }
        }
    }

    /// Loads the stored parameters of `group` on top of the defaults.
    fn load_group(&mut self, group: Group) {
        self.od.restore_defaults(group.range());
        let loaded = match self.storage.load(group) {
            Ok(Some(blob)) => storage::apply(&mut self.od, group, &blob).map(|_| ()),
            Ok(None) => Ok(()),
            Err(e) => Err(e),
        };
        let bit = storage_bit(group);
        if loaded.is_err() {
            self.od.restore_defaults(group.range());
            self.storage_faults |= bit;
            self.push_event(Event::StorageLoadFailed(group));
        } else {
            self.storage_faults &= !bit;
        }
    }

    fn enter(&mut self, to: State, now: Instant) {
        let from = self.state;
        if from == to {
            return;
        }
        self.state = to;
        if let Some(p) = &mut self.pdo {
            p.set_operational(to == State::Operational, now);
        }
        match to {
            State::Stopped => {
                self.emcy.drop_queue();
                self.sync.stop();
                self.sdo_reset = true;
            }
            State::PreOperational | State::Operational
                if matches!(from, State::Stopped | State::Initialising) =>
            {
                self.sync.restart(now, true);
            }
            _ => {}
        }
        self.push_event(Event::StateChanged { from, to });
    }

    fn reset_communication(&mut self, now: Instant, out: &mut Outbox) {
        self.enter(State::Initialising, now);
        self.heartbeat.stop();
        self.sync.stop();
        self.load_group(Group::Communication);
        self.emcy.reset();
        self.pdo_faults.clear();
        self.guarding.reset();
        self.overrun = false;
        self.bus_off_recovered = false;
        self.configure();
        if let Some(p) = &mut self.pdo {
            let _ = p.configure(&self.od, now);
        }
        self.sdo_reset = true;
        self.push_event(Event::ResetCommunication);
        // §7.3.2.2.1: the boot-up message ends initialisation; the device is then
        // pre-operational, and the boot-up counts as the first heartbeat.
        out.push(ErrorControl::boot_up(self.config.node_id).encode());
        self.boot_up_unsent = true;
        self.sdo_answer_unsent = None;
        self.enter(State::PreOperational, now);
        self.heartbeat.start(now);
        if self.error_passive {
            self.raise_sending(EMCY_ERROR_PASSIVE, [0; 5], true);
        }
        // The reset above cleared the errors; stored parameters that could not be loaded
        // are still not in effect.
        if self.storage_faults != 0
            && let Some(code) = self.config.storage_fault
        {
            self.raise_sending(code, [self.storage_faults, 0, 0, 0, 0], true);
        }
    }

    fn reset_node(&mut self, now: Instant, out: &mut Outbox) {
        self.enter(State::Initialising, now);
        self.load_group(Group::Manufacturer);
        self.load_group(Group::Application);
        self.push_event(Event::ResetApplication);
        self.reset_communication(now, out);
    }

    /// A communication error: 0x1029 sub 1. The EMCY reporting the error goes out before
    /// the state changes, so that a master learns why the device stopped.
    fn communication_error(&mut self, now: Instant, out: &mut Outbox) {
        // After bus-off nothing queued before it is confirmed; the EMCY must not wait.
        self.sdo_answer_unsent = None;
        self.send_emcys(now, out);
        if let Some(to) = self.reaction.apply(self.state) {
            self.enter(to, now);
        }
    }

    /// Raises `code`, its 0x1003 entry made by the hooks (see [`Emcy::raise`]).
    fn raise(&mut self, code: u16, manufacturer: [u8; 5]) -> bool {
        let send = self.state.allows(Service::Emcy);
        self.raise_sending(code, manufacturer, send)
    }

    fn raise_sending(&mut self, code: u16, manufacturer: [u8; 5], send: bool) -> bool {
        let Core {
            emcy, hooks, od, ..
        } = self;
        emcy.raise_with(code, manufacturer, send, |register| {
            hooks.error_entry(od, code, register, manufacturer)
        })
    }

    fn clear(&mut self, code: u16) {
        let send = self.state.allows(Service::Emcy);
        self.emcy.clear(code, send);
    }

    fn partner_recovered(&mut self) {
        if !self.consumer.any_lost()
            && !self.guarding.is_lost()
            && let Some(code) = self.config.error_control_fault
        {
            self.clear(code);
        }
    }

    fn run_timers(&mut self, now: Instant, out: &mut Outbox) {
        self.now = now;
        if self.state == State::Initialising {
            return;
        }
        let mut lost = [0u8; 8];
        let mut n_lost = 0;
        let mut more = Vec::new();
        self.consumer.on_tick(now, |node| {
            if n_lost < lost.len() {
                lost[n_lost] = node;
                n_lost += 1;
            } else {
                more.push(node);
            }
        });
        for node in lost[..n_lost].iter().copied().chain(more) {
            self.push_event(Event::HeartbeatLost { node });
            if let Some(code) = self.config.error_control_fault {
                self.raise(code, [node, 0, 0, 0, 0]);
            }
            self.communication_error(now, out);
        }
        if self.guarding.on_tick(now) {
            self.push_event(Event::LifeGuardingLost);
            if let Some(code) = self.config.error_control_fault {
                self.raise(code, [0; 5]);
            }
            self.communication_error(now, out);
        }
        if self.heartbeat.poll(now) {
            out.push(ErrorControl::heartbeat(self.config.node_id, self.state.wire()).encode());
        }
        if self.state.allows(Service::Sync)
            && let Some((frame, counter)) = self.sync.poll(now)
        {
            out.push(frame);
            self.push_event(Event::Sync { counter });
            if let Some(p) = &mut self.pdo {
                p.on_sync(counter, now, &mut self.od, &mut self.hooks, out);
            }
        }
        if let Some(p) = &mut self.pdo {
            p.on_tick(now, &self.od, &mut self.hooks, out);
        }
        self.pdo_events();
        self.send_emcys(now, out);
    }

    /// Whether EMCYs may go out now: in a state that allows them, behind the boot-up
    /// message and behind the answer to the SDO request being served.
    fn emcy_may_send(&self) -> bool {
        self.state.allows(Service::Emcy) && !self.boot_up_unsent && self.sdo_answer_unsent.is_none()
    }

    fn send_emcys(&mut self, now: Instant, out: &mut Outbox) {
        if self.emcy_may_send() {
            while let Some(mut e) = self.emcy.poll(now) {
                e.manufacturer =
                    self.hooks
                        .emcy_manufacturer(&self.od, e.code, e.register, e.manufacturer);
                out.push(e.encode(self.emcy.cob_id().can_id()));
            }
        }
    }

    /// Raises the EMCYs of PDO faults and clears them when the RPDO is received correctly
    /// again: 0x8250 (deadline missed) and 0x8210 (too short) by the next processed
    /// reception, 0x8220 (too long) by the next reception of the right length. A code stays
    /// active while any RPDO still has that fault.
    fn pdo_events(&mut self) {
        let mut too_long = None;
        while let Some(e) = self.pdo.as_mut().and_then(PdoEngine::poll_event) {
            match e {
                PdoEvent::LengthError { rpdo, emcy, .. } => {
                    if emcy == crate::pdo::EMCY_PDO_LENGTH_EXCEEDED {
                        too_long = Some(rpdo);
                    }
                    self.pdo_fault(rpdo, emcy);
                }
                PdoEvent::Timeout { rpdo } => self.pdo_fault(rpdo, crate::pdo::EMCY_RPDO_TIMEOUT),
                // The application decides (CiA 301 leaves it open); the stack only passes
                // the event on.
                PdoEvent::Refused { .. } => {}
                PdoEvent::Received { rpdo } => {
                    let long = too_long.take() == Some(rpdo);
                    self.pdo_faults.retain(|&(n, code)| {
                        n != rpdo || long && code == crate::pdo::EMCY_PDO_LENGTH_EXCEEDED
                    });
                    for code in [
                        crate::pdo::EMCY_PDO_LENGTH,
                        crate::pdo::EMCY_PDO_LENGTH_EXCEEDED,
                        crate::pdo::EMCY_RPDO_TIMEOUT,
                    ] {
                        if !self.pdo_faults.iter().any(|&(_, c)| c == code) {
                            self.clear(code);
                        }
                    }
                }
            }
            self.push_event(Event::Pdo(e));
        }
    }

    fn pdo_fault(&mut self, rpdo: u16, code: u16) {
        if !self.pdo_faults.contains(&(rpdo, code)) {
            self.pdo_faults.push((rpdo, code));
        }
        self.raise(code, [0; 5]);
    }

    fn next_deadline(&self) -> Option<Instant> {
        if self.state == State::Initialising {
            return None;
        }
        // The earliest of the services' deadlines, folded one by one: asked after every call
        // the bus makes (the Node contract), so it stays a handful of compares whatever the
        // hooks' layout (an array of options through an iterator did not always fold away).
        let mut next =
            Instant::earliest(self.consumer.next_deadline(), self.guarding.next_deadline());
        next = Instant::earliest(next, self.heartbeat.next_deadline());
        if self.state.allows(Service::Sync) {
            next = Instant::earliest(next, self.sync.next_deadline());
        }
        next = Instant::earliest(next, self.pdo.as_ref().and_then(PdoEngine::next_deadline));
        if self.emcy_may_send() {
            next = Instant::earliest(next, self.emcy.next_deadline().map(|t| t.max(self.now)));
        }
        next
    }

    /// The frame handling of everything but SDO; returns whether the frame was consumed.
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) -> bool {
        self.now = now;
        if self.overrun {
            self.overrun = false;
            self.clear(EMCY_CAN_OVERRUN);
        }
        let id = frame.id();
        if matches!(id, Id::Standard(s) if s.as_raw() == wire::NMT_COB_ID) {
            if let Ok(cmd) = NmtCommand::decode(frame)
                && cmd.addresses(self.config.node_id)
            {
                match nmt::command(self.state, cmd.cs) {
                    Transition::None => {}
                    Transition::Enter(s) => self.enter(s, now),
                    Transition::ResetNode => self.reset_node(now, out),
                    Transition::ResetCommunication => self.reset_communication(now, out),
                }
            }
            return true;
        }
        if self.state == State::Initialising {
            return true;
        }
        if id == self.sync.id() && !frame.is_remote() {
            // A SYNC producer is the only one on its network (§7.2.5): a frame on its own
            // SYNC identifier is its own echo, already handled when it was produced.
            if self.state.allows(Service::Sync) && !self.sync.is_producer() {
                match self.sync.on_receive(frame, now) {
                    Ok(counter) => {
                        self.push_event(Event::Sync { counter });
                        if let Some(p) = &mut self.pdo {
                            p.on_sync(counter, now, &mut self.od, &mut self.hooks, out);
                        }
                        self.pdo_events();
                    }
                    Err(code) => {
                        self.raise(code, [0; 5]);
                    }
                }
            }
            return true;
        }
        if let Id::Standard(s) = id {
            let raw = s.as_raw();
            if raw & !0x7F == wire::ERROR_CONTROL_BASE {
                self.on_error_control(frame, (raw & 0x7F) as u8, now, out);
                return true;
            }
        }
        if id == self.time.id() && self.time.consumer() {
            if self.state.allows(Service::Time)
                && let Some(t) = self.time.consume(frame)
            {
                self.push_event(Event::Time(t));
            }
            return true;
        }
        if !frame.is_remote() && self.emcy_rx.contains(&id) {
            if self.state.allows(Service::Emcy)
                && let Ok(emcy) = wire::Emcy::decode(frame)
            {
                self.push_event(Event::Emcy { id, emcy });
            }
            return true;
        }
        false
    }

    fn on_error_control(&mut self, frame: &Frame, node: u8, now: Instant, out: &mut Outbox) {
        if !self.state.allows(Service::ErrorControl) || node == 0 {
            return;
        }
        let Ok(msg) = ErrorControl::decode(frame, node) else {
            return;
        };
        match msg {
            ErrorControl::GuardRequest { node } if node == self.config.node_id => {
                // Heartbeat takes precedence: with 0x1017 ≠ 0 guarding is not used.
                if self.heartbeat.enabled() {
                    return;
                }
                let a = self.guarding.on_request(self.state.wire() as u8, now);
                out.push(Frame::data_array(frame.id(), [a.byte]));
                if a.recovered {
                    self.push_event(Event::LifeGuardingRecovered);
                    self.partner_recovered();
                }
            }
            ErrorControl::State { node, state, .. } => {
                match self.consumer.on_heartbeat(node, state, now) {
                    Heard::NotMonitored | Heard::Alive => {}
                    Heard::Recovered => {
                        self.push_event(Event::HeartbeatRecovered { node });
                        self.partner_recovered();
                    }
                    Heard::BootUp { was_lost } => {
                        self.push_event(Event::RemoteBootUp { node });
                        if was_lost {
                            self.partner_recovered();
                        }
                    }
                }
            }
            ErrorControl::GuardRequest { .. } => {}
        }
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.now = now;
        match event {
            ControllerEvent::ErrorPassive => {
                self.error_passive = true;
                self.raise(EMCY_ERROR_PASSIVE, [0; 5]);
            }
            ControllerEvent::ErrorActive => {
                self.error_passive = false;
                self.clear(EMCY_ERROR_PASSIVE);
            }
            ControllerEvent::BusOff => {
                self.push_event(Event::BusOff);
                self.communication_error(now, out);
            }
            ControllerEvent::BusOffRecovered => {
                self.error_passive = false;
                self.clear(EMCY_ERROR_PASSIVE);
                self.bus_off_recovered = true;
                self.raise(EMCY_BUS_OFF_RECOVERED, [0; 5]);
            }
            ControllerEvent::RxOverrun => {
                self.overrun = true;
                self.raise(EMCY_CAN_OVERRUN, [0; 5]);
            }
            ControllerEvent::TxDropped => {}
        }
    }
}

impl<H: OdHooks> Core<H> {
    /// The rules of the communication objects (CiA 301 §7.5.2) for a whole value.
    fn write_comm(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let id = self.od.locate(index, sub)?;
        self.od.check_download(id, data)?;
        let v = u32_of(data);
        let old = self.u32(index, sub).unwrap_or(0);
        match (index, sub) {
            (0x1003, 0) => {
                // §7.5.2.4: only 0 may be written, and it clears the field.
                if v != 0 {
                    return Err(AbortCode::INVALID_VALUE);
                }
                self.emcy.clear_history();
                self.mirror_errors();
                return Ok(());
            }
            (0x1010, 1..) => return self.store(sub, v),
            (0x1011, 1..) => return self.restore(sub, v),
            _ => {}
        }
        // Every COB-ID entry (SYNC, TIME, EMCY, EMCY consumers, SDO server and client
        // parameters) follows one rule, CiA 301 §7.3.5 and the entries' tables; the PDO
        // engine applies the same rule to the PDO COB-IDs below.
        let entry = cob_id::Entry::of(
            index,
            sub,
            self.config.node_id,
            self.config.sync_producer,
            self.config.time_producer,
        );
        if let Some(e) = entry.filter(|e| !e.is_pdo()) {
            cob_id::check(e, old, v)?;
        }
        let invalid = AbortCode::INVALID_VALUE;
        let refused = match (index, sub) {
            // §7.5.2.19: bits 24..=31 are reserved (0); one entry per monitored node.
            (0x1016, 1..) if v & 0xFF00_0000 != 0 => Some(invalid),
            (0x1016, 1..) => self
                .consumer
                .conflicts(sub, v)
                .then_some(AbortCode::PARAMETER_INCOMPATIBLE),
            // §7.5.2.37: changes only while no SYNC is produced; 1 and 241..=255 are
            // reserved.
            (0x1019, 0) if !self.sync.period().is_zero() => Some(AbortCode::DEVICE_STATE),
            (0x1019, 0) => (v == 1 || v > 240).then_some(invalid),
            (0x1029, 1..) => Reaction::from_u8(v as u8).is_none().then_some(invalid),
            // §7.5.2.33, §7.5.2.34: the node-ID of the SDO client (server) is 1..=127;
            // 0, no node-ID assigned, is the entry's default, which a DCF carries back.
            (0x1201..=0x12FF, 3) => (v > 127).then_some(invalid),
            (0x1400..=0x1BFF, _) => self
                .pdo
                .as_ref()
                .and_then(|p| p.validate_write(&self.od, index, sub, data).err()),
            _ => None,
        };
        if let Some(code) = refused {
            return Err(code);
        }
        // The PDO parameters are hooked for the PDO engine, which checked them above; the
        // device's hooks see them too, after it, so a device can narrow what CiA 301 allows
        // (a manual's "not supported" values).
        let hooked = self.od.description().is_hooked(index);
        if hooked {
            self.hooks.validate(&self.od, index, sub, data)?;
        }
        self.od.set_raw(id, data)?;
        self.apply_comm(index, sub, v);
        if hooked {
            self.hooks.written(&mut self.od, index, sub);
        }
        Ok(())
    }

    /// A landed communication parameter takes effect.
    fn apply_comm(&mut self, index: u16, sub: u8, v: u32) {
        let now = self.now;
        let running = self.running();
        match index {
            0x1005 => {
                self.sync.set_cob_id(CobId(v), now, running);
                self.accept_stale = true;
            }
            0x1006 => self.sync.set_period(v, now, running),
            0x1007 => self.sync.set_window(v),
            0x1019 => self.sync.set_overflow(v as u8),
            0x100C | 0x100D => self.guarding.set_life_time(
                self.u32(0x100C, 0).unwrap_or(0) as u16,
                self.u32(0x100D, 0).unwrap_or(0) as u8,
            ),
            0x1012 => {
                self.time = TimeService::new(CobId(v));
                self.accept_stale = true;
            }
            0x1014 => self.emcy.set_cob_id(CobId(v)),
            0x1015 => self.emcy.set_inhibit(v as u16),
            0x1016 => {
                self.consumer.set(sub, v);
                self.accept_stale = true;
            }
            0x1017 => self
                .heartbeat
                .set_time(v as u16, now, self.state != State::Initialising),
            0x1028 => self.configure_emcy_consumers(),
            0x1029 if sub == 1 => {
                self.reaction = Reaction::from_u8(v as u8).unwrap_or(Reaction::NoChange);
            }
            0x1200..=0x127F => self.sdo_changed = true,
            0x1400..=0x1BFF => {
                if let Some(p) = &mut self.pdo {
                    p.after_write(&self.od, index, sub, now);
                }
                self.accept_stale = true;
            }
            _ => {}
        }
    }

    /// 0x1010: "save" stores the selected groups.
    fn store(&mut self, sub: u8, v: u32) -> Result<(), AbortCode> {
        let s = signed_storage(&mut self.storage, v, storage::SAVE)?;
        let groups = Group::for_sub(sub);
        let blobs: Vec<Vec<u8>> = groups
            .iter()
            .map(|g| storage::encode(&self.od, *g))
            .collect();
        let changes: Vec<storage::Change<'_>> = groups
            .iter()
            .zip(&blobs)
            .map(|(g, b)| (*g, Some(b.as_slice())))
            .collect();
        // "Save all" replaces the groups as one (see `storage`).
        s.commit(&changes)
            .map_err(|_: StorageError| AbortCode::HARDWARE_ERROR)?;
        // The store is whole again for these groups.
        for g in groups {
            self.storage_faults &= !storage_bit(*g);
        }
        if self.storage_faults == 0
            && let Some(code) = self.config.storage_fault
        {
            self.clear(code);
        }
        Ok(())
    }

    /// 0x1011: "load" erases the selected groups; defaults apply after the next reset.
    fn restore(&mut self, sub: u8, v: u32) -> Result<(), AbortCode> {
        let s = signed_storage(&mut self.storage, v, storage::LOAD)?;
        let changes: Vec<storage::Change<'_>> =
            Group::for_sub(sub).iter().map(|g| (*g, None)).collect();
        s.commit(&changes)
            .map_err(|_: StorageError| AbortCode::HARDWARE_ERROR)?;
        Ok(())
    }
}

/// The bit of [`Core::storage_faults`] for `group`: its own 0x1010 sub-index.
fn storage_bit(group: Group) -> u8 {
    let sub = match group {
        Group::Communication => 2,
        Group::Application => 3,
        Group::Manufacturer => 4,
    };
    1 << sub
}

/// The storage behind a write of `v` to 0x1010 or 0x1011, which only the signature
/// `signature` ("save" or "load") triggers: any other value is refused with 0x0800 0020
/// (CiA 301 §7.5.2.10 and §7.5.2.11). A failing backend answers 0x0606 0000 where it is
/// used.
fn signed_storage(
    storage: &mut Box<dyn Storage>,
    v: u32,
    signature: u32,
) -> Result<&mut dyn Storage, AbortCode> {
    if v != signature {
        return Err(AbortCode::DATA_TRANSFER);
    }
    Ok(storage.as_mut())
}

impl<H: OdHooks> ObjectAccess for Core<H> {
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Result<ReadInfo, AbortCode> {
        if index == 0x1003 && sub > 0 {
            // §7.5.2.4: sub-index 0 holds the number of errors recorded; a sub-index beyond
            // it holds no error. Reading one is answered with 0x0800 0024 "no data
            // available" (what conformance tools accept), not a made-up 0.
            self.od.locate(index, sub)?;
            if self.u32(0x1003, 0).unwrap_or(0) < u32::from(sub) {
                return Err(AbortCode::NO_DATA);
            }
        }
        Hooked::new(&mut self.od, &mut self.hooks).read(index, sub, offset, buf)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        if index < 0x2000 {
            let r = self.write_comm(index, sub, data);
            self.mirror_errors();
            return r;
        }
        Hooked::new(&mut self.od, &mut self.hooks).write(index, sub, data)?;
        if let Some(p) = &mut self.pdo {
            p.mark_changed(index, sub);
        }
        Ok(())
    }

    fn fixed_size(&mut self, index: u16, sub: u8) -> Option<usize> {
        self.od.fixed_size(index, sub)
    }

    fn write_begin(&mut self, index: u16, sub: u8, size: Option<usize>) -> Result<(), AbortCode> {
        if index < 0x2000 {
            // Communication objects are checked as a whole by `write_comm` at the end.
            return self.od.stage_begin(index, sub, size).map(|_| ());
        }
        // Application objects: the device's hooks may refuse a download at its initiate
        // (e.g. 0x08000022 in the wrong state), as for the bare dictionary.
        Hooked::new(&mut self.od, &mut self.hooks).write_begin(index, sub, size)
    }

    fn write_segment(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let id = self.od.locate(index, sub)?;
        self.od.stage_append(id, data)
    }

    fn write_end(&mut self, index: u16, sub: u8) -> Result<(), AbortCode> {
        if index < 0x2000 {
            let data = self.od.staged().to_vec();
            self.od.stage_cancel();
            return self.write(index, sub, &data);
        }
        Hooked::new(&mut self.od, &mut self.hooks).write_end(index, sub)?;
        if let Some(p) = &mut self.pdo {
            p.mark_changed(index, sub);
        }
        Ok(())
    }

    fn write_cancel(&mut self, _index: u16, _sub: u8) {
        self.od.stage_cancel();
    }
}

impl<H: OdHooks> ObjectAccess for Device<H> {
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Result<ReadInfo, AbortCode> {
        self.core.read(index, sub, offset, buf)
    }

    fn fixed_size(&mut self, index: u16, sub: u8) -> Option<usize> {
        self.core.fixed_size(index, sub)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let r = self.core.write(index, sub, data);
        self.apply_sdo_config();
        self.refresh();
        r
    }

    fn write_begin(&mut self, index: u16, sub: u8, size: Option<usize>) -> Result<(), AbortCode> {
        self.core.write_begin(index, sub, size)
    }

    fn write_segment(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        self.core.write_segment(index, sub, data)
    }

    fn write_end(&mut self, index: u16, sub: u8) -> Result<(), AbortCode> {
        let r = self.core.write_end(index, sub);
        self.apply_sdo_config();
        self.refresh();
        r
    }

    fn write_cancel(&mut self, index: u16, sub: u8) {
        self.core.write_cancel(index, sub);
    }
}

impl<H: OdHooks> Node for Device<H> {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.core.now = now;
        self.core.state = State::Initialising;
        self.core.error_passive = false;
        self.core.events.clear();
        self.core.od.restore_defaults(0x0000..=0xFFFF);
        self.core.load_group(Group::Manufacturer);
        self.core.load_group(Group::Application);
        self.core.reset_communication(now, out);
        self.after(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if !self.filter_passes(frame.id()) {
            // A frame none of the services reacts to: all the full path would do is run
            // the timers due by now, and a driver that keeps to the contract has already
            // ticked those.
            self.core.now = now;
            if self.next_deadline().is_some_and(|d| d <= now) {
                self.after(now, out);
            }
            return;
        }
        if !self.core.on_frame(frame, now, out) && self.core.state.allows(Service::Sdo) {
            let mut handled = false;
            let queued = out.len();
            for s in &mut self.sdo {
                if s.on_frame(frame, now, &mut self.core, out) {
                    handled = true;
                    break;
                }
            }
            if handled && out.len() > queued {
                self.core.sdo_answer_unsent = out.frames().last().copied();
            }
            if !handled
                && self.core.state == State::Operational
                && let Some(p) = &mut self.core.pdo
            {
                p.on_frame(frame, now, &mut self.core.od, &mut self.core.hooks, out);
                self.core.pdo_events();
            }
        }
        self.after(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.after(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        match self.deadline {
            Some(cached) => cached,
            None => self.compute_deadline(),
        }
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.core.now = now;
        if self.core.boot_up_unsent
            && *frame == ErrorControl::boot_up(self.core.config.node_id).encode()
        {
            // The boot-up message is on the bus: the EMCYs behind it follow.
            self.core.boot_up_unsent = false;
        }
        if self.core.sdo_answer_unsent.as_ref() == Some(frame) {
            self.core.sdo_answer_unsent = None;
        }
        if let Some(p) = &mut self.core.pdo {
            p.on_sent(frame, now);
        }
        if self.core.bus_off_recovered {
            // A frame of ours made it onto the bus: the recovery is complete.
            self.core.bus_off_recovered = false;
            self.core.clear(EMCY_BUS_OFF_RECOVERED);
        }
        self.after(now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.core.on_controller_event(event, now, out);
        self.after(now, out);
    }

    fn accepts(&self, id: Id) -> bool {
        self.filter_passes(id)
    }

    fn acceptance_version(&self) -> Option<u64> {
        // Everything `filter_passes` reads: the list (through its generation), and the
        // states in which every identifier passes.
        let core = &self.core;
        Some(
            core.accept_generation << 3
                | u64::from(core.accept_stale) << 2
                | u64::from(core.overrun) << 1
                | u64::from(core.config.acceptance_filter),
        )
    }
}
