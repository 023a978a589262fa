//! Round trips without loss: every corpus file read, written and read again; the EDS
//! generated from each device's dictionary read back into the same dictionary (objects,
//! dummy objects included, types, access, limits, defaults, PDO mapping flags); and DCFs
//! made for one node keep what the file says and invent nothing.
#![allow(clippy::unwrap_used)]

use cantwin_canopen::od::{OdDescription, Value};
use cantwin_eds::{
    DeviceCommissioning, DeviceInfo, EdsValue, FileInfo, Severity, commission, configured, from_od,
    load, load_bytes, to_od, write,
};
use std::path::PathBuf;

fn files() -> Vec<(String, Vec<u8>)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut out = Vec::new();
    for dir in [root.clone(), root.join("irregular")] {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if matches!(p.extension().and_then(|x| x.to_str()), Some("eds" | "dcf")) {
                out.push((p.display().to_string(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    assert!(out.len() >= 20, "{}", out.len());
    out
}

/// What a dictionary says of each object, in a comparable form.
fn describe(d: &OdDescription) -> Vec<String> {
    let mut out = Vec::new();
    for o in d.objects() {
        out.push(format!(
            "{:04X} {:?} {} flags={}",
            o.index(),
            o.code(),
            o.name(),
            o.flags()
        ));
        for (s, x) in o.subs() {
            out.push(format!(
                "{:04X}:{s} {} {:?} {:?} pdo={} low={:?} high={:?} default={:?} nodeid={}",
                o.index(),
                x.name,
                x.data_type,
                x.access,
                x.pdo_mappable,
                x.low_limit,
                x.high_limit,
                // No default means the type's zero value (CiA 306 lets a file leave it out).
                x.default
                    .clone()
                    .unwrap_or_else(|| Value::zero(x.data_type)),
                x.default_node_id_relative
            ));
        }
    }
    out
}

#[test]
fn cia306_every_corpus_file_reads_writes_and_reads_back_the_same() {
    for (name, bytes) in files() {
        let first = load_bytes(&bytes);
        let text = write(&first.eds);
        let again = load(&text);
        assert_eq!(again.eds, first.eds, "{name}");
        // Written once more, the text is stable.
        assert_eq!(write(&again.eds), text, "{name}");
        let (a, b) = (to_od(&first.eds), to_od(&again.eds));
        assert_eq!(
            a.as_ref().map(describe).ok(),
            b.as_ref().map(describe).ok(),
            "{name}"
        );
    }
}

#[test]
fn cia306_the_eds_of_every_twin_reads_back_into_the_same_dictionary() {
    for (name, bytes) in files() {
        let Ok(desc) = to_od(&configured(&load_bytes(&bytes).eds)) else {
            continue;
        };
        let info = DeviceInfo {
            vendor_name: Some("cantwin".into()),
            ..DeviceInfo::default()
        };
        let exported = write(&from_od(&desc, info, FileInfo::new("twin.eds")));
        let back = load(&exported);
        assert!(back.report.is_ok(), "{name}\n{}", back.report);
        let again = to_od(&back.eds).unwrap();
        assert_eq!(describe(&again), describe(&desc), "{name}");
    }
}

#[test]
fn cia306_dummy_objects_0002_to_0007_survive_import_and_export() {
    let bytes = std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/servo_like.eds"),
    )
    .unwrap();
    let desc = to_od(&load_bytes(&bytes).eds).unwrap();
    let exported = from_od(&desc, DeviceInfo::default(), FileInfo::new("servo.eds"));
    for index in 0x0002..=0x0007u16 {
        let o = exported.objects.get(&index).unwrap();
        assert_eq!(o.entry.object_type, Some(0x5), "{index:#06X}");
    }
    assert_eq!(
        exported.entry(0x0004, 0).unwrap().default_value,
        Some(EdsValue::Integer(32))
    );
}

const VENDOR_LIKE: &str = "[FileInfo]\nEDSVersion=4.0\n[DeviceInfo]\nVendorName=x\n\
[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n\
[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x192\n\
[1001]\nParameterName=Error register\nDataType=0x0005\nAccessType=ro\n\
[1018]\nParameterName=Identity\nObjectType=0x9\nSubNumber=2\n\
[1018sub0]\nParameterName=Highest\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\n\
[1018sub1]\nParameterName=Vendor\nDataType=0x0007\nAccessType=ro\nDefaultValue=9\n\
[ManufacturerObjects]\nSupportedObjects=3\n1=0x2000\n2=0x2001\n3=0x2002\n\
[2000]\nParameterName=Acceleration\nDataType=0x0007\nAccessType=rw\nLowLimit=1\nHighLimit=100000\n\
[2001]\nParameterName=Mode\nDataType=0x0005\nAccessType=rw\nDefaultValue=3\nLowLimit=1\nHighLimit=8\n\
[2002]\nParameterName=Service time\nDataType=0x000C\nAccessType=rw\nDefaultValue=0 0\nParameterValue=365 43200000\n";

/// `eds dcf`: an object without a default and without a value stays unset with a note —
/// never a zero below its LowLimit — and the DCF passes its own check.
#[test]
fn cia306_a_dcf_made_for_a_node_invents_no_value() {
    let l = load(VENDOR_LIKE);
    assert!(l.report.is_ok(), "{}", l.report);
    let (dcf, notes) = commission(&l.eds, 4, DeviceCommissioning::default());
    assert_eq!(dcf.entry(0x2000, 0).unwrap().parameter_value, None);
    let noted: Vec<(&str, Severity)> = notes
        .iter()
        .map(|n| (n.section.as_str(), n.severity))
        .collect();
    assert_eq!(noted, [("1001", Severity::Note), ("2000", Severity::Note)]);
    assert!(
        notes[1]
            .message
            .contains("no DefaultValue and no ParameterValue")
    );
    assert_eq!(
        dcf.entry(0x2001, 0).unwrap().parameter_value,
        Some(EdsValue::Integer(3))
    );
    let again = load(&write(&dcf));
    assert!(again.report.is_ok(), "{}", again.report);
    assert_eq!(again.eds.commissioning.unwrap().node_id, None);
}

/// `eds dcf` of a DCF keeps its ParameterValues (a heartbeat of 50 stays 50), and resolves
/// `$NODEID` for the node.
#[test]
fn cia306_a_dcf_made_from_a_dcf_keeps_its_parameter_values() {
    let bytes = std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/irregular/i12_dcf.dcf"),
    )
    .unwrap();
    let l = load_bytes(&bytes);
    let (dcf, _) = commission(&l.eds, 0x21, DeviceCommissioning::default());
    let pv = |i| dcf.entry(i, 0).unwrap().parameter_value.clone();
    assert_eq!(pv(0x1017), Some(EdsValue::Integer(50)));
    assert_eq!(pv(0x2000), Some(EdsValue::Integer(1500)));
    assert_eq!(pv(0x2001), Some(EdsValue::Integer(0xA1)));
}

/// The checker and the loader judge a TIME_OF_DAY written as `days ms` alike.
#[test]
fn cia306_check_and_loader_agree_on_time_of_day() {
    let l = load(VENDOR_LIKE);
    assert!(
        !l.report.issues.iter().any(|i| i.section == "2002"),
        "{}",
        l.report
    );
    let desc = to_od(&configured(&l.eds)).unwrap();
    let d = desc.get(0x2002, 0).unwrap();
    assert_eq!(
        d.default.as_ref().map(Value::to_string).as_deref(),
        Some("365d 43200000ms")
    );
    let bad = load(&VENDOR_LIKE.replace("365 43200000", "noon"));
    let e = bad.report.errors().next().unwrap();
    assert_eq!(
        (e.section.as_str(), e.key.as_deref()),
        ("2002", Some("ParameterValue"))
    );
    let desc = to_od(&configured(&bad.eds)).unwrap();
    assert_eq!(
        desc.get(0x2002, 0)
            .unwrap()
            .default
            .as_ref()
            .map(Value::to_string)
            .as_deref(),
        Some("0d 0ms")
    );
}
