//! One-line descriptions of DeviceNet frames: the identifier's group and message ID named by
//! the Predefined Master/Slave Connection Set, and explicit messages decoded down to the
//! service, class, instance and attribute. The widths of the class and instance fields are
//! the message body format the slave answered its Allocate request with (DeviceNet Vol. 1
//! §3-5, Allocate_Master/Slave_Connection_Set response: 8/8, 8/16, 16/16 or 16/8), learned
//! per MAC ID by [`BodyFormats`] from the exchanges it sees; 8/8, the format the predefined
//! set opens with, until then.

use std::collections::BTreeMap;

use cantwin_can::Frame;
use cantwin_devicenet::objects::devicenet::CLASS as DEVICENET_CLASS;
use cantwin_devicenet::wire::{
    Allocate, BodyFormat, DnId, DupMac, ExplicitFrame, FragKind, Request, Response, choice, group2,
    service,
};

use crate::hex::hex_bytes;

fn service_name(code: u8) -> &'static str {
    match code {
        service::GET_ATTRIBUTES_ALL => "Get_Attributes_All",
        service::SET_ATTRIBUTES_ALL => "Set_Attributes_All",
        service::RESET => "Reset",
        service::GET_ATTRIBUTE_SINGLE => "Get_Attribute_Single",
        service::SET_ATTRIBUTE_SINGLE => "Set_Attribute_Single",
        service::ALLOCATE => "Allocate_Master/Slave_Connection_Set",
        service::RELEASE => "Release_Master/Slave_Connection_Set",
        service::DEVICE_HEARTBEAT => "Device_Heartbeat",
        service::DEVICE_SHUTDOWN => "Device_Shutdown",
        _ => "service",
    }
}

/// The body format's name, class width / instance width in bits.
fn format_name(f: BodyFormat) -> &'static str {
    match f {
        BodyFormat::F8_8 => "8/8",
        BodyFormat::F8_16 => "8/16",
        BodyFormat::F16_16 => "16/16",
        BodyFormat::F16_8 => "16/8",
    }
}

/// The connections an allocation or release choice byte names (DeviceNet object attribute 5).
fn choice_names(c: u8) -> String {
    const NAMES: [(u8, &str); 7] = [
        (choice::EXPLICIT, "explicit"),
        (choice::POLLED, "polled"),
        (choice::BIT_STROBED, "bit-strobed"),
        (choice::MULTICAST_POLL, "multicast poll"),
        (choice::CHANGE_OF_STATE, "change of state"),
        (choice::CYCLIC, "cyclic"),
        (choice::ACK_SUPPRESSION, "acknowledge suppression"),
    ];
    let mut names: Vec<&str> = NAMES
        .iter()
        .filter(|(bit, _)| c & bit != 0)
        .map(|&(_, n)| n)
        .collect();
    if c & 0x80 != 0 {
        names.push("reserved bit 7");
    }
    if names.is_empty() {
        names.push("none");
    }
    format!("0x{c:02X} ({})", names.join(", "))
}

/// An Allocate or Release request the decoder saw and whose response it waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    Allocate(u8),
    Release(u8),
}

/// What the decoder knows of one slave's predefined master/slave connection set.
#[derive(Debug, Clone, Copy, Default)]
struct SlaveState {
    /// The explicit connection's message body format.
    format: BodyFormat,
    pending: Option<Pending>,
}

/// The message body format of each slave's explicit connection, by MAC ID, learned from the
/// Allocate_Master/Slave_Connection_Set exchanges of one bus (DeviceNet Vol. 1 §3-5: the
/// response's data byte, bits 3–0, is the actual body format). A slave not seen allocated
/// is decoded as 8/8. At most 64 entries, one per MAC ID.
#[derive(Debug, Clone, Default)]
pub struct BodyFormats {
    slaves: BTreeMap<u8, SlaveState>,
}

impl BodyFormats {
    /// No slave known: every explicit message decoded as 8/8.
    pub fn new() -> Self {
        Self::default()
    }

