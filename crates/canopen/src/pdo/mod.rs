//! Process data objects (CiA 301 §7.2.2): the RPDO/TPDO engine.
//!
//! [`PdoEngine`] is a sans-IO state machine over the PDO communication and mapping objects
//! of an [`ObjectDictionary`] (0x1400+n / 0x1600+n for RPDO n+1, 0x1800+n / 0x1A00+n for
//! TPDO n+1, n < 512). The device that owns it tells it about SYNCs, frames, time, NMT
//! state changes and writes to those objects; it answers with frames in an [`Outbox`] and
//! with [`PdoEvent`]s (received data, length errors and deadline misses that the device
//! raises as EMCY 0x8210/0x8220/0x8250).
//!
//! Behaviour chosen where CiA 301 leaves room, each pinned by a test in `tests/pdo*.rs`:
//!
//! * **Inhibit time** (§7.2.2.5, 100 µs units) is the minimum time between two
//!   transmissions of the same TPDO on the bus. It is counted from the end of the previous
//!   transmission ([`PdoEngine::on_sent`]); until that confirmation arrives it is counted from
//!   the moment the frame was queued. An event that falls inside the inhibit time is kept and
//!   sent when the inhibit time ends.
//! * **Event timer** of a TPDO of type 254/255 (§7.5.2.35): an event every period, restarted
//!   by every transmission (queueing time). Of an RPDO: deadline monitoring, armed by the
//!   first correctly received PDO and re-armed by every further one; when it expires without
//!   a new PDO the engine reports [`PdoEvent::Timeout`] (EMCY 0x8250) once and waits for the
//!   next reception.
//! * **Entering OPERATIONAL** resets all SYNC counters, waits again for the SYNC start
//!   value, arms the TPDO event timers from that instant and sends each event-driven TPDO
//!   (types 254/255) once so the consumers start from current values. Leaving OPERATIONAL
//!   drops pending events and buffered synchronous RPDO data (§7.3.2.2: no PDOs outside
//!   OPERATIONAL).
//! * **Valid PDOs** (§7.5.2.35–38): the entries that may not change while the PDO is valid
//!   (COB-ID, inhibit time, SYNC start value, mapping) accept a download of the value they
//!   hold, which changes nothing, so a DCF can be written back to a running device.
//! * **RPDO length** (§7.2.2.2): fewer bytes than mapped are not processed
//!   ([`PdoEvent::LengthError`] with 0x8210); more bytes are processed (the mapped bytes
//!   are used, the excess ignored) and reported with 0x8220, unless the device chose
//!   otherwise ([`PdoEngine::set_excess_length_processed`]).
//! * **RPDO data go through the device's hooks** as an SDO download does (CiA 301
//!   §7.2.2.2 leaves the use of received data to the application): every mapped entry is
//!   checked first (the dictionary's value checks and [`OdHooks::validate`], with the
//!   bytes an expedited download of that object would carry); if one refuses, none is
//!   written and [`PdoEvent::Refused`] tells the device, which sends no EMCY for it and
//!   does not count it as a reception. Otherwise the entries are written
//!   ([`OdHooks::write`] or storage) and the hooks notified in mapping order
//!   ([`Plan::unpack`]). TPDOs read hooked objects through [`OdHooks::read`]
//!   ([`Plan::pack`]), so a value the device's model holds is sent fresh.
//! * **RTR**: a remote frame on a TPDO's COB-ID with bit 30 clear is answered for types 252
//!   (the data sampled at the last SYNC; nothing before the first SYNC), 253, 254 and 255
//!   (current data, subject to the inhibit time). Synchronous cyclic and acyclic TPDOs
//!   (0..=240) ignore remote requests.
//! * **Dynamic mapping** (§7.5.2.36, §7.5.2.38): a mapping object can be written only while
//!   the PDO is invalid, and its entries only while sub-index 0 is 0; otherwise the write
//!   is refused with 0x06010000 "unsupported access to an object" (the code CANopenNode's
//!   `OD_write_PDO_mapping` and its Go port give; lely answers 0x06090030; CiA 301 names
//!   no code for it, and 0x08000022 is for the NMT state, which mapping does not depend
//!   on). Entries are checked when written (0x06020000 for a missing object, 0x06040041
//!   for one that cannot be mapped, 0x06040042 for more than 64 bits) and again, with the
//!   total length, when sub-index 0 enables them (0x06040042). A count above the entries
//!   the object holds is 0x06040042 whatever the state, checked first. A PDO whose stored
//!   mapping is invalid (see [`PdoEngine::load`]) cannot be made valid until the mapping
//!   is repaired (0x06040043).
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_can::{Duration, Frame, Instant, Outbox};
//! use cantwin_canopen::device::NoHooks;
//! use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
//! use cantwin_canopen::pdo::{PdoEngine, PdoObjects};
//!
//! let builder = OdBuilder::new().var(
//!     0x6000,
//!     SubObject::new("Inputs", DataType::Unsigned16, Access::Ro).mappable(),
//! );
//! // TPDO1 (0x180 + node-ID), cyclic on every SYNC, carrying 0x6000.
//! let builder = PdoObjects::new(0, 1).tpdo(0, 1, &[0x6000_0010]).add_to(builder);
//! let mut od = ObjectDictionary::new(Arc::new(builder.build().unwrap()), 5);
//! od.set(0x6000, 0, &Value::Unsigned16(0xBEEF)).unwrap();
//!
//! let mut pdo = PdoEngine::new(&od).unwrap();
//! let mut out = Outbox::new();
//! pdo.set_operational(true, Instant::ZERO);
//! pdo.on_sync(None, Instant::from_nanos(1_000_000), &mut od, &mut NoHooks, &mut out);
//! assert_eq!(out.frames(), [Frame::std(0x185, &[0xEF, 0xBE]).unwrap()]);
//! ```

