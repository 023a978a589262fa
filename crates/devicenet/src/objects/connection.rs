//! Connection object (class 0x05, DeviceNet Vol. 1 §5): one instance per connection,
//! with its state, identifiers, sizes, expected packet rate and inactivity watchdog.
//!
//! Instance 1 is the predefined explicit messaging connection, instance 2 the polled I/O
//! connection; explicit connections opened through the UCMM get instances from
//! [`crate::SlaveConfig::ucmm_first_instance`] on.

use super::{AttrDef, CipError, Reply, attribute_service, exact_len, get, get_set};
use crate::fragment::{ExplicitReassembler, ExplicitSender, IoReassembler};
use crate::wire::{BodyFormat, DnId, MacId, Request, service, status};
use cantwin_can::{Duration, Instant};

/// Class 0x05.
pub const CLASS: u16 = 0x05;

/// Watchdog timeout action "transition to timed out" (I/O default).
pub const WATCHDOG_TIMED_OUT: u8 = 0;
/// Watchdog timeout action "auto delete" (explicit default).
pub const WATCHDOG_AUTO_DELETE: u8 = 1;
/// Watchdog timeout action "auto reset".
pub const WATCHDOG_AUTO_RESET: u8 = 2;

/// Connection instance state (attribute 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConnState {
    /// Allocated, waiting for its expected packet rate.
    Configuring,
    /// Exchanging messages.
    Established,
    /// The inactivity watchdog expired.
    TimedOut,
}

impl ConnState {
    /// Attribute 1 value.
    pub const fn code(self) -> u8 {
        match self {
            ConnState::Configuring => 1,
            ConnState::Established => 3,
            ConnState::TimedOut => 4,
        }
    }
}

/// Explicit messaging or polled I/O.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConnKind {
    /// Explicit messaging (server, transport class 3).
    Explicit,
    /// Polled I/O (server, transport class 2).
    Polled,
}

/// One connection instance.
#[derive(Debug, Clone)]
pub struct Connection {
    /// Connection object instance ID.
    pub instance: u16,
    /// Explicit or polled.
    pub kind: ConnKind,
    /// State.
    pub state: ConnState,
    /// Identifier the slave produces on.
    pub produced_id: DnId,
    /// Identifier the slave consumes.
    pub consumed_id: DnId,
    /// Attribute 6: initial communication characteristics.
    pub initial_comm: u8,
    /// Attribute 7: produced connection size in bytes.
    pub produced_size: u16,
    /// Attribute 8: consumed connection size in bytes.
    pub consumed_size: u16,
    /// Attribute 9: expected packet rate in ms (0 = no watchdog).
    pub epr_ms: u16,
    /// Attribute 12: watchdog timeout action.
    pub watchdog_action: u8,
    /// When the connection last consumed a message.
    pub last_activity: Instant,
    /// The client (master) at the other end.
    pub peer: MacId,
    /// Message body format of an explicit connection.
    pub format: BodyFormat,
    /// Explicit fragment reassembly.
    pub rx: ExplicitReassembler,
    /// Explicit fragmented response in flight.
    pub tx: Option<ExplicitSender>,
    /// I/O fragment reassembly.
    pub io_rx: IoReassembler,
    /// The last poll command was empty (master idle).
    pub idle: bool,
}