    /// The body format the explicit connection of slave `mac` is decoded with.
    pub fn format(&self, mac: u8) -> BodyFormat {
        self.slaves.get(&mac).map(|s| s.format).unwrap_or_default()
    }

    /// One line for a DeviceNet frame, learning from it: an Allocate request and its
    /// response set the slave's body format, a Release of the explicit connection and a
    /// duplicate MAC ID check request at the slave's MAC ID (a node coming on line, with no
    /// connection) return it to 8/8.
    pub fn describe(&mut self, frame: &Frame) -> String {
        let Ok(DnId::Group2 { mac, msg }) = DnId::decode(frame.id()) else {
            return describe(frame);
        };
        let slave = mac.get();
        let d = frame.data_bytes();
        // The format of the request is the one agreed before it (an Allocate's own answer
        // changes it for the requests after).
        let format = self.format(slave);
        match msg {
            group2::EXPLICIT_RESPONSE => self.learn_response(slave, d),
            group2::EXPLICIT_REQUEST => self.learn_request(slave, d, format),
            // The group 2 only unconnected port carries Allocate and Release only, in 8/8
            // (DeviceNet Vol. 1 §3-5: no format is agreed before the allocation).
            group2::UNCONNECTED_REQUEST => self.learn_request(slave, d, BodyFormat::F8_8),
            // A duplicate MAC ID check request: a node is coming on line at this MAC ID,
            // with no connection yet (DeviceNet Vol. 1 §6, network access). The response
            // comes from the node already there, whose connections stand.
            group2::DUP_MAC_CHECK if DupMac::decode(d).is_some_and(|m| !m.response) => {
                self.slaves.remove(&slave);
            }
            _ => {}
        }
        format!("G2 MAC {mac} msg {msg}: {}", group2_text(msg, d, format))
    }

    /// Remembers an Allocate or Release request to `slave`, for its response.
    fn learn_request(&mut self, slave: u8, data: &[u8], format: BodyFormat) {
        let Ok(ExplicitFrame::Whole { body, .. }) = ExplicitFrame::decode(data) else {
            return;
        };
        let Ok(r) = Request::decode(body, format) else {
            return;
        };
        let pending = match (r.service, r.class, r.instance, r.data.first()) {
            (service::ALLOCATE, DEVICENET_CLASS, 1, Some(&c)) => Pending::Allocate(c),
            (service::RELEASE, DEVICENET_CLASS, 1, Some(&c)) => Pending::Release(c),
            _ => return,
        };
        self.slaves.entry(slave).or_default().pending = Some(pending);
    }

    /// Learns from a slave's response to the Allocate or Release it answers.
    fn learn_response(&mut self, slave: u8, data: &[u8]) {
        let Ok(ExplicitFrame::Whole { body, .. }) = ExplicitFrame::decode(data) else {
            return;
        };
        let s = self.slaves.entry(slave).or_default();
        let pending = s.pending.take();
        match Response::decode(body) {
            Some(Response::Success { service, data }) if service == service::ALLOCATE => {
                // An allocation of I/O connections alone leaves the explicit connection as
                // it was; a response whose request was not seen is the only word there is
                // on the format, and is taken. A code outside 0–3 is decoded as 8/8, as
                // the scanner does.
                let io_only =
                    matches!(pending, Some(Pending::Allocate(c)) if c & choice::EXPLICIT == 0);
                if !io_only {
                    s.format = allocated_format(data).unwrap_or_default();
                }
            }
            Some(Response::Success { service, .. }) if service == service::RELEASE => {
                if matches!(pending, Some(Pending::Release(c)) if c & choice::EXPLICIT != 0) {
                    s.format = BodyFormat::F8_8;
                }
            }
            _ => {}
        }
    }
}

/// The body format an Allocate response's data grants (bits 3–0 of its first byte).
fn allocated_format(data: &[u8]) -> Option<BodyFormat> {
    data.first().and_then(|b| BodyFormat::from_code(b & 0x0F))
}