mod map;
mod objects;

pub use map::{Direction, MAX_ENTRIES, MAX_PDO_BITS, MapEntry, Plan, Refusal, check_entry};
pub use objects::PdoObjects;

use crate::abort::AbortCode;
use crate::cob_id;
use crate::od::{ObjectDictionary, OdDescription, OdHooks};
use cantwin_can::{Duration, Frame, Id, Instant, Outbox};
use std::collections::VecDeque;
use std::sync::Arc;

/// First RPDO communication parameter object.
pub const RPDO_COMM: u16 = 0x1400;
/// First RPDO mapping parameter object.
pub const RPDO_MAP: u16 = 0x1600;
/// First TPDO communication parameter object.
pub const TPDO_COMM: u16 = 0x1800;
/// First TPDO mapping parameter object.
pub const TPDO_MAP: u16 = 0x1A00;
/// The most RPDOs (and TPDOs) a device can have (CiA 301 §7.4.8).
pub const MAX_PDOS: u16 = 512;

/// EMCY 0x8210: PDO not processed due to length error (CiA 301 table 21).
pub const EMCY_PDO_LENGTH: u16 = 0x8210;
/// EMCY 0x8220: PDO length exceeded (CiA 301 table 21).
pub const EMCY_PDO_LENGTH_EXCEEDED: u16 = 0x8220;
/// EMCY 0x8250: RPDO timeout (CiA 301 table 21).
pub const EMCY_RPDO_TIMEOUT: u16 = 0x8250;

/// The engine keeps at most this many unpolled events; older ones are dropped.
pub const MAX_QUEUED_EVENTS: usize = 256;

/// A PDO COB-ID entry (sub-index 1 of 0x1400+n / 0x1800+n, CiA 301 §7.5.2.35).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct CobId(pub u32);

impl CobId {
    /// Bit 31: set when the PDO does not exist (is invalid).
    pub const INVALID: u32 = 1 << 31;
    /// Bit 30: set when remote requests are not allowed (TPDO).
    pub const NO_RTR: u32 = 1 << 30;
    /// Bit 29: set for a 29-bit identifier.
    pub const EXTENDED: u32 = 1 << 29;

    /// Whether the PDO exists (bit 31 clear).
    pub const fn is_valid(self) -> bool {
        self.0 & Self::INVALID == 0
    }

    /// Whether remote requests are answered (bit 30 clear).
    pub const fn rtr_allowed(self) -> bool {
        self.0 & Self::NO_RTR == 0
    }

    /// Whether it uses a 29-bit identifier (bit 29).
    pub const fn is_extended(self) -> bool {
        self.0 & Self::EXTENDED != 0
    }

    /// The CAN identifier, if the bits form one (11 bits when bit 29 is clear).
    pub fn id(self) -> Option<Id> {
        if self.is_extended() {
            Id::extended(self.0 & 0x1FFF_FFFF).ok()
        } else if self.0 & 0x1FFF_F800 == 0 {
            Id::standard((self.0 & 0x7FF) as u16).ok()
        } else {
            None
        }
    }
}

/// What the engine tells the device. RPDO numbers are slot numbers: `rpdo: n` is the
/// RPDO with communication object 0x1400 + n (RPDO n + 1 in CiA 301 wording).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PdoEvent {
    /// An RPDO's data were written into the mapped objects.
    Received {
        /// Slot number.
        rpdo: u16,
    },
    /// An RPDO had the wrong length (CiA 301 §7.2.2.2); raise EMCY `emcy`
    /// ([`EMCY_PDO_LENGTH`]: too short, not processed; [`EMCY_PDO_LENGTH_EXCEEDED`]: too long,
    /// processed).
    LengthError {
        /// Slot number.
        rpdo: u16,
        /// 0x8210 or 0x8220.
        emcy: u16,
        /// The received data length.
        len: u8,
    },
    /// An RPDO's deadline (event timer) expired without a new PDO: raise EMCY 0x8250.
    Timeout {
        /// Slot number.
        rpdo: u16,
    },
    /// An RPDO of the right length carried a value a mapped object refuses (the abort
    /// code an SDO download of the same bytes would get): none of its data were written.
    /// CiA 301 leaves the reaction to the application; the stack sends no EMCY.
    Refused {
        /// Slot number.
        rpdo: u16,
        /// The refused entry's object.
        index: u16,
        /// Its sub-index.
        sub: u8,
        /// Why.
        code: AbortCode,
    },
}

impl PdoEvent {
    /// The EMCY error code the device raises for this event, if any.
    pub const fn emcy_code(&self) -> Option<u16> {
        match self {
            PdoEvent::Received { .. } | PdoEvent::Refused { .. } => None,
            PdoEvent::LengthError { emcy, .. } => Some(*emcy),
            PdoEvent::Timeout { .. } => Some(EMCY_RPDO_TIMEOUT),
        }
    }
}

