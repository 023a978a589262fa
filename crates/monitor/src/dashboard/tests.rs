use std::time::Duration as WallDuration;

use cantwin_bus::ErrorKind;
use cantwin_bus::{Bus, BusConfig, PortConfig};
use cantwin_can::{ControllerEvent, Id, ListenOnly};

use super::*;

/// Two ports on one bus: a TM3 coupler and the dashboard's master.
fn model() -> (Model, PortId, PortId) {
    let mut bus = Bus::new(BusConfig::new("field", BitRate::R500K));
    let device = bus.attach(ListenOnly, PortConfig::default());
    let master = bus.attach(ListenOnly, PortConfig::default());
    let model = Model::new(
        "plant".into(),
        vec![("field".into(), BitRate::R500K)],
        vec![Device {
            name: "island".into(),
            kind: "tm3".into(),
            port: device,
            bus: 0,
            bus_name: "field".into(),
            node_id: None,
            canopen: true,
            monitor_kind: None,
        }],
        vec![master],
    );
    (model, device, master)
}

fn frame(id: u16, data: &[u8]) -> Frame {
    Frame::data(Id::standard(id).unwrap(), data).unwrap()
}

fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

fn sample(wall_ms: u64, events: Vec<Seen>, frames: u64) -> Sample {
    Sample {
        now: ms(wall_ms),
        wall: WallDuration::from_millis(wall_ms),
        events: vec![(events, 0)],
        buses: vec![BusSample {
            frames,
            error_frames: 0,
            load_percent: 1.5,
            load_span: Duration::from_secs(1),
            bit_rate: BitRate::R500K,
        }],
        devices: vec![DeviceSample::default()],
        labels: Vec::new(),
    }
}

#[test]
fn cia303_3_leds_add_power_and_controller_state_to_what_the_bus_shows() {
    let c = ErrorCounters::new();
    let seen = Leds {
        run: Led::On,
        err: Led::DoubleFlash,
    };
    let pair = |l: Leds| (l.run, l.err);
    assert_eq!(
        pair(leds(true, Some(seen), &c)),
        (Led::On, Led::DoubleFlash)
    );
    assert_eq!(pair(leds(false, Some(seen), &c)), (Led::Off, Led::Off));
    assert_eq!(pair(leds(true, None, &c)), (Led::Unknown, Led::Off));
}

#[test]
fn a_device_is_named_by_the_node_id_of_its_heartbeat_and_its_frames_are_decoded() {
    let (mut m, device, master) = model();
    let seen = vec![
        Seen::Frame {
            at: ms(1),
            frame: frame(0x705, &[0x00]),
            sender: device,
            dropped: false,
        },
        Seen::Frame {
            at: ms(2),
            frame: frame(0x000, &[0x80, 5]),
            sender: master,
            dropped: false,
        },
        Seen::Frame {
            at: ms(3),
            frame: frame(0x705, &[0x05]),
            sender: device,
            dropped: true,
        },
    ];
    let s = m.update(sample(10, seen, 3));
    assert_eq!(m.devices()[0].node_id, Some(5));
    assert_eq!(s.nodes[0].node_id, Some(5));
    // The dropped heartbeat (operational) reached nobody: the node is still in the
    // pre-operational state the master's command put it in.
    assert_eq!(s.nodes[0].nmt, Some("pre-operational"));
    let froms: Vec<&str> = s.frames.iter().map(|r| r.from.as_str()).collect();
    assert_eq!(froms, ["island", "dashboard", "island"], "oldest first");
    assert_eq!(s.frames[2].kind, RowKind::Dropped);
    assert_eq!(s.frames[2].text, "", "a dropped frame is not decoded");
    assert!(!s.frames[0].text.is_empty());
}

#[test]
fn frames_per_second_count_the_frames_since_the_previous_snapshot_over_wall_time() {
    let (mut m, ..) = model();
    let first = m.update(sample(0, Vec::new(), 100));
    assert_eq!(first.buses[0].fps, 0.0);
    let second = m.update(sample(500, Vec::new(), 150));
    assert_eq!(second.buses[0].fps, 100.0);
    let history = m.history();
    let series = |key: &str| {
        history
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, p)| p.clone())
            .unwrap()
    };
    assert_eq!(series("bus/field/fps"), [(0.0, 0.0), (0.5, 100.0)]);
    assert_eq!(series("bus/field/load"), [(0.0, 1.5), (0.5, 1.5)]);
}