/// An explicit request body decoded in `format`.
fn request_text(body: &[u8], format: BodyFormat) -> String {
    let r = match Request::decode(body, format) {
        Ok(r) => r,
        Err(e) => return format!("explicit request: {e}: {}", hex_bytes(body)),
    };
    let mut s = format!(
        "{} (0x{:02X}) class 0x{:02X} instance {}",
        service_name(r.service),
        r.service,
        r.class,
        r.instance
    );
    let predefined_set = r.class == DEVICENET_CLASS && r.instance == 1;
    match r.service {
        // Allocate_Master/Slave_Connection_Set: [allocation choice][allocator's MAC ID].
        service::ALLOCATE if predefined_set && r.data.len() == 2 => {
            if let Some(a) = Allocate::decode(r.data) {
                s.push_str(&format!(
                    " allocation choice {} allocator MAC {}",
                    choice_names(a.choice),
                    a.allocator.get()
                ));
            }
        }
        // Release_Master/Slave_Connection_Set: [release choice].
        service::RELEASE if predefined_set && r.data.len() == 1 => {
            s.push_str(&format!(" release choice {}", choice_names(r.data[0])));
        }
        service::GET_ATTRIBUTE_SINGLE | service::SET_ATTRIBUTE_SINGLE if !r.data.is_empty() => {
            s.push_str(&format!(" attribute {}", r.data[0]));
            if r.data.len() > 1 {
                s.push_str(&format!(" data {}", hex_bytes(&r.data[1..])));
            }
        }
        _ if !r.data.is_empty() => s.push_str(&format!(" data {}", hex_bytes(r.data))),
        _ => {}
    }
    s
}