/// A PDO configuration in a dictionary that the engine cannot run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PdoError {
    /// The mapping object's entries are not a valid mapping.
    #[error("PDO mapping {index:#06X} is invalid: {code}")]
    Mapping {
        /// The mapping object.
        index: u16,
        /// Why, as the abort code a download of it would get.
        code: AbortCode,
    },
    /// A communication parameter is out of range.
    #[error("PDO communication parameter {index:#06X}:{sub} is invalid: {code}")]
    Communication {
        /// The communication object.
        index: u16,
        /// The sub-index.
        sub: u8,
        /// Why.
        code: AbortCode,
    },
}

/// A receive PDO.
#[derive(Debug, Clone, Default)]
struct Rpdo {
    cob: CobId,
    ttype: u8,
    deadline: Duration,
    /// `None`: the mapping in the dictionary is invalid and the PDO cannot run.
    plan: Option<Plan>,
    /// The frame identifier, when the PDO is valid and runnable.
    id: Option<Id>,
    /// Synchronous data waiting for the next SYNC.
    buffered: Option<[u8; 8]>,
    /// Deadline monitoring: when the next PDO is due.
    due: Option<Instant>,
}

/// A transmit PDO.
#[derive(Debug, Clone, Default)]
struct Tpdo {
    cob: CobId,
    ttype: u8,
    inhibit: Duration,
    event_timer: Duration,
    sync_start: u8,
    plan: Option<Plan>,
    id: Option<Id>,
    /// SYNCs left until the next cyclic transmission.
    sync_left: u8,
    /// Waiting for the SYNC whose counter equals the start value.
    wait_start: bool,
    /// An application event (or RTR, or timer expiry inside the inhibit time) is pending.
    event: bool,
    inhibit_until: Instant,
    timer_due: Option<Instant>,
    /// Type 252: the data sampled at the last SYNC.
    sampled: Option<[u8; 8]>,
}

impl Tpdo {
    fn is_async(&self) -> bool {
        self.ttype >= 253
    }

    fn is_event_driven(&self) -> bool {
        self.ttype >= 254
    }
}

/// The PDO engine of one device. See the [module documentation](self).
#[derive(Debug, Clone)]
pub struct PdoEngine {
    desc: Arc<OdDescription>,
    rpdos: Vec<Rpdo>,
    tpdos: Vec<Tpdo>,
    /// Runnable RPDOs by frame key, sorted.
    rx_index: Vec<(u32, u16)>,
    /// Runnable TPDOs by frame key, sorted.
    tx_index: Vec<(u32, u16)>,
    /// Runnable TPDOs of types 0..=252.
    sync_tx: Vec<u16>,
    /// Runnable TPDOs of types 253..=255.
    async_tx: Vec<u16>,
    /// Runnable RPDOs with deadline monitoring.
    timed_rx: Vec<u16>,
    /// RPDOs holding data for the next SYNC.
    sync_rx_pending: Vec<u16>,
    operational: bool,
    dummy_mapping: bool,
    /// See [`PdoEngine::set_excess_length_processed`].
    excess_processed: bool,
    events: VecDeque<PdoEvent>,
}

fn push_event(events: &mut VecDeque<PdoEvent>, e: PdoEvent) {
    if events.len() >= MAX_QUEUED_EVENTS {
        events.pop_front();
    }
    events.push_back(e);
}

/// The event for RPDO slot `n` whose data were applied, or refused by an entry.
fn received(n: usize, result: Result<(), Refusal>) -> PdoEvent {
    let rpdo = n as u16;
    match result {
        Ok(()) => PdoEvent::Received { rpdo },
        Err(Refusal { index, sub, code }) => PdoEvent::Refused {
            rpdo,
            index,
            sub,
            code,
        },
    }
}

fn key(id: Id) -> u32 {
    id.as_raw() | if id.is_extended() { 1 << 31 } else { 0 }
}

fn lookup(index: &[(u32, u16)], id: Id) -> Option<usize> {
    let k = key(id);
    index
        .binary_search_by_key(&k, |e| e.0)
        .ok()
        .map(|i| usize::from(index[i].1))
}

fn le_value(data: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    u32::from_le_bytes(b)
}

/// Which PDO object an index is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PdoObject {
    Comm(Direction, usize),
    Map(Direction, usize),
}

fn classify(index: u16) -> Option<PdoObject> {
    let n = |base: u16| usize::from(index - base);
    match index {
        0x1400..=0x15FF => Some(PdoObject::Comm(Direction::Rx, n(RPDO_COMM))),
        0x1600..=0x17FF => Some(PdoObject::Map(Direction::Rx, n(RPDO_MAP))),
        0x1800..=0x19FF => Some(PdoObject::Comm(Direction::Tx, n(TPDO_COMM))),
        0x1A00..=0x1BFF => Some(PdoObject::Map(Direction::Tx, n(TPDO_MAP))),
        _ => None,
    }
}

fn comm_index(dir: Direction, n: usize) -> u16 {
    let base = match dir {
        Direction::Rx => RPDO_COMM,
        Direction::Tx => TPDO_COMM,
    };
    base + n as u16
}

