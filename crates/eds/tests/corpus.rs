//! The corpus in `tests/corpus/`: every file parses, writes and re-parses equal, passes the
//! checks, and says what it was written to say.
#![allow(clippy::unwrap_used)]

use cantwin_canopen::od::Access;
use cantwin_eds::{EdsValue, Severity, parse, parse_bytes, render_markdown, write};
use std::path::PathBuf;

fn corpus() -> Vec<(String, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("eds" | "dcf")))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    files.sort();
    assert_eq!(files.len(), 8, "the corpus files");
    files
}

fn load(name: &str) -> cantwin_eds::Eds {
    let (_, bytes) = corpus().into_iter().find(|(n, _)| n == name).unwrap();
    parse_bytes(&bytes).unwrap()
}

#[test]
fn cia306_round_trip_parse_write_parse_is_lossless() {
    for (name, bytes) in corpus() {
        let first = parse_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let text = write(&first);
        let second = parse(&text).unwrap_or_else(|e| panic!("{name} rewritten: {e}\n{text}"));
        assert_eq!(second, first, "{name}");
        // The canonical layout is a fixed point.
        assert_eq!(write(&second), text, "{name}");
    }
}

#[test]
fn cia306_corpus_passes_the_checks_without_errors() {
    for (name, bytes) in corpus() {
        let report = parse_bytes(&bytes).unwrap().check();
        assert!(report.is_ok(), "{name}:\n{report}");
    }
}

#[test]
fn cia306_4_3_device_info_bit_rates_and_granularity() {
    let eds = load("io_module.eds");
    let d = &eds.device_info;
    assert_eq!(d.baud_rates(), vec![10, 20, 50, 125, 250, 500, 1000]);
    assert_eq!(d.baud_rate_800, Some(false));
    assert_eq!(d.granularity, Some(8));
    assert_eq!(d.vendor_number, Some(0xACE));
    assert_eq!(d.lss_supported, Some(true));
    assert_eq!(d.nr_of_rx_pdo, Some(1));
    assert_eq!(eds.file_info.file_revision, Some(2));
    assert_eq!(eds.file_info.modified_by.as_deref(), Some("cantwin"));
    let dummy = eds.dummy_usage.as_ref().unwrap();
    assert_eq!(dummy.len(), 7);
    assert_eq!(dummy.get(&1), Some(&false));
    assert_eq!(dummy.get(&7), Some(&true));
    assert_eq!(eds.comments.as_ref().unwrap().len(), 2);
}

#[test]
fn cia306_4_5_object_lists_in_listed_order() {
    let eds = load("io_module.eds");
    assert_eq!(eds.mandatory_objects, vec![0x1000, 0x1001, 0x1018]);
    assert_eq!(eds.optional_objects.len(), 10);
    assert_eq!(eds.optional_objects[3], 0x1029);
    assert_eq!(eds.manufacturer_objects, vec![0x2000]);
    assert_eq!(eds.object_links.get(&0x2000), Some(&vec![0x6000, 0x6200]));
    assert_eq!(eds.objects[&0x2000].entry.obj_flags, Some(1));
}

#[test]
fn cia306_compact_sub_obj_expands_with_names_and_recompacts() {
    let eds = load("io_module.eds");
    let o = &eds.objects[&0x6000];
    assert_eq!(o.compact_sub_obj, Some(2));
    assert_eq!(o.subs.len(), 3);
    let s0 = &o.subs[&0];
    assert_eq!(s0.data_type, Some(0x0005));
    assert_eq!(s0.default_value, Some(EdsValue::Integer(2)));
    let s2 = &o.subs[&2];
    assert_eq!(s2.parameter_name, "Inputs 9-16");
    assert_eq!(s2.data_type, Some(0x0005));
    assert_eq!(s2.access_type, Some(Access::Ro));
    assert_eq!(s2.pdo_mapping, Some(true));
    // Limits are carried to every sub-object.
    assert_eq!(
        eds.objects[&0x1029].subs[&1].high_limit,
        Some(EdsValue::Integer(2))
    );
    let text = write(&eds);
    assert!(
        text.contains(
            "[6000]\nParameterName=Read input 8-bit\nObjectType=0x8\nCompactSubObj=0x2\n"
        )
    );
    assert!(text.contains("[6000Name]\nNrOfEntries=2\n1=Inputs 1-8\n2=Inputs 9-16\n"));
    assert!(!text.contains("[6000sub"));
}

