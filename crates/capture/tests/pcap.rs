//! Classic pcap with LINKTYPE_CAN_SOCKETCAN (tcpdump.org link-layer header type 227).
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::pcap::{MAX_RECORD_LEN, PcapReader, PcapWriter, Resolution};
use cantwin_capture::{CaptureReader, Error, ErrorFrame, Record, error_class};

fn sample(channel: &str) -> Vec<Record> {
    let std = |id| Id::standard(id).unwrap();
    let ext = |id| Id::extended(id).unwrap();
    vec![
        Record::new(
            1_700_000_000_000_123_456,
            channel,
            Frame::data(std(0x123), &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap(),
        ),
        Record::new(
            1_700_000_000_000_200_000,
            channel,
            Frame::data(std(0x000), &[]).unwrap(),
        ),
        Record::new(
            1_700_000_000_001_000_001,
            channel,
            Frame::data(ext(0x1FFF_FFFF), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap(),
        ),
        Record::new(
            1_700_000_001_000_000_000,
            channel,
            Frame::remote(std(0x705), 1).unwrap(),
        ),
        Record::new(
            1_700_000_001_000_000_999,
            channel,
            Frame::remote(ext(0x18DA_F110), 0).unwrap(),
        ),
        Record::new(
            1_700_000_002_999_999_999,
            channel,
            ErrorFrame::new(
                error_class::CONTROLLER | error_class::BUS_OFF,
                [0, 0x04, 0, 0, 0, 0, 0x80, 0x7F],
            )
            .unwrap(),
        ),
    ]
}

fn write(records: &[Record], resolution: Resolution) -> Vec<u8> {
    let mut w = PcapWriter::with_resolution(Vec::new(), resolution).unwrap();
    for r in records {
        w.write_record(r).unwrap();
    }
    w.into_inner()
}

fn read(bytes: &[u8]) -> Result<Vec<Record>, Error> {
    PcapReader::new(bytes)?.collect()
}

#[test]
fn round_trip_nanosecond_resolution_is_exact() {
    let records = sample("can0");
    let bytes = write(&records, Resolution::Nano);
    assert_eq!(bytes.len(), 24 + records.len() * 32);
    assert_eq!(read(&bytes).unwrap(), records);
}

#[test]
fn round_trip_microsecond_resolution_truncates_to_microseconds() {
    let records = sample("can1");
    let bytes = write(&records, Resolution::Micro);
    let reader = PcapReader::new(bytes.as_slice())
        .unwrap()
        .with_channel("can1");
    assert_eq!(reader.resolution(), Resolution::Micro);
    let back: Vec<Record> = reader.collect::<Result<_, _>>().unwrap();
    let want: Vec<Record> = records
        .into_iter()
        .map(|mut r| {
            r.timestamp_ns -= r.timestamp_ns % 1_000;
            r
        })
        .collect();
    assert_eq!(back, want);
}

/// The file header and one record, byte by byte: little-endian header fields, the
/// nanosecond magic, link type 227, and a packet whose CAN ID is big-endian with the EFF and
/// RTR flags in its top bits and the DLC in the length byte.
#[test]
fn linktype_227_record_is_byte_exact() {
    let frame = Frame::remote(Id::extended(0x0123_4567).unwrap(), 5).unwrap();
    let bytes = write(
        &[Record::new(3_000_000_007, "can0", frame)],
        Resolution::Nano,
    );
    #[rustfmt::skip]
    let want: [u8; 56] = [
        0x4D, 0x3C, 0xB2, 0xA1, // magic, nanosecond resolution, little-endian
        2, 0, 4, 0,             // version 2.4
        0, 0, 0, 0,             // thiszone
        0, 0, 0, 0,             // sigfigs
        0xFF, 0xFF, 0, 0,       // snaplen 65535
        227, 0, 0, 0,           // LINKTYPE_CAN_SOCKETCAN
        3, 0, 0, 0,             // ts_sec
        7, 0, 0, 0,             // ts_nsec
        16, 0, 0, 0,            // incl_len
        16, 0, 0, 0,            // orig_len
        0xC1, 0x23, 0x45, 0x67, // EFF | RTR | 0x01234567, big-endian
        5,                      // length: the requested DLC
        0, 0, 0,                // FD flags, reserved, len8_dlc
        0, 0, 0, 0, 0, 0, 0, 0, // no payload for a remote frame: padding
    ];
    assert_eq!(bytes, want);
}

/// A standard data frame and an error frame, built by hand in a big-endian microsecond file:
/// the reader swaps the headers but never the CAN ID, which is big-endian in both.
#[test]
fn big_endian_microsecond_file_is_read() {
    #[rustfmt::skip]
    let mut bytes = vec![
        0xA1, 0xB2, 0xC3, 0xD4, 0, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 16, 0, 0, 0, 227,
        // ts 1 s + 2 µs, 12 bytes captured (trailing padding stripped), 16 on the wire
        0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 12, 0, 0, 0, 16,
        0x00, 0x00, 0x07, 0xFF, 4, 0, 0, 0, 0xCA, 0xFE, 0xBA, 0xBE,
    ];
    #[rustfmt::skip]
    bytes.extend_from_slice(&[
        0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 16, 0, 0, 0, 16,
        0x20, 0x00, 0x00, 0x20, 8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    ]);
    let got = read(&bytes).unwrap();
    assert_eq!(
        got,
        [
            Record::new(
                1_000_002_000,
                "can0",
                Frame::std(0x7FF, &[0xCA, 0xFE, 0xBA, 0xBE]).unwrap()
            ),
            Record::new(
                2_000_000_000,
                "can0",
                ErrorFrame::new(error_class::NO_ACK, [0; 8]).unwrap()
            ),
        ]
    );
}

/// CAN FD packets (FDF flag, a length above 8, or the 72-byte CANFD_MTU) are skipped and
/// counted; the classic frames around them are read.
#[test]
fn can_fd_packets_are_skipped_and_counted() {
    let classic = Record::new(5, "can0", Frame::std(0x10, &[1]).unwrap());
    let mut bytes = write(std::slice::from_ref(&classic), Resolution::Nano);
    let mut fd = vec![0, 0, 0, 0, 0, 0, 0, 0, 72, 0, 0, 0, 72, 0, 0, 0];
    fd.extend_from_slice(&[0x00, 0x00, 0x01, 0x23, 12, 0x05, 0, 0]);
    fd.extend_from_slice(&[0xAA; 64]);
    bytes.extend_from_slice(&fd);
    bytes.extend_from_slice(&write(std::slice::from_ref(&classic), Resolution::Nano)[24..]);
    let mut reader = PcapReader::new(bytes.as_slice()).unwrap();
    assert_eq!(reader.read_record().unwrap(), Some(classic.clone()));
    assert_eq!(reader.read_record().unwrap(), Some(classic));
    assert_eq!(reader.read_record().unwrap(), None);
    assert_eq!(reader.skipped(), 1);
}

#[test]
fn other_link_types_are_rejected() {
    let mut bytes = write(&[], Resolution::Nano);
    bytes[20] = 1; // LINKTYPE_ETHERNET
    bytes[21] = 0;
    let err = PcapReader::new(bytes.as_slice()).unwrap_err();
    assert!(matches!(err, Error::LinkType { link_type: 1, .. }), "{err}");
    assert_eq!(
        err.to_string(),
        "pcap: link type 1 at byte 20 is not LINKTYPE_CAN_SOCKETCAN (227)"
    );
}

#[test]
fn truncated_files_are_errors_with_the_offset() {
    let bytes = write(&sample("can0"), Resolution::Nano);
    let err = read(&bytes[..10]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                offset: 0,
                what: "file header",
                ..
            }
        ),
        "{err}"
    );
    // Cut inside the second record's header, then inside its packet.
    let err = read(&bytes[..24 + 32 + 5]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                offset: 56,
                what: "record header",
                ..
            }
        ),
        "{err}"
    );
    let err = read(&bytes[..24 + 32 + 20]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                offset: 56,
                what: "record",
                ..
            }
        ),
        "{err}"
    );
}

