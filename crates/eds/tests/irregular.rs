//! The irregularities of EDS and DCF files in the field (I1–I16), one file each in
//! `corpus/irregular/`, written for these tests: each loads, the dictionary is what the
//! file evidently means, and what CiA 306 does not allow is a diagnostic with its line,
//! section, key and severity.
#![allow(clippy::unwrap_used)]

use cantwin_canopen::od::{
    Access, DataType, ObjectCode, ObjectDictionary, OdDescription, TimeOfDay, Value,
};
use cantwin_eds::{EdsValue, Loaded, Severity, configured, load_bytes, to_od};
use std::path::PathBuf;
use std::sync::Arc;

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus/irregular")
        .join(name)
}

fn file(name: &str) -> Loaded {
    load_bytes(&std::fs::read(path(name)).unwrap())
}

fn od(l: &Loaded) -> OdDescription {
    to_od(&configured(&l.eds)).unwrap()
}

/// The diagnostic at `line` in `section`/`key` with that severity and words, as text.
#[track_caller]
fn diag(
    l: &Loaded,
    severity: Severity,
    line: usize,
    section: &str,
    key: Option<&str>,
    words: &str,
) {
    let hit = l.report.issues.iter().any(|i| {
        i.severity == severity
            && i.line == Some(line)
            && i.section.eq_ignore_ascii_case(section)
            && i.key.as_deref() == key
            && i.message.contains(words)
    });
    assert!(
        hit,
        "no {severity:?} at line {line} [{section}] {key:?} {words:?} in\n{}",
        l.report
    );
}

fn default(d: &OdDescription, index: u16, sub: u8) -> Option<Value> {
    d.get(index, sub).unwrap().default.clone()
}

#[test]
fn i01_counts_that_disagree_with_the_listed_entries() {
    let l = file("i01_counts.eds");
    assert_eq!(l.eds.optional_objects, vec![0x1017, 0x1008]);
    assert_eq!(l.eds.manufacturer_objects, vec![0x2000]);
    diag(
        &l,
        Severity::Warning,
        60,
        "OptionalObjects",
        Some("SupportedObjects"),
        "says 3, 2 entries",
    );
    diag(
        &l,
        Severity::Warning,
        77,
        "ManufacturerObjects",
        Some("SupportedObjects"),
        "says 0, 1 entries",
    );
    assert!(l.report.is_ok(), "{}", l.report);
    assert_eq!(default(&od(&l), 0x2000, 0), Some(Value::Unsigned16(10)));
}

#[test]
fn i02_eds_version_402_4_404_or_missing() {
    let text = std::fs::read_to_string(path("i02_eds_version.eds")).unwrap();
    for (version, words) in [
        (Some("402"), "\"402\" is not a CiA 306 version"),
        (Some("4"), "\"4\" is not a CiA 306 version"),
        (Some("404"), "\"404\" is not a CiA 306 version"),
        (None, "missing; read as 4.0"),
    ] {
        let t = match version {
            Some(v) => text.replace("EDSVersion=402", &format!("EDSVersion={v}")),
            None => text.replace("EDSVersion=402\n", ""),
        };
        let l = cantwin_eds::load(&t);
        let line = if version.is_some() { 5 } else { 1 };
        diag(
            &l,
            Severity::Note,
            line,
            "FileInfo",
            Some("EDSVersion"),
            words,
        );
        assert!(l.report.is_ok(), "{}", l.report);
        assert!(od(&l).get(0x1018, 1).is_some());
    }
}

#[test]
fn i03_hash_comment_lines() {
    let l = file("i03_hash_comments.eds");
    diag(&l, Severity::Note, 1, "", None, "starting with `#`");
    assert_eq!(
        l.report.notes().filter(|i| i.message.contains('#')).count(),
        1
    );
    let d = od(&l);
    assert!(d.get(0x1001, 0).is_some());
    assert_eq!(default(&d, 0x2000, 0), Some(Value::Unsigned32(7)));
    assert!(l.report.is_ok(), "{}", l.report);
}

