//! The ODVA EDS writer: the text is an INI file (sections, `key = value;` entries that may
//! span lines, `$` comments) with the sections and keys DeviceNet EDS files carry.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;

use cantwin_devicenet::Identity;
use cantwin_devicenet::eds::{
    CipType, DeviceEds, EdsDate, EdsParam, EdsTime, FileSection, descriptor, write,
};

type Ini = BTreeMap<String, BTreeMap<String, String>>;

/// Parse EDS text: `$` starts a comment outside quotes, entries end at `;`.
fn parse(text: &str) -> Ini {
    let mut ini = Ini::new();
    let mut section: Option<String> = None;
    let mut entry = String::new();
    for raw in text.lines() {
        let mut line = String::new();
        let mut in_quote = false;
        for c in raw.chars() {
            match c {
                '"' => in_quote = !in_quote,
                '$' if !in_quote => break,
                _ => {}
            }
            line.push(c);
        }
        assert!(!in_quote, "unterminated string: {raw}");
        let t = line.trim();
        if entry.is_empty() && t.starts_with('[') {
            assert!(t.ends_with(']'), "{t}");
            let name = t[1..t.len() - 1].to_string();
            assert!(!ini.contains_key(&name), "section {name} twice");
            ini.insert(name.clone(), BTreeMap::new());
            section = Some(name);
            continue;
        }
        if t.is_empty() {
            continue;
        }
        entry.push_str(t);
        if t.ends_with(';') {
            let (k, v) = entry.split_once('=').expect(&entry);
            let sec = ini
                .get_mut(section.as_ref().expect("entry before a section"))
                .unwrap();
            let key = k.trim().to_string();
            assert!(!sec.contains_key(&key), "key {key} twice");
            sec.insert(key, v.trim().trim_end_matches(';').trim().to_string());
            entry.clear();
        }
    }
    assert!(entry.is_empty(), "unterminated entry {entry}");
    ini
}

fn device() -> DeviceEds {
    let mut speed = EdsParam::new(600, "Ramp ref 1", CipType::Dint, 4);
    speed.units = "rpm".into();
    speed.min = Some(-8192);
    speed.max = Some(8192);
    speed.default = Some(0);
    let mut mode = EdsParam::new(4000, "Fieldbus type", CipType::Udint, 4);
    mode.enums = vec![(0, "Off".into()), (2, "DeviceNet".into())];
    let mut monitor = EdsParam::new(7, "Motor \"speed\"", CipType::Dint, 4);
    monitor.descriptor = descriptor::READ_ONLY | descriptor::MONITOR;
    DeviceEds {
        file: FileSection {
            description: "Test device".into(),
            date: EdsDate {
                month: 3,
                day: 4,
                year: 2026,
            },
            time: EdsTime {
                hour: 5,
                minute: 6,
                second: 7,
            },
            revision: (1, 2),
        },
        identity: Identity {
            vendor: 0x1234,
            device_type: 0x02,
            product_code: 4,
            revision: (3, 1),
            serial: 9,
            product_name: "Drive".into(),
        },
        vendor_name: "Maker".into(),
        product_type_name: "AC Drive".into(),
        catalog: Some("D-1".into()),
        polled: Some((6, 4)),
        params: vec![monitor, speed, mode],
    }
}

#[test]
fn eds_parses_as_ini_with_file_device_and_classification() {
    let ini = parse(&write(&device()));
    let file = &ini["File"];
    assert_eq!(file["DescText"], "\"Test device\"");
    assert_eq!(file["CreateDate"], "03-04-2026");
    assert_eq!(file["CreateTime"], "05:06:07");
    assert_eq!(file["ModDate"], "03-04-2026");
    assert_eq!(file["Revision"], "1.2");
    let dev = &ini["Device"];
    assert_eq!(dev["VendCode"], "4660");
    assert_eq!(dev["VendName"], "\"Maker\"");
    assert_eq!(dev["ProdType"], "2");
    assert_eq!(dev["ProdTypeStr"], "\"AC Drive\"");
    assert_eq!(dev["ProdCode"], "4");
    assert_eq!(dev["MajRev"], "3");
    assert_eq!(dev["MinRev"], "1");
    assert_eq!(dev["ProdName"], "\"Drive\"");
    assert_eq!(dev["Catalog"], "\"D-1\"");
    assert_eq!(ini["Device Classification"]["Class1"], "DeviceNet");
    // DeviceNet EDS files have no Connection Manager (EtherNet/IP, ControlNet only).
    assert!(!ini.contains_key("Connection Manager"));
}

#[test]
fn eds_io_info_gives_the_polled_sizes() {
    let ini = parse(&write(&device()));
    let io = &ini["IO_Info"];
    assert_eq!(io["Default"], "0x0001");
    assert_eq!(io["PollInfo"], "0x0001, 1, 1");
    let fields =
        |k: &str| -> Vec<String> { io[k].split(',').map(|f| f.trim().to_string()).collect() };
    assert_eq!(fields("Input1")[..3], ["6", "0", "0x0001"]);
    assert_eq!(fields("Output1")[..3], ["4", "0", "0x0001"]);
    let mut none = device();
    none.polled = None;
    assert!(!parse(&write(&none)).contains_key("IO_Info"));
}

#[test]
fn eds_params_carry_paths_types_limits_and_enums() {
    let ini = parse(&write(&device()));
    assert_eq!(ini["ParamClass"]["MaxInst"], "4000");
    let params = &ini["Params"];
    let fields =
        |k: &str| -> Vec<String> { params[k].split(',').map(|f| f.trim().to_string()).collect() };
    // reserved, path size, path, descriptor, type, size, name, units, help, min, max, default,
    // 4 scaling, 4 links, decimals: 21 fields.
    let p600 = fields("Param600");
    assert_eq!(p600.len(), 21, "{p600:?}");
    assert_eq!(
        p600[..6],
        [
            "0",
            "8",
            "\"20 0F 25 00 58 02 30 01\"",
            "0x0000",
            "0xC4",
            "4"
        ]
    );
    assert_eq!(
        p600[6..12],
        ["\"Ramp ref 1\"", "\"rpm\"", "\"\"", "-8192", "8192", "0"]
    );
    let p7 = fields("Param7");
    assert_eq!(p7[1..4], ["6", "\"20 0F 24 07 30 01\"", "0x0030"]);
    assert_eq!(p7[6], "\"Motor 'speed'\"");
    let p4000 = fields("Param4000");
    assert_eq!(p4000[3..5], ["0x0002", "0xC8"]);
    assert_eq!(params["Enum4000"], "0, \"Off\", 2, \"DeviceNet\"");
}
