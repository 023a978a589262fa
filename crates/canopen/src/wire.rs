//! CANopen frames as typed messages (CiA 301 §7.2): decode and encode, nothing else.
//!
//! One type per service: [`NmtCommand`] (§7.2.8.3.1), [`ErrorControl`] (boot-up,
//! heartbeat and node-guarding responses, §7.2.8.3.2), [`Sync`] (§7.2.5), [`Time`]
//! (§7.2.6) and [`Emcy`] (§7.2.7). [`decode`] classifies any frame by the pre-defined
//! connection set (§7.3.4, table 70) so that the trace decoder and the fuzz targets use the
//! same code as the device.

use crate::od::TimeOfDay;
use cantwin_can::{Frame, Id};

/// The COB-ID of the NMT module control service.
pub const NMT_COB_ID: u16 = 0x000;
/// The default COB-ID of SYNC.
pub const SYNC_COB_ID: u16 = 0x080;
/// The default COB-ID of TIME.
pub const TIME_COB_ID: u16 = 0x100;
/// The base of the default EMCY COB-IDs (0x080 + node-ID).
pub const EMCY_BASE: u16 = 0x080;
/// The base of the NMT error-control COB-IDs (0x700 + node-ID).
pub const ERROR_CONTROL_BASE: u16 = 0x700;
/// The base of the default SDO server → client COB-IDs (0x580 + node-ID).
pub const SDO_TX_BASE: u16 = 0x580;
/// The base of the default SDO client → server COB-IDs (0x600 + node-ID).
pub const SDO_RX_BASE: u16 = 0x600;

/// A frame that is not a valid message of the service its identifier belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// The data length does not fit the service.
    #[error("{service} frame with {len} data bytes")]
    Length {
        /// The service.
        service: &'static str,
        /// The data length (or the DLC of a remote frame).
        len: u8,
    },
    /// A remote frame where a data frame is expected (or the other way round).
    #[error("{0}: unexpected remote/data frame type")]
    FrameType(&'static str),
    /// An NMT command specifier CiA 301 does not define.
    #[error("unknown NMT command specifier {0:#04X}")]
    UnknownNmtCommand(u8),
    /// A node-ID above 127.
    #[error("node-ID {0} is above 127")]
    NodeId(u8),
}

fn std_id(raw: u16) -> Id {
    // Callers pass 0x000..=0x7FF (fixed COB-IDs plus a node-ID of at most 127).
    Id::standard(raw & 0x7FF).unwrap_or(Id::Standard(cantwin_can::StandardId::MAX))
}

/// The NMT state a node reports in its error-control messages (CiA 301 §7.2.8.3.2,
/// table 51). The byte values are the wire encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum NmtState {
    /// Boot-up (only in the boot-up message).
    BootUp = 0x00,
    /// Stopped.
    Stopped = 0x04,
    /// Operational.
    Operational = 0x05,
    /// Pre-operational.
    PreOperational = 0x7F,
}

impl NmtState {
    /// The state with this 7-bit code, if CiA 301 defines it.
    pub const fn from_u8(v: u8) -> Option<NmtState> {
        match v {
            0x00 => Some(NmtState::BootUp),
            0x04 => Some(NmtState::Stopped),
            0x05 => Some(NmtState::Operational),
            0x7F => Some(NmtState::PreOperational),
            _ => None,
        }
    }
}

/// An NMT module control command specifier (CiA 301 §7.2.8.3.1, table 50).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum NmtCs {
    /// Start remote node (cs 1).
    Start = 0x01,
    /// Stop remote node (cs 2).
    Stop = 0x02,
    /// Enter pre-operational (cs 128).
    EnterPreOperational = 0x80,
    /// Reset node (cs 129).
    ResetNode = 0x81,
    /// Reset communication (cs 130).
    ResetCommunication = 0x82,
}

impl NmtCs {
    /// The command with this specifier.
    pub const fn from_u8(v: u8) -> Option<NmtCs> {
        match v {
            0x01 => Some(NmtCs::Start),
            0x02 => Some(NmtCs::Stop),
            0x80 => Some(NmtCs::EnterPreOperational),
            0x81 => Some(NmtCs::ResetNode),
            0x82 => Some(NmtCs::ResetCommunication),
            _ => None,
        }
    }
}

