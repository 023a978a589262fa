//! One-line descriptions of CANopen frames and the meanings of EMCY codes, shared by the
//! live trace (`cantwin trace`) and the capture report; PDO decoders built from EDS files.

use std::sync::Arc;

use cantwin_can::Frame;
use cantwin_canopen::master::pdo::{PdoDecoder, PdoParams};
use cantwin_canopen::od::{ObjectDictionary, Value};
use cantwin_canopen::pdo::MapEntry;
use cantwin_canopen::sdo::wire::Response;
use cantwin_canopen::wire::{self, ErrorControl, Message};

/// Why an EDS could not be turned into PDO decoders.
#[derive(Debug, thiserror::Error)]
pub enum EdsError {
    /// The file is not a valid EDS/DCF.
    #[error("{0}")]
    Parse(#[from] cantwin_eds::ParseError),
    /// The EDS does not convert to an object dictionary.
    #[error("{0}")]
    Convert(#[from] cantwin_eds::ConvertError),
}

/// Meaning of an EMCY error code (CiA 301 §7.2.7.1, table 21), most specific first.
pub fn emcy_meaning(code: u16) -> &'static str {
    match code {
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard error or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8150 => "CAN-ID collision",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8230 => "DAM MPDO not processed, destination object not available",
        0x8240 => "unexpected SYNC data length",
        0x8250 => "RPDO timeout",
        // CiA 301 table 21: the whole 00xx range is "error reset or no error", 10xx generic.
        _ if code >> 8 == 0x00 => "error reset or no error",
        _ if code >> 8 == 0x10 => "generic error",
        _ => match code >> 12 {
            0x2 => "current",
            0x3 => "voltage",
            0x4 => "temperature",
            0x5 => "device hardware",
            0x6 => "device software",
            0x7 => "additional modules",
            0x8 => "monitoring",
            0x9 => "external error",
            0xF if code >> 8 == 0xFF => "device specific",
            0xF => "additional functions",
            _ => "unknown error code",
        },
    }
}

/// The name of an NMT state code (CiA 301 §7.2.8.3.2, table 51).
pub fn state_name(state: u8) -> &'static str {
    match state {
        0 => "boot-up",
        4 => "stopped",
        5 => "operational",
        127 => "pre-operational",
        _ => "unknown state",
    }
}

/// Adds to `decoder` the PDOs that the EDS/DCF `bytes` declares for `node`: their COB-IDs
/// (0x1400.. / 0x1800.. sub 1, with `$NODEID` resolved) and mappings (0x1600.. / 0x1A00..).
pub fn add_eds_pdos(decoder: &mut PdoDecoder, node: u8, bytes: &[u8]) -> Result<(), EdsError> {
    let eds = cantwin_eds::parse_bytes(bytes)?;
    let desc = Arc::new(cantwin_eds::to_od(&eds)?);
    let mut od = ObjectDictionary::new(desc, node);
    cantwin_eds::apply_parameter_values(&eds, &mut od)?;
    add_od_pdos(decoder, &od);
    Ok(())
}

/// Adds to `decoder` the PDOs an object dictionary holds now (a twin's, or one made from an
/// EDS): COB-IDs from 0x1400.. / 0x1800.. sub 1, mappings from 0x1600.. / 0x1A00...
pub fn add_od_pdos(decoder: &mut PdoDecoder, od: &ObjectDictionary) {
    let u32_of = |index, sub| match od.get(index, sub) {
        Ok(Value::Unsigned32(v)) => Some(v),
        _ => None,
    };
    let u8_of = |index, sub| match od.get(index, sub) {
        Ok(Value::Unsigned8(v)) => Some(v),
        _ => None,
    };
    // CiA 301 §7.5.2.35–38: RPDO communication/mapping at 0x1400/0x1600, TPDO at
    // 0x1800/0x1A00, 512 of each.
    for (comm_base, map_base) in [(0x1400u16, 0x1600u16), (0x1800, 0x1A00)] {
        for n in 0..512u16 {
            let (comm, map) = (comm_base + n, map_base + n);
            let Some(cob_id) = u32_of(comm, 1) else {
                continue;
            };
            let count = u8_of(map, 0).unwrap_or(0);
            let mapping: Vec<MapEntry> = (1..=count)
                .filter_map(|s| u32_of(map, s).map(MapEntry::from_u32))
                .collect();
            let params = PdoParams {
                cob_id,
                transmission_type: u8_of(comm, 2).unwrap_or(0),
                inhibit_time: None,
                event_timer: None,
                mapping,
            };
            decoder.add(&params, od.description().clone());
        }
    }
}

pub use crate::hex::hex_bytes;

/// The decoded values of a PDO `decoder` knows, as `name=value` pairs.
pub fn describe_pdo(frame: &Frame, pdos: &PdoDecoder) -> Option<String> {
    pdos.decode(frame).map(|values| match values {
        Ok(values) => {
            let parts: Vec<String> = values
                .iter()
                .map(|v| format!("{}={}", v.name, v.value))
                .collect();
            format!("PDO {}", parts.join(" "))
        }
        Err(e) => format!("PDO (cannot decode: {e})"),
    })
}