fn pdos(device: PortId, from: u64, n: u64) -> Vec<Seen> {
    (from..from + n)
        .map(|i| Seen::Frame {
            at: ms(i),
            frame: frame(0x181, &[i as u8]),
            sender: device,
            dropped: false,
        })
        .collect()
}

#[test]
fn each_snapshot_carries_every_row_since_the_previous_one_numbered_without_gaps() {
    let (mut m, device, _) = model();
    let first = m.update(sample(250, pdos(device, 0, 300), 300));
    let second = m.update(sample(500, pdos(device, 300, 200), 500));
    let seqs: Vec<u64> = first
        .frames
        .iter()
        .chain(&second.frames)
        .map(|r| r.seq)
        .collect();
    assert_eq!(seqs, (0..500).collect::<Vec<u64>>());
    assert_eq!(second.next_seq, 500);
    assert_eq!(second.frames[0].at, ms(300));
    // Nothing new: an empty snapshot, nothing counted as lost.
    let third = m.update(sample(750, Vec::new(), 500));
    assert!(third.frames.is_empty());
    assert_eq!((third.next_seq, third.missed), (500, 0));
}

#[test]
fn past_the_bound_a_snapshot_leaves_out_the_oldest_rows_and_their_numbers_show_the_gap() {
    let (mut m, device, _) = model();
    let extra = 5;
    let s = m.update(sample(1000, pdos(device, 0, STREAM_LEN as u64 + extra), 0));
    assert_eq!(s.frames.len(), STREAM_LEN);
    assert_eq!(s.frames[0].seq, extra, "rows 0..5 left out");
    assert_eq!(s.next_seq, STREAM_LEN as u64 + extra);
    // What the tap could not keep is counted per snapshot and in total.
    let mut lost = sample(1250, Vec::new(), 0);
    lost.events = vec![(Vec::new(), 7)];
    let s = m.update(lost);
    assert_eq!((s.missed, s.missed_total), (7, 7));
    let s = m.update(sample(1500, Vec::new(), 0));
    assert_eq!((s.missed, s.missed_total), (0, 7));
}

#[test]
fn signals_cover_bus_statistics_device_values_and_decoded_pdo_values() {
    let (mut m, device, _) = model();
    let mut s = sample(
        10,
        vec![
            Seen::Frame {
                at: ms(1),
                frame: frame(0x705, &[0x05]),
                sender: device,
                dropped: false,
            },
            // TM3 TPDO1 of node 5: the first digital input byte.
            Seen::Frame {
                at: ms(2),
                frame: frame(0x185, &[0x21, 0x00]),
                sender: device,
                dropped: false,
            },
        ],
        2,
    );
    s.devices = vec![DeviceSample {
        values: vec![
            LiveValue::measured("temperature", -3.5, "°C"),
            LiveValue::digital("digital_input.1.0", true, Role::DigitalInput),
            LiveValue {
                name: "analog_input.3.0".into(),
                value: 2.0,
                unit: "V",
                role: Role::AnalogInput {
                    min: 0.0,
                    max: 10.0,
                },
            },
        ],
        ..DeviceSample::default()
    }];
    let snap = m.update(s);
    let find = |key: &str| {
        snap.signals
            .iter()
            .find(|s| s.key == key)
            .unwrap_or_else(|| panic!("no {key} in {:#?}", snap.signals))
    };
    assert!(find("bus/field/load").non_negative);
    assert_eq!(find("bus/field/fps").unit, "1/s");
    let t = find("device/island/temperature");
    assert_eq!((t.value, t.non_negative), (-3.5, false));
    assert!(find("device/island/digital_input.1.0").non_negative);
    assert!(find("device/island/analog_input.3.0").non_negative);
    let pdo: Vec<&Signal> = snap
        .signals
        .iter()
        .filter(|s| s.source == SignalSource::Pdo)
        .collect();
    assert!(!pdo.is_empty(), "{:#?}", snap.signals);
    assert!(pdo.iter().all(|s| s.key.starts_with("pdo/field/5/TPDO1/")));
    assert!(
        pdo[0].label.starts_with("island TPDO1 "),
        "{}",
        pdo[0].label
    );
    assert_eq!(pdo[0].value, 33.0, "0x21 as a number: {:?}", pdo[0]);
    // Each signal has its series.
    assert!(
        m.history()
            .iter()
            .any(|(k, p)| *k == "device/island/temperature" && p == &[(0.01, -3.5)])
    );
}