/// An NMT module control message on COB-ID 0: 2 bytes, command specifier and node-ID
/// (0 addresses all nodes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct NmtCommand {
    /// The command.
    pub cs: NmtCs,
    /// The addressed node, 0 for all.
    pub node: u8,
}

impl NmtCommand {
    /// Whether the command addresses the node `node_id` (directly or as a broadcast).
    pub const fn addresses(&self, node_id: u8) -> bool {
        self.node == 0 || self.node == node_id
    }

    /// Decodes a frame on COB-ID 0. CiA 301 fixes the length at 2 bytes.
    pub fn decode(frame: &Frame) -> Result<NmtCommand, WireError> {
        if frame.is_remote() {
            return Err(WireError::FrameType("NMT"));
        }
        let [cs, node] = frame.data_bytes() else {
            return Err(WireError::Length {
                service: "NMT",
                len: frame.dlc(),
            });
        };
        let cs = NmtCs::from_u8(*cs).ok_or(WireError::UnknownNmtCommand(*cs))?;
        if *node > 127 {
            return Err(WireError::NodeId(*node));
        }
        Ok(NmtCommand { cs, node: *node })
    }

    /// The frame on COB-ID 0.
    pub fn encode(&self) -> Frame {
        Frame::data_array(std_id(NMT_COB_ID), [self.cs as u8, self.node])
    }
}

/// A message on the NMT error-control COB-ID 0x700 + node-ID (CiA 301 §7.2.8.3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorControl {
    /// The node-guarding remote frame a master sends.
    GuardRequest {
        /// The guarded node.
        node: u8,
    },
    /// A one-byte state report: a boot-up message (state 0), a heartbeat (toggle 0) or a
    /// node-guarding response (toggle alternating).
    State {
        /// The reporting node.
        node: u8,
        /// Bit 7: the node-guarding toggle bit.
        toggle: bool,
        /// Bits 0..6: the state code (table 51); kept raw so that unknown codes are traced.
        state: u8,
    },
}

impl ErrorControl {
    /// The boot-up message of `node` (§7.2.8.3.2.4: one byte 0x00).
    pub const fn boot_up(node: u8) -> ErrorControl {
        ErrorControl::State {
            node,
            toggle: false,
            state: 0,
        }
    }

    /// A heartbeat of `node` in `state` (toggle bit 0).
    pub const fn heartbeat(node: u8, state: NmtState) -> ErrorControl {
        ErrorControl::State {
            node,
            toggle: false,
            state: state as u8,
        }
    }

    /// Decodes a frame on 0x700 + `node` (node-ID 1..=127 is the caller's check).
    pub fn decode(frame: &Frame, node: u8) -> Result<ErrorControl, WireError> {
        if frame.is_remote() {
            // Masters send the guarding RTR with DLC 1; CiA 301 does not make the DLC
            // part of the protocol, so any DLC is accepted.
            return Ok(ErrorControl::GuardRequest { node });
        }
        let [b] = frame.data_bytes() else {
            return Err(WireError::Length {
                service: "NMT error control",
                len: frame.dlc(),
            });
        };
        Ok(ErrorControl::State {
            node,
            toggle: b & 0x80 != 0,
            state: b & 0x7F,
        })
    }

    /// The frame on 0x700 + node-ID.
    pub fn encode(&self) -> Frame {
        match *self {
            ErrorControl::GuardRequest { node } => {
                // A DLC of 0 would request zero bytes; masters ask for the one byte answer.
                Frame::remote(std_id(ERROR_CONTROL_BASE + u16::from(node & 0x7F)), 1)
                    .unwrap_or_else(|_| Frame::data_array(std_id(ERROR_CONTROL_BASE), []))
            }
            ErrorControl::State {
                node,
                toggle,
                state,
            } => Frame::data_array(
                std_id(ERROR_CONTROL_BASE + u16::from(node & 0x7F)),
                [(u8::from(toggle) << 7) | (state & 0x7F)],
            ),
        }
    }
}