fn map_index(dir: Direction, n: usize) -> u16 {
    comm_index(dir, n) + 0x200
}

fn read_u(od: &ObjectDictionary, index: u16, sub: u8, default: u64) -> u64 {
    od.get_unsigned(index, sub).unwrap_or(default)
}

/// Reads a mapping object's enabled entries and checks them.
fn load_plan(
    od: &ObjectDictionary,
    dir: Direction,
    n: usize,
    dummy_mapping: bool,
) -> Result<Plan, AbortCode> {
    let index = map_index(dir, n);
    if od.description().object(index).is_none() {
        return Ok(Plan::default());
    }
    let count = read_u(od, index, 0, 0);
    if count > u64::from(MAX_ENTRIES) {
        return Err(AbortCode::PDO_LENGTH_EXCEEDED);
    }
    let mut entries = [MapEntry::from_u32(0); MAX_ENTRIES as usize];
    for (i, e) in entries.iter_mut().take(count as usize).enumerate() {
        // An enabled entry the object does not have makes the mapping too long for it.
        let v = od
            .get_unsigned(index, i as u8 + 1)
            .ok_or(AbortCode::PDO_LENGTH_EXCEEDED)?;
        *e = MapEntry::from_u32(v as u32);
    }
    Plan::build(
        od.description(),
        dir,
        dummy_mapping,
        entries[..count as usize].iter().copied(),
    )
}

impl PdoEngine {
    /// An engine for the PDO objects of `od`, not yet OPERATIONAL. Dummy mapping is
    /// supported. Errors name the first PDO whose configuration cannot run; see
    /// [`PdoEngine::load`] for an engine that runs the others anyway.
    pub fn new(od: &ObjectDictionary) -> Result<Self, PdoError> {
        let (engine, result) = Self::load(od);
        result.map(|()| engine)
    }

    /// An engine for the PDO objects of `od` that runs every PDO whose configuration is
    /// valid, together with the first configuration error, if any (as a real device boots
    /// with a bad stored mapping and leaves that PDO off).
    pub fn load(od: &ObjectDictionary) -> (Self, Result<(), PdoError>) {
        let mut engine = PdoEngine {
            desc: Arc::clone(od.description()),
            rpdos: Vec::new(),
            tpdos: Vec::new(),
            rx_index: Vec::new(),
            tx_index: Vec::new(),
            sync_tx: Vec::new(),
            async_tx: Vec::new(),
            timed_rx: Vec::new(),
            sync_rx_pending: Vec::new(),
            operational: false,
            dummy_mapping: true,
            excess_processed: true,
            events: VecDeque::new(),
        };
        let result = engine.configure(od, Instant::ZERO);
        (engine, result)
    }

    /// Whether dummy entries (0x0001..=0x0007) may be mapped into RPDOs. Takes effect for
    /// later mapping checks and the next [`PdoEngine::configure`].
    pub fn set_dummy_mapping(&mut self, supported: bool) {
        self.dummy_mapping = supported;
    }

    /// Whether an RPDO longer than its mapping is processed (the default: the mapped bytes
    /// are used and 0x8220 reported) or, as some devices' manuals say, not processed and
    /// reported with 0x8210 like a short one (§7.2.2.2 leaves the choice to the device).
    pub fn set_excess_length_processed(&mut self, processed: bool) {
        self.excess_processed = processed;
    }

    /// (Re)reads every PDO object of `od`: at start-up and after NMT reset communication.
    /// A PDO whose mapping or parameters are invalid does not run; the first such PDO is
    /// reported, the others are still loaded.
    pub fn configure(&mut self, od: &ObjectDictionary, now: Instant) -> Result<(), PdoError> {
        self.desc = Arc::clone(od.description());
        let count = |base: u16| {
            (0..MAX_PDOS)
                .rev()
                .find(|n| od.description().object(base + n).is_some())
                .map_or(0, |n| usize::from(n) + 1)
        };
        self.rpdos = vec![Rpdo::default(); count(RPDO_COMM)];
        self.tpdos = vec![Tpdo::default(); count(TPDO_COMM)];
        self.sync_rx_pending = Vec::with_capacity(self.rpdos.len());
        let mut first = Ok(());
        for n in 0..self.rpdos.len() {
            let r = self.load_pdo(od, Direction::Rx, n, now);
            first = first.and(r);
        }
        for n in 0..self.tpdos.len() {
            let r = self.load_pdo(od, Direction::Tx, n, now);
            first = first.and(r);
        }
        self.reindex();
        first
    }

