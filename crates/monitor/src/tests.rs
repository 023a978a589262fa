use cantwin_can::Id;
use cantwin_canopen::wire::NmtState;

use super::*;

fn f(id: u16, data: &[u8]) -> Frame {
    Frame::data(Id::standard(id).unwrap(), data).unwrap()
}

fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

fn view() -> NetworkView {
    NetworkView::new(Config::default())
}

#[test]
fn node_table_from_boot_up_and_heartbeats() {
    let mut v = view();
    v.push(ms(0), &f(0x705, &[0x00]));
    v.push(ms(1), &f(0x703, &[0x00]));
    let n5 = v.node(5).unwrap();
    assert_eq!(n5.boot_ups, 1);
    assert_eq!(n5.nmt(), Some(NmtState::PreOperational));
    assert_eq!(n5.state_name(), "pre-operational");
    assert_eq!(n5.heartbeat_period, None);
    v.push(ms(100), &f(0x705, &[0x7F]));
    v.push(ms(200), &f(0x705, &[0x05]));
    v.push(ms(300), &f(0x705, &[0x04]));
    let n5 = v.node(5).unwrap();
    assert_eq!(n5.nmt(), Some(NmtState::Stopped));
    assert_eq!(n5.heartbeat_period, Some(Duration::from_millis(100)));
    assert_eq!(n5.frames, 4);
    v.advance(ms(350));
    assert_eq!(
        v.node(5).unwrap().heartbeat_age(v.now()),
        Some(Duration::from_millis(50))
    );
    // Node guarding answers carry the toggle bit; the state is bits 0–6.
    v.push(ms(400), &f(0x705, &[0x85]));
    assert_eq!(v.node(5).unwrap().nmt(), Some(NmtState::Operational));
    let ids: Vec<u8> = v.nodes().map(|n| n.id).collect();
    assert_eq!(ids, [3, 5]);
    assert_eq!(
        v.node(3).unwrap().heartbeat_age(ms(401)),
        Some(Duration::from_millis(400))
    );
    // Unknown state codes are kept and named as such.
    v.push(ms(500), &f(0x706, &[0x09]));
    assert_eq!(v.node(6).unwrap().nmt(), None);
    assert_eq!(v.node(6).unwrap().state_name(), "unknown state");
}

#[test]
fn frames_to_a_node_do_not_invent_it() {
    let mut v = view();
    v.push(ms(0), &f(0x000, &[0x01, 0x09]));
    v.push(ms(1), &f(0x609, &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]));
    v.push(ms(2), &f(0x209, &[1]));
    assert!(v.nodes().next().is_none());
    v.push(
        ms(3),
        &f(0x589, &[0x43, 0x00, 0x10, 0, 0x91, 0x01, 0x0F, 0x00]),
    );
    let n = v.node(9).unwrap();
    assert_eq!(n.frames, 1);
    assert_eq!(n.device_type, Some(0x000F_0191));
}

#[test]
fn emcy_decoding_error_register_and_reset() {
    let mut v = view();
    v.declare(5, Some("node5".into()), None);
    v.push(ms(0), &f(0x705, &[0x05]));
    v.push(
        ms(10),
        &f(0x085, &[0x10, 0x42, 0x09, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE]),
    );
    let n = v.node(5).unwrap();
    let e = n.last_emcy.as_ref().unwrap();
    assert_eq!(e.code, 0x4210);
    assert_eq!(e.meaning(), "temperature");
    assert_eq!(e.register, 0x09);
    assert_eq!(e.manufacturer, [0xAA, 0xBB, 0xCC, 0xDD, 0xEE]);
    assert_eq!(e.at, ms(10));
    assert_eq!(n.error_register, Some(0x09));
    assert!(n.emcy_active);
    assert_eq!(
        n.leds(v.now()).err,
        Led::Off,
        "no CiA 303-3 indication for 0x4210"
    );
    let entry = v.frames().last().unwrap();
    assert_eq!(entry.service, Service::Emcy);
    assert!(
        entry.text.contains("0x4210 (temperature)"),
        "{}",
        entry.text
    );
    // Error reset: the last EMCY stays on record, no longer in force.
    v.push(ms(20), &f(0x085, &[0, 0, 0, 0, 0, 0, 0, 0]));
    let n = v.node(5).unwrap();
    assert_eq!(n.last_emcy.as_ref().unwrap().code, 0x4210);
    assert!(!n.emcy_active);
    assert_eq!(n.error_register, Some(0));
    assert_eq!(n.emcy_count, 2);
}

