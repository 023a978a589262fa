use std::time::Duration as WallDuration;

use cantwin_bus::{Bus, BusConfig, PortConfig};
use cantwin_can::{Id, ListenOnly};

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
            bit_rate: BitRate::R500K,
        }],
        devices: vec![DeviceSample::default()],
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
            frame: frame(0x000, &[0x01, 5]),
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
    // The dropped heartbeat reached nobody: the node is still pre-operational.
    assert_eq!(s.nodes[0].nmt, Some("pre-operational"));
    let froms: Vec<&str> = s.frames.iter().map(|r| r.from.as_str()).collect();
    assert_eq!(froms, ["island", "dashboard", "island"], "newest first");
    assert_eq!(s.frames[0].kind, RowKind::Dropped);
    assert_eq!(s.frames[0].text, "", "a dropped frame is not decoded");
    assert!(!s.frames[2].text.is_empty());
}

#[test]
fn frames_per_second_count_the_frames_since_the_previous_snapshot_over_wall_time() {
    let (mut m, ..) = model();
    let first = m.update(sample(0, Vec::new(), 100));
    assert_eq!(first.buses[0].fps, 0.0);
    let second = m.update(sample(500, Vec::new(), 150));
    assert_eq!(second.buses[0].fps, 100.0);
    assert_eq!(second.buses[0].fps_history, [(0.5, 0.0), (0.0, 100.0)]);
    assert_eq!(second.buses[0].load_history.len(), 2);
}

#[test]
fn the_stream_keeps_the_last_rows_only() {
    let (mut m, device, _) = model();
    let seen = (0..STREAM_LEN as u64 + 5)
        .map(|i| Seen::Frame {
            at: ms(i),
            frame: frame(0x181, &[i as u8]),
            sender: device,
            dropped: false,
        })
        .collect();
    let s = m.update(sample(1000, seen, 0));
    assert_eq!(s.frames.len(), STREAM_LEN);
    assert_eq!(s.frames[0].at, ms(STREAM_LEN as u64 + 4));
}

#[test]
fn a_history_forgets_what_left_the_window() {
    let mut h = History::default();
    h.push(WallDuration::from_secs(0), 1.0);
    h.push(WallDuration::from_secs(30), 2.0);
    h.push(WallDuration::from_secs(61), 3.0);
    let now = WallDuration::from_secs(61);
    assert_eq!(h.points(now), [(31.0, 2.0), (0.0, 3.0)]);
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