#[test]
fn cia306_compact_object_changed_by_hand_is_written_expanded() {
    let mut eds = load("io_module.eds");
    let o = eds.objects.get_mut(&0x6200).unwrap();
    o.subs.get_mut(&2).unwrap().data_type = Some(0x0006);
    let text = write(&eds);
    assert!(text.contains("[6200sub2]"));
    assert!(!text.contains("[6200Name]"));
    let back = parse(&text).unwrap();
    assert_eq!(back.objects[&0x6200].subs, eds.objects[&0x6200].subs);
    assert_eq!(back.objects[&0x6200].compact_sub_obj, None);
}

#[test]
fn cia306_4_6_3_nodeid_defaults_stay_symbolic() {
    let eds = load("io_module.eds");
    let tpdo = eds
        .entry(0x1800, 1)
        .unwrap()
        .default_value
        .as_ref()
        .unwrap();
    assert_eq!(tpdo, &EdsValue::NodeId(0x180));
    assert_eq!(tpdo.evaluate(0x7F), Some(0x1FF));
    let rpdo = eds
        .entry(0x1400, 1)
        .unwrap()
        .default_value
        .as_ref()
        .unwrap();
    assert_eq!(rpdo.evaluate(1), Some(0x201));
    assert!(write(&eds).contains("DefaultValue=$NODEID+0x180\n"));
    let q = load("quirks.eds");
    assert_eq!(
        q.entry(0x1014, 0).unwrap().default_value,
        Some(EdsValue::NodeId(0x80))
    );
    assert_eq!(
        q.entry(0x1280, 1).unwrap().default_value,
        Some(EdsValue::NodeId(0x600))
    );
    // 02600 is octal: 0x580.
    assert_eq!(
        q.entry(0x1280, 2).unwrap().default_value,
        Some(EdsValue::NodeId(0x580))
    );
    assert_eq!(
        q.entry(0x1280, 3).unwrap().default_value,
        Some(EdsValue::NodeId(0))
    );
}

#[test]
fn cia306_values_are_typed_by_data_type() {
    let eds = load("drive.eds");
    assert_eq!(
        eds.entry(0x2000, 1).unwrap().default_value,
        Some(EdsValue::Real32(12.5))
    );
    assert_eq!(
        eds.entry(0x2000, 1).unwrap().low_limit,
        Some(EdsValue::Real32(0.5))
    );
    assert_eq!(
        eds.entry(0x2000, 3).unwrap().default_value,
        Some(EdsValue::Real64(120.25))
    );
    assert_eq!(
        eds.entry(0x2000, 4).unwrap().default_value,
        Some(EdsValue::Bytes(vec![0xDE, 0xAD, 0xBE, 0xEF, 0x01, 0x02]))
    );
    let off = eds.entry(0x2001, 0).unwrap();
    assert_eq!(off.default_value, Some(EdsValue::Integer(-150)));
    assert_eq!(off.low_limit, Some(EdsValue::Integer(-(1 << 31))));
    assert_eq!(off.high_limit, Some(EdsValue::Integer((1 << 31) - 1)));
    assert_eq!(off.access_type, Some(Access::Rww));
    assert_eq!(
        eds.entry(0x1008, 0).unwrap().default_value,
        Some(EdsValue::Text("Drive V1 (400 V)".into()))
    );
    assert_eq!(
        eds.entry(0x1021, 0).unwrap().upload_file.as_deref(),
        Some("drive.eds")
    );
    assert_eq!(eds.objects[&0x1010].object_code(), cantwin_eds::ARRAY);
    assert_eq!(eds.objects[&0x6048].object_code(), cantwin_eds::RECORD);
}