#[test]
fn leds_follow_cia303_3() {
    let mut v = view();
    let leds = |v: &NetworkView| v.node(5).unwrap().leds(v.now());
    v.push(ms(0), &f(0x705, &[0x00]));
    assert_eq!(
        leds(&v),
        Leds {
            run: Led::Blinking,
            err: Led::Off
        }
    );
    v.push(ms(100), &f(0x705, &[0x05]));
    assert_eq!(leds(&v).run, Led::On);
    v.push(ms(150), &f(0x085, &[0x20, 0x81, 0x11, 0, 0, 0, 0, 0]));
    assert_eq!(leds(&v).err, Led::SingleFlash, "0x8120 error passive");
    v.push(ms(160), &f(0x085, &[0x30, 0x81, 0x11, 0, 0, 0, 0, 0]));
    assert_eq!(leds(&v).err, Led::DoubleFlash, "0x8130 heartbeat event");
    v.push(ms(200), &f(0x705, &[0x04]));
    assert_eq!(leds(&v).run, Led::SingleFlash);
    v.push(ms(210), &f(0x085, &[0, 0, 0, 0, 0, 0, 0, 0]));
    assert_eq!(leds(&v).err, Led::Off);
    // Heartbeat every 100 ms: silent for more than 200 ms is lost.
    v.advance(ms(400));
    assert_eq!(leds(&v).run, Led::SingleFlash);
    v.advance(ms(401));
    assert!(v.node(5).unwrap().heartbeat_lost(v.now()));
    assert_eq!(
        leds(&v),
        Leds {
            run: Led::Unknown,
            err: Led::Unknown
        }
    );
    assert!(Led::Blinking.lit_at(ms(100)) && !Led::Blinking.lit_at(ms(300)));
    assert!(Led::DoubleFlash.lit_at(ms(450)) && !Led::DoubleFlash.lit_at(ms(700)));
}

#[test]
fn sdo_answers_name_and_identify_devices() {
    let mut v = view();
    // Expedited upload of 0x1000: device type 0x00000192 | 2 << 16.
    v.push(ms(0), &f(0x602, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]));
    v.push(
        ms(1),
        &f(0x582, &[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]),
    );
    // Segmented upload of 0x1008 = "ADV200".
    v.push(ms(2), &f(0x602, &[0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]));
    v.push(ms(3), &f(0x582, &[0x41, 0x08, 0x10, 0x00, 6, 0, 0, 0]));
    v.push(ms(4), &f(0x602, &[0x60, 0, 0, 0, 0, 0, 0, 0]));
    v.push(
        ms(5),
        &f(0x582, &[0x03, b'A', b'D', b'V', b'2', b'0', b'0', 0]),
    );
    // Identity sub 1 and an aborted read of sub 4.
    v.push(ms(6), &f(0x602, &[0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0]));
    v.push(
        ms(7),
        &f(0x582, &[0x43, 0x18, 0x10, 0x01, 0xA7, 0x0C, 0, 0]),
    );
    v.push(ms(8), &f(0x602, &[0x40, 0x18, 0x10, 0x04, 0, 0, 0, 0]));
    v.push(
        ms(9),
        &f(0x582, &[0x80, 0x18, 0x10, 0x04, 0x11, 0, 0x09, 0x06]),
    );
    let n = v.node(2).unwrap();
    assert_eq!(n.device_type, Some(0x0002_0192));
    assert_eq!(n.device_name.as_deref(), Some("ADV200"));
    assert_eq!(n.identity.vendor_id, Some(0xCA7));
    assert_eq!(n.identity.serial, None);
    assert_eq!(n.kind.as_ref().unwrap().name, "ADV200 DS402");
    assert_eq!(n.display_name(), "ADV200");
    // Its PDOs now read as values.
    v.push(ms(10), &f(0x182, &[0x37, 0x02, 0xDC, 0x05]));
    let n = v.node(2).unwrap();
    assert_eq!(
        n.value("statusword").unwrap().text,
        "0x0237 operation enabled"
    );
    assert_eq!(n.value("control effort").unwrap().text, "1500 rpm");
    let text = &v.frames().last().unwrap().text;
    assert_eq!(
        text,
        "TPDO1 node 2: statusword=0x0237 operation enabled control effort=1500 rpm"
    );
}

