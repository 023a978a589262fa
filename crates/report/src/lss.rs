//! One line for an LSS frame (CiA 305 §4): the master's requests on 0x7E5 and the slaves'
//! answers on 0x7E4, decoded with the protocol crate's stateless `lss::wire`.

use cantwin_can::Frame;
use cantwin_canopen::lss::wire::{
    self, FASTSCAN_CONFIRM, IdentifyField, MASTER_ID, Mode, Part, Request, Response, SLAVE_ID,
};

use crate::hex::hex_bytes;

fn part_name(p: Part) -> &'static str {
    match p {
        Part::Vendor => "vendor-ID",
        Part::Product => "product code",
        Part::Revision => "revision number",
        Part::Serial => "serial number",
    }
}

fn field_name(f: IdentifyField) -> &'static str {
    match f {
        IdentifyField::Vendor => "vendor-ID",
        IdentifyField::Product => "product code",
        IdentifyField::RevisionLow => "revision number low",
        IdentifyField::RevisionHigh => "revision number high",
        IdentifyField::SerialLow => "serial number low",
        IdentifyField::SerialHigh => "serial number high",
    }
}

/// The bit timing a configure bit timing request names (CiA 305 §4.4.2 table 4).
fn bit_timing(table: u8, index: u8) -> String {
    match (table, wire::bit_rate_of(index)) {
        (0, Some(rate)) => format!("{} kbit/s", rate.bits_per_second() / 1000),
        (0, None) if index == 9 => "automatic bit rate detection".to_string(),
        (0, None) => format!("reserved table index {index}"),
        (1..=127, _) => format!("reserved table {table} index {index}"),
        _ => format!("manufacturer table {table} index {index}"),
    }
}

/// The result of a configure or store answer: 0 success, 0xFF manufacturer-specific with
/// its own code, others as the service's clause lists them (`meaning`).
fn outcome(error: u8, spec: u8, meaning: &str) -> String {
    match error {
        0 => "success".to_string(),
        0xFF => format!("manufacturer-specific error {spec:#04X}"),
        _ => format!("error {error}: {meaning}"),
    }
}

fn request(r: Request) -> String {
    match r {
        Request::SwitchGlobal(Mode::Waiting) => "switch state global: waiting".to_string(),
        Request::SwitchGlobal(Mode::Configuration) => {
            "switch state global: configuration".to_string()
        }
        Request::SwitchSelective(p, v) => {
            format!("switch state selective {} 0x{v:08X}", part_name(p))
        }
        Request::ConfigureNodeId(n) if n == wire::UNCONFIGURED => {
            "configure node-ID 0xFF (not configured)".to_string()
        }
        Request::ConfigureNodeId(n) => format!("configure node-ID {n}"),
        Request::ConfigureBitTiming { table, index } => {
            format!("configure bit timing {}", bit_timing(table, index))
        }
        Request::ActivateBitTiming { delay_ms } => {
            format!("activate bit timing, switch delay {delay_ms} ms")
        }
        Request::StoreConfiguration => "store configuration".to_string(),
        Request::IdentifyRemote(f, v) => {
            format!("identify remote slave {} 0x{v:08X}", field_name(f))
        }
        Request::IdentifyNonConfigured => "identify non-configured remote slave".to_string(),
        Request::Fastscan {
            bit_check: FASTSCAN_CONFIRM,
            ..
        } => "fastscan: reset (every non-configured slave answers)".to_string(),
        Request::Fastscan {
            id_number,
            bit_check,
            sub,
            next,
        } => format!(
            "fastscan {} 0x{id_number:08X} bits {bit_check}-31, next {}",
            Part::at(sub).map_or("?", part_name),
            Part::at(next).map_or("?", part_name)
        ),
        Request::Inquire(p) => format!("inquire {}", part_name(p)),
        Request::InquireNodeId => "inquire node-ID".to_string(),
    }
}

