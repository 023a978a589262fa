//! Frame-exact checks against DeviceNet frames printed in public vendor manuals. Each test
//! names its source; the identifiers and data bytes are the manual's, the slave on the
//! other side is ours.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_can::{Instant, Node, Outbox};
use cantwin_devicenet::objects::CipError;
use cantwin_devicenet::wire::{self, BodyFormat, DupMac, Request, status};
use cantwin_devicenet::{Application, Reply, Slave, SlaveConfig};
use common::*;

/// ICP DAS "I-7242D DeviceNet/Modbus RTU Gateway User's Manual" v1.1 (July 2006), §7.2.8
/// "Reset Service" step 1: master 0x0A allocates explicit messaging from slave 0x09.
/// `ID=10 001001 110 Data= 0A 4B 03 01 01 0A` → `ID=10 001001 011 Data= 0A CB 00`.
#[test]
fn allocate_explicit_icpdas_i7242d_7_2_8() {
    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B0301010A", t), ["44B#0ACB00"]);
    assert_eq!(s.devicenet_object().master, Some(mac(10)));
}

/// ICP DAS "CAN-8124/CAN-8224/CAN-8424 User Manual" v2.0 (Aug 2007), §7.2.2 "How to apply
/// the Poll IO connection", step 2 (p. 113): Set_Attribute_Single of the poll connection's
/// expected packet rate, `ID=10 001001 100 Data= 0A 10 05 02 09 0A 0E` (0x0E0A = 3594 ms),
/// answered `ID=10 001001 011 Data= 0A 90 10 0E`: the slave rounds the rate up to its timer
/// tick and replies with the value it uses (0x0E10 = 3600 ms). The I-7242D manual (p. 83)
/// shows the same exchange on its COS/cyclic instance 4.
#[test]
fn set_expected_packet_rate_replies_actual_value_icpdas_can8x24_7_2_2() {
    let req = Request::decode(&[0x10, 0x05, 0x04, 0x09, 0x0A, 0x0E], BodyFormat::F8_8).unwrap();
    assert_eq!(
        (req.class, req.instance, req.data),
        (5, 4, &[0x09, 0x0A, 0x0E][..])
    );

    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B0301030A", t), ["44B#0ACB00"]);
    assert_eq!(deliver(&mut s, "44C#0A100502090A0E", t), ["44B#0A90100E"]);
    assert_eq!(s.poll_connection().unwrap().epr_ms, 3600);
}

/// Rockwell Automation 1760-DNET Pico DeviceNet Communications Module user manual
/// (1760-UM003A-EN-P, 2005), §4 "DeviceNet Functions": slave 3 answers master 0 with a
/// 9-byte body in two acknowledged fragments:
/// `41B: 80 00 B2 C2 05 00 05 09`, ack `41C: 80 C0 00`, `41B: 80 81 0D 05 04`,
/// ack `41C: 80 C1 00`.
#[test]
fn fragmented_response_rockwell_1760_dnet() {
    /// Answers service 0x32 of class 0x64 with the Pico-LINK reply bytes of the trace.
    struct Pico;
    impl Application for Pico {
        fn poll_sizes(&self) -> (u16, u16) {
            (0, 0)
        }
        fn produce(&mut self, _: Instant) -> Vec<u8> {
            Vec::new()
        }
        fn consume(&mut self, _: &[u8], _: Instant) {}
        fn request(&mut self, req: &Request<'_>, _: Instant) -> Option<Reply> {
            (req.class == 0x64).then(|| match req.service {
                0x32 => Reply::Data(vec![0xC2, 0x05, 0x00, 0x05, 0x09, 0x0D, 0x05, 0x04]),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            })
        }
    }
    let mut s = Slave::new(
        SlaveConfig::new(mac(3), cantwin_can::BitRate::R125K, identity()),
        Pico,
    )
    .unwrap();
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    s.on_tick(at(SEC), &mut out);
    s.on_tick(at(2 * SEC), &mut out);
    let t = at(2 * SEC);
    assert_eq!(deliver(&mut s, "41E#004B03010100", t), ["41B#00CB00"]);
    assert_eq!(
        deliver(&mut s, "41C#0032640100", t),
        ["41B#8000B2C205000509"]
    );
    assert_eq!(deliver(&mut s, "41C#80C000", t), ["41B#80810D0504"]);
    assert!(deliver(&mut s, "41C#80C100", t).is_empty());
    assert!(s.explicit_connection().unwrap().tx.is_none());
}

/// MKS Baratron DMA series manual, Appendix D, explicit messaging example 3 (slave MAC 5,
/// master MAC 1): an unsupported service is answered `42B: 01 94 08 FF`.
#[test]
fn service_not_supported_mks() {
    let mut s = slave(5);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "42E#014B03010101", t), ["42B#01CB00"]);
    // Service 0x4E on the Identity instance: not supported.
    assert_eq!(deliver(&mut s, "42C#014E0101", t), ["42B#019408FF"]);
}

