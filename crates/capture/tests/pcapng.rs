//! pcapng (draft-ietf-opsawg-pcapng): SHB, IDB per channel, EPB; reader for SHB/IDB/EPB/SPB.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::pcapng::{MAX_BLOCK_LEN, PcapngReader, PcapngWriter};
use cantwin_capture::{CaptureReader, Error, ErrorFrame, Format, Record, error_class};

fn records() -> Vec<Record> {
    let std = |id| Id::standard(id).unwrap();
    let ext = |id| Id::extended(id).unwrap();
    vec![
        Record::new(
            1_700_000_000_000_000_001,
            "can0",
            Frame::data(std(0x181), &[1, 2]).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_000_002,
            "vcan1",
            Frame::data(ext(0x0CFE_6CEE), &[0xFF; 8]).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_000_003,
            "can0",
            Frame::remote(std(0x701), 1).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_000_004,
            "a bus with spaces",
            Frame::data(std(0), &[]).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_000_005,
            "vcan1",
            ErrorFrame::new(error_class::PROTOCOL, [0, 0, 0x08, 0x19, 0, 0, 0, 0]).unwrap(),
        ),
        Record::new(u64::MAX, "can0", Frame::data(std(0x7FF), &[9]).unwrap()),
    ]
}

fn write(records: &[Record]) -> Vec<u8> {
    let mut w = PcapngWriter::new(Vec::new()).unwrap();
    for r in records {
        w.write_record(r).unwrap();
    }
    w.into_inner()
}

fn read(bytes: &[u8]) -> Result<Vec<Record>, Error> {
    PcapngReader::new(bytes)?.collect()
}

#[test]
fn round_trip_several_channels_nanoseconds() {
    let records = records();
    let mut w = PcapngWriter::new(Vec::new()).unwrap();
    for r in &records {
        w.write_record(r).unwrap();
    }
    assert_eq!(w.channels(), ["can0", "vcan1", "a bus with spaces"]);
    assert_eq!(read(&w.into_inner()).unwrap(), records);
}

/// SHB, then the IDB of `can0` (if_name, if_tsresol = 9) right before its first EPB.
#[test]
fn blocks_are_byte_exact() {
    let frame = Frame::data(Id::standard(0x123).unwrap(), &[0xAB]).unwrap();
    let mut w = PcapngWriter::new(Vec::new()).unwrap();
    w.write_record(&Record::new(0x1_0000_0002, "can0", frame))
        .unwrap();
    let bytes = w.into_inner();
    #[rustfmt::skip]
    let want: Vec<u8> = [
        // Section Header Block
        &[0x0A, 0x0D, 0x0D, 0x0A, 28, 0, 0, 0, 0x4D, 0x3C, 0x2B, 0x1A, 1, 0, 0, 0][..],
        &[0xFF; 8], &[28, 0, 0, 0],
        // Interface Description Block: link type 227, snaplen 0
        &[1, 0, 0, 0, 40, 0, 0, 0, 227, 0, 0, 0, 0, 0, 0, 0],
        &[2, 0, 4, 0, b'c', b'a', b'n', b'0'],  // if_name "can0"
        &[9, 0, 1, 0, 9, 0, 0, 0],               // if_tsresol 10^-9
        &[0, 0, 0, 0, 40, 0, 0, 0],              // opt_endofopt, total length
        // Enhanced Packet Block: interface 0, timestamp high/low, 16 bytes
        &[6, 0, 0, 0, 48, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 16, 0, 0, 0, 16, 0, 0, 0],
        &[0, 0, 0x01, 0x23, 1, 0, 0, 0, 0xAB, 0, 0, 0, 0, 0, 0, 0],
        &[48, 0, 0, 0],
    ]
    .concat();
    assert_eq!(bytes, want);
}

fn block(big: bool, kind: u32, body: &[u8]) -> Vec<u8> {
    let len = (12 + body.len()) as u32;
    let w = |v: u32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    [&w(kind)[..], &w(len), body, &w(len)].concat()
}