#[test]
fn a_history_forgets_what_left_the_window() {
    let mut h = History::default();
    h.push(WallDuration::from_secs(0), 1.0);
    h.push(WallDuration::from_secs(30), 2.0);
    h.push(WallDuration::from_secs(301), 3.0);
    assert_eq!(h.points(), [(30.0, 2.0), (301.0, 3.0)]);
}

#[test]
fn inputs_take_values_of_their_role() {
    let values = [
        LiveValue {
            name: "digital_input.4".into(),
            value: 0.0,
            unit: "",
            role: Role::DigitalInput,
        },
        LiveValue {
            name: "analog_input.3.0".into(),
            value: 0.0,
            unit: "V",
            role: Role::AnalogInput {
                min: -10.0,
                max: 10.0,
            },
        },
        LiveValue::measured("speed", 0.0, "rpm"),
    ];
    let set = |input: &str, value: f64| input_signal(&values, "island", input, value);
    assert_eq!(set("digital_input.4", 1.0), Ok(SignalValue::Bool(true)));
    assert!(set("digital_input.4", 2.0).unwrap_err().contains("0 or 1"));
    assert_eq!(set("analog_input.3.0", 5.0), Ok(SignalValue::Integer(5)));
    assert_eq!(set("analog_input.3.0", 2.5), Ok(SignalValue::Real(2.5)));
    assert!(
        set("analog_input.3.0", 11.0)
            .unwrap_err()
            .contains("-10–10")
    );
    assert_eq!(
        set("speed", 1.0),
        Err("island has no input \"speed\" (inputs: digital_input.4, analog_input.3.0)".into())
    );
    assert_eq!(
        input_signal(&values[2..], "drive", "speed", 1.0),
        Err("drive has no inputs".into())
    );
}

#[test]
fn the_fixed_trace_keeps_one_row_per_identifier_of_every_sender_and_skips_dropped_frames() {
    let (mut m, device, master) = model();
    // A port that is neither a device nor the dashboard (a gateway's client).
    let mut bus = Bus::new(BusConfig::new("other", BitRate::R500K));
    bus.attach(ListenOnly, PortConfig::default());
    bus.attach(ListenOnly, PortConfig::default());
    let outsider = bus.attach(ListenOnly, PortConfig::default());
    let seen = |at: u64, id: u16, data: &[u8], sender: PortId, dropped: bool| Seen::Frame {
        at: ms(at),
        frame: frame(id, data),
        sender,
        dropped,
    };
    m.update(sample(
        100,
        vec![
            seen(0, 0x705, &[0x7F], device, false),
            seen(10, 0x123, &[1, 2], outsider, false),
            seen(30, 0x123, &[1, 3], outsider, false),
            seen(40, 0x123, &[9, 9], outsider, true),
            seen(50, 0x000, &[0x01, 5], master, false),
            seen(100, 0x705, &[0x05], device, false),
        ],
        5,
    ));
    let fixed = m.fixed_trace(0).unwrap();
    let ids: Vec<u32> = fixed.rows().map(|r| r.key.id).collect();
    assert_eq!(ids, [0x000, 0x123, 0x705]);
    let other = fixed.rows().find(|r| r.key.id == 0x123).unwrap();
    assert_eq!(other.count, 2, "the dropped frame reached nobody");
    assert_eq!(other.cycle.last.unwrap().as_millis(), 20);
    assert_eq!(other.changed, 0b10);
    assert_eq!(
        other.last.text, "",
        "0x123 is no identifier of the CANopen predefined connection set"
    );
    let hb = fixed.rows().find(|r| r.key.id == 0x705).unwrap();
    assert_eq!((hb.count, hb.cycle.last.unwrap().as_millis()), (2, 100));
    assert!(!hb.last.text.is_empty());
}