/// A SYNC message (CiA 301 §7.2.5): no data, or one counter byte (1..=240).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Sync {
    /// The counter, when the producer has a counter overflow value (0x1019) above 1.
    pub counter: Option<u8>,
}

impl Sync {
    /// Decodes a frame on the SYNC COB-ID. Lengths other than 0 and 1 are errors (the
    /// consumer answers them with EMCY 0x8240, §7.2.5.2.1).
    pub fn decode(frame: &Frame) -> Result<Sync, WireError> {
        if frame.is_remote() {
            return Err(WireError::FrameType("SYNC"));
        }
        match frame.data_bytes() {
            [] => Ok(Sync { counter: None }),
            [c] => Ok(Sync { counter: Some(*c) }),
            _ => Err(WireError::Length {
                service: "SYNC",
                len: frame.dlc(),
            }),
        }
    }

    /// The frame on `id`.
    pub fn encode(&self, id: Id) -> Frame {
        match self.counter {
            None => Frame::data_array(id, []),
            Some(c) => Frame::data_array(id, [c]),
        }
    }
}

/// A TIME message (CiA 301 §7.2.6): a 6-byte TIME_OF_DAY.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Time(pub TimeOfDay);

impl Time {
    /// Decodes a frame on the TIME COB-ID.
    pub fn decode(frame: &Frame) -> Result<Time, WireError> {
        if frame.is_remote() {
            return Err(WireError::FrameType("TIME"));
        }
        let b: [u8; 6] = frame
            .data_bytes()
            .try_into()
            .map_err(|_| WireError::Length {
                service: "TIME",
                len: frame.dlc(),
            })?;
        Ok(Time(TimeOfDay::from_le_bytes(b)))
    }

    /// The frame on `id`.
    pub fn encode(&self, id: Id) -> Frame {
        Frame::data_array(id, self.0.to_le_bytes())
    }
}

/// An EMCY message (CiA 301 §7.2.7.3.1): error code, error register (0x1001) and five
/// manufacturer-specific bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Emcy {
    /// The emergency error code (table 21); 0x0000 is "error reset or no error".
    pub code: u16,
    /// The error register at the time of the event.
    pub register: u8,
    /// Manufacturer-specific error code.
    pub manufacturer: [u8; 5],
}

impl Emcy {
    /// Decodes an EMCY frame (8 data bytes).
    pub fn decode(frame: &Frame) -> Result<Emcy, WireError> {
        if frame.is_remote() {
            return Err(WireError::FrameType("EMCY"));
        }
        let [c0, c1, reg, m0, m1, m2, m3, m4] = frame.data_bytes() else {
            return Err(WireError::Length {
                service: "EMCY",
                len: frame.dlc(),
            });
        };
        Ok(Emcy {
            code: u16::from_le_bytes([*c0, *c1]),
            register: *reg,
            manufacturer: [*m0, *m1, *m2, *m3, *m4],
        })
    }

    /// The frame on `id`.
    pub fn encode(&self, id: Id) -> Frame {
        let c = self.code.to_le_bytes();
        let m = self.manufacturer;
        Frame::data_array(
            id,
            [c[0], c[1], self.register, m[0], m[1], m[2], m[3], m[4]],
        )
    }
}

/// A COB-ID entry of a communication object (0x1005, 0x1012, 0x1014, 0x1028, 0x1200..,
/// 0x1400.., 0x1800..): bit 31 and bit 30 are service flags, bit 29 selects the 29-bit
/// format, the rest is the CAN identifier (CiA 301 §7.5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CobId(pub u32);

impl Default for CobId {
    /// Not valid: bit 31 set, identifier 0.
    fn default() -> Self {
        CobId(0x8000_0000)
    }
}

