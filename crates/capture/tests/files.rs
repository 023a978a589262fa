//! Files: the format chosen from the extension on write, detected from the content on
//! read, and the `cantwin dump` listing.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::{
    Error, ErrorFrame, Format, Record, create, dump_file, error_class, format_record, open,
    read_all,
};
use std::path::PathBuf;

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

fn records() -> Vec<Record> {
    vec![
        Record::new(
            1_700_000_000_000_123_000,
            "can0",
            Frame::std(0x123, &[0xDE, 0xAD]).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_124_000,
            "can0",
            Frame::remote(Id::extended(0x1234_5678).unwrap(), 4).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_125_000,
            "can0",
            ErrorFrame::new(
                error_class::CONTROLLER | error_class::BUS_OFF,
                [0, 0x04, 0, 0, 0, 0, 0, 0],
            )
            .unwrap(),
        ),
    ]
}

#[test]
fn create_by_extension_and_open_by_content() {
    for (name, format) in [
        ("files.pcap", Format::Pcap),
        ("files.pcapng", Format::Pcapng),
        ("files.log", Format::Candump),
        ("files.CANDUMP", Format::Candump),
    ] {
        let p = path(name);
        let mut w = create(&p).unwrap();
        for r in records() {
            w.write_record(&r).unwrap();
        }
        w.flush().unwrap();
        drop(w);
        assert_eq!(open(&p).unwrap().format(), format, "{name}");
        assert_eq!(read_all(&p).unwrap(), records(), "{name}");
    }
}

#[test]
fn unknown_extension_is_an_error() {
    let err = create(path("files.txt")).err().unwrap();
    assert!(matches!(err, Error::UnknownExtension(_)), "{err}");
    assert_eq!(Format::from_extension("a/b.PcapNG"), Some(Format::Pcapng));
    assert_eq!(Format::from_extension("noext"), None);
}

#[test]
fn dump_lists_one_record_per_line() {
    let p = path("dump.pcapng");
    let mut w = create(&p).unwrap();
    for r in records() {
        w.write_record(&r).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    let mut out = Vec::new();
    let summary = dump_file(&p, &mut out).unwrap();
    assert_eq!(summary.records, 3);
    assert_eq!(summary.skipped, 0);
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "1700000000.000123000  can0  123#DEAD               [2]\n\
         1700000000.000124000  can0  12345678#R4            [4]  remote\n\
         1700000000.000125000  can0  20000044#0004000000000000 [8]  error: controller-problem|bus-off\n"
    );
}

#[test]
fn dump_counts_skipped_fd_frames() {
    let p = path("dump_fd.log");
    std::fs::write(&p, "(1.000000) can0 123##0AA\n(2.000000) can0 001#\n").unwrap();
    let mut out = Vec::new();
    let summary = dump_file(&p, &mut out).unwrap();
    assert_eq!((summary.records, summary.skipped), (1, 1));
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "2.000000000  can0  001#                   [0]\n# 1 CAN FD / CAN XL frames skipped\n"
    );
}

#[test]
fn error_frame_names_unknown_class_bits() {
    let r = Record::new(0, "c", ErrorFrame::new(0x1000_0001, [0; 8]).unwrap());
    assert!(format_record(&r).ends_with("error: tx-timeout|0x10000000"));
    let r = Record::new(0, "c", ErrorFrame::new(0, [0; 8]).unwrap());
    assert!(format_record(&r).ends_with("error: none"));
}

#[test]
fn open_missing_file_is_io_error() {
    let err = open(path("does-not-exist.pcap")).unwrap_err();
    assert!(matches!(err, Error::Io(_)), "{err}");
}