    /// Reads one PDO's objects into its slot and restarts it.
    fn load_pdo(
        &mut self,
        od: &ObjectDictionary,
        dir: Direction,
        n: usize,
        now: Instant,
    ) -> Result<(), PdoError> {
        let ci = comm_index(dir, n);
        let present = od.description().object(ci).is_some();
        let plan = load_plan(od, dir, n, self.dummy_mapping);
        let cob = CobId(read_u(od, ci, 1, u64::from(CobId::INVALID)) as u32);
        let ttype = read_u(od, ci, 2, 255) as u8;
        let ttype_ok = match dir {
            Direction::Rx => ttype <= 240 || ttype >= 254,
            Direction::Tx => ttype <= 240 || ttype >= 252,
        };
        let mut result = match &plan {
            Err(code) => Err(PdoError::Mapping {
                index: map_index(dir, n),
                code: *code,
            }),
            Ok(_) => Ok(()),
        };
        if present && cob.is_valid() && cob.id().is_none() {
            result = result.and(Err(PdoError::Communication {
                index: ci,
                sub: 1,
                code: AbortCode::INVALID_VALUE,
            }));
        }
        if present && !ttype_ok {
            result = result.and(Err(PdoError::Communication {
                index: ci,
                sub: 2,
                code: AbortCode::INVALID_VALUE,
            }));
        }
        let runnable = present && ttype_ok && cob.is_valid();
        let plan = plan.ok();
        let id = if runnable && plan.is_some() {
            cob.id()
        } else {
            None
        };
        match dir {
            Direction::Rx => {
                self.rpdos[n] = Rpdo {
                    cob,
                    ttype,
                    deadline: Duration::from_millis(read_u(od, ci, 5, 0)),
                    plan,
                    id,
                    buffered: None,
                    due: None,
                };
                self.sync_rx_pending.retain(|&p| usize::from(p) != n);
            }
            Direction::Tx => {
                let was_running = self.tpdos[n].id.is_some();
                self.tpdos[n] = Tpdo {
                    cob,
                    ttype,
                    inhibit: Duration::from_micros(read_u(od, ci, 3, 0) * 100),
                    event_timer: Duration::from_millis(read_u(od, ci, 5, 0)),
                    sync_start: read_u(od, ci, 6, 0) as u8,
                    plan,
                    id,
                    ..Tpdo::default()
                };
                if self.operational {
                    // A PDO that starts running sends its current values once, as on
                    // entering OPERATIONAL; a parameter change of a running PDO does not.
                    self.start_tpdo(n, now, !was_running);
                }
            }
        }
        result
    }

    /// Rebuilds the lookup tables and work lists after a configuration change.
    fn reindex(&mut self) {
        self.rx_index.clear();
        self.timed_rx.clear();
        for (n, r) in self.rpdos.iter().enumerate() {
            if let Some(id) = r.id {
                self.rx_index.push((key(id), n as u16));
                if !r.deadline.is_zero() {
                    self.timed_rx.push(n as u16);
                }
            }
        }
        self.tx_index.clear();
        self.sync_tx.clear();
        self.async_tx.clear();
        for (n, t) in self.tpdos.iter().enumerate() {
            if let Some(id) = t.id {
                self.tx_index.push((key(id), n as u16));
                if t.is_async() {
                    self.async_tx.push(n as u16);
                } else {
                    self.sync_tx.push(n as u16);
                }
            }
        }
        // Two PDOs on one identifier: the lower slot wins, as a lookup must pick one.
        self.rx_index.sort_unstable();
        self.rx_index.dedup_by_key(|e| e.0);
        self.tx_index.sort_unstable();
        self.tx_index.dedup_by_key(|e| e.0);
    }

    fn start_tpdo(&mut self, n: usize, now: Instant, initial_event: bool) {
        let t = &mut self.tpdos[n];
        t.sync_left = t.ttype;
        t.wait_start = t.sync_start != 0;
        t.event = initial_event && t.is_event_driven();
        t.inhibit_until = Instant::ZERO;
        t.timer_due =
            (t.is_event_driven() && !t.event_timer.is_zero()).then(|| now + t.event_timer);
        t.sampled = None;
    }

    /// Whether the engine runs (the device is OPERATIONAL).
    pub fn is_operational(&self) -> bool {
        self.operational
    }

    /// The NMT state changed: PDOs run only in OPERATIONAL (CiA 301 §7.3.2.2). Entering it
    /// restarts every PDO (see the module documentation); leaving it stops them.
    pub fn set_operational(&mut self, operational: bool, now: Instant) {
        if operational == self.operational {
            return;
        }
        self.operational = operational;
        for r in &mut self.rpdos {
            r.buffered = None;
            r.due = None;
        }
        self.sync_rx_pending.clear();
        for n in 0..self.tpdos.len() {
            if operational {
                self.start_tpdo(n, now, true);
            } else {
                let t = &mut self.tpdos[n];
                t.event = false;
                t.timer_due = None;
                t.sampled = None;
            }
        }
    }

    /// Number of RPDO slots (communication objects 0x1400..).
    pub fn rpdo_slots(&self) -> usize {
        self.rpdos.len()
    }

    /// Number of TPDO slots (communication objects 0x1800..).
    pub fn tpdo_slots(&self) -> usize {
        self.tpdos.len()
    }

    /// Whether RPDO slot `n` exists, is valid and has a runnable mapping.
    pub fn rpdo_active(&self, n: usize) -> bool {
        self.rpdos.get(n).is_some_and(|r| r.id.is_some())
    }

    /// Whether TPDO slot `n` exists, is valid and has a runnable mapping.
    pub fn tpdo_active(&self, n: usize) -> bool {
        self.tpdos.get(n).is_some_and(|t| t.id.is_some())
    }