impl Connection {
    /// A connection in `state` with defaults for its kind.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        instance: u16,
        kind: ConnKind,
        peer: MacId,
        produced_id: DnId,
        consumed_id: DnId,
        initial_comm: u8,
        sizes: (u16, u16),
        epr_ms: u16,
        now: Instant,
    ) -> Connection {
        let (state, watchdog_action) = match kind {
            ConnKind::Explicit => (ConnState::Established, WATCHDOG_AUTO_DELETE),
            ConnKind::Polled => (ConnState::Configuring, WATCHDOG_TIMED_OUT),
        };
        Connection {
            instance,
            kind,
            state,
            produced_id,
            consumed_id,
            initial_comm,
            produced_size: sizes.0,
            consumed_size: sizes.1,
            epr_ms,
            watchdog_action,
            last_activity: now,
            peer,
            format: BodyFormat::F8_8,
            rx: ExplicitReassembler::new(usize::from(sizes.1)),
            tx: None,
            io_rx: IoReassembler::new(usize::from(sizes.1)),
            idle: false,
        }
    }

    /// The inactivity watchdog period: 4 × expected packet rate (DeviceNet Vol. 1,
    /// Connection object, "Expected Packet Rate"; Rockwell 1769-SDN user manual, "Expected
    /// Packet Rate": a device that receives nothing for four times the EPR drops the
    /// connection), or `None` when the rate is 0.
    pub fn watchdog_period(&self) -> Option<Duration> {
        (self.epr_ms > 0).then(|| Duration::from_millis(4 * u64::from(self.epr_ms)))
    }

    /// When the watchdog expires, while established.
    pub fn watchdog_deadline(&self) -> Option<Instant> {
        if self.state != ConnState::Established {
            return None;
        }
        self.watchdog_period().map(|p| self.last_activity + p)
    }

    /// Restart the inactivity watchdog.
    pub fn kick(&mut self, now: Instant) {
        self.last_activity = now;
    }

    fn attribute(&self, attr: u8) -> Vec<u8> {
        let u16le = |v: u16| v.to_le_bytes().to_vec();
        match attr {
            1 => vec![self.state.code()],
            2 => vec![u8::from(self.kind == ConnKind::Polled)],
            3 => vec![match self.kind {
                ConnKind::Explicit => 0x83,
                ConnKind::Polled => 0x82,
            }],
            4 => u16le(self.produced_id.raw()),
            5 => u16le(self.consumed_id.raw()),
            6 => vec![self.initial_comm],
            7 => u16le(self.produced_size),
            8 => u16le(self.consumed_size),
            9 => u16le(self.epr_ms),
            12 => vec![self.watchdog_action],
            // Paths (13–16) are empty: the device has no Assembly object. 17: no inhibit.
            14 | 16 => Vec::new(),
            _ => u16le(0),
        }
    }

    /// Serve a request to this instance. `resolution_ms` is the device's timer tick: an
    /// expected packet rate is rounded up to it and the Set reply carries the value
    /// actually used (as the I-7242D trace of a Set EPR shows: 0x0E0A → 0x0E10).
    pub fn serve(&mut self, req: &Request<'_>, resolution_ms: u16, now: Instant) -> Reply {
        // Reset restarts the inactivity timer and brings a timed-out connection back to
        // Established (as the Rockwell 1403-NDNET data tables describe the service).
        if req.service == service::RESET {
            if !req.data.is_empty() {
                return CipError::new(status::TOO_MUCH_DATA).into();
            }
            if self.state == ConnState::TimedOut {
                self.state = ConnState::Established;
            }
            self.kick(now);
            return Reply::Data(Vec::new());
        }
        const ATTRS: [AttrDef; 15] = [
            get(1),
            get(2),
            get(3),
            get(4),
            get(5),
            get(6),
            get(7),
            get(8),
            get_set(9),
            get_set(12),
            get(13),
            get(14),
            get(15),
            get(16),
            get(17),
        ];
        let snapshot = self.attribute_snapshot();
        attribute_service(
            req,
            &ATTRS,
            |a| snapshot.attribute(a),
            |a, d| self.set(a, d, resolution_ms, now),
        )
    }

    fn attribute_snapshot(&self) -> Snapshot {
        Snapshot((1..=17).map(|a| self.attribute(a)).collect::<Vec<_>>())
    }

    fn set(
        &mut self,
        attr: u8,
        data: &[u8],
        resolution_ms: u16,
        now: Instant,
    ) -> Result<Vec<u8>, CipError> {
        match attr {
            9 => {
                exact_len(data, 2)?;
                let want = u16::from_le_bytes([data[0], data[1]]);
                let res = resolution_ms.max(1);
                let actual = want.div_ceil(res).saturating_mul(res);
                self.epr_ms = actual;
                if self.state == ConnState::Configuring {
                    self.state = ConnState::Established;
                }
                self.kick(now);
                Ok(actual.to_le_bytes().to_vec())
            }
            _ => {
                exact_len(data, 1)?;
                let ok = match self.kind {
                    ConnKind::Polled => data[0] <= WATCHDOG_AUTO_RESET,
                    ConnKind::Explicit => data[0] == WATCHDOG_AUTO_DELETE,
                };
                if !ok {
                    return Err(CipError::new(status::INVALID_ATTRIBUTE_VALUE));
                }
                self.watchdog_action = data[0];
                Ok(Vec::new())
            }
        }
    }
}

struct Snapshot(Vec<Vec<u8>>);

impl Snapshot {
    fn attribute(&self, attr: u8) -> Vec<u8> {
        self.0
            .get(usize::from(attr).saturating_sub(1))
            .cloned()
            .unwrap_or_default()
    }
}
