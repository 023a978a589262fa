//! Malformed files: nothing is refused; each irregularity is a diagnostic naming the line,
//! the section, the key and how serious it is, and the rest of the file is read.
#![allow(clippy::unwrap_used)]

use cantwin_eds::{ParseErrorKind, Severity, load, parse};

const VAR_1000: &str = "[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\n";

/// (file, line, section, key, severity, words of the message)
type Case = (
    String,
    usize,
    &'static str,
    Option<&'static str>,
    Severity,
    &'static str,
);

fn cases() -> Vec<Case> {
    use Severity::*;
    vec![
        ("FileName=x\n[FileInfo]\n".into(), 1, "", None, Warning, "outside any section"),
        ("[FileInfo]\n[DeviceInfo\n".into(), 2, "", None, Error, "malformed section header"),
        (format!("{VAR_1000}DefaultValue 5\n"), 5, "1000", None, Error, "expected `key=value`"),
        (format!("{VAR_1000}=5\n"), 5, "1000", None, Error, "empty key"),
        (format!("{VAR_1000}accesstype=rw\n"), 5, "1000", Some("accesstype"), Error, "first defined at line 4"),
        (format!("{VAR_1000}\n{VAR_1000}"), 6, "1000", None, Error, "duplicate section, first defined at line 1"),
        ("[1000]\nParameterName=x\nDataType=0xZZ\nAccessType=ro\n".into(), 3, "1000", Some("DataType"), Error, "a data type index"),
        ("[1000]\nParameterName=x\nDataType=0x0007\nAccessType=readwrite\n".into(), 4, "1000", Some("AccessType"), Error, "held as ro"),
        (format!("{VAR_1000}DefaultValue=12abc\n"), 5, "1000", Some("DefaultValue"), Error, "\"12abc\" is not an integer"),
        (format!("{VAR_1000}DefaultValue=$NODEID-1\n"), 5, "1000", Some("DefaultValue"), Error, "is not an integer"),
        (format!("{VAR_1000}PDOMapping=2\n"), 5, "1000", Some("PDOMapping"), Error, "0 or 1"),
        ("[1000]\nParameterName=x\nObjectType=0x100\n".into(), 3, "1000", Some("ObjectType"), Error, "an object code"),
        ("[2000]\nParameterName=x\nDataType=0x000A\nAccessType=ro\nDefaultValue=0A1\n".into(), 5, "2000", Some("DefaultValue"), Error, "hex bytes"),
        ("[2000]\nParameterName=x\nDataType=0x0008\nAccessType=ro\nHighLimit=fast\n".into(), 5, "2000", Some("HighLimit"), Error, "is not a number"),
        ("[1000]\nDataType=0x0007\nAccessType=ro\n".into(), 1, "1000", Some("ParameterName"), Warning, "missing required key"),
        ("[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n".into(), 2, "MandatoryObjects", Some("SupportedObjects"), Warning, "says 3, 2 entries are listed"),
        ("[OptionalObjects]\n1=0x1005\n".into(), 1, "OptionalObjects", Some("SupportedObjects"), Warning, "missing required key"),
        ("[OptionalObjects]\nSupportedObjects=1\n1=0x10000\n".into(), 3, "OptionalObjects", Some("1"), Error, "an object index"),
        ("[2000sub1]\nParameterName=x\nDataType=0x0005\nAccessType=ro\n".into(), 1, "2000sub1", None, Warning, "taken as a RECORD"),
        ("[2000]\nParameterName=a\nObjectType=0x8\nCompactSubObj=2\nDataType=0x0005\nAccessType=ro\n\n[2000sub1]\nParameterName=b\nDataType=0x0005\nAccessType=ro\n".into(), 8, "2000sub1", None, Error, "taken as written"),
        ("[2000]\nParameterName=a\nObjectType=0x8\nCompactSubObj=2\nDataType=0x0005\nAccessType=ro\n[2000Name]\nNrOfEntries=3\n1=x\n2=y\n".into(), 8, "2000Name", Some("NrOfEntries"), Warning, "says 3, 2 entries"),
        ("[2000]\nParameterName=a\nObjectType=0x9\n[2000sub1]\nParameterName=b\nDataType=5\nAccessType=ro\n[2000sub01]\nParameterName=c\nDataType=5\nAccessType=ro\n".into(), 8, "2000sub01", None, Error, "duplicate section, first defined at line 4"),
        ("[Comments]\nLines=2\nLine1=only one\n".into(), 2, "Comments", Some("Lines"), Warning, "says 2, 1 entries"),
        ("[DummyUsage]\nDummy0001=0\nDummy0002=5\n".into(), 3, "DummyUsage", Some("Dummy0002"), Error, "0 or 1"),
        ("[DummyUsage]\nDummy2=1\n".into(), 2, "DummyUsage", Some("Dummy2"), Warning, "a key `Dummyxxxx`"),
        ("[DeviceInfo]\nVendorName=x\nVendorNumber=ACME\n".into(), 3, "DeviceInfo", Some("VendorNumber"), Warning, "0..=0xFFFFFFFF"),
        ("[DeviceComissioning]\nNodeID=300\n".into(), 2, "DeviceComissioning", Some("NodeID"), Warning, "0..=255"),
        ("[DeviceComissioning]\nNodeID=1\n[DeviceCommissioning]\nNodeID=2\n".into(), 3, "DeviceCommissioning", None, Error, "duplicate section, first defined at line 1"),
        ("[1000ObjectLinks]\nObjectLinks=1\n1=0x2000\n2=0x2001\n".into(), 2, "1000ObjectLinks", Some("ObjectLinks"), Warning, "says 1, 2 entries"),
    ]
}

#[test]
fn cia306_malformed_files_give_line_section_key_and_severity() {
    for (text, line, section, key, severity, words) in cases() {
        let loaded = load(&text);
        let found = loaded.report.issues.iter().find(|i| {
            i.line == Some(line)
                && i.section == section
                && i.key.as_deref() == key
                && i.severity == severity
                && i.message.contains(words)
        });
        assert!(found.is_some(), "{text}\n{}", loaded.report);
    }
}

#[test]
fn cia306_parse_refuses_at_the_first_error_and_names_it() {
    let e = parse(&format!("{VAR_1000}AccessType=rw\n")).unwrap_err();
    assert_eq!(
        e.to_string(),
        "line 5 [1000] AccessType: duplicate key, first defined at line 4"
    );
    assert_eq!(e.kind, ParseErrorKind::DuplicateKey(4));
    // Warnings do not refuse a file.
    let eds = parse("[MandatoryObjects]\nSupportedObjects=0\n1=0x1000\n").unwrap();
    assert_eq!(eds.mandatory_objects, vec![0x1000]);
}

#[test]
fn cia306_diagnostics_read_well() {
    let loaded = load("[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n");
    let first = loaded.report.issues[0].to_string();
    assert_eq!(
        first,
        "warning: line 2 [MandatoryObjects] SupportedObjects: says 3, 2 entries are listed; the listed entries are taken"
    );
}
