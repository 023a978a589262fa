//! What the monitor knows about one node, and the indicator states CiA 303-3 derives from
//! it.

use std::fmt;

use cantwin_can::{Duration, Instant};
use cantwin_canopen::wire::NmtState;
use cantwin_report::canopen::{emcy_meaning, state_name};

use crate::kind::{DeviceKind, LiveValue};

/// An emergency message as seen on the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EmcyEvent {
    /// When it was seen.
    pub at: Instant,
    /// The emergency error code (CiA 301 §7.2.7.1, table 21).
    pub code: u16,
    /// The error register (0x1001) sent with it.
    pub register: u8,
    /// The manufacturer-specific bytes.
    pub manufacturer: [u8; 5],
}

impl EmcyEvent {
    /// The generic meaning of the code, CiA 301 table 21 (shared with `cantwin trace` and
    /// the capture report); see [`NodeInfo::emcy_meaning`] for the device's own.
    pub fn meaning(&self) -> &'static str {
        emcy_meaning(self.code)
    }
}

/// The identity object 0x1018, as far as SDO answers on the bus showed it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Identity {
    /// Sub 1: vendor-ID.
    pub vendor_id: Option<u32>,
    /// Sub 2: product code.
    pub product_code: Option<u32>,
    /// Sub 3: revision number.
    pub revision: Option<u32>,
    /// Sub 4: serial number.
    pub serial: Option<u32>,
}

/// The state of an indicator (CiA 303-3 §2: LED states and flash rates).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Led {
    /// Constantly off.
    Off,
    /// Constantly on.
    On,
    /// Blinking: 200 ms on, 200 ms off.
    Blinking,
    /// Single flash: 200 ms on, 1000 ms off.
    SingleFlash,
    /// Double flash: two 200 ms flashes, then 1000 ms off.
    DoubleFlash,
    /// Not observable from the bus (the node fell silent).
    Unknown,
}

impl Led {
    /// A short word for tables.
    pub fn name(self) -> &'static str {
        match self {
            Led::Off => "off",
            Led::On => "on",
            Led::Blinking => "blinking",
            Led::SingleFlash => "single flash",
            Led::DoubleFlash => "double flash",
            Led::Unknown => "?",
        }
    }

    /// Whether the LED is lit at `t` of its cycle (for drawing it): blinking has a 400 ms
    /// period, the flashes a 1200/1600 ms one (CiA 303-3 §2).
    pub fn lit_at(self, t: Instant) -> bool {
        let ms = t.as_nanos() / 1_000_000;
        match self {
            Led::Off | Led::Unknown => false,
            Led::On => true,
            Led::Blinking => ms % 400 < 200,
            Led::SingleFlash => ms % 1200 < 200,
            Led::DoubleFlash => {
                let p = ms % 1600;
                p < 200 || (400..600).contains(&p)
            }
        }
    }
}

impl fmt::Display for Led {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The two indicators of a CANopen device (CiA 303-3 §3): the green RUN LED and the red
/// ERROR LED.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Leds {
    /// RUN (green): the NMT state.
    pub run: Led,
    /// ERROR (red): the CAN and error control condition.
    pub err: Led,
}

/// Everything the monitor knows about one node.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeInfo {
    /// The node-ID.
    pub id: u8,
    /// A name given by the front end (the scenario's device name).
    pub name: Option<String>,
    /// The kind of device, given or identified from 0x1000/0x1008.
    pub kind: Option<DeviceKind>,
    /// Whether `kind` was given rather than identified (a given kind is never replaced).
    pub kind_given: bool,
    /// Manufacturer device name (0x1008) from an SDO transfer on the bus.
    pub device_name: Option<String>,
    /// Device type (0x1000) from an SDO transfer on the bus.
    pub device_type: Option<u32>,
    /// Identity (0x1018) from SDO transfers on the bus.
    pub identity: Identity,
    /// The last NMT state code reported by boot-up, heartbeat or node guarding, or, for a
    /// node that reports none after it, the state an NMT command put it in.
    pub state: Option<u8>,
    /// Whether `state` comes from an NMT command rather than from the node itself: a node
    /// without heartbeat or node guarding (CiA 301 §7.2.8.3.2) tells nothing of its state, and
    /// the command is the best knowledge (§7.3.2.2.1, the NMT state machine).
    pub state_commanded: bool,
    /// When the last heartbeat/boot-up/guarding answer was seen.
    pub last_heartbeat: Option<Instant>,
    /// The gap between the last two heartbeats (the producer's period, as observed).
    pub heartbeat_period: Option<Duration>,
    /// Boot-up messages seen.
    pub boot_ups: u32,
    /// The error register, from EMCY or an SDO read of 0x1001.
    pub error_register: Option<u8>,
    /// The last EMCY other than an error reset.
    pub last_emcy: Option<EmcyEvent>,
    /// Whether the last EMCY is still in force (no error reset or clear register since).
    pub emcy_active: bool,
    /// EMCY messages seen.
    pub emcy_count: u32,
    /// Frames about this node (see [`crate::filter::node_of`]).
    pub frames: u64,
    /// Values decoded from its PDOs, in the kind's field order, with when they came.
    pub values: Vec<(LiveValue, Instant)>,
    /// Whether its state reports answer node guarding requests (CiA 301 §7.2.8.3.2.1)
    /// rather than being heartbeats (§7.2.8.3.2.2).
    pub guarded: bool,
}

