//! One-line descriptions of DeviceNet frames: the identifier's group and message ID named by
//! the Predefined Master/Slave Connection Set, and explicit messages decoded down to the
//! service, class, instance and attribute (8-bit class and instance, the format the
//! predefined set opens with).

use cantwin_can::Frame;
use cantwin_devicenet::wire::{
    BodyFormat, DnId, ExplicitFrame, FragKind, Request, Response, service,
};

use crate::hex::hex_bytes;

fn service_name(code: u8) -> &'static str {
    match code {
        service::GET_ATTRIBUTES_ALL => "Get_Attributes_All",
        service::SET_ATTRIBUTES_ALL => "Set_Attributes_All",
        service::RESET => "Reset",
        service::GET_ATTRIBUTE_SINGLE => "Get_Attribute_Single",
        service::SET_ATTRIBUTE_SINGLE => "Set_Attribute_Single",
        service::ALLOCATE => "Allocate",
        service::RELEASE => "Release",
        service::DEVICE_HEARTBEAT => "Device_Heartbeat",
        service::DEVICE_SHUTDOWN => "Device_Shutdown",
        _ => "service",
    }
}

/// An explicit message body: a request (client → server) or a response.
fn explicit(data: &[u8], request: bool) -> String {
    match ExplicitFrame::decode(data) {
        Ok(ExplicitFrame::Whole { header, body }) => {
            let mac = header.mac;
            if request {
                match Request::decode(body, BodyFormat::F8_8) {
                    Ok(r) => {
                        let mut s = format!(
                            "{} (0x{:02X}) class 0x{:02X} instance {}",
                            service_name(r.service),
                            r.service,
                            r.class,
                            r.instance
                        );
                        match r.attribute() {
                            Some(a) => s.push_str(&format!(" attribute {a}")),
                            None if !r.data.is_empty() => {
                                s.push_str(&format!(" data {}", hex_bytes(r.data)));
                            }
                            None => {}
                        }
                        format!("{s} [MAC {mac}]")
                    }
                    Err(e) => format!("explicit request: {e}: {}", hex_bytes(body)),
                }
            } else {
                match Response::decode(body) {
                    Some(Response::Success { service, data }) => {
                        let data = if data.is_empty() {
                            "no data".to_string()
                        } else {
                            hex_bytes(data)
                        };
                        format!(
                            "{} (0x{service:02X}) response {data} [MAC {mac}]",
                            service_name(service)
                        )
                    }
                    Some(Response::Error {
                        general,
                        additional,
                    }) => format!(
                        "error response: general status 0x{general:02X}, additional code 0x{additional:02X} [MAC {mac}]"
                    ),
                    None => format!("explicit response: {}", hex_bytes(body)),
                }
            }
        }
        Ok(ExplicitFrame::Fragment { frag, data, .. }) => {
            let kind = match frag.kind {
                FragKind::First => "first",
                FragKind::Middle => "middle",
                FragKind::Last => "last",
                FragKind::Ack => "ack",
            };
            format!("{kind} fragment {}: {}", frag.count, hex_bytes(data))
        }
        Ok(ExplicitFrame::Ack { count, status, .. }) => {
            format!("fragment {count} acknowledged, status 0x{status:02X}")
        }
        Err(e) => e.to_string(),
    }
}

/// The MAC ID a DeviceNet frame's identifier carries (DeviceNet spec. vol. 3 §2-2.2: groups
/// 1 and 3 name the source MAC ID; group 2 names the slave's, source or destination by the
/// message ID); `None` for group 4 and invalid identifiers.
pub fn node_of(frame: &Frame) -> Option<u8> {
    match DnId::decode(frame.id()) {
        Ok(DnId::Group1 { mac, .. } | DnId::Group2 { mac, .. } | DnId::Group3 { mac, .. }) => {
            Some(mac.get())
        }
        Ok(DnId::Group4 { .. }) | Err(_) => None,
    }
}

/// One line for a DeviceNet frame.
pub fn describe(frame: &Frame) -> String {
    let d = frame.data_bytes();
    let raw = hex_bytes(d);
    match DnId::decode(frame.id()) {
        Ok(DnId::Group1 { msg, mac }) => {
            let what = match msg {
                0xC => "slave multicast-poll response",
                0xD => "slave change of state / cyclic",
                0xE => "slave bit-strobe response",
                0xF => "slave poll response / COS-cyclic acknowledge",
                _ => "group 1 message",
            };
            format!("G1 msg {msg} from MAC {mac}: {what}: {raw}")
        }
        Ok(DnId::Group2 { mac, msg }) => {
            let text = match msg {
                0 => format!("master bit-strobe command: {raw}"),
                1 => format!("master multicast poll: {raw}"),
                2 => format!("master change of state / cyclic acknowledge: {raw}"),
                3 => format!("slave explicit response: {}", explicit(d, false)),
                4 => format!("master explicit request: {}", explicit(d, true)),
                5 => format!("master poll command / COS / cyclic: {raw}"),
                6 => format!("unconnected explicit request: {}", explicit(d, true)),
                _ => format!("duplicate MAC ID check: {raw}"),
            };
            format!("G2 MAC {mac} msg {msg}: {text}")
        }
        Ok(DnId::Group3 { msg, mac }) => {
            let text = match msg {
                5 => format!("UCMM explicit response: {}", explicit(d, false)),
                6 => format!("UCMM explicit request: {}", explicit(d, true)),
                _ => format!("explicit message: {raw}"),
            };
            format!("G3 msg {msg} from MAC {mac}: {text}")
        }
        Ok(DnId::Group4 { msg }) => {
            let what = match msg {
                0x2C => "communication faulted response",
                0x2D => "communication faulted request",
                0x2E => "offline ownership response",
                0x2F => "offline ownership request",
                _ => "group 4 message",
            };
            format!("G4 msg 0x{msg:02X}: {what}: {raw}")
        }
        Err(e) => format!("{e}: {raw}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;

    fn f(id: u16, data: &[u8]) -> Frame {
        Frame::data(Id::standard(id).unwrap(), data).unwrap()
    }

    #[test]
    fn predefined_set_explicit_request_and_response() {
        // Get_Attribute_Single of Identity (class 1) instance 1 attribute 7 to MAC 5
        // (0x404 | 5 << 3), from master MAC 1.
        assert_eq!(
            describe(&f(0x42C, &[0x01, 0x0E, 0x01, 0x01, 0x07])),
            "G2 MAC 5 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 1]"
        );
        assert_eq!(
            describe(&f(0x42B, &[0x01, 0x8E, 0x41, 0x42])),
            "G2 MAC 5 msg 3: slave explicit response: Get_Attribute_Single (0x0E) response 41 42 [MAC 1]"
        );
        assert_eq!(
            describe(&f(0x42B, &[0x01, 0x94, 0x14, 0xFF])),
            "G2 MAC 5 msg 3: slave explicit response: error response: general status 0x14, additional code 0xFF [MAC 1]"
        );
        assert_eq!(
            describe(&f(0x3C5, &[0x10, 0x20])),
            "G1 msg 15 from MAC 5: slave poll response / COS-cyclic acknowledge: 10 20"
        );
        assert_eq!(
            describe(&f(0x7EF, &[])),
            "G4 msg 0x2F: offline ownership request: "
        );
    }
}