fn response(r: Response) -> String {
    match r {
        Response::SwitchSelective => "switch state selective: in configuration".to_string(),
        Response::ConfigureNodeId { error, spec } => format!(
            "configure node-ID: {}",
            outcome(error, spec, "node-ID out of range")
        ),
        Response::ConfigureBitTiming { error, spec } => format!(
            "configure bit timing: {}",
            outcome(error, spec, "bit timing not supported")
        ),
        Response::StoreConfiguration { error, spec } => format!(
            "store configuration: {}",
            outcome(
                error,
                spec,
                if error == 1 {
                    "store not supported"
                } else {
                    "storage media access error"
                }
            )
        ),
        Response::IdentifySlave => "identify slave".to_string(),
        Response::NonConfiguredSlave => "identify non-configured slave".to_string(),
        Response::Address(p, v) => format!("{} 0x{v:08X}", part_name(p)),
        Response::NodeId(n) if n == wire::UNCONFIGURED => {
            "node-ID 0xFF (not configured)".to_string()
        }
        Response::NodeId(n) => format!("node-ID {n}"),
    }
}

/// One line for `frame` if it is on an LSS identifier (0x7E5 master, 0x7E4 slave), `None`
/// for any other frame. A frame on those identifiers that is no LSS message (another length,
/// an unknown command specifier) is named as such with its bytes.
pub fn describe(frame: &Frame) -> Option<String> {
    if frame.is_extended() || frame.is_remote() {
        return None;
    }
    let id = frame.id().as_raw();
    if id == u32::from(MASTER_ID) {
        Some(match Request::decode(frame) {
            Ok(r) => format!("LSS master: {}", request(r)),
            Err(e) => format!("LSS master ({e}): {}", hex_bytes(frame.data_bytes())),
        })
    } else if id == u32::from(SLAVE_ID) {
        Some(match Response::decode(frame) {
            Ok(r) => format!("LSS slave: {}", response(r)),
            Err(e) => format!("LSS slave ({e}): {}", hex_bytes(frame.data_bytes())),
        })
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use cantwin_can::{BitRate, Id};

    use super::*;

    #[test]
    fn cia305_services_are_named() {
        let cases = [
            (
                Request::SwitchGlobal(Mode::Configuration).encode(),
                "LSS master: switch state global: configuration",
            ),
            (
                Request::SwitchSelective(Part::Vendor, 0x0000_0093).encode(),
                "LSS master: switch state selective vendor-ID 0x00000093",
            ),
            (
                Request::ConfigureNodeId(12).encode(),
                "LSS master: configure node-ID 12",
            ),
            (
                Request::ConfigureBitTiming {
                    table: 0,
                    index: wire::table_index_of(BitRate::R250K).unwrap(),
                }
                .encode(),
                "LSS master: configure bit timing 250 kbit/s",
            ),
            (
                Request::ActivateBitTiming { delay_ms: 100 }.encode(),
                "LSS master: activate bit timing, switch delay 100 ms",
            ),
            (
                Request::Fastscan {
                    id_number: 0,
                    bit_check: FASTSCAN_CONFIRM,
                    sub: 0,
                    next: 0,
                }
                .encode(),
                "LSS master: fastscan: reset (every non-configured slave answers)",
            ),
            (
                Response::ConfigureNodeId { error: 1, spec: 0 }.encode(),
                "LSS slave: configure node-ID: error 1: node-ID out of range",
            ),
            (
                Response::StoreConfiguration { error: 0, spec: 0 }.encode(),
                "LSS slave: store configuration: success",
            ),
            (
                Response::Address(Part::Serial, 0x1234).encode(),
                "LSS slave: serial number 0x00001234",
            ),
            (
                Response::NodeId(wire::UNCONFIGURED).encode(),
                "LSS slave: node-ID 0xFF (not configured)",
            ),
        ];
        for (frame, text) in cases {
            assert_eq!(describe(&frame).as_deref(), Some(text), "{frame}");
        }
    }

    #[test]
    fn frames_on_lss_identifiers_that_are_no_lss_message_say_why() {
        let short = Frame::data(Id::standard(0x7E5).unwrap(), &[0x11, 5]).unwrap();
        assert_eq!(
            describe(&short).unwrap(),
            "LSS master (LSS frames carry 8 data bytes, not 2): 11 05"
        );
        let unknown =
            Frame::data(Id::standard(0x7E4).unwrap(), &[0x99, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert!(
            describe(&unknown)
                .unwrap()
                .starts_with("LSS slave (unknown LSS command specifier 0x99)")
        );
        let other = Frame::data(Id::standard(0x7E3).unwrap(), &[0; 8]).unwrap();
        assert_eq!(describe(&other), None);
    }
}