#[test]
fn cia306_5_dcf_parameter_values_denotations_and_commissioning() {
    let eds = load("configured.dcf");
    assert!(eds.is_dcf());
    let c = eds.commissioning.as_ref().unwrap();
    assert_eq!(c.node_id, Some(5));
    assert_eq!(c.node_name.as_deref(), Some("Cabinet 2 inputs"));
    assert_eq!(c.baudrate, Some(250));
    assert_eq!(c.net_number, Some(1));
    assert_eq!(c.network_name.as_deref(), Some("Line A"));
    assert_eq!(c.canopen_manager, Some(false));
    assert_eq!(c.lss_serial_number, Some(0xC0FFEE));
    assert_eq!(eds.file_info.last_eds.as_deref(), Some("io_module.eds"));
    let hb = eds.entry(0x1017, 0).unwrap();
    assert_eq!(hb.parameter_value, Some(EdsValue::Integer(500)));
    assert_eq!(hb.denotation.as_deref(), Some("Heartbeat to the PLC"));
    assert_eq!(
        eds.entry(0x1800, 1).unwrap().parameter_value,
        Some(EdsValue::NodeId(0x180))
    );
    let inputs = &eds.objects[&0x6000];
    assert_eq!(
        inputs.subs[&2].parameter_value,
        Some(EdsValue::Integer(0x0F))
    );
    assert_eq!(inputs.subs[&1].parameter_value, None);
    assert_eq!(inputs.subs[&1].denotation.as_deref(), Some("Door switches"));
    let text = write(&eds);
    assert!(text.contains("[DeviceComissioning]\nNodeID=5\n"));
    assert!(text.contains("[6000Value]\nNrOfEntries=1\n2=0xF\n"));
    assert!(text.contains("[6000Denotation]\nNrOfEntries=2\n1=Door switches\n2=Light curtain\n"));
}

#[test]
fn cia306_4_1_case_comments_order_and_unknown_sections_are_kept() {
    let eds = load("quirks.eds");
    assert_eq!(eds.file_info.file_name.as_deref(), Some("quirks.eds"));
    // 07 and 010 are octal.
    assert_eq!(eds.file_info.file_revision, Some(7));
    assert_eq!(eds.device_info.revision_number, Some(8));
    assert_eq!(eds.device_info.vendor_number, Some(2766));
    assert_eq!(
        eds.file_info.description.as_deref(),
        Some("Device with unknown sections; and a semicolon inside a value")
    );
    assert_eq!(
        eds.file_info.extra,
        vec![("ExportTool".into(), "cantwin 0.1".into())]
    );
    assert_eq!(
        eds.device_info.extra,
        vec![("VendorSpecificFlag".into(), "yes".into())]
    );
    assert_eq!(eds.comments.as_ref().unwrap()[1], "");
    assert_eq!(eds.mandatory_objects, vec![0x1000, 0x1001, 0x1018]);
    assert_eq!(eds.objects[&0x1018].subs.len(), 2);
    assert_eq!(eds.entry(0x1018, 1).unwrap().access_type, Some(Access::Ro));
    assert_eq!(
        eds.objects[&0x1000].entry.extra,
        vec![("StorageLocation".into(), "ROM".into())]
    );
    assert_eq!(
        eds.entry(0x3000, 0).unwrap().default_value,
        Some(EdsValue::Text(String::new()))
    );
    let names: Vec<_> = eds.other_sections.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        ["SupportedModules", "M1ModuleInfo", "Tools", "1280Name"]
    );
    assert_eq!(
        eds.other_sections[2].entries[1],
        ("Tool1".into(), "cantwin eds doc".into())
    );
}