/// A record header claiming 4 GB of packet is an error before anything is allocated.
#[test]
fn a_record_claiming_4_gb_is_rejected_without_allocating() {
    let mut bytes = write(&[], Resolution::Nano);
    bytes.extend_from_slice(&[
        0, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF,
    ]);
    let err = read(&bytes).unwrap_err();
    assert!(matches!(err, Error::Malformed { offset: 24, .. }), "{err}");
    assert!(err.to_string().contains(&MAX_RECORD_LEN.to_string()));
}

#[test]
fn a_packet_shorter_than_its_length_byte_is_malformed() {
    let mut bytes = write(&[], Resolution::Nano);
    bytes.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0, 10, 0, 0, 0, 10, 0, 0, 0]);
    bytes.extend_from_slice(&[0, 0, 1, 0, 8, 0, 0, 0, 1, 2]);
    let err = read(&bytes).unwrap_err();
    assert!(matches!(err, Error::Malformed { offset: 24, .. }), "{err}");
}

/// pcap has no channel field: one file per bus.
#[test]
fn a_second_channel_is_refused() {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    w.write_record(&Record::new(0, "can0", Frame::std(1, &[]).unwrap()))
        .unwrap();
    let err = w
        .write_record(&Record::new(0, "can1", Frame::std(1, &[]).unwrap()))
        .unwrap_err();
    assert!(
        matches!(&err, Error::Channel { expected, found } if expected == "can0" && found == "can1")
    );
    assert_eq!(w.into_inner().len(), 24 + 32);
}

/// Seconds beyond u32 (after 2106-02-07) cannot be written.
#[test]
fn timestamps_beyond_2106_are_refused() {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let late = (u64::from(u32::MAX) + 1) * 1_000_000_000;
    let err = w
        .write_record(&Record::new(late, "can0", Frame::std(1, &[]).unwrap()))
        .unwrap_err();
    assert!(matches!(err, Error::Timestamp { timestamp_ns, .. } if timestamp_ns == late));
}

#[test]
fn capture_reader_detects_pcap_in_either_byte_order() {
    let bytes = write(&sample("x"), Resolution::Micro);
    let reader = CaptureReader::new(bytes.as_slice())
        .unwrap()
        .with_pcap_channel("x");
    assert_eq!(reader.format(), cantwin_capture::Format::Pcap);
    assert_eq!(reader.count(), 6);
    let mut be = bytes[..24].to_vec();
    be[..4].reverse();
    be[4..6].reverse();
    be[6..8].reverse();
    be[16..20].reverse();
    be[20..24].reverse();
    let reader = CaptureReader::new(be.as_slice()).unwrap();
    assert_eq!(reader.format(), cantwin_capture::Format::Pcap);
    assert_eq!(reader.count(), 0);
}