/// An explicit message: a request (client → server) decoded in `format`, or a response.
fn explicit(data: &[u8], request: bool, format: BodyFormat) -> String {
    match ExplicitFrame::decode(data) {
        Ok(ExplicitFrame::Whole { header, body }) => {
            let mac = header.mac;
            if request {
                return format!("{} [MAC {mac}]", request_text(body, format));
            }
            match Response::decode(body) {
                Some(Response::Success { service, data })
                    if service == service::ALLOCATE && data.len() == 1 =>
                {
                    let granted = match allocated_format(data) {
                        Some(f) => format!("message body format {}", format_name(f)),
                        None => format!("message body format code {}", data[0] & 0x0F),
                    };
                    format!(
                        "{} (0x{service:02X}) response {granted} [MAC {mac}]",
                        service_name(service)
                    )
                }
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

/// What a group 2 message says (DeviceNet Vol. 1 §3-7, the predefined master/slave
/// connection set); a master's explicit request decoded in `format`, the slave's responses
/// and the unconnected port's requests in 8/8.
fn group2_text(msg: u8, d: &[u8], format: BodyFormat) -> String {
    let raw = hex_bytes(d);
    match msg {
        group2::BIT_STROBE => format!("master bit-strobe command: {raw}"),
        group2::MULTICAST_POLL => format!("master multicast poll: {raw}"),
        group2::COS_ACK => format!("master change of state / cyclic acknowledge: {raw}"),
        group2::EXPLICIT_RESPONSE => format!(
            "slave explicit response: {}",
            explicit(d, false, BodyFormat::F8_8)
        ),
        group2::EXPLICIT_REQUEST => {
            format!("master explicit request: {}", explicit(d, true, format))
        }
        group2::POLL_COMMAND => format!("master poll command / COS / cyclic: {raw}"),
        group2::UNCONNECTED_REQUEST => format!(
            "unconnected explicit request: {}",
            explicit(d, true, BodyFormat::F8_8)
        ),
        _ => format!("duplicate MAC ID check: {raw}"),
    }
}

/// One line for a DeviceNet frame on its own, explicit messages decoded in 8/8; a listing
/// decodes through [`BodyFormats`], which knows each slave's format.
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
            format!(
                "G2 MAC {mac} msg {msg}: {}",
                group2_text(msg, d, BodyFormat::F8_8)
            )
        }
        Ok(DnId::Group3 { msg, mac }) => {
            let text = match msg {
                5 => format!(
                    "UCMM explicit response: {}",
                    explicit(d, false, BodyFormat::F8_8)
                ),
                6 => format!(
                    "UCMM explicit request: {}",
                    explicit(d, true, BodyFormat::F8_8)
                ),
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

    /// Decodes `frames` (candump `ID#DATA`) in order through one [`BodyFormats`].
    fn lines(formats: &mut BodyFormats, frames: &[&str]) -> Vec<String> {
        frames
            .iter()
            .map(|t| {
                let (id, data) = t.split_once('#').unwrap();
                let data: Vec<u8> = (0..data.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&data[i..i + 2], 16).unwrap())
                    .collect();
                formats.describe(&f(u16::from_str_radix(id, 16).unwrap(), &data))
            })
            .collect()
    }

    #[test]
    fn vol1_3_5_an_allocate_answered_8_16_decodes_the_explicit_connection_in_8_16() {
        // The ADV200 twin (MAC 12) as `cantwin sim scenarios/adv200-devicenet.toml` put it on
        // the bus for `cantwin dnet get 12 1 1 7`: its duplicate MAC ID check, the scanner's
        // (MAC 0), Allocate on the group 2 only port answered with body format 8/16, a
        // fragmented Get_Attribute_Single of Identity attribute 7 (instance 0x0001 in 16
        // bits), Release.
        let mut formats = BodyFormats::new();
        let got = lines(
            &mut formats,
            &[
                "467#00000001000000",
                "407#000000EEFFC000",
                "466#404B03010100",
                "463#40CB01",
                "464#000E01010007",
                "463#80008E1541445632",
                "464#80C000",
                "463#8041303020455850",
                "464#80C100",
                "463#80422D43414E2F44",
                "464#80C200",
                "463#80834E2D414456",
                "464#80C300",
                "466#404C030101",
                "463#40CC",
            ],
        );
        let want = [
            "G2 MAC 12 msg 7: duplicate MAC ID check: 00 00 00 01 00 00 00",
            "G2 MAC 0 msg 7: duplicate MAC ID check: 00 00 00 EE FF C0 00",
            "G2 MAC 12 msg 6: unconnected explicit request: Allocate_Master/Slave_Connection_Set (0x4B) class 0x03 instance 1 allocation choice 0x01 (explicit) allocator MAC 0 [MAC 0]",
            "G2 MAC 12 msg 3: slave explicit response: Allocate_Master/Slave_Connection_Set (0x4B) response message body format 8/16 [MAC 0]",
            "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 0]",
            "G2 MAC 12 msg 3: slave explicit response: first fragment 0: 8E 15 41 44 56 32",
            "G2 MAC 12 msg 4: master explicit request: fragment 0 acknowledged, status 0x00",
            "G2 MAC 12 msg 3: slave explicit response: middle fragment 1: 30 30 20 45 58 50",
            "G2 MAC 12 msg 4: master explicit request: fragment 1 acknowledged, status 0x00",
            "G2 MAC 12 msg 3: slave explicit response: middle fragment 2: 2D 43 41 4E 2F 44",
            "G2 MAC 12 msg 4: master explicit request: fragment 2 acknowledged, status 0x00",
            "G2 MAC 12 msg 3: slave explicit response: last fragment 3: 4E 2D 41 44 56",
            "G2 MAC 12 msg 4: master explicit request: fragment 3 acknowledged, status 0x00",
            "G2 MAC 12 msg 6: unconnected explicit request: Release_Master/Slave_Connection_Set (0x4C) class 0x03 instance 1 release choice 0x01 (explicit) [MAC 0]",
            "G2 MAC 12 msg 3: slave explicit response: Release_Master/Slave_Connection_Set (0x4C) response no data [MAC 0]",
        ];
        for (n, (g, w)) in got.iter().zip(want).enumerate() {
            assert_eq!(g, w, "line {}", n + 1);
        }
        assert_eq!(got.len(), want.len());
        // The explicit connection released, the slave is back to 8/8.
        assert_eq!(formats.format(12), BodyFormat::F8_8);

        // Without the Allocate exchange the same request reads as 8/8: instance 1, then
        // attribute 0 and a data byte.
        assert_eq!(
            BodyFormats::new().describe(&f(0x464, &[0x00, 0x0E, 0x01, 0x01, 0x00, 0x07])),
            "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 0 data 07 [MAC 0]"
        );
    }

    #[test]
    fn vol1_3_5_an_allocate_answered_8_8_keeps_8_bit_class_and_instance() {
        let mut formats = BodyFormats::new();
        let got = lines(
            &mut formats,
            &[
                // MAC 5 allocated by master MAC 1, explicit and polled, answered 8/8.
                "42E#014B03010301",
                "42B#01CB00",
                "42C#010E010107",
                "42C#01100F2001E803",
            ],
        );
        assert_eq!(
            got,
            [
                "G2 MAC 5 msg 6: unconnected explicit request: Allocate_Master/Slave_Connection_Set (0x4B) class 0x03 instance 1 allocation choice 0x03 (explicit, polled) allocator MAC 1 [MAC 1]",
                "G2 MAC 5 msg 3: slave explicit response: Allocate_Master/Slave_Connection_Set (0x4B) response message body format 8/8 [MAC 1]",
                "G2 MAC 5 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 1]",
                "G2 MAC 5 msg 4: master explicit request: Set_Attribute_Single (0x10) class 0x0F instance 32 attribute 1 data E8 03 [MAC 1]",
            ]
        );
        assert_eq!(formats.format(5), BodyFormat::F8_8);
    }

    #[test]
    fn body_formats_are_kept_per_mac_id_and_forgotten_when_the_slave_comes_on_line_again() {
        let mut formats = BodyFormats::new();
        // MAC 12 granted 16/16; MAC 5 never allocated stays 8/8.
        lines(&mut formats, &["466#404B03010100", "463#40CB02"]);
        assert_eq!(formats.format(12), BodyFormat::F16_16);
        assert_eq!(formats.format(5), BodyFormat::F8_8);
        assert_eq!(
            lines(&mut formats, &["464#000E0F00010203", "42C#010E010107"]),
            [
                "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x0F instance 513 attribute 3 [MAC 0]",
                "G2 MAC 5 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 1]",
            ]
        );
        // An allocation of polled I/O alone leaves the explicit connection's format.
        lines(&mut formats, &["466#404B03010200", "463#40CB00"]);
        assert_eq!(formats.format(12), BodyFormat::F16_16);
        // An error response learns nothing.
        lines(&mut formats, &["466#404B03010100", "463#40940C02"]);
        assert_eq!(formats.format(12), BodyFormat::F16_16);
        // The slave answering another node's duplicate MAC ID check keeps its connection;
        // a check request at its MAC ID is a node coming on line, with no connection.
        lines(&mut formats, &["467#80000001000000"]);
        assert_eq!(formats.format(12), BodyFormat::F16_16);
        lines(&mut formats, &["467#00000001000000"]);
        assert_eq!(formats.format(12), BodyFormat::F8_8);
        assert_eq!(formats.format(12), BodyFormat::F8_8);
        // A response whose request was not seen is taken; a format code outside 0–3 is
        // named by its code and decoded as 8/8.
        lines(&mut formats, &["463#40CB03"]);
        assert_eq!(formats.format(12), BodyFormat::F16_8);
        assert_eq!(
            lines(&mut formats, &["463#40CB04"]),
            [
                "G2 MAC 12 msg 3: slave explicit response: Allocate_Master/Slave_Connection_Set (0x4B) response message body format code 4 [MAC 0]"
            ]
        );
        assert_eq!(formats.format(12), BodyFormat::F8_8);
    }
}
