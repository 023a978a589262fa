//! can-utils candump log files (`candump -l`; `lib.c` compact frame notation).
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::candump::{CandumpReader, CandumpWriter, format_line};
use cantwin_capture::{CaptureReader, Error, ErrorFrame, Format, Record, error_class};

fn read(text: &str) -> Result<Vec<Record>, Error> {
    CandumpReader::new(text.as_bytes()).collect()
}

fn std(id: u16) -> Id {
    Id::standard(id).unwrap()
}

fn ext(id: u32) -> Id {
    Id::extended(id).unwrap()
}

/// The writer's exact lines: 10.6-digit timestamp, 3-digit standard and 8-digit extended
/// ids, upper-case data, `R`/`R<dlc>` remotes, error frames with CAN_ERR_FLAG in an 8-digit
/// id, and no direction flag.
#[test]
fn writer_lines_are_exact_can_utils_format() {
    let records = [
        Record::new(
            1_700_000_000_000_123_999,
            "can0",
            Frame::data(std(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap(),
        ),
        Record::new(
            5_000_001,
            "vcan0",
            Frame::data(ext(0x1ABC), &[0x0A]).unwrap(),
        ),
        Record::new(0, "can0", Frame::data(std(0x00F), &[]).unwrap()),
        Record::new(0, "can0", Frame::remote(std(0x123), 0).unwrap()),
        Record::new(0, "can0", Frame::remote(ext(0x1FFF_FFFF), 4).unwrap()),
        Record::new(
            0,
            "can0",
            ErrorFrame::new(error_class::CONTROLLER, [0, 0x04, 0, 0, 0, 0, 0, 0]).unwrap(),
        ),
    ];
    let mut w = CandumpWriter::new(Vec::new());
    for r in &records {
        w.write_record(r).unwrap();
    }
    let text = String::from_utf8(w.into_inner()).unwrap();
    assert_eq!(
        text,
        "(1700000000.000123) can0 123#DEADBEEF\n\
         (0000000000.005000) vcan0 00001ABC#0A\n\
         (0000000000.000000) can0 00F#\n\
         (0000000000.000000) can0 123#R\n\
         (0000000000.000000) can0 1FFFFFFF#R4\n\
         (0000000000.000000) can0 20000004#0004000000000000\n"
    );
}

#[test]
fn round_trip_microsecond_timestamps() {
    let records = vec![
        Record::new(
            1_700_000_000_000_123_000,
            "can0",
            Frame::data(std(0x7FF), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap(),
        ),
        Record::new(
            1_700_000_000_100_000_000,
            "can1",
            Frame::remote(std(0), 8).unwrap(),
        ),
        Record::new(
            1_700_000_001_000_000_000,
            "vcan-long_name.0",
            Frame::data(ext(0), &[]).unwrap(),
        ),
        Record::new(
            1_700_000_002_000_001_000,
            "can0",
            ErrorFrame::new(error_class::BUS_OFF, [0; 8]).unwrap(),
        ),
    ];
    let mut w = CandumpWriter::new(Vec::new());
    for r in &records {
        w.write_record(r).unwrap();
    }
    let bytes = w.into_inner();
    assert_eq!(read(std::str::from_utf8(&bytes).unwrap()).unwrap(), records);
    let via_detect: Vec<Record> = CaptureReader::new(bytes.as_slice())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(via_detect, records);
}

/// What other writers produce: ` T`/` R` direction flags (candump ≥ 2023, python-can 4),
/// lower-case hex, `.` separators, nanosecond fractions, `_<len8_dlc>` suffixes, CR LF and
/// blank lines.
#[test]
fn reader_tolerates_variants() {
    let text = "(1700000000.000001) can0 123#DEADBEEF R\n\
                (1700000000.000002) can0 1abcdef0#de.ad T\r\n\
                \n\
                (1700000000.123456789) can0 7ff#r7\n\
                (1700000000.5)  can1   001#1122334455667788_9\n\
                (1700000000.000003) can0 2000000a#0a00000000000000\n";
    assert_eq!(
        read(text).unwrap(),
        [
            Record::new(
                1_700_000_000_000_001_000,
                "can0",
                Frame::data(std(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap()
            ),
            Record::new(
                1_700_000_000_000_002_000,
                "can0",
                Frame::data(ext(0x1ABC_DEF0), &[0xDE, 0xAD]).unwrap()
            ),
            Record::new(
                1_700_000_000_123_456_789,
                "can0",
                Frame::remote(std(0x7FF), 7).unwrap()
            ),
            Record::new(
                1_700_000_000_500_000_000,
                "can1",
                Frame::data(std(1), &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88]).unwrap()
            ),
            Record::new(
                1_700_000_000_000_003_000,
                "can0",
                ErrorFrame::new(
                    error_class::LOST_ARBITRATION | error_class::PROTOCOL,
                    [0x0A, 0, 0, 0, 0, 0, 0, 0]
                )
                .unwrap()
            ),
        ]
    );
}

/// CAN FD (`##`) and CAN XL lines are skipped and counted, not errors.
#[test]
fn can_fd_and_xl_lines_are_skipped_and_counted() {
    let text = "(1.000000) can0 123##1DEADBEEF\n\
                (2.000000) can0 456#11\n\
                (3.000000) xl0 12345#00:01:00000000#AA\n";
    let mut r = CandumpReader::new(text.as_bytes());
    assert_eq!(
        r.read_record().unwrap(),
        Some(Record::new(
            2_000_000_000,
            "can0",
            Frame::std(0x456, &[0x11]).unwrap()
        ))
    );
    assert_eq!(r.read_record().unwrap(), None);
    assert_eq!(r.skipped(), 2);
    assert_eq!(r.line_number(), 3);
}

#[test]
fn errors_name_the_line() {
    let cases = [
        ("(1.0) can0 123#00\n1.0 can0 123#00\n", 2, "expected `(`"),
        ("(1.0 can0 123#00", 1, "`)`"),
        ("(1.x) can0 123#00", 1, "bad timestamp"),
        ("(1.0) can0", 1, "missing frame"),
        ("(1.0) can0 123", 1, "no `#`"),
        ("\n\n(1.0) can0 800#", 3, "above 0x7FF"),
        ("(1.0) can0 12#00", 1, "2 digits"),
        ("(1.0) can0 80000001#00", 1, "flag bits"),
        ("(1.0) can0 123#0", 1, "odd number"),
        ("(1.0) can0 123#001122334455667788", 1, "9 data bytes"),
        ("(1.0) can0 123#zz", 1, "not a hex byte"),
        ("(1.0) can0 123#R9", 1, "DLC"),
        ("(1.0) can0 123#00 X", 1, "unexpected text"),
        ("(1.0) can0 123#00 T extra", 1, "unexpected text"),
    ];
    for (text, line, needle) in cases {
        let err = read(text).unwrap_err();
        let Error::Line { line: got, reason } = &err else {
            panic!("{text:?}: {err}");
        };
        assert_eq!(*got, line, "{text:?}: {err}");
        assert!(reason.contains(needle), "{text:?}: {reason}");
        assert!(
            err.to_string()
                .starts_with(&format!("candump log line {line}: "))
        );
    }
}

#[test]
fn binary_garbage_and_overlong_lines_are_errors() {
    let err = CandumpReader::new(&b"(1.0) can0 123#00\n\xFF\xFE\n"[..])
        .collect::<Result<Vec<_>, _>>()
        .unwrap_err();
    assert!(matches!(err, Error::Line { line: 2, .. }), "{err}");
    let long = "a".repeat(10_000);
    let err = read(&long).unwrap_err();
    assert!(matches!(err, Error::Line { line: 1, .. }), "{err}");
}

#[test]
fn channels_the_format_cannot_carry_are_refused() {
    let frame = Frame::std(1, &[]).unwrap();
    for bad in ["", "can 0", "can\t0"] {
        let err = format_line(&Record::new(0, bad, frame)).unwrap_err();
        assert!(matches!(err, Error::BadChannel(..)), "{bad:?}: {err}");
    }
}

#[test]
fn text_is_detected_as_candump_and_empty_file_is_empty_log() {
    let r = CaptureReader::new(&b"(1.0) can0 123#00\n"[..]).unwrap();
    assert_eq!(r.format(), Format::Candump);
    assert_eq!(r.count(), 1);
    let r = CaptureReader::new(&b""[..]).unwrap();
    assert_eq!(r.format(), Format::Candump);
    assert_eq!(r.count(), 0);
    let err = CaptureReader::new(&[0u8, 1, 2, 3, 4][..]).unwrap_err();
    assert!(
        matches!(&err, Error::UnknownFormat { prefix } if prefix == &[0, 1, 2, 3]),
        "{err}"
    );
}