#[test]
fn a_port_that_is_no_device_is_named_as_its_bus_names_it_and_keeps_the_name_after_it_left() {
    let (mut m, ..) = model();
    let mut bus = Bus::new(BusConfig::new("other", BitRate::R500K));
    bus.attach(ListenOnly, PortConfig::default());
    bus.attach(ListenOnly, PortConfig::default());
    let client = bus.attach(ListenOnly, PortConfig::default());
    let stranger = bus.attach(ListenOnly, PortConfig::default());
    let from = |at: u64, sender: PortId| Seen::Frame {
        at: ms(at),
        frame: frame(0x123, &[1]),
        sender,
        dropped: false,
    };
    let s = m.update(Sample {
        labels: vec![(client, "socketcand 127.0.0.1:54012".into())],
        ..sample(100, vec![from(10, client), from(20, stranger)], 2)
    });
    let froms: Vec<&str> = s.frames.iter().map(|r| r.from.as_str()).collect();
    assert_eq!(froms, ["socketcand 127.0.0.1:54012", "port 3"]);
    // Later samples need not name it again: its frames keep its name.
    let s = m.update(sample(200, vec![from(150, client)], 3));
    assert_eq!(s.frames[0].from, "socketcand 127.0.0.1:54012");
}

#[test]
fn a_pdo_value_charts_as_its_fields_number_or_as_its_typed_text() {
    use crate::kind::{Field, Format, PdoLayout};
    use cantwin_canopen::wire::PdoKind;
    let kind = DeviceKind {
        name: "test".into(),
        pdos: vec![PdoLayout {
            pdo: PdoKind::Transmit(1),
            fields: vec![Field::new(
                "torque",
                0,
                16,
                Format::Signed(Some("%".into())),
            )],
        }],
        emcy: Vec::new(),
    };
    let value = |name: &str, raw: Option<u64>, text: &str| crate::LiveValue {
        name: name.into(),
        pdo: PdoKind::Transmit(1),
        raw,
        text: text.into(),
    };
    // The kind's signed field: 0xFFFE is -2.
    let torque = value("torque", Some(0xFFFE), "-2 %");
    assert_eq!(pdo_number(Some(&kind), &torque), Some(-2.0));
    assert_eq!(pdo_unit(Some(&kind), &torque), "%");
    assert!(!pdo_unsigned(Some(&kind), &torque));
    // Mapped from a dictionary: an INTEGER16 -1 is its text, not its 65535 raw bits.
    assert_eq!(
        pdo_number(None, &value("x", Some(0xFFFF), "-1")),
        Some(-1.0)
    );
    assert_eq!(pdo_number(None, &value("b", Some(1), "true")), Some(1.0));
    assert_eq!(pdo_number(None, &value("s", None, "abc")), None);
    assert!(!pdo_unsigned(None, &value("x", Some(1), "1")));
}

/// Two buses: `field` with a device of `kind` (a CANopen node) and an outside port (a
/// gateway's client), `line` with a device that is no CANopen node (a DeviceNet slave).
fn two_buses(kind: &str) -> (Model, PortId, PortId, PortId) {
    let mut field = Bus::new(BusConfig::new("field", BitRate::R500K));
    let device = field.attach(ListenOnly, PortConfig::default());
    let outsider = field.attach(ListenOnly, PortConfig::default());
    let mut line = Bus::new(BusConfig::new("line", BitRate::R500K));
    let slave = line.attach(ListenOnly, PortConfig::default());
    let device_on = |name: &str, kind: &str, port, bus: usize, canopen| Device {
        name: name.into(),
        kind: kind.into(),
        port,
        bus,
        bus_name: ["field", "line"][bus].into(),
        node_id: None,
        canopen,
        monitor_kind: None,
    };
    let model = Model::new(
        "plant".into(),
        vec![
            ("field".into(), BitRate::R500K),
            ("line".into(), BitRate::R500K),
        ],
        vec![
            device_on("drive", kind, device, 0, true),
            device_on("valve", "devicenet", slave, 1, false),
        ],
        Vec::new(),
    );
    (model, device, outsider, slave)
}

fn two_bus_sample(wall_ms: u64, field: Vec<Seen>, line: Vec<Seen>) -> Sample {
    let bus = BusSample {
        frames: 0,
        error_frames: 0,
        load_percent: 1.5,
        load_span: Duration::from_secs(1),
        bit_rate: BitRate::R500K,
    };
    Sample {
        now: ms(wall_ms),
        wall: WallDuration::from_millis(wall_ms),
        events: vec![(field, 0), (line, 0)],
        buses: vec![bus.clone(), bus],
        devices: vec![DeviceSample::default(), DeviceSample::default()],
        labels: Vec::new(),
    }
}