/// One line for an error control state report of `node` (CiA 301 §7.2.8.3.2): a boot-up
/// (state 0), a node guarding response (`guarded`: it answers a guard request; its bit 7 is
/// the toggle bit) or a heartbeat (bit 7 is reserved and 0: heartbeats have no toggle).
///
/// Alone, a frame tells a guarding response only by a set toggle bit; a decoder that saw the
/// guard request (the monitor, the capture report) passes `guarded` itself.
pub fn error_control(node: u8, state: u8, toggle: bool, guarded: bool) -> String {
    match (state, guarded) {
        (0, _) => format!("BOOT-UP node {node}"),
        (_, true) => format!(
            "NODE GUARD response node {node} {} (toggle {})",
            state_name(state),
            u8::from(toggle)
        ),
        (_, false) => format!("HEARTBEAT node {node} {}", state_name(state)),
    }
}

/// One line for a frame: the service and its decoded content (empty for frames outside
/// the pre-defined connection set that no PDO of `pdos` claims).
pub fn describe(frame: &Frame, pdos: &PdoDecoder) -> String {
    if let Some(text) = describe_pdo(frame, pdos) {
        return text;
    }
    let msg = wire::decode(frame);
    match msg {
        Message::Nmt(cmd) => {
            let target = if cmd.node == 0 {
                "all nodes".to_string()
            } else {
                format!("node {}", cmd.node)
            };
            format!("NMT {:?} {target}", cmd.cs)
        }
        Message::Sync(s) => match s.counter {
            Some(c) => format!("SYNC counter {c}"),
            None => "SYNC".to_string(),
        },
        Message::Emcy { node, emcy } => format!(
            "EMCY node {node} code 0x{:04X} ({}) register 0x{:02X} data {}",
            emcy.code,
            emcy_meaning(emcy.code),
            emcy.register,
            hex_bytes(&emcy.manufacturer)
        ),
        Message::Time(t) => format!("TIME {}", t.0),
        Message::Pdo { kind, node, .. } => format!("PDO {kind:?} node {node}"),
        Message::SdoRequest { node, .. } => match msg.sdo_request() {
            Some(Ok(r)) => format!("SDO request to node {node}: {r}"),
            _ => format!("SDO request to node {node} (segment or malformed)"),
        },
        Message::SdoResponse { node, .. } => match msg.sdo_response() {
            Some(Ok(Response::Abort { mux, code })) => format!(
                "SDO abort from node {node} {:#06X}sub{}: {code}",
                mux.index, mux.sub
            ),
            Some(Ok(r)) => format!("SDO response from node {node}: {r}"),
            _ => format!("SDO response from node {node} (segment or malformed)"),
        },
        Message::ErrorControl(ErrorControl::GuardRequest { node }) => {
            format!("NODE GUARD request node {node}")
        }
        Message::ErrorControl(ErrorControl::State {
            node,
            toggle,
            state,
        }) => error_control(node, state, toggle, toggle),
        Message::Malformed { error, .. } => {
            crate::lss::describe(frame).unwrap_or_else(|| format!("malformed: {error}"))
        }
        Message::Other(_) => crate::lss::describe(frame).unwrap_or_default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;

    #[test]
    fn cia301_table_21_emcy_meanings() {
        assert_eq!(emcy_meaning(0x8130), "life guard error or heartbeat error");
        assert_eq!(emcy_meaning(0x4210), "temperature");
        assert_eq!(emcy_meaning(0xFF01), "device specific");
        assert_eq!(emcy_meaning(0xF001), "additional functions");
        assert_eq!(emcy_meaning(0x0000), "error reset or no error");
        assert_eq!(emcy_meaning(0x0080), "error reset or no error");
        assert_eq!(emcy_meaning(0x1000), "generic error");
        assert_eq!(emcy_meaning(0x10FF), "generic error");
        assert_eq!(emcy_meaning(0x1100), "unknown error code");
    }

    #[test]
    fn sdo_frames_are_described_in_protocol_terms() {
        let none = PdoDecoder::new();
        let upload = Frame::data(
            Id::standard(0x605).unwrap(),
            &[0x40, 0x18, 0x10, 1, 0, 0, 0, 0],
        )
        .unwrap();
        assert_eq!(
            describe(&upload, &none),
            "SDO request to node 5: upload 0x1018sub1"
        );
        let answer = Frame::data(
            Id::standard(0x585).unwrap(),
            &[0x43, 0x18, 0x10, 1, 0x78, 0x56, 0x34, 0x12],
        )
        .unwrap();
        assert_eq!(
            describe(&answer, &none),
            "SDO response from node 5: upload 0x1018sub1: expedited [78 56 34 12]"
        );
    }

    #[test]
    fn describe_boot_up_and_heartbeat() {
        let none = PdoDecoder::new();
        let boot = Frame::data(Id::standard(0x705).unwrap(), &[0]).unwrap();
        assert_eq!(describe(&boot, &none), "BOOT-UP node 5");
        let hb = Frame::data(Id::standard(0x705).unwrap(), &[0x7F]).unwrap();
        assert_eq!(describe(&hb, &none), "HEARTBEAT node 5 pre-operational");
        // A set bit 7 is the guarding toggle (CiA 301 §7.2.8.3.2.1): heartbeats have none.
        let guard = Frame::data(Id::standard(0x705).unwrap(), &[0x85]).unwrap();
        assert_eq!(
            describe(&guard, &none),
            "NODE GUARD response node 5 operational (toggle 1)"
        );
        assert_eq!(
            error_control(5, 0x05, false, true),
            "NODE GUARD response node 5 operational (toggle 0)"
        );
    }
}