#[test]
fn i04_access_types_in_any_case() {
    let l = file("i04_access_case.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let d = od(&l);
    let access = |i| d.get(i, 0).unwrap().access;
    assert_eq!(
        [0x2000, 0x2001, 0x2002, 0x2003, 0x2004].map(access),
        [
            Access::Const,
            Access::Ro,
            Access::Rw,
            Access::Wo,
            Access::Rww
        ]
    );
}

#[test]
fn i05_decimal_hex_and_zero_padded_numbers() {
    let l = file("i05_numbers.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let d = od(&l);
    assert_eq!(d.get(0x2000, 0).unwrap().data_type, DataType::Unsigned32);
    assert_eq!(d.get(0x2001, 0).unwrap().data_type, DataType::Unsigned32);
    assert_eq!(d.object(0x2002).unwrap().code(), ObjectCode::Record);
    assert_eq!(default(&d, 0x2002, 1), Some(Value::Unsigned16(3)));
}

#[test]
fn i06_trailing_tabs_and_spaces() {
    let l = file("i06_trailing_blanks.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let d = od(&l);
    let s = d.get(0x2000, 0).unwrap();
    assert_eq!(s.name, "Gain");
    assert_eq!(s.access, Access::Rw);
    assert_eq!(s.default, Some(Value::Unsigned16(100)));
    assert_eq!(s.low_limit, Some(Value::Unsigned16(10)));
    assert_eq!(s.high_limit, Some(Value::Unsigned16(1000)));
}

#[test]
fn i07_sparse_sub_indices_and_an_omitted_sub() {
    let l = file("i07_sparse_subs.eds");
    let d = od(&l);
    let subs: Vec<u8> = d.object(0x2000).unwrap().subs().map(|(s, _)| s).collect();
    assert_eq!(subs, [0, 1, 4]);
    assert_eq!(default(&d, 0x2000, 4), Some(Value::Unsigned32(4)));
    assert!(d.get(0x2000, 2).is_none());
    let subs: Vec<u8> = d.object(0x2001).unwrap().subs().map(|(s, _)| s).collect();
    assert_eq!(subs, [0, 1, 3]);
    // SubNumber=3 with three sub-objects is right; SubNumber=4 with three is not.
    diag(
        &l,
        Severity::Warning,
        85,
        "2001",
        Some("SubNumber"),
        "says 4, the object has 3",
    );
    assert_eq!(l.report.warnings().count(), 1, "{}", l.report);
    assert!(l.report.is_ok());
}

#[test]
fn i08_compact_sub_obj_with_name_and_value_sections() {
    let l = file("i08_compact.eds");
    let d = od(&l);
    let o = d.object(0x2000).unwrap();
    assert!(o.compact_sub_obj());
    assert_eq!(o.sub_number(), 4);
    assert_eq!(d.get(0x2000, 1).unwrap().name, "Inputs 1-8");
    assert_eq!(d.get(0x2000, 2).unwrap().name, "Inputs2");
    assert_eq!(d.get(0x2000, 3).unwrap().name, "Inputs 17-24");
    assert!(d.get(0x2000, 3).unwrap().pdo_mappable);
    assert_eq!(default(&d, 0x2000, 0), Some(Value::Unsigned8(3)));
    // The [2000Value] entry is the configured value of sub-index 2.
    assert_eq!(default(&d, 0x2000, 2), Some(Value::Unsigned8(0x55)));
    // Names for some sub-indices only are what CiA 306 allows: no warning.
    assert_eq!(l.report.warnings().count(), 0, "{}", l.report);
    assert!(l.report.is_ok());
}

#[test]
fn i09_node_id_expressions_in_any_form() {
    let l = file("i09_nodeid.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let o = ObjectDictionary::new(Arc::new(od(&l)), 5);
    assert_eq!(o.get(0x2000, 0).unwrap(), Value::Unsigned32(0x185));
    assert_eq!(o.get(0x2001, 0).unwrap(), Value::Unsigned32(0x8000_0205));
    assert_eq!(o.get(0x2002, 0).unwrap(), Value::Unsigned32(0x305));
    assert_eq!(o.get(0x2003, 0).unwrap(), Value::Unsigned32(517));
}

#[test]
fn i10_twos_complement_limits_and_limits_upside_down() {
    let l = file("i10_limits.eds");
    let d = od(&l);
    let s = d.get(0x2000, 0).unwrap();
    assert_eq!(s.low_limit, Some(Value::Integer32(i32::MIN)));
    assert_eq!(s.high_limit, Some(Value::Integer32(-1)));
    let s = d.get(0x2001, 0).unwrap();
    assert_eq!(s.low_limit, Some(Value::Integer16(-10)));
    assert_eq!(s.high_limit, Some(Value::Integer16(10)));
    // LowLimit=100 and HighLimit=1: the range evidently meant is 1..=100, the limits taken
    // swapped (a warning), the same in the check and the dictionary; the default 5 is in it.
    let s = d.get(0x2002, 0).unwrap();
    assert_eq!(
        (s.low_limit.clone(), s.high_limit.clone()),
        (Some(Value::Unsigned16(1)), Some(Value::Unsigned16(100)))
    );
    assert_eq!(s.default, Some(Value::Unsigned16(5)));
    diag(
        &l,
        Severity::Warning,
        80,
        "2002",
        Some("LowLimit"),
        "100 is above HighLimit 1; the limits are taken swapped (1..=100)",
    );
    assert!(l.report.is_ok(), "{}", l.report);
    let mut o = ObjectDictionary::new(Arc::new(d), 1);
    assert_eq!(
        o.download(0x2002, 0, &[0, 0]),
        Err(cantwin_canopen::AbortCode::VALUE_TOO_LOW)
    );
    assert_eq!(o.download(0x2002, 0, &[100, 0]), Ok(()));
}

#[test]
fn i11_obj_flags_in_any_notation() {
    let l = file("i11_obj_flags.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let d = od(&l);
    let flags = [0x2000, 0x2001, 0x2002, 0x2003, 0x2004].map(|i| d.object(i).unwrap().flags());
    assert_eq!(flags, [0, 0, 1, 2, 3]);
}

#[test]
fn i12_dcf_parameter_values_denotation_and_commissioning() {
    let l = file("i12_dcf.dcf");
    assert!(l.report.is_ok(), "{}", l.report);
    let c = l.eds.commissioning.as_ref().unwrap();
    assert_eq!(c.node_id, Some(0x21));
    assert_eq!(c.node_name.as_deref(), Some("Conveyor 3"));
    assert_eq!(
        l.eds.entry(0x2000, 0).unwrap().denotation.as_deref(),
        Some("Conveyor speed limit")
    );
    let o = ObjectDictionary::new(Arc::new(od(&l)), 0x21);
    assert_eq!(o.get(0x1017, 0).unwrap(), Value::Unsigned16(50));
    assert_eq!(o.get(0x2000, 0).unwrap(), Value::Unsigned16(1500));
    assert_eq!(o.get(0x2001, 0).unwrap(), Value::Unsigned32(0xA1));
}

#[test]
fn i13_quoted_strings_real_bits_negative_hex_and_time_of_day() {
    let l = file("i13_lely_values.eds");
    let d = od(&l);
    assert_eq!(
        default(&d, 0x2000, 0),
        Some(Value::VisibleString("pump station".into()))
    );
    assert_eq!(default(&d, 0x2001, 0), Some(Value::Real32(1.5)));
    assert_eq!(default(&d, 0x2002, 0), Some(Value::Integer16(-16)));
    assert_eq!(
        default(&d, 0x2003, 0),
        Some(Value::TimeOfDay(TimeOfDay {
            days: 365,
            ms: 43_200_000
        }))
    );
    diag(
        &l,
        Severity::Note,
        63,
        "2000",
        Some("DefaultValue"),
        "read without the quotes",
    );
    assert!(l.report.is_ok(), "{}", l.report);
}

#[test]
fn i14_octet_string_and_domain_defaults() {
    let l = file("i14_bytes.eds");
    let d = od(&l);
    assert_eq!(
        default(&d, 0x2000, 0),
        Some(Value::OctetString(b"ABCD".to_vec()))
    );
    assert_eq!(default(&d, 0x2001, 0), Some(Value::OctetString(vec![1, 2])));
    assert_eq!(
        default(&d, 0x2002, 0),
        Some(Value::Domain(vec![0xDE, 0xAD, 0xBE, 0xEF]))
    );
    assert_eq!(default(&d, 0x2003, 0), Some(Value::Domain(vec![])));
    diag(
        &l,
        Severity::Note,
        63,
        "2000",
        Some("DefaultValue"),
        "bytes of the text",
    );
    assert!(l.report.is_ok(), "{}", l.report);
}

#[test]
fn i15_an_undefined_manufacturer_data_type() {
    let l = file("i15_undefined_type.eds");
    let d = od(&l);
    let s = d.get(0x2000, 0).unwrap();
    assert_eq!(s.data_type, DataType::Domain);
    assert_eq!((s.default.clone(), s.low_limit.clone()), (None, None));
    assert_eq!(default(&d, 0x2001, 0), Some(Value::Unsigned8(1)));
    diag(
        &l,
        Severity::Warning,
        62,
        "2000",
        Some("DataType"),
        "0x0040 is not a basic data type; held as DOMAIN",
    );
    diag(
        &l,
        Severity::Note,
        64,
        "2000",
        Some("DefaultValue"),
        "no definition here",
    );
    // The file keeps its type when written again.
    let again = cantwin_eds::parse(&cantwin_eds::write(&l.eds)).unwrap();
    assert_eq!(again.entry(0x2000, 0).unwrap().data_type, Some(0x0040));
    assert!(l.report.is_ok(), "{}", l.report);
}

#[test]
fn i16_crlf_latin1_and_utf8_text() {
    let l = file("i16_latin1_crlf.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let e = l.eds.entry(0x2000, 0).unwrap();
    assert_eq!(e.parameter_name, "Température moteur");
    assert_eq!(
        e.default_value,
        Some(EdsValue::Text("Chaîne à 25 °C".into()))
    );
    let u = file("i16_utf8.eds");
    let e = u.eds.entry(0x2000, 0).unwrap();
    assert_eq!(
        e.default_value,
        Some(EdsValue::Text("5 € pro Stück".into()))
    );
    // Written (as UTF-8) and read again, the text is the same.
    for eds in [&l.eds, &u.eds] {
        let again = load_bytes(cantwin_eds::write(eds).as_bytes());
        assert_eq!(&again.eds, eds);
    }
}

fn shaped(name: &str) -> Loaded {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus")
        .join(name);
    load_bytes(&std::fs::read(p).unwrap())
}

/// Shaped like python-canopen's `test/sample.eds`.
#[test]
fn sample_like_dcf_loads_with_its_quirks_as_warnings() {
    let l = shaped("sample_like.dcf");
    assert!(l.report.is_ok(), "{}", l.report);
    assert_eq!(l.eds.manufacturer_objects, vec![0x2000]);
    diag(
        &l,
        Severity::Warning,
        502,
        "ManufacturerObjects",
        Some("SupportedObjects"),
        "says 0, 1 entries",
    );
    diag(
        &l,
        Severity::Warning,
        114,
        "OptionalObjects",
        Some("SupportedObjects"),
        "says 10, 11 entries",
    );
    let d = od(&l);
    let subs = |i| {
        d.object(i)
            .unwrap()
            .subs()
            .map(|(s, _)| s)
            .collect::<Vec<u8>>()
    };
    assert_eq!(subs(0x1018), [0, 1, 2, 4]);
    assert_eq!(subs(0x1003), [0, 1, 3, 5]);
    assert_eq!(subs(0x3003), [0]);
    assert_eq!(subs(0x3004), [0, 1, 2, 3]);
    assert_eq!(d.get(0x2020, 0).unwrap().data_type, DataType::Domain);
    assert_eq!(d.get(0x3010, 0).unwrap().data_type, DataType::Real32);
    let s = d.get(0x3040, 0).unwrap();
    assert_eq!(
        (s.low_limit.clone(), s.high_limit.clone()),
        (Some(Value::Integer64(-10)), Some(Value::Integer64(10)))
    );
    // The DCF's ParameterValue is the configured value.
    assert_eq!(default(&d, 0x3002, 0), Some(Value::Real32(5.2)));
    let o = ObjectDictionary::new(Arc::new(d), 0x12);
    assert_eq!(o.get(0x1400, 1).unwrap(), Value::Unsigned32(0x212));
    assert_eq!(o.get(0x1401, 1).unwrap(), Value::Unsigned32(0x312));
}

/// Shaped like python-canopen's `test/datatypes.eds`.
#[test]
fn datatypes_like_eds_has_every_type_and_a_domain_written_with_at() {
    let l = shaped("datatypes_like.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    assert!(
        l.report
            .warnings()
            .any(|i| i.message.contains("mandatory object 0x1000"))
    );
    let d = od(&l);
    assert_eq!(
        default(&d, 0x200F, 0),
        Some(Value::Domain(b"WXYZ".to_vec()))
    );
    assert_eq!(
        default(&d, 0x200A, 0),
        Some(Value::OctetString(vec![0x0A, 0x0B, 0x0C]))
    );
    assert_eq!(
        default(&d, 0x200B, 0),
        Some(Value::UnicodeString("añb".encode_utf16().collect()))
    );
    assert_eq!(default(&d, 0x2015, 0), Some(Value::Integer64(-64)));
    assert_eq!(default(&d, 0x201B, 0), Some(Value::Unsigned64(64)));
    assert_eq!(d.objects().filter(|o| o.index() >= 0x2000).count(), 23);
}

/// Shaped like python-canopen's `examples/eds/e35.eds`.
#[test]
fn servo_like_eds_loads_with_its_version_count_and_dummy_objects() {
    let l = shaped("servo_like.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    diag(
        &l,
        Severity::Note,
        5,
        "FileInfo",
        Some("EDSVersion"),
        "\"402\" is not a CiA 306 version",
    );
    diag(
        &l,
        Severity::Warning,
        118,
        "ManufacturerObjects",
        Some("SupportedObjects"),
        "says 12, 10 entries",
    );
    let d = od(&l);
    for index in 0x0002..=0x0007u16 {
        assert_eq!(
            d.object(index).unwrap().code(),
            ObjectCode::DefType,
            "{index:#06X}"
        );
    }
    assert_eq!(default(&d, 0x0003, 0), Some(Value::Unsigned32(16)));
    assert_eq!(d.get(0x6040, 0).unwrap().access, Access::Rww);
    assert!(!d.get(0x6502, 0).unwrap().pdo_mappable);
}

/// A `;` after white space starts an inline comment, as python-canopen reads EDS files
/// (`inline_comment_prefixes=(';',)`), in every key; each is a note, since CiA 306 has
/// comments only on lines of their own. A `;` right after text is part of the value.
#[test]
fn i17_inline_comments_after_white_space() {
    let l = file("i17_inline_comments.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    let e = l.eds.entry(0x2000, 0).unwrap();
    assert_eq!(e.parameter_name, "Set point");
    assert_eq!(e.access_type, Some(Access::Rw));
    assert_eq!(e.default_value, Some(EdsValue::Integer(0)));
    assert_eq!(
        l.eds.entry(0x2001, 0).unwrap().default_value,
        Some(EdsValue::NodeId(0x180))
    );
    assert_eq!(
        l.eds.entry(0x2002, 0).unwrap().default_value,
        Some(EdsValue::Text("a;b".into()))
    );
    assert_eq!(
        l.eds.file_info.description.as_deref(),
        Some("Inline comments")
    );
    for (line, section, key) in [
        (6, "FileInfo", "Description"),
        (60, "2000", "ParameterName"),
        (63, "2000", "AccessType"),
        (64, "2000", "DefaultValue"),
        (72, "2001", "DefaultValue"),
    ] {
        diag(
            &l,
            Severity::Note,
            line,
            section,
            Some(key),
            "read as the start of an inline comment",
        );
    }
    assert!(
        !l.report.issues.iter().any(|i| i.line == Some(80)),
        "{}",
        l.report
    );
    let d = od(&l);
    assert_eq!(default(&d, 0x2000, 0), Some(Value::Unsigned16(0)));
}

/// A file that is not UTF-8 is Windows-1252 text: 0x80 is `€` and 0x89 `‰` (not the C1
/// control characters ISO 8859-1 has there), with a note at the first such line.
#[test]
fn i16_windows_1252_text() {
    let bytes = std::fs::read(path("i16_cp1252.eds")).unwrap();
    assert!(std::str::from_utf8(&bytes).is_err());
    let l = load_bytes(&bytes);
    assert!(l.report.is_ok(), "{}", l.report);
    let e = l.eds.entry(0x2000, 0).unwrap();
    assert_eq!(e.parameter_name, "Preis in €");
    assert_eq!(e.default_value, Some(EdsValue::Text("5 €, 3 ‰, ä".into())));
    diag(&l, Severity::Note, 60, "", None, "read as Windows-1252");
    // The bytes Windows-1252 leaves undefined stand for the control characters of their
    // number; the others of 0x80..=0x9F are its characters.
    assert_eq!(
        cantwin_eds::decode(&[0x80, 0x81, 0x8A, 0x9F, 0xFF]),
        "\u{20AC}\u{81}\u{160}\u{178}\u{FF}"
    );
}

/// A default mapping that names an object the file lacks (python-canopen's `sample.eds`
/// maps 0x6040/0x6041 without defining them): a warning naming the PDO, at the entry's
/// line; the other PDOs are not mentioned.
#[test]
fn a_pdo_mapping_an_object_the_file_lacks_is_a_warning() {
    let l = shaped("pdo_missing_object.eds");
    assert!(l.report.is_ok(), "{}", l.report);
    diag(
        &l,
        Severity::Warning,
        289,
        "1A01sub1",
        Some("DefaultValue"),
        "TPDO 2 maps 0x6041, which the file does not define: the PDO is off",
    );
    let pdo: Vec<_> = l
        .report
        .issues
        .iter()
        .filter(|i| i.message.contains("PDO"))
        .collect();
    assert_eq!(pdo.len(), 1, "{}", l.report);
    assert_eq!(cantwin_eds::pdo_issues(&l.eds).len(), 1);
}

/// `cantwin eds check` prints the diagnostics in the order of their lines.
#[test]
fn diagnostics_come_in_line_order() {
    let l = shaped("sample_like.dcf");
    let lines: Vec<usize> = l.report.issues.iter().filter_map(|i| i.line).collect();
    assert!(lines.len() > 3, "{}", l.report);
    assert!(lines.windows(2).all(|w| w[0] <= w[1]), "{}", l.report);
    let after = l.report.issues.iter().skip_while(|i| i.line.is_some());
    assert!(after.clone().all(|i| i.line.is_none()), "{}", l.report);
}