impl NodeInfo {
    /// A node nothing is known about yet.
    pub fn new(id: u8) -> NodeInfo {
        NodeInfo {
            id,
            name: None,
            kind: None,
            kind_given: false,
            device_name: None,
            device_type: None,
            identity: Identity::default(),
            state: None,
            state_commanded: false,
            last_heartbeat: None,
            heartbeat_period: None,
            boot_ups: 0,
            error_register: None,
            last_emcy: None,
            emcy_active: false,
            emcy_count: 0,
            frames: 0,
            values: Vec::new(),
            guarded: false,
        }
    }

    /// The NMT state, if the last report was a state CiA 301 defines. A boot-up message
    /// is sent on entering pre-operational (CiA 301 §7.2.8.2.2.1), so it reads as that.
    pub fn nmt(&self) -> Option<NmtState> {
        match NmtState::from_u8(self.state?)? {
            NmtState::BootUp => Some(NmtState::PreOperational),
            s => Some(s),
        }
    }

    /// The NMT state's name (`operational`, `unknown state`), or `-` if none was seen.
    pub fn state_name(&self) -> &'static str {
        match (self.state, self.nmt()) {
            (None, _) => "-",
            (Some(_), Some(s)) => state_name(s as u8),
            (Some(code), None) => state_name(code),
        }
    }

    /// How long ago the last heartbeat was, at `now`.
    pub fn heartbeat_age(&self, now: Instant) -> Option<Duration> {
        self.last_heartbeat
            .map(|t| Duration::from_nanos(now.as_nanos().saturating_sub(t.as_nanos())))
    }

    /// Whether the node's heartbeat stopped: more than twice its observed period has passed
    /// since the last one (a monitor's rule of thumb; a consumer uses its own 0x1016 time).
    pub fn heartbeat_lost(&self, now: Instant) -> bool {
        match (self.heartbeat_age(now), self.heartbeat_period) {
            (Some(age), Some(period)) if !period.is_zero() => {
                age.as_nanos() > period.as_nanos().saturating_mul(2)
            }
            _ => false,
        }
    }

    /// What kind of device it is, for a table: the kind's name, else the device profile its
    /// device type names (0x1000 bits 0–15, CiA 301 §7.5.2.1: 0 is a device without a
    /// profile, a plain CiA 301 device), else nothing.
    pub fn kind_label(&self) -> Option<String> {
        if let Some(k) = &self.kind {
            return Some(k.name.clone());
        }
        match self.device_type? & 0xFFFF {
            0 => Some("CiA 301".to_string()),
            profile => Some(format!("CiA {profile}")),
        }
    }

    /// Its error control service: `node guarding` once it answered a guard request,
    /// `heartbeat` once it sent a state report otherwise, `None` before.
    pub fn error_control(&self) -> Option<&'static str> {
        match (self.state, self.guarded) {
            (None, _) => None,
            (Some(_), true) => Some("node guarding"),
            (Some(_), false) => Some("heartbeat"),
        }
    }

    /// The name to show: the given name, else the device name, else the kind.
    pub fn display_name(&self) -> &str {
        self.name
            .as_deref()
            .or(self.device_name.as_deref())
            .or(self.kind.as_ref().map(|k| k.name.as_str()))
            .unwrap_or("")
    }

    /// The LED states CiA 303-3 §3 prescribes for what the bus shows of this node at `now`.
    ///
    /// RUN: on in operational, blinking in pre-operational, single flash in stopped. ERROR:
    /// single flash while an EMCY 0x8120 (error passive: an error counter reached the
    /// warning level) is in force, double flash for 0x8130 (a guarding or heartbeat
    /// consumer event), otherwise off — other error codes have no CiA 303-3 indication and
    /// show in the error register. Both are unknown once the heartbeat is lost or before
    /// any state was seen (RUN only).
    pub fn leds(&self, now: Instant) -> Leds {
        if self.heartbeat_lost(now) {
            return Leds {
                run: Led::Unknown,
                err: Led::Unknown,
            };
        }
        let run = match self.nmt() {
            Some(NmtState::Operational) => Led::On,
            Some(NmtState::PreOperational | NmtState::BootUp) => Led::Blinking,
            Some(NmtState::Stopped) => Led::SingleFlash,
            None => Led::Unknown,
        };
        let err = match (&self.last_emcy, self.emcy_active) {
            (Some(e), true) if e.code == 0x8120 => Led::SingleFlash,
            (Some(e), true) if e.code == 0x8130 => Led::DoubleFlash,
            _ => Led::Off,
        };
        Leds { run, err }
    }

    /// The meaning of the last EMCY: the kind's own for its code, else CiA 301 table 21's.
    pub fn emcy_meaning(&self) -> Option<&str> {
        let e = self.last_emcy.as_ref()?;
        Some(
            self.kind
                .as_ref()
                .and_then(|k| k.emcy_meaning(e.code))
                .unwrap_or_else(|| e.meaning()),
        )
    }

    /// The value named `name`, if a PDO carried it.
    pub fn value(&self, name: &str) -> Option<&LiveValue> {
        self.values.iter().map(|(v, _)| v).find(|v| v.name == name)
    }
}