#[test]
fn cia306_check_reports_errors_and_warnings() {
    let mut eds = load("drive.eds");
    assert!(eds.check().issues.is_empty(), "{}", eds.check());
    eds.objects.remove(&0x1001);
    let o = eds.objects.get_mut(&0x6046).unwrap();
    o.sub_number = Some(5);
    o.subs.get_mut(&2).unwrap().default_value = Some(EdsValue::Integer(1 << 40));
    let e = eds
        .objects
        .get_mut(&0x2000)
        .unwrap()
        .subs
        .get_mut(&2)
        .unwrap();
    e.default_value = Some(EdsValue::Integer(40));
    e.access_type = None;
    eds.objects.get_mut(&0x6042).unwrap().entry.data_type = Some(0x0300);
    eds.optional_objects.push(0x2001);
    eds.dummy_usage.as_mut().unwrap().remove(&3);
    eds.object_links.insert(0x6040, vec![0x6041, 0x7000]);
    let acc = eds.objects.get_mut(&0x6048).unwrap();
    acc.compact_sub_obj = Some(2);
    let r = eds.check();
    let errors: Vec<String> = r.errors().map(ToString::to_string).collect();
    assert_eq!(
        errors,
        [
            "error: [2000sub2] AccessType: missing; held as ro",
            "error: [6046sub2] DefaultValue: 1099511627776 is outside the range of UNSIGNED32; ignored",
        ],
        "{r}"
    );
    let warnings: Vec<String> = r.warnings().map(ToString::to_string).collect();
    for w in [
        "warning: [2000sub2] DefaultValue: 40 is above HighLimit 32; the device starts at 40, as the file says",
        "warning: [1001]: mandatory object 0x1001 is missing (CiA 301 object dictionary); the device answers it with 0x06020000",
        "warning: [MandatoryObjects] 2: lists 0x1001, which has no section",
        "warning: [6046] SubNumber: says 5, the object has 3 sub-objects; the ones there are taken",
        "warning: [6042] DataType: 0x0300 is not a basic data type; held as DOMAIN",
        "warning: [6040ObjectLinks] 2: links to 0x7000, which has no section",
        "warning: [6048] CompactSubObj: only an ARRAY can be described compactly",
        "warning: [DummyUsage] Dummy0003: missing; some readers require all of Dummy0001..Dummy0007",
        "warning: [OptionalObjects] 11: 0x2001 belongs in another list (CiA 306 object lists)",
    ] {
        assert!(warnings.contains(&w.to_string()), "{w}\n{r}");
    }
    let notes: Vec<String> = r.notes().map(ToString::to_string).collect();
    assert!(
        notes.contains(
            &"note: [6042] DefaultValue: ignored: the data type has no definition here".to_string()
        ),
        "{r}"
    );
}

#[test]
fn markdown_doc_lists_every_object() {
    let eds = load("drive.eds");
    let md = render_markdown(&eds);
    assert!(md.starts_with("# Drive V1\n"));
    assert!(md.contains("| Bit rates | 125 kbit/s, 250 kbit/s, 500 kbit/s, 1000 kbit/s |"));
    assert!(md.contains("| 0x2001 | | Speed offset | VAR | INTEGER32 | rww | yes | -150 | -2147483648 .. 2147483647 |"));
    assert!(md.contains("| 0x1200 | | **SDO server parameter** | RECORD | | | | | |"));
    assert!(
        md.contains("| | 1 | COB-ID client to server | | UNSIGNED32 | ro | | $NODEID+0x600 | |")
    );
    let rows = md.lines().filter(|l| l.starts_with("| 0x")).count();
    assert_eq!(rows, eds.objects.len());
    let severity_order = Severity::Warning < Severity::Error;
    assert!(severity_order);
}

#[test]
fn markdown_doc_of_a_dcf_shows_configured_values_and_commissioning() {
    let md = render_markdown(&load("configured.dcf"));
    assert!(md.contains("| Node-ID | 5 |"));
    assert!(md.contains("| Bit rate | 250 kbit/s |"));
    assert!(md.contains(
        "| Index | Sub | Name | Object | Type | Access | PDO | Default | Limits | Value | Denotation |\n|---|---|---|---|---|---|---|---|---|---|---|\n"
    ));
    assert!(md.contains(
        "| 0x1017 | | Producer heartbeat time | VAR | UNSIGNED16 | rw | | 0x0 | | 0x1F4 | Heartbeat to the PLC |"
    ));
    assert!(
        md.contains("| | 2 | Inputs 9-16 | | UNSIGNED8 | ro | yes | 0x0 | | 0xF | Light curtain |")
    );
}

#[test]
fn cia306_check_nodeid_values_must_fit_every_node_id() {
    let mut eds = load("drive.eds");
    let e = eds
        .objects
        .get_mut(&0x6048)
        .unwrap()
        .subs
        .get_mut(&2)
        .unwrap();
    // UNSIGNED16: 0xFFF0 + 127 overflows.
    e.default_value = Some(EdsValue::NodeId(0xFFF0));
    let r = eds.check();
    let errors: Vec<String> = r.errors().map(ToString::to_string).collect();
    assert_eq!(
        errors,
        [
            "error: [6048sub2] DefaultValue: $NODEID+65520 leaves the range of UNSIGNED16 for some node-ID 1..=127; ignored"
        ]
    );
}