    /// The identifiers [`PdoEngine::on_frame`] reacts to: every runnable RPDO's (its data)
    /// and every runnable TPDO's (a remote request for it, §7.2.2.3). A frame on any other
    /// identifier leaves the engine as it was, so a device may filter the others out.
    pub fn cob_ids(&self) -> impl Iterator<Item = Id> + '_ {
        let rx = self.rpdos.iter().filter_map(|r| r.id);
        let tx = self.tpdos.iter().filter_map(|t| t.id);
        rx.chain(tx)
    }

    /// The next event the device should report, oldest first.
    pub fn poll_event(&mut self) -> Option<PdoEvent> {
        self.events.pop_front()
    }

    /// An application event on TPDO slot `n`: sent at the next SYNC for type 0, at once
    /// (or when its inhibit time ends) for types 254/255, on the next
    /// [`PdoEngine::on_tick`]. Other types ignore it.
    pub fn trigger_tpdo(&mut self, n: usize) {
        if !self.operational {
            return;
        }
        if let Some(t) = self.tpdos.get_mut(n)
            && t.id.is_some()
            && (t.ttype == 0 || t.is_event_driven())
        {
            t.event = true;
        }
    }

    /// The device changed the value of `index`/`sub`: an application event for every
    /// TPDO of type 0, 254 or 255 that maps it (CiA 301 §7.2.2.4, change of state).
    pub fn mark_changed(&mut self, index: u16, sub: u8) {
        let Ok(id) = self.desc.locate(index, sub) else {
            return;
        };
        for n in 0..self.tpdos.len() {
            if self.tpdos[n].plan.as_ref().is_some_and(|p| p.maps(id)) {
                self.trigger_tpdo(n);
            }
        }
    }

    /// Packs a TPDO (or takes the data sampled for it) and queues it.
    #[inline]
    fn transmit<H: OdHooks + ?Sized>(
        t: &mut Tpdo,
        data: Option<[u8; 8]>,
        od: &ObjectDictionary,
        hooks: &mut H,
        now: Instant,
        out: &mut Outbox,
    ) {
        let (Some(id), Some(plan)) = (t.id, t.plan.as_ref()) else {
            return;
        };
        let bytes = data.unwrap_or_else(|| plan.pack(od, hooks));
        if let Ok(f) = Frame::data(id, &bytes[..plan.len()]) {
            out.push(f);
        }
        t.event = false;
        t.inhibit_until = now + t.inhibit;
        if t.is_event_driven() && !t.event_timer.is_zero() {
            t.timer_due = Some(now + t.event_timer);
        }
    }

    /// A SYNC with its counter (if 0x1019 makes SYNCs carry one) at `now`: synchronous
    /// RPDO data received since the last SYNC are written to the dictionary, then
    /// synchronous TPDOs are sampled and sent (CiA 301 §7.2.2.4, §7.2.5).
    pub fn on_sync<H: OdHooks + ?Sized>(
        &mut self,
        counter: Option<u8>,
        now: Instant,
        od: &mut ObjectDictionary,
        hooks: &mut H,
        out: &mut Outbox,
    ) {
        if !self.operational {
            return;
        }
        for i in 0..self.sync_rx_pending.len() {
            let n = usize::from(self.sync_rx_pending[i]);
            let r = &mut self.rpdos[n];
            if let (Some(data), Some(plan)) = (r.buffered.take(), r.plan.as_ref()) {
                let e = received(n, plan.unpack(&data, od, hooks));
                push_event(&mut self.events, e);
            }
        }
        self.sync_rx_pending.clear();
        for &n in &self.sync_tx {
            let t = &mut self.tpdos[usize::from(n)];
            match t.ttype {
                0 => {
                    if t.event {
                        Self::transmit(t, None, od, hooks, now, out);
                    }
                }
                1..=240 => {
                    if t.wait_start {
                        // §7.5.2.35 sub 6: with a SYNC counter, the first transmission is on
                        // the SYNC whose counter equals the start value. SYNCs without a
                        // counter ignore it.
                        match counter {
                            Some(c) if c != t.sync_start => continue,
                            Some(_) => {
                                t.wait_start = false;
                                t.sync_left = t.ttype;
                                Self::transmit(t, None, od, hooks, now, out);
                                continue;
                            }
                            None => t.wait_start = false,
                        }
                    }
                    t.sync_left = t.sync_left.saturating_sub(1);
                    if t.sync_left == 0 {
                        t.sync_left = t.ttype;
                        Self::transmit(t, None, od, hooks, now, out);
                    }
                }
                _ => {
                    // 252: sample now, send on request.
                    if let Some(plan) = &t.plan {
                        t.sampled = Some(plan.pack(od, hooks));
                    }
                }
            }
        }
    }

    /// A frame from the bus. RPDO data are checked for length and written to the
    /// dictionary (types 254/255) or kept for the next SYNC (types 0..=240); a remote
    /// frame on a TPDO is answered. Returns whether the frame was one of this engine's PDOs.
    pub fn on_frame<H: OdHooks + ?Sized>(
        &mut self,
        frame: &Frame,
        now: Instant,
        od: &mut ObjectDictionary,
        hooks: &mut H,
        out: &mut Outbox,
    ) -> bool {
        if frame.is_remote() {
            let Some(n) = lookup(&self.tx_index, frame.id()) else {
                return false;
            };
            if !self.operational {
                return true;
            }
            let t = &mut self.tpdos[n];
            if !t.cob.rtr_allowed() {
                return true;
            }
            match t.ttype {
                252 => {
                    if let Some(data) = t.sampled {
                        Self::transmit(t, Some(data), od, hooks, now, out);
                    }
                }
                253..=255 => {
                    if now >= t.inhibit_until {
                        Self::transmit(t, None, od, hooks, now, out);
                    } else {
                        t.event = true;
                    }
                }
                _ => {}
            }
            return true;
        }
        let Some(n) = lookup(&self.rx_index, frame.id()) else {
            return false;
        };
        if !self.operational {
            return true;
        }
        let r = &mut self.rpdos[n];
        let Some(plan) = r.plan.as_ref() else {
            return true;
        };
        let len = frame.len();
        let mapped = plan.len();
        if len < mapped || (len > mapped && !self.excess_processed) {
            push_event(
                &mut self.events,
                PdoEvent::LengthError {
                    rpdo: n as u16,
                    emcy: EMCY_PDO_LENGTH,
                    len: len as u8,
                },
            );
            return true;
        }
        if !r.deadline.is_zero() {
            r.due = Some(now + r.deadline);
        }
        let applied = if r.ttype <= 240 {
            let mut data = [0u8; 8];
            data[..len].copy_from_slice(frame.data_bytes());
            if r.buffered.replace(data).is_none() {
                self.sync_rx_pending.push(n as u16);
            }
            None
        } else {
            Some(plan.unpack(frame.data_bytes(), od, hooks))
        };
        if len > mapped {
            push_event(
                &mut self.events,
                PdoEvent::LengthError {
                    rpdo: n as u16,
                    emcy: EMCY_PDO_LENGTH_EXCEEDED,
                    len: len as u8,
                },
            );
        }
        if let Some(result) = applied {
            push_event(&mut self.events, received(n, result));
        }
        true
    }

    /// Timers: event-driven TPDOs whose event or event timer is due and whose inhibit time
    /// is over are sent; expired RPDO deadlines are reported.
    pub fn on_tick<H: OdHooks + ?Sized>(
        &mut self,
        now: Instant,
        od: &ObjectDictionary,
        hooks: &mut H,
        out: &mut Outbox,
    ) {
        if !self.operational {
            return;
        }
        for &n in &self.async_tx {
            let t = &mut self.tpdos[usize::from(n)];
            if t.timer_due.is_some_and(|d| d <= now) {
                t.timer_due = None;
                t.event = t.is_event_driven();
            }
            if t.event && now >= t.inhibit_until {
                Self::transmit(t, None, od, hooks, now, out);
            }
        }
        for i in 0..self.timed_rx.len() {
            let n = usize::from(self.timed_rx[i]);
            let r = &mut self.rpdos[n];
            if r.due.is_some_and(|d| d <= now) {
                r.due = None;
                push_event(&mut self.events, PdoEvent::Timeout { rpdo: n as u16 });
            }
        }
    }

    /// When [`PdoEngine::on_tick`] is next needed.
    pub fn next_deadline(&self) -> Option<Instant> {
        if !self.operational {
            return None;
        }
        let tx = self.async_tx.iter().filter_map(|&n| {
            let t = &self.tpdos[usize::from(n)];
            let ev = t.event.then_some(t.inhibit_until);
            match (ev, t.timer_due) {
                (Some(a), Some(b)) => Some(a.min(b.max(t.inhibit_until))),
                (a, b) => a.or(b),
            }
        });
        let rx = self
            .timed_rx
            .iter()
            .filter_map(|&n| self.rpdos[usize::from(n)].due);
        tx.chain(rx).min()
    }

    /// One of the device's frames finished transmission at `now`: a TPDO's inhibit time
    /// counts from here.
    pub fn on_sent(&mut self, frame: &Frame, now: Instant) {
        if frame.is_remote() {
            return;
        }
        if let Some(n) = lookup(&self.tx_index, frame.id()) {
            let t = &mut self.tpdos[n];
            t.inhibit_until = now + t.inhibit;
        }
    }

    /// Checks a download to a PDO object (0x1400..=0x1BFF) against CiA 301 §7.5.2.35–38
    /// before it lands; other indices pass. `data` is the value as downloaded.
    pub fn validate_write(
        &self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        let Some(obj) = classify(index) else {
            return Ok(());
        };
        let v = le_value(data);
        // §7.5.2.35–38 forbid changing the entries of a valid PDO; a download of the value
        // an entry already holds (a configuration tool writing a DCF back) changes nothing.
        if od.get_unsigned(index, sub) == Some(u64::from(v)) {
            return Ok(());
        }
        match obj {
            PdoObject::Comm(dir, n) => {
                let cur = match dir {
                    Direction::Rx => self.rpdos.get(n).map(|r| r.cob),
                    Direction::Tx => self.tpdos.get(n).map(|t| t.cob),
                }
                .unwrap_or(CobId(CobId::INVALID));
                match sub {
                    1 => {
                        // §7.5.2.35, §7.5.2.37: the stack's one rule for COB-ID entries
                        // (restricted CAN-IDs, frame bits, no change of the identifier of
                        // a valid PDO: set bit 31 first).
                        let entry = match dir {
                            Direction::Rx => cob_id::Entry::Rpdo,
                            Direction::Tx => cob_id::Entry::Tpdo,
                        };
                        cob_id::check(entry, cur.0, v)?;
                        if !CobId(v).is_valid() {
                            return Ok(());
                        }
                        // A PDO whose stored mapping is invalid cannot be made valid until the
                        // mapping is repaired.
                        let mapped = match dir {
                            Direction::Rx => self.rpdos.get(n).map(|r| r.plan.is_some()),
                            Direction::Tx => self.tpdos.get(n).map(|t| t.plan.is_some()),
                        };
                        if mapped == Some(false) {
                            return Err(AbortCode::PARAMETER_INCOMPATIBLE);
                        }
                        Ok(())
                    }
                    2 => {
                        let ok = match dir {
                            Direction::Rx => v <= 240 || (254..=255).contains(&v),
                            Direction::Tx => v <= 240 || (252..=255).contains(&v),
                        };
                        if ok {
                            Ok(())
                        } else {
                            Err(AbortCode::INVALID_VALUE)
                        }
                    }
                    // Inhibit time and SYNC start value change only while the PDO is invalid.
                    3 | 6 if cur.is_valid() => Err(AbortCode::INVALID_VALUE),
                    6 if v > 240 => Err(AbortCode::INVALID_VALUE),
                    _ => Ok(()),
                }
            }
            PdoObject::Map(dir, n) => {
                // §7.5.2.36, §7.5.2.38: sub-index 0 counts the enabled entries. More than
                // the object holds (or than 64) is a mapping longer than the PDO can have,
                // 0x06040042, in any state: the value is out of the object's range before
                // the state matters.
                let mut entries = [MapEntry::from_u32(0); MAX_ENTRIES as usize];
                if sub == 0 {
                    if v > u32::from(MAX_ENTRIES) {
                        return Err(AbortCode::PDO_LENGTH_EXCEEDED);
                    }
                    for (i, e) in entries.iter_mut().take(v as usize).enumerate() {
                        let raw = od
                            .get_unsigned(index, i as u8 + 1)
                            .ok_or(AbortCode::PDO_LENGTH_EXCEEDED)?;
                        *e = MapEntry::from_u32(raw as u32);
                    }
                }
                let valid = match dir {
                    Direction::Rx => self.rpdos.get(n).is_some_and(|r| r.cob.is_valid()),
                    Direction::Tx => self.tpdos.get(n).is_some_and(|t| t.cob.is_valid()),
                };
                if valid {
                    return Err(AbortCode::UNSUPPORTED_ACCESS);
                }
                if sub == 0 {
                    Plan::build(
                        od.description(),
                        dir,
                        self.dummy_mapping,
                        entries[..v as usize].iter().copied(),
                    )
                    .map(|_| ())
                } else {
                    if read_u(od, index, 0, 0) != 0 {
                        return Err(AbortCode::UNSUPPORTED_ACCESS);
                    }
                    let e = MapEntry::from_u32(v);
                    // A cleared entry is allowed: it is checked when enabled.
                    if v == 0 {
                        return Ok(());
                    }
                    if u32::from(e.bits) > MAX_PDO_BITS {
                        return Err(AbortCode::PDO_LENGTH_EXCEEDED);
                    }
                    check_entry(od.description(), dir, self.dummy_mapping, e).map(|_| ())
                }
            }
        }
    }

    /// A download to `index`/`sub` landed in the dictionary at `now`: the PDO it belongs to
    /// is reloaded (and restarted if the device is OPERATIONAL).
    pub fn after_write(&mut self, od: &ObjectDictionary, index: u16, sub: u8, now: Instant) {
        let _ = sub;
        let Some(obj) = classify(index) else {
            return;
        };
        let (dir, n) = match obj {
            PdoObject::Comm(d, n) | PdoObject::Map(d, n) => (d, n),
        };
        let in_range = match dir {
            Direction::Rx => n < self.rpdos.len(),
            Direction::Tx => n < self.tpdos.len(),
        };
        if !in_range {
            return;
        }
        // Validation ran before the write, so the reloaded PDO is runnable or invalid.
        let _ = self.load_pdo(od, dir, n, now);
        self.reindex();
    }

    /// The engine as [`OdHooks`] for the PDO objects, for writes arriving at `now`:
    /// `Hooked::new(&mut od, &mut engine.hooks(now))`.
    pub fn hooks(&mut self, now: Instant) -> PdoHooks<'_> {
        PdoHooks { engine: self, now }
    }
}

/// [`PdoEngine::validate_write`] and [`PdoEngine::after_write`] as [`OdHooks`]; see
/// [`PdoEngine::hooks`].
#[derive(Debug)]
pub struct PdoHooks<'a> {
    engine: &'a mut PdoEngine,
    now: Instant,
}

impl OdHooks for PdoHooks<'_> {
    fn validate(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        self.engine.validate_write(od, index, sub, data)
    }

    fn written(&mut self, od: &mut ObjectDictionary, index: u16, sub: u8) {
        self.engine.after_write(od, index, sub, self.now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cob_id_bits() {
        let c = CobId(0x4000_0185);
        assert!(c.is_valid());
        assert!(!c.rtr_allowed());
        assert_eq!(c.id(), Some(Id::standard(0x185).unwrap()));
        assert_eq!(CobId(0x0000_0985).id(), None);
        assert_eq!(CobId(0x2000_0985).id(), Some(Id::extended(0x985).unwrap()));
        assert!(!CobId(0x8000_0185).is_valid());
    }
}
