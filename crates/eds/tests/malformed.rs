//! Malformed files: each gives an error naming the line, the section and the key.
#![allow(clippy::unwrap_used)]

use cantwin_eds::{ParseErrorKind, parse};

const VAR_1000: &str = "[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\n";

fn invalid(value: &str, expected: &str) -> ParseErrorKind {
    ParseErrorKind::InvalidValue {
        value: value.into(),
        expected: expected.into(),
    }
}

/// (file, line, section, key, kind)
type Case = (
    String,
    usize,
    Option<&'static str>,
    Option<&'static str>,
    ParseErrorKind,
);

fn cases() -> Vec<Case> {
    vec![
        ("FileName=x\n[FileInfo]\n".into(), 1, None, None, ParseErrorKind::OutsideSection),
        ("[FileInfo]\n[DeviceInfo\n".into(), 2, None, None, ParseErrorKind::BadHeader),
        (format!("{VAR_1000}DefaultValue 5\n"), 5, Some("1000"), None, ParseErrorKind::NotKeyValue),
        (format!("{VAR_1000}=5\n"), 5, Some("1000"), None, ParseErrorKind::EmptyKey),
        (
            format!("{VAR_1000}accesstype=rw\n"),
            5,
            Some("1000"),
            Some("accesstype"),
            ParseErrorKind::DuplicateKey(4),
        ),
        (format!("{VAR_1000}\n{VAR_1000}"), 6, Some("1000"), None, ParseErrorKind::DuplicateSection(1)),
        (
            "[1000]\nParameterName=x\nDataType=0xZZ\nAccessType=ro\n".into(),
            3,
            Some("1000"),
            Some("DataType"),
            invalid("0xZZ", "a data type index"),
        ),
        (
            "[1000]\nParameterName=x\nDataType=0x0007\nAccessType=readwrite\n".into(),
            4,
            Some("1000"),
            Some("AccessType"),
            invalid("readwrite", "ro, wo, rw, rwr, rww or const"),
        ),
        (
            format!("{VAR_1000}DefaultValue=12abc\n"),
            5,
            Some("1000"),
            Some("DefaultValue"),
            invalid("12abc", "an integer (decimal, 0x hex or 0 octal)"),
        ),
        (
            format!("{VAR_1000}DefaultValue=$NODEID-1\n"),
            5,
            Some("1000"),
            Some("DefaultValue"),
            invalid("$NODEID-1", "`$NODEID`, `$NODEID+n` or `n+$NODEID`"),
        ),
        (
            format!("{VAR_1000}PDOMapping=2\n"),
            5,
            Some("1000"),
            Some("PDOMapping"),
            invalid("2", "0 or 1"),
        ),
        (
            "[1000]\nParameterName=x\nObjectType=0x100\n".into(),
            3,
            Some("1000"),
            Some("ObjectType"),
            invalid("0x100", "an object code"),
        ),
        (
            "[2000]\nParameterName=x\nDataType=0x000A\nAccessType=ro\nDefaultValue=0A1\n".into(),
            5,
            Some("2000"),
            Some("DefaultValue"),
            invalid("0A1", "hex bytes"),
        ),
        (
            "[2000]\nParameterName=x\nDataType=0x0008\nAccessType=ro\nHighLimit=fast\n".into(),
            5,
            Some("2000"),
            Some("HighLimit"),
            invalid("fast", "a REAL32 number"),
        ),
        (
            "[1000]\nDataType=0x0007\nAccessType=ro\n".into(),
            1,
            Some("1000"),
            Some("ParameterName"),
            ParseErrorKind::MissingKey,
        ),
        (
            "[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n".into(),
            1,
            Some("MandatoryObjects"),
            Some("SupportedObjects"),
            ParseErrorKind::ListEntry(3),
        ),
        (
            "[MandatoryObjects]\nSupportedObjects=1\n1=0x1000\n2=0x1001\n".into(),
            4,
            Some("MandatoryObjects"),
            Some("2"),
            ParseErrorKind::ListEntry(2),
        ),
        (
            "[OptionalObjects]\n1=0x1005\n".into(),
            1,
            Some("OptionalObjects"),
            Some("SupportedObjects"),
            ParseErrorKind::MissingKey,
        ),
        (
            "[OptionalObjects]\nSupportedObjects=1\n1=0x10000\n".into(),
            3,
            Some("OptionalObjects"),
            Some("1"),
            invalid("0x10000", "an object index 0x0000..=0xFFFF"),
        ),
        (
            "[2000sub1]\nParameterName=x\nDataType=0x0005\nAccessType=ro\n".into(),
            1,
            Some("2000sub1"),
            None,
            ParseErrorKind::NoObject(0x2000),
        ),
        (
            "[2000]\nParameterName=a\nObjectType=0x8\nCompactSubObj=2\nDataType=0x0005\nAccessType=ro\n\n[2000sub1]\nParameterName=b\nDataType=0x0005\nAccessType=ro\n".into(),
            8,
            Some("2000sub1"),
            None,
            ParseErrorKind::CompactWithSubs(0x2000),
        ),
        (
            "[2000]\nParameterName=a\nObjectType=0x8\nCompactSubObj=2\nDataType=0x0005\nAccessType=ro\n[2000Name]\nNrOfEntries=3\n1=x\n2=y\n".into(),
            8,
            Some("2000Name"),
            Some("NrOfEntries"),
            invalid("3", "the number of entries (2)"),
        ),
        (
            "[2000]\nParameterName=a\nObjectType=0x9\n[2000sub1]\nParameterName=b\nDataType=5\nAccessType=ro\n[2000sub01]\nParameterName=c\nDataType=5\nAccessType=ro\n".into(),
            8,
            Some("2000sub01"),
            None,
            ParseErrorKind::DuplicateSection(4),
        ),
        (
            "[Comments]\nLines=2\nLine1=only one\n".into(),
            1,
            Some("Comments"),
            Some("Lines"),
            ParseErrorKind::ListEntry(2),
        ),
        (
            "[DummyUsage]\nDummy0001=0\nDummy0002=5\n".into(),
            3,
            Some("DummyUsage"),
            Some("Dummy0002"),
            invalid("5", "0 or 1"),
        ),
        (
            "[DummyUsage]\nDummy2=1\n".into(),
            2,
            Some("DummyUsage"),
            Some("Dummy2"),
            invalid("Dummy2", "a key `Dummyxxxx`"),
        ),
        (
            "[DeviceInfo]\nVendorName=x\nVendorNumber=ACME\n".into(),
            3,
            Some("DeviceInfo"),
            Some("VendorNumber"),
            invalid("ACME", "an integer 0..=0xFFFFFFFF"),
        ),
        (
            "[DeviceInfo]\nBaudRate_500=2\n".into(),
            2,
            Some("DeviceInfo"),
            Some("BaudRate_500"),
            invalid("2", "0 or 1"),
        ),
        (
            "[DeviceComissioning]\nNodeID=300\n".into(),
            2,
            Some("DeviceComissioning"),
            Some("NodeID"),
            invalid("300", "an integer 0..=255"),
        ),
        (
            "[DeviceComissioning]\nNodeID=1\n[DeviceCommissioning]\nNodeID=2\n".into(),
            3,
            Some("DeviceCommissioning"),
            None,
            ParseErrorKind::DuplicateSection(1),
        ),
        (
            "[1000ObjectLinks]\nObjectLinks=1\n1=0x2000\n2=0x2001\n".into(),
            4,
            Some("1000ObjectLinks"),
            Some("2"),
            ParseErrorKind::ListEntry(2),
        ),
    ]
}

#[test]
fn cia306_malformed_files_give_line_section_and_key() {
    for (text, line, section, key, kind) in cases() {
        let e = parse(&text).expect_err(&text);
        assert_eq!(e.line, line, "{text}\n{e}");
        assert_eq!(e.section.as_deref(), section, "{text}\n{e}");
        assert_eq!(e.key.as_deref(), key, "{text}\n{e}");
        assert_eq!(e.kind, kind, "{text}\n{e}");
    }
}

#[test]
fn cia306_error_messages_read_well() {
    let e = parse("[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n").unwrap_err();
    assert_eq!(
        e.to_string(),
        "line 1 [MandatoryObjects] SupportedObjects: entry 3 is outside the count or missing"
    );
    let e = parse(&format!("{VAR_1000}AccessType=rw\n")).unwrap_err();
    assert_eq!(
        e.to_string(),
        "line 5 [1000] AccessType: duplicate key, first defined at line 4"
    );
}