/// Duplicate MAC ID check message layout (Lika SFA-5000/10000 DeviceNet manual §6.4.1,
/// Datalogic AMT58x-DN manual §6.4.1): identifier `10 MMMMMM 111`, 7 bytes
/// `[R/R | port][vendor ID LE][serial number LE]`.
#[test]
fn duplicate_mac_message_layout_lika_datalogic() {
    let mut s = slave(9);
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    let frames = sent(&mut out);
    // vendor 0x0123, serial 0x0A0B0C0D.
    assert_eq!(frames, ["44F#0023010D0C0B0A"]);
    let m = DupMac::decode(f(&frames[0]).data_bytes()).unwrap();
    assert!(!m.response);
    assert_eq!((m.vendor, m.serial), (0x0123, 0x0A0B_0C0D));
    assert_eq!(
        wire::DnId::decode(id(0x44F)).unwrap(),
        wire::DnId::g2(mac(9), wire::group2::DUP_MAC_CHECK)
    );
}

/// The master side of the same Rockwell 1760-DNET trace: the scanner (MAC 0) acknowledges
/// each fragment of slave 3's response with `41C: 80 C0 00` and `41C: 80 C1 00`.
#[test]
fn scanner_acknowledges_fragments_rockwell_1760_dnet() {
    use cantwin_devicenet::scanner::ScannerConfig;
    use cantwin_devicenet::{Scanner, ScannerEvent};
    let mut m = Scanner::new(ScannerConfig::new(mac(0), 1, 2));
    let mut out = Outbox::new();
    m.on_power_up(at(0), &mut out);
    m.on_tick(at(SEC), &mut out);
    m.on_tick(at(2 * SEC), &mut out);
    out.clear();
    let t = at(2 * SEC);
    m.allocate(mac(3), 1).unwrap();
    m.request(mac(3), 0x32, 0x64, 1, &[0]).unwrap();
    m.on_tick(t, &mut out);
    assert_eq!(sent(&mut out), ["41E#404B03010100"]);
    assert_eq!(deliver(&mut m, "41B#40CB00", t), ["41C#0032640100"]);
    assert_eq!(deliver(&mut m, "41B#8000B2C205000509", t), ["41C#80C000"]);
    assert_eq!(deliver(&mut m, "41B#80810D0504", t), ["41C#80C100"]);
    let ev: Vec<_> = std::iter::from_fn(|| m.poll_event()).collect();
    assert_eq!(
        ev.last(),
        Some(&ScannerEvent::Response {
            slave: mac(3),
            service: 0x32,
            data: vec![0xC2, 0x05, 0x00, 0x05, 0x09, 0x0D, 0x05, 0x04]
        })
    );
}

/// Same CAN-8x24 manual, §7.2.2 step 1 (p. 112): the master allocates explicit, polled and
/// bit-strobed connections, `ID=10 001001 110 Data= 0A 4B 03 01 07 0A`. The gateway accepts;
/// the drive card has no bit-strobe connection and refuses the whole choice (invalid
/// allocation choice), leaving nothing allocated.
#[test]
fn allocate_with_bit_strobe_refused_icpdas_can8x24_7_2_2() {
    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B0301070A", t), ["44B#0A942002"]);
    assert_eq!(s.devicenet_object().master, None);
}

/// MKS Baratron DMA series manual, Appendix D, explicit messaging examples 1 and 2: the
/// master (MAC 1) reads the Identity vendor ID of the device at MAC 5,
/// `42C: 01 0E 01 01 01` → `42B: 01 8E 36 00` (vendor 0x0036).
#[test]
fn get_attribute_single_vendor_id_mks_appendix_d() {
    let mut id = identity();
    id.vendor = 0x0036;
    let mut s = Slave::new(
        SlaveConfig::new(mac(5), cantwin_can::BitRate::R125K, id),
        Drive::new(1, 1),
    )
    .unwrap();
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "42E#014B03010101", t), ["42B#01CB00"]);
    assert_eq!(deliver(&mut s, "42C#010E010101", t), ["42B#018E3600"]);
}

/// BEI IDEACOD DeviceNet user manual (UME-OCD-D2, 05/04), "Release Master / Slave
/// Connection Set", release polling: `41E: 0A 4C 03 01 03` (slave MAC 3, master 0x0A).
#[test]
fn release_bei_ideacod_ume_ocd_d2() {
    let mut s = slave(3);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "41E#0A4B0301030A", t), ["41B#0ACB00"]);
    assert_eq!(deliver(&mut s, "41E#0A4C030103", t), ["41B#0ACC"]);
    assert_eq!(s.devicenet_object().master, None);
    assert!(s.poll_connection().is_none() && s.explicit_connection().is_none());
}

/// I-7242D manual §7.2.11.1 "Unacknowledged Fragmentation example": a poll connection
/// consuming 10 bytes gets `ID=10 001001 101 Data= 00 01 02 03 04 05 06 07` then
/// `81 08 09 0A` from master 0x0A.
#[test]
fn io_fragmented_poll_command_icpdas_i7242d_7_2_11_1() {
    let data: Vec<u8> = (1..=10).collect();
    assert_eq!(
        wire::io_fragments(&data),
        vec![vec![0x00, 1, 2, 3, 4, 5, 6, 7], vec![0x81, 8, 9, 10]]
    );
    let mut s = slave_with(9, Drive::new(5, 1));
    let t = online(&mut s);
    deliver(&mut s, "44E#0A4B0301030A", t);
    deliver(&mut s, "44C#0A100502096400", t);
    assert!(deliver(&mut s, "44D#0001020304050607", t).is_empty());
    assert_eq!(deliver(&mut s, "44D#8108090A", t), ["3C9#0001"]);
    assert_eq!(s.app().consumed, vec![data]);
}