/// A big-endian file built by hand: a microsecond interface without if_name, a custom block
/// (skipped), an EPB, a Simple Packet Block (no timestamp: 0), then a second section in
/// little-endian order whose interface 0 is a different one.
#[test]
fn big_endian_sections_spb_and_unknown_blocks() {
    let be32 = |v: u32| v.to_be_bytes();
    let mut f = Vec::new();
    f.extend(block(
        true,
        0x0A0D_0D0A,
        &[&be32(0x1A2B_3C4D)[..], &[0, 1, 0, 0], &[0xFF; 8]].concat(),
    ));
    f.extend(block(true, 1, &[0, 227, 0, 0, 0, 0, 0, 16]));
    f.extend(block(true, 0x4000_0BAD, &[1, 2, 3, 4, 5, 6, 7, 8]));
    let pkt = [0x80, 0x00, 0x00, 0x42, 2, 0, 0, 0, 0x11, 0x22];
    let epb = [
        &be32(0)[..],
        &be32(0),
        &be32(2_500_000),
        &be32(10),
        &be32(16),
        &pkt,
        &[0, 0],
    ]
    .concat();
    f.extend(block(true, 6, &epb));
    let spb_pkt = [0x00, 0x00, 0x00, 0x08, 0, 0, 0, 0];
    f.extend(block(true, 3, &[&be32(8)[..], &spb_pkt].concat()));
    f.extend(block(
        false,
        0x0A0D_0D0A,
        &[&0x1A2B_3C4Du32.to_le_bytes()[..], &[1, 0, 0, 0], &[0xFF; 8]].concat(),
    ));
    f.extend(block(
        false,
        1,
        &[
            227, 0, 0, 0, 0, 0, 0, 0, 2, 0, 3, 0, b'c', b'a', b'n', 0, 0, 0, 0, 0,
        ],
    ));
    let epb = [
        &0u32.to_le_bytes()[..],
        &0u32.to_le_bytes(),
        &7u32.to_le_bytes(),
        &16u32.to_le_bytes(),
        &16u32.to_le_bytes(),
        &[0, 0, 0, 1, 0, 0, 0, 0],
        &[0; 8],
    ]
    .concat();
    f.extend(block(false, 6, &epb));

    let got = read(&f).unwrap();
    assert_eq!(
        got,
        [
            Record::new(
                2_500_000_000,
                "if0",
                Frame::data(Id::extended(0x42).unwrap(), &[0x11, 0x22]).unwrap()
            ),
            Record::new(0, "if0", Frame::std(0x008, &[]).unwrap()),
            Record::new(7_000, "can", Frame::std(0x001, &[]).unwrap()),
        ]
    );
}

#[test]
fn other_link_types_are_rejected() {
    let mut f = write(&records()[..1]);
    f[28 + 8] = 1; // the IDB's link type: LINKTYPE_ETHERNET
    let err = read(&f).unwrap_err();
    assert!(
        matches!(
            err,
            Error::LinkType {
                format: Format::Pcapng,
                offset: 28,
                link_type: 1
            }
        ),
        "{err}"
    );
}

#[test]
fn truncation_and_bad_lengths_are_errors_with_offsets() {
    let f = write(&records());
    let err = read(&f[..f.len() - 3]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                format: Format::Pcapng,
                ..
            }
        ),
        "{err}"
    );
    let err = read(&f[..5]).unwrap_err();
    assert!(matches!(err, Error::Truncated { offset: 0, .. }), "{err}");
    // Trailing length that disagrees with the leading one.
    let mut bad = f.clone();
    bad[28 + 40 + 44] = 52;
    let err = read(&bad).unwrap_err();
    assert!(matches!(err, Error::Malformed { offset: 68, .. }), "{err}");
    // A packet on an interface that was never described.
    let mut bad = f.clone();
    bad[28 + 40 + 8] = 9;
    let err = read(&bad).unwrap_err();
    assert!(matches!(err, Error::Malformed { offset: 68, .. }), "{err}");
    assert!(err.to_string().contains("undeclared interface 9"));
}

/// An EPB claiming 4 GB is refused before allocating; an unknown block of any size is
/// skipped by streaming.
#[test]
fn huge_lengths_do_not_allocate() {
    let mut f = write(&records()[..1]);
    f.extend_from_slice(&[6, 0, 0, 0, 0xFC, 0xFF, 0xFF, 0xFF]);
    let err = read(&f).unwrap_err();
    assert!(
        err.to_string().contains(&MAX_BLOCK_LEN.to_string()),
        "{err}"
    );
    let mut f = write(&records()[..1]);
    f.extend_from_slice(&[0x99, 0, 0, 0, 0xFC, 0xFF, 0xFF, 0xFF]);
    let err = read(&f).unwrap_err();
    assert!(
        matches!(err, Error::Truncated { what: "block", .. }),
        "{err}"
    );
}

#[test]
fn not_a_pcapng_file() {
    let err = PcapngReader::new(&b"hello world"[..]).unwrap_err();
    assert!(matches!(err, Error::Malformed { offset: 0, .. }), "{err}");
}

#[test]
fn capture_reader_detects_pcapng() {
    let f = write(&records());
    let reader = CaptureReader::new(f.as_slice()).unwrap();
    assert_eq!(reader.format(), Format::Pcapng);
    assert_eq!(reader.collect::<Result<Vec<_>, _>>().unwrap(), records());
}