#[test]
fn a_canopen_bus_decodes_every_senders_frames_and_a_bus_of_other_devices_none() {
    let (mut m, device, outsider, slave) = two_buses("cia402");
    let f = |at: u64, id: u16, data: &[u8], sender: PortId| Seen::Frame {
        at: ms(at),
        frame: frame(id, data),
        sender,
        dropped: false,
    };
    let s = m.update(two_bus_sample(
        100,
        vec![
            // An outside master's NMT start, a generator's SYNC and an SDO upload request.
            f(1, 0x000, &[0x01, 7], outsider),
            f(2, 0x080, &[], outsider),
            f(3, 0x607, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0], outsider),
            // The CiA 402 drive's heartbeat: operational.
            f(4, 0x707, &[0x05], device),
        ],
        vec![f(5, 0x707, &[0x05], slave)],
    ));
    let texts: Vec<&str> = s.frames.iter().map(|r| r.text.as_str()).collect();
    for (row, text) in texts[..4].iter().enumerate() {
        assert!(!text.is_empty(), "row {row} of the CANopen bus is decoded");
    }
    assert_eq!(texts[4], "", "the other bus's frame is not read as CANopen");
    let fixed = m.fixed_trace(0).unwrap();
    assert!(fixed.rows().all(|r| !r.last.text.is_empty()));
    assert_eq!(
        m.fixed_trace(1).unwrap().rows().next().unwrap().last.text,
        ""
    );
    // The cia402 node has its node-ID, NMT state and heartbeat in the node table.
    assert_eq!(s.nodes[0].node_id, Some(7));
    assert_eq!(s.nodes[0].nmt, Some("operational"));
    assert!(s.nodes[0].heartbeat_age.is_some());
    assert_eq!(s.nodes[1].node_id, None);
}

#[test]
fn a_load_measured_over_less_than_the_sampling_period_is_not_charted() {
    let (mut m, ..) = model();
    let load = |s: &Snapshot| {
        s.signals
            .iter()
            .find(|g| g.key == "bus/field/load")
            .map(|g| g.value)
    };
    // The first window after start: 3 ms of bus time, a few frames in it read as 35 %.
    let mut first = sample(3, Vec::new(), 2);
    first.buses[0].load_percent = 35.0;
    first.buses[0].load_span = Duration::from_millis(3);
    let s = m.update(first);
    assert_eq!(s.buses[0].load, 35.0, "the table still shows it");
    assert!(!s.buses[0].load_settled);
    assert_eq!(load(&s), None);
    assert!(m.history().iter().all(|(k, _)| *k != "bus/field/load"));
    let mut settled = sample(300, Vec::new(), 3);
    settled.buses[0].load_percent = 0.1;
    settled.buses[0].load_span = Duration::from_millis(300);
    let s = m.update(settled);
    assert_eq!(load(&s), Some(0.1));
    let history = m.history();
    let points = &history
        .iter()
        .find(|(k, _)| *k == "bus/field/load")
        .unwrap()
        .1;
    assert_eq!(
        points,
        &[(0.3, 0.1)],
        "the axis is set by settled samples only"
    );
}

#[test]
fn error_and_controller_rows_are_in_words() {
    let (mut m, device, _) = model();
    let s = m.update(sample(
        10,
        vec![
            Seen::Error {
                at: ms(1),
                frame: frame(0x185, &[1]),
                sender: device,
                kind: ErrorKind::BitRateMismatch,
            },
            Seen::Error {
                at: ms(2),
                frame: frame(0x185, &[1]),
                sender: device,
                kind: ErrorKind::Ack,
            },
            Seen::Controller {
                at: ms(3),
                port: device,
                event: ControllerEvent::ErrorPassive,
            },
            Seen::Controller {
                at: ms(4),
                port: device,
                event: ControllerEvent::BusOff,
            },
        ],
        0,
    ));
    let texts: Vec<&str> = s.frames.iter().map(|r| r.text.as_str()).collect();
    assert_eq!(
        texts,
        [
            "error frame: stuff error (bit-rate mismatch)",
            "error frame: acknowledgement error",
            "controller: error passive",
            "controller: bus-off",
        ]
    );
}