#[test]
fn a_given_kind_is_not_replaced_and_values_keep_field_order() {
    let mut v = view();
    v.declare(3, Some("island".into()), Some(DeviceKind::tm3()));
    v.push(
        ms(0),
        &f(0x583, &[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0, 0]),
    );
    assert_eq!(v.node(3).unwrap().kind.as_ref().unwrap().name, "TM3");
    v.push(ms(1), &f(0x283, &[0xB0, 0x04, 0, 0, 0, 0, 0, 0]));
    v.push(ms(2), &f(0x183, &[0x21]));
    let names: Vec<&str> = v
        .node(3)
        .unwrap()
        .values
        .iter()
        .map(|(v, _)| v.name.as_str())
        .collect();
    assert_eq!(names, ["DI byte 1", "AI 1", "AI 2", "AI 3", "AI 4"]);
    v.push(ms(3), &f(0x183, &[0x01]));
    let n = v.node(3).unwrap();
    assert_eq!(n.value("DI byte 1").unwrap().text, "0000_0001");
    assert_eq!(n.values[0].1, ms(3));
    assert_eq!(n.value("AI 1").unwrap().text, "1200");
    // A node without a kind gets no values, and its PDOs are traced plainly.
    v.declare(4, None, None);
    v.push(ms(4), &f(0x184, &[1, 2]));
    assert!(v.node(4).unwrap().values.is_empty());
    assert_eq!(v.frames().last().unwrap().text, "PDO Transmit(1) node 4");
}

#[test]
fn the_ring_is_bounded_and_filters_apply() {
    let mut v = NetworkView::new(Config {
        ring: 4,
        ..Config::default()
    });
    v.push(ms(0), &f(0x705, &[0x7F]));
    v.push(ms(1), &f(0x080, &[]));
    v.push(ms(2), &f(0x706, &[0x7F]));
    v.push(ms(3), &f(0x186, &[1]));
    v.push(ms(4), &f(0x085, &[0x10, 0x42, 0x09, 0, 0, 0, 0, 0]));
    v.push(ms(5), &f(0x080, &[]));
    assert_eq!(v.frames().len(), 4);
    assert_eq!(v.total_frames(), 6);
    assert_eq!(v.dropped_frames(), 2);
    let seqs: Vec<u64> = v.frames().map(|e| e.seq).collect();
    assert_eq!(seqs, [2, 3, 4, 5]);
    let by = |text: &str| -> Vec<u64> {
        let filter = Filter::parse(text).unwrap();
        v.filtered(&filter).map(|e| e.seq).collect()
    };
    assert_eq!(by(""), [2, 3, 4, 5]);
    assert_eq!(by("node=6"), [2, 3]);
    assert_eq!(by("svc=sync"), [5]);
    assert_eq!(by("svc=emcy,hb"), [2, 4]);
    assert_eq!(by("id=0x080-0x0FF"), [4, 5]);
    assert_eq!(by("node=5 svc=hb"), Vec::<u64>::new());
    // The node table keeps what the dropped frames said.
    assert_eq!(v.node(5).unwrap().nmt(), Some(NmtState::PreOperational));
}

#[test]
fn load_windows_count_exact_frame_bits() {
    let mut v = NetworkView::new(Config {
        bit_rate: cantwin_can::BitRate::R125K,
        window: Duration::from_millis(10),
        windows: 3,
        ..Config::default()
    });
    let hb = f(0x705, &[0x05]);
    let pdo = f(0x185, &[0xFF; 8]);
    v.push(ms(1), &hb);
    v.push(ms(2), &pdo);
    v.push(ms(12), &hb);
    v.advance(ms(25));
    let w: Vec<Window> = v.load().windows().copied().collect();
    assert_eq!(w.len(), 3);
    assert_eq!(w[0].bits, u64::from(hb.bit_length() + pdo.bit_length()));
    assert_eq!(w[1].frames, 1);
    assert_eq!(w[2].frames, 0);
    // 125 kbit/s × 10 ms = 1250 bits a window.
    let expected = f64::from(hb.bit_length()) / 1250.0;
    assert!((v.load().load(&w[1]) - expected).abs() < 1e-12);
    assert_eq!(v.load().fps_series(), [200.0, 100.0, 0.0]);
    v.advance(ms(45));
    assert_eq!(v.load().windows().len(), 3, "bounded");
    assert_eq!(v.load().windows().next().unwrap().start, ms(20));
}