impl CobId {
    /// Bit 31.
    pub const fn bit31(self) -> bool {
        self.0 & (1 << 31) != 0
    }
    /// Bit 30.
    pub const fn bit30(self) -> bool {
        self.0 & (1 << 30) != 0
    }
    /// Bit 29: 29-bit identifier.
    pub const fn extended(self) -> bool {
        self.0 & (1 << 29) != 0
    }
    /// The identifier bits (0..=28), without the flags.
    pub const fn raw_id(self) -> u32 {
        self.0 & 0x1FFF_FFFF
    }
    /// The CAN identifier: 29 bits with bit 29 set, else the low 11 bits.
    pub fn can_id(self) -> Id {
        if self.extended() {
            Id::extended(self.raw_id()).unwrap_or(Id::Extended(cantwin_can::ExtendedId::MAX))
        } else {
            std_id((self.0 & 0x7FF) as u16)
        }
    }
    /// Whether the identifier part (bits 0..=29) differs from `other`'s.
    pub const fn id_differs(self, other: CobId) -> bool {
        (self.0 ^ other.0) & 0x3FFF_FFFF != 0
    }
}

/// Which PDO of the pre-defined connection set a COB-ID belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PdoKind {
    /// TPDO 1..=4 of the node (0x180/0x280/0x380/0x480 + node-ID).
    Transmit(u8),
    /// RPDO 1..=4 of the node (0x200/0x300/0x400/0x500 + node-ID).
    Receive(u8),
}

/// Any CANopen frame classified by the pre-defined connection set (CiA 301 §7.3.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// NMT module control (COB-ID 0x000).
    Nmt(NmtCommand),
    /// SYNC (COB-ID 0x080).
    Sync(Sync),
    /// EMCY of node 1..=127 (0x080 + node-ID).
    Emcy {
        /// The producing node.
        node: u8,
        /// The message.
        emcy: Emcy,
    },
    /// TIME (COB-ID 0x100).
    Time(Time),
    /// A default-COB-ID PDO; the data is left to the PDO mapping.
    Pdo {
        /// Which PDO.
        kind: PdoKind,
        /// The node-ID part of the COB-ID.
        node: u8,
        /// The frame.
        frame: Frame,
    },
    /// SDO client → server (0x600 + node-ID); decode the bytes with the SDO codec.
    SdoRequest {
        /// The server's node-ID.
        node: u8,
        /// The 8 bytes (shorter frames padded with zeros; see `len`).
        data: [u8; 8],
        /// The data length on the wire (CiA 301 requires 8).
        len: u8,
    },
    /// SDO server → client (0x580 + node-ID).
    SdoResponse {
        /// The server's node-ID.
        node: u8,
        /// The 8 bytes (shorter frames padded with zeros; see `len`).
        data: [u8; 8],
        /// The data length on the wire.
        len: u8,
    },
    /// NMT error control (0x700 + node-ID): boot-up, heartbeat, guarding.
    ErrorControl(ErrorControl),
    /// A frame on a pre-defined COB-ID that does not decode as its service.
    Malformed {
        /// The frame.
        frame: Frame,
        /// What is wrong with it.
        error: WireError,
    },
    /// A frame outside the pre-defined connection set (extended frames, LSS, reserved
    /// identifiers, node-ID 0 in node-specific ranges).
    Other(Frame),
}

impl Message {
    /// The SDO request of an [`Message::SdoRequest`], decoded with the SDO codec
    /// ([`crate::sdo::wire::Request`]). Block download segments carry no command specifier
    /// and decode only with the state of the transfer, so they come out as whatever their
    /// first byte resembles; `None` for other messages and frames shorter than 8 bytes.
    pub fn sdo_request(
        &self,
    ) -> Option<Result<crate::sdo::wire::Request, crate::sdo::wire::WireError>> {
        match self {
            Message::SdoRequest { data, len: 8, .. } => {
                Some(crate::sdo::wire::Request::decode(data))
            }
            _ => None,
        }
    }

    /// The SDO response of an [`Message::SdoResponse`], decoded with the SDO codec.
    pub fn sdo_response(
        &self,
    ) -> Option<Result<crate::sdo::wire::Response, crate::sdo::wire::WireError>> {
        match self {
            Message::SdoResponse { data, len: 8, .. } => {
                Some(crate::sdo::wire::Response::decode(data))
            }
            _ => None,
        }
    }
}