#[test]
fn short_sdo_frames_and_malformed_frames_do_not_disturb_the_model() {
    let mut v = view();
    v.push(ms(0), &f(0x585, &[0x43, 0x00]));
    v.push(ms(1), &f(0x085, &[0x10]));
    v.push(ms(2), &f(0x705, &[]));
    v.push(
        ms(3),
        &Frame::data(Id::extended(0x1234).unwrap(), &[1]).unwrap(),
    );
    assert_eq!(v.frames().len(), 4);
    let services: Vec<Service> = v.frames().map(|e| e.service).collect();
    assert_eq!(
        services,
        [Service::Sdo, Service::Other, Service::Other, Service::Other]
    );
    let n = v.node(5).unwrap();
    assert_eq!(n.device_type, None);
    assert_eq!(n.last_emcy, None);
    assert_eq!(n.state, None);
}

#[test]
fn a_kind_names_its_own_emcy_codes_in_the_table_and_the_stream() {
    let mut v = view();
    v.declare(3, None, Some(DeviceKind::tm3()));
    v.push(ms(0), &f(0x083, &[0x80, 0x00, 0x21, 0, 0, 0, 0, 0]));
    v.push(ms(1), &f(0x084, &[0x80, 0x00, 0x21, 0, 0, 0, 0, 0]));
    let n3 = v.node(3).unwrap();
    assert_eq!(n3.emcy_meaning(), Some("analog input interrupts disabled"));
    assert_eq!(
        n3.last_emcy.as_ref().unwrap().meaning(),
        "error reset or no error"
    );
    let texts: Vec<&str> = v.frames().map(|e| e.text.as_str()).collect();
    assert!(
        texts[0].contains("code 0x0080 (analog input interrupts disabled) register 0x21"),
        "{}",
        texts[0]
    );
    // A node of no known kind keeps the generic meaning (CiA 301 table 21: 00xx).
    assert!(
        texts[1].contains("(error reset or no error)"),
        "{}",
        texts[1]
    );
    assert_eq!(
        v.node(4).unwrap().emcy_meaning(),
        Some("error reset or no error")
    );
}

#[test]
fn pdo_mappings_name_the_values_of_nodes_without_a_kind() {
    use cantwin_canopen::master::pdo::PdoParams;
    use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject};
    use cantwin_canopen::pdo::MapEntry;
    let od = OdBuilder::new()
        .var(
            0x2000,
            SubObject::new("Flag", DataType::Boolean, Access::Rw),
        )
        .var(
            0x2001,
            SubObject::new("Speed", DataType::Integer16, Access::Rw),
        )
        .build()
        .unwrap();
    let mut pdos = PdoDecoder::new();
    pdos.add(
        &PdoParams {
            cob_id: 0x185,
            mapping: vec![
                MapEntry::from_u32(0x2000_0001),
                MapEntry::from_u32(0x0001_0007),
                MapEntry::from_u32(0x2001_0010),
            ],
            ..PdoParams::default()
        },
        std::sync::Arc::new(od),
    );
    let mut v = NetworkView::new(Config {
        pdos,
        ..Config::default()
    });
    v.declare(5, None, None);
    v.push(ms(0), &f(0x185, &[0x01, 0x18, 0xFC]));
    let n = v.node(5).unwrap();
    let flag = n.value("Flag").unwrap();
    assert_eq!((flag.text.as_str(), flag.raw), ("true", Some(1)));
    let speed = n.value("Speed").unwrap();
    assert_eq!((speed.text.as_str(), speed.raw), ("-1000", Some(0xFC18)));
    assert_eq!(speed.pdo, cantwin_canopen::wire::PdoKind::Transmit(1));
    assert!(v.frames().last().unwrap().text.contains("Speed=-1000"));
    // A frame too short for the mapping gives no values and keeps the old ones.
    v.push(ms(1), &f(0x185, &[0x00]));
    assert_eq!(v.node(5).unwrap().value("Speed").unwrap().text, "-1000");
}

#[test]
fn cia301_7_2_8_3_2_heartbeat_and_node_guarding_are_named_apart() {
    let mut v = view();
    // Node 5 produces heartbeats: bit 7 is 0 and no request asked for them.
    v.push(ms(0), &f(0x705, &[0x7F]));
    // Node 6 is guarded: the master's remote request, then its answers, toggling from 0.
    let rtr = Frame::remote(Id::standard(0x706).unwrap(), 1).unwrap();
    v.push(ms(10), &rtr);
    v.push(ms(11), &f(0x706, &[0x7F]));
    v.push(ms(110), &rtr);
    v.push(ms(111), &f(0x706, &[0xFF]));
    let texts: Vec<&str> = v.frames().map(|e| e.text.as_str()).collect();
    assert_eq!(
        texts,
        [
            "HEARTBEAT node 5 pre-operational",
            "NODE GUARD request node 6",
            "NODE GUARD response node 6 pre-operational (toggle 0)",
            "NODE GUARD request node 6",
            "NODE GUARD response node 6 pre-operational (toggle 1)",
        ]
    );
    assert_eq!(v.node(5).unwrap().error_control(), Some("heartbeat"));
    assert_eq!(v.node(6).unwrap().error_control(), Some("node guarding"));
    // A guard request alone does not bring a node into the table.
    v.push(
        ms(200),
        &Frame::remote(Id::standard(0x707).unwrap(), 1).unwrap(),
    );
    assert!(v.node(7).is_none());
}

#[test]
fn cia305_lss_frames_are_decoded_and_filtered_as_lss() {
    let mut v = view();
    v.push(ms(0), &f(0x7E5, &[0x04, 0x01, 0, 0, 0, 0, 0, 0]));
    v.push(ms(1), &f(0x7E5, &[0x5E, 0, 0, 0, 0, 0, 0, 0]));
    v.push(ms(2), &f(0x7E4, &[0x5E, 0x0C, 0, 0, 0, 0, 0, 0]));
    let lss = Filter::parse("svc=lss").unwrap();
    let texts: Vec<&str> = v.filtered(&lss).map(|e| e.text.as_str()).collect();
    assert_eq!(
        texts,
        [
            "LSS master: switch state global: configuration",
            "LSS master: inquire node-ID",
            "LSS slave: node-ID 12",
        ]
    );
}

#[test]
fn cia301_7_5_2_1_a_declared_device_type_names_the_profile_in_the_kind_column() {
    let mut v = view();
    v.declare(5, Some("node5".into()), None);
    assert_eq!(v.node(5).unwrap().kind_label(), None);
    // A plain CiA 301 device: profile 0.
    v.declare_device_type(5, 0x0000_0000);
    assert_eq!(v.node(5).unwrap().kind_label().as_deref(), Some("CiA 301"));
    assert!(v.node(5).unwrap().kind.is_none());
    // Profile 401 is a kind the monitor reads PDOs of.
    v.declare(7, None, None);
    v.declare_device_type(7, 0x000F_0191);
    assert_eq!(
        v.node(7).unwrap().kind_label().as_deref(),
        Some("CiA 401 I/O")
    );
    // Another profile is named by its number.
    v.declare_device_type(8, 0x0002_0196);
    assert_eq!(v.node(8).unwrap().kind_label().as_deref(), Some("CiA 406"));
}

/// A node without heartbeat (the TM3 island, a CiA 402 axis) takes the state its NMT
/// commands put it in (CiA 301 §7.3.2.2.1), marked as commanded; its own report wins again
/// when it comes, and a reset leaves the state unknown until the boot-up.
#[test]
fn cia301_7_3_2_2_1_nmt_commands_set_the_state_of_a_node_that_reports_none() {
    let mut v = view();
    v.push(ms(0), &f(0x703, &[0x00]));
    v.push(ms(0), &f(0x705, &[0x00]));
    v.push(ms(10), &f(0x000, &[0x01, 3]));
    let n3 = v.node(3).unwrap();
    assert_eq!(n3.nmt(), Some(NmtState::Operational));
    assert!(n3.state_commanded);
    assert_eq!(
        v.node(5).unwrap().nmt(),
        Some(NmtState::PreOperational),
        "not addressed"
    );
    // A broadcast stop reaches both.
    v.push(ms(20), &f(0x000, &[0x02, 0]));
    assert_eq!(v.node(3).unwrap().nmt(), Some(NmtState::Stopped));
    assert_eq!(v.node(5).unwrap().nmt(), Some(NmtState::Stopped));
    // The node's own heartbeat is the better knowledge.
    v.push(ms(30), &f(0x705, &[0x7F]));
    let n5 = v.node(5).unwrap();
    assert_eq!(n5.nmt(), Some(NmtState::PreOperational));
    assert!(!n5.state_commanded);
    // Reset node: unknown until the boot-up.
    v.push(ms(40), &f(0x000, &[0x81, 3]));
    assert_eq!(v.node(3).unwrap().state_name(), "-");
    v.push(ms(41), &f(0x703, &[0x00]));
    assert_eq!(v.node(3).unwrap().nmt(), Some(NmtState::PreOperational));
    assert!(!v.node(3).unwrap().state_commanded);
}