/// Classifies a frame by the pre-defined connection set and decodes it.
pub fn decode(frame: &Frame) -> Message {
    let Id::Standard(sid) = frame.id() else {
        return Message::Other(*frame);
    };
    let raw = sid.as_raw();
    let function = raw >> 7;
    let node = (raw & 0x7F) as u8;
    let malformed = |error| Message::Malformed {
        frame: *frame,
        error,
    };
    let sdo = || {
        let mut data = [0u8; 8];
        let b = frame.data_bytes();
        data[..b.len()].copy_from_slice(b);
        (data, frame.len() as u8)
    };
    match (function, node) {
        (0x0, 0) => NmtCommand::decode(frame).map_or_else(malformed, Message::Nmt),
        (0x1, 0) => Sync::decode(frame).map_or_else(malformed, Message::Sync),
        (0x1, n) => {
            Emcy::decode(frame).map_or_else(malformed, |emcy| Message::Emcy { node: n, emcy })
        }
        (0x2, 0) => Time::decode(frame).map_or_else(malformed, Message::Time),
        (0x3..=0xA, n) if n != 0 => {
            let k = (function - 1) / 2;
            let kind = if function % 2 == 1 {
                PdoKind::Transmit(k as u8)
            } else {
                PdoKind::Receive(k as u8)
            };
            Message::Pdo {
                kind,
                node: n,
                frame: *frame,
            }
        }
        (0xB, n) | (0xC, n) if n != 0 => {
            if frame.is_remote() {
                return malformed(WireError::FrameType("SDO"));
            }
            let (data, len) = sdo();
            if function == 0xB {
                Message::SdoResponse { node: n, data, len }
            } else {
                Message::SdoRequest { node: n, data, len }
            }
        }
        (0xE, n) if n != 0 => {
            ErrorControl::decode(frame, n).map_or_else(malformed, Message::ErrorControl)
        }
        _ => Message::Other(*frame),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(s: &str) -> Frame {
        let (id, data) = s.split_once('#').unwrap();
        let id = Id::standard(u16::from_str_radix(id, 16).unwrap()).unwrap();
        if let Some(r) = data.strip_prefix('R') {
            return Frame::remote(id, r.parse().unwrap_or(0)).unwrap();
        }
        let bytes: Vec<u8> = (0..data.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&data[i..i + 2], 16).unwrap())
            .collect();
        Frame::data(id, &bytes).unwrap()
    }

    #[test]
    fn cia301_7_2_8_3_1_nmt_commands_round_trip() {
        for (text, cs, node) in [
            ("000#0105", NmtCs::Start, 5),
            ("000#0200", NmtCs::Stop, 0),
            ("000#807F", NmtCs::EnterPreOperational, 127),
            ("000#8101", NmtCs::ResetNode, 1),
            ("000#8201", NmtCs::ResetCommunication, 1),
        ] {
            let frame = f(text);
            assert_eq!(decode(&frame), Message::Nmt(NmtCommand { cs, node }));
            assert_eq!(NmtCommand { cs, node }.encode(), frame);
        }
        assert!(matches!(
            decode(&f("000#0305")),
            Message::Malformed {
                error: WireError::UnknownNmtCommand(3),
                ..
            }
        ));
        assert!(matches!(decode(&f("000#01")), Message::Malformed { .. }));
        assert!(matches!(
            decode(&f("000#0180")),
            Message::Malformed {
                error: WireError::NodeId(0x80),
                ..
            }
        ));
    }

    #[test]
    fn cia301_7_2_8_3_2_error_control_frames() {
        assert_eq!(ErrorControl::boot_up(5).encode(), f("705#00"));
        assert_eq!(
            ErrorControl::heartbeat(5, NmtState::Operational).encode(),
            f("705#05")
        );
        assert_eq!(
            ErrorControl::State {
                node: 5,
                toggle: true,
                state: 0x7F
            }
            .encode(),
            f("705#FF")
        );
        assert_eq!(
            decode(&f("705#R1")),
            Message::ErrorControl(ErrorControl::GuardRequest { node: 5 })
        );
        assert_eq!(ErrorControl::GuardRequest { node: 5 }.encode(), f("705#R1"));
        assert_eq!(
            decode(&f("77F#84")),
            Message::ErrorControl(ErrorControl::State {
                node: 127,
                toggle: true,
                state: 4
            })
        );
        assert!(matches!(decode(&f("705#0000")), Message::Malformed { .. }));
    }

    #[test]
    fn cia301_7_2_5_sync_with_and_without_counter() {
        assert_eq!(decode(&f("080#")), Message::Sync(Sync { counter: None }));
        assert_eq!(
            decode(&f("080#F0")),
            Message::Sync(Sync { counter: Some(240) })
        );
        assert!(matches!(decode(&f("080#0102")), Message::Malformed { .. }));
        let id = Id::standard(0x80).unwrap();
        assert_eq!(Sync { counter: Some(3) }.encode(id), f("080#03"));
    }

    #[test]
    fn cia301_7_2_6_time_of_day_is_six_bytes() {
        let t = Time(TimeOfDay {
            ms: 0x0123_4567,
            days: 0x89AB,
        });
        let frame = t.encode(Id::standard(0x100).unwrap());
        assert_eq!(frame, f("100#67452301AB89"));
        assert_eq!(decode(&frame), Message::Time(t));
        assert!(matches!(decode(&f("100#0102")), Message::Malformed { .. }));
    }

    #[test]
    fn cia301_7_2_7_3_1_emcy_layout() {
        let e = Emcy {
            code: 0x8130,
            register: 0x11,
            manufacturer: [1, 2, 3, 4, 5],
        };
        let frame = e.encode(Id::standard(0x85).unwrap());
        assert_eq!(frame, f("085#3081110102030405"));
        assert_eq!(decode(&frame), Message::Emcy { node: 5, emcy: e });
        assert!(matches!(decode(&f("085#3081")), Message::Malformed { .. }));
    }

    #[test]
    fn cia301_7_3_4_predefined_connection_set() {
        let d = |s| decode(&f(s));
        assert!(matches!(
            d("181#01"),
            Message::Pdo {
                kind: PdoKind::Transmit(1),
                node: 1,
                ..
            }
        ));
        assert!(matches!(
            d("201#01"),
            Message::Pdo {
                kind: PdoKind::Receive(1),
                ..
            }
        ));
        assert!(matches!(
            d("4FF#"),
            Message::Pdo {
                kind: PdoKind::Transmit(4),
                node: 127,
                ..
            }
        ));
        assert!(matches!(
            d("57F#"),
            Message::Pdo {
                kind: PdoKind::Receive(4),
                ..
            }
        ));
        assert!(matches!(
            d("605#4000100000000000"),
            Message::SdoRequest {
                node: 5,
                len: 8,
                ..
            }
        ));
        assert!(matches!(
            d("585#4300100092010000"),
            Message::SdoResponse { node: 5, .. }
        ));
        let req = d("605#4000100000000000").sdo_request();
        assert!(matches!(
            req,
            Some(Ok(crate::sdo::wire::Request::InitiateUpload { .. }))
        ));
        assert!(d("605#40").sdo_request().is_none());
        assert!(matches!(
            d("585#4300100092010000").sdo_response(),
            Some(Ok(_))
        ));
        assert!(d("585#4300100092010000").sdo_request().is_none());
        assert!(matches!(d("7E5#"), Message::Other(_)));
        assert!(matches!(d("180#"), Message::Other(_)));
    }

    #[test]
    fn cob_id_fields() {
        let c = CobId(0xC000_0085);
        assert!(c.bit31() && c.bit30() && !c.extended());
        assert_eq!(c.can_id(), Id::standard(0x85).unwrap());
        assert!(!c.id_differs(CobId(0x0000_0085)));
        assert!(c.id_differs(CobId(0x0000_0086)));
        assert_eq!(CobId(0x2000_1234).can_id(), Id::extended(0x1234).unwrap());
    }
}
