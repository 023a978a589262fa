//! SDO block transfer conformance (CiA 301 §7.2.4.3.9–7.2.4.3.16): exact frames.
#![allow(clippy::unwrap_used)]

mod sdo_harness;

use cantwin_canopen::AbortCode;
use cantwin_canopen::od::Value;
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_canopen::sdo::wire::{BlockSegment, Response};
use sdo_harness::*;

fn seg(last: bool, seqno: u8, data: &[u8]) -> [u8; 8] {
    let mut d = [0u8; 7];
    d[..data.len()].copy_from_slice(data);
    BlockSegment {
        last,
        seqno,
        data: d,
    }
    .encode()
}

fn crc_bytes(data: &[u8]) -> [u8; 2] {
    Crc16::of(data).to_le_bytes()
}

// ---- block download ----

#[test]
fn cia301_7_2_4_3_9_block_download_of_0_bytes() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xC6, 0x03, 0x20, 0x00, 0, 0, 0, 0]),
        [0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]
    );
    assert_eq!(h.one(seg(true, 1, &[])), [0xA2, 1, 127, 0, 0, 0, 0, 0]);
    // n = 7: the last segment carries no data; the CRC of nothing is 0.
    assert_eq!(
        h.one([0xDD, 0, 0, 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(vec![])));
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_3_9_block_download_of_1_byte() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xC6, 0x03, 0x20, 0x00, 1, 0, 0, 0]),
        [0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]
    );
    assert_eq!(h.one(seg(true, 1, &[0xAB])), [0xA2, 1, 127, 0, 0, 0, 0, 0]);
    let c = crc_bytes(&[0xAB]);
    assert_eq!(
        h.one([0xD9, c[0], c[1], 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(vec![0xAB])));
}

#[test]
fn cia301_7_2_4_3_9_block_download_of_7_bytes() {
    let mut h = Harness::new();
    let data = pattern(7);
    h.one([0xC6, 0x03, 0x20, 0x00, 7, 0, 0, 0]);
    assert_eq!(h.one(seg(true, 1, &data)), [0xA2, 1, 127, 0, 0, 0, 0, 0]);
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xC1, c[0], c[1], 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_9_block_download_of_8_bytes() {
    let mut h = Harness::new();
    let data = pattern(8);
    h.one([0xC6, 0x03, 0x20, 0x00, 8, 0, 0, 0]);
    assert!(h.req(seg(false, 1, &data[..7])).is_empty());
    assert_eq!(
        h.one(seg(true, 2, &data[7..])),
        [0xA2, 2, 127, 0, 0, 0, 0, 0]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xD9, c[0], c[1], 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_9_block_download_of_889_bytes_is_one_full_block() {
    let mut h = Harness::new();
    let data = pattern(889);
    let frames = h.block_download(0x2003, 0, &data, true).unwrap();
    assert_eq!(
        frames,
        [
            [0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0],
            [0xA2, 127, 127, 0, 0, 0, 0, 0],
            [0xA1, 0, 0, 0, 0, 0, 0, 0]
        ]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_9_block_download_of_100000_bytes() {
    let mut h = Harness::new();
    let data = pattern(100_000);
    let frames = h.block_download(0x2003, 0, &data, true).unwrap();
    // 14 286 segments: 112 full blocks of 127 and one of 62.
    assert_eq!(frames.len(), 1 + 113 + 1);
    assert!(
        frames[1..113]
            .iter()
            .all(|f| *f == [0xA2, 127, 127, 0, 0, 0, 0, 0])
    );
    assert_eq!(frames[113], [0xA2, 62, 127, 0, 0, 0, 0, 0]);
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_9_block_download_without_crc() {
    let mut h = Harness::new();
    // cc = 0: the client does not use CRC; the CRC field is not checked.
    assert_eq!(
        h.one([0xC2, 0x03, 0x20, 0x00, 1, 0, 0, 0]),
        [0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]
    );
    h.one(seg(true, 1, &[5]));
    assert_eq!(
        h.one([0xD9, 0, 0, 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(vec![5])));
}

#[test]
fn cia301_7_2_4_3_9_block_download_to_a_fixed_size_object() {
    let mut h = Harness::new();
    let v = 0x0102_0304_0506_0708u64.to_le_bytes();
    h.block_download(0x2005, 0, &v, true).unwrap();
    assert_eq!(
        h.access.get(0x2005, 0),
        Ok(Value::Unsigned64(0x0102_0304_0506_0708))
    );
}

#[test]
fn cia301_7_2_4_3_10_server_block_size_is_negotiated() {
    let mut h = Harness::new();
    h.server.set_block_size(4);
    let data = pattern(40);
    let frames = h.block_download(0x2003, 0, &data, true).unwrap();
    assert_eq!(
        frames,
        [
            [0xA4, 0x03, 0x20, 0x00, 4, 0, 0, 0],
            [0xA2, 4, 4, 0, 0, 0, 0, 0],
            [0xA2, 2, 4, 0, 0, 0, 0, 0],
            [0xA1, 0, 0, 0, 0, 0, 0, 0]
        ]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_10_lost_segment_is_repeated_after_ackseq() {
    let mut h = Harness::new();
    h.server.set_block_size(4);
    let data = pattern(30); // segments of 7, 7, 7, 7, 2
    h.one([0xC6, 0x03, 0x20, 0x00, 30, 0, 0, 0]);
    assert!(h.req(seg(false, 1, &data[0..7])).is_empty());
    assert!(h.req(seg(false, 2, &data[7..14])).is_empty());
    // Segment 3 is lost; segment 4 ends the block out of sequence.
    assert_eq!(
        h.one(seg(false, 4, &data[21..28])),
        [0xA2, 2, 4, 0, 0, 0, 0, 0]
    );
    // The client continues after ackseq, numbering from 1 again.
    assert!(h.req(seg(false, 1, &data[14..21])).is_empty());
    assert!(h.req(seg(false, 2, &data[21..28])).is_empty());
    assert_eq!(
        h.one(seg(true, 3, &data[28..30])),
        [0xA2, 3, 4, 0, 0, 0, 0, 0]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xD5, c[0], c[1], 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_10_repeated_segment_is_ignored() {
    let mut h = Harness::new();
    let data = pattern(14);
    h.one([0xC6, 0x03, 0x20, 0x00, 14, 0, 0, 0]);
    assert!(h.req(seg(false, 1, &data[0..7])).is_empty());
    assert!(h.req(seg(false, 1, &data[0..7])).is_empty());
    assert_eq!(
        h.one(seg(true, 2, &data[7..14])),
        [0xA2, 2, 127, 0, 0, 0, 0, 0]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xC1, c[0], c[1], 0, 0, 0, 0, 0]),
        [0xA1, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}

#[test]
fn cia301_7_2_4_3_17_block_download_invalid_sequence_number() {
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 30, 0, 0, 0]);
    assert_eq!(
        h.one(seg(false, 0, &[1; 7])),
        [0x80, 0x03, 0x20, 0x00, 0x03, 0x00, 0x04, 0x05]
    );
    let mut h = Harness::new();
    h.server.set_block_size(4);
    h.one([0xC6, 0x03, 0x20, 0x00, 30, 0, 0, 0]);
    h.req(seg(false, 1, &[1; 7]));
    assert_eq!(
        h.one(seg(false, 5, &[1; 7])),
        abort(0x2003, 0, AbortCode::INVALID_SEQUENCE_NUMBER)
    );
    assert_eq!(h.access.staged(), b"");
}

#[test]
fn cia301_7_2_4_3_17_block_download_crc_error() {
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 1, 0, 0, 0]);
    h.one(seg(true, 1, &[0xAB]));
    let c = Crc16::of(&[0xAB]) ^ 1;
    assert_eq!(
        h.one([0xD9, c as u8, (c >> 8) as u8, 0, 0, 0, 0, 0]),
        [0x80, 0x03, 0x20, 0x00, 0x04, 0x00, 0x04, 0x05]
    );
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(vec![])));
}

#[test]
fn cia301_7_2_4_3_11_block_download_end_must_follow_the_last_block() {
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 1, 0, 0, 0]);
    h.one(seg(true, 1, &[0xAB]));
    // Another segment where the end frame was due.
    assert_eq!(
        h.one(seg(false, 1, &[0xAB])),
        abort(0x2003, 0, AbortCode::INVALID_COMMAND)
    );
}

#[test]
fn cia301_7_2_4_3_11_block_download_size_mismatch() {
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 2, 0, 0, 0]);
    h.one(seg(true, 1, &[0xAB]));
    let c = crc_bytes(&[0xAB]);
    assert_eq!(
        h.one([0xD9, c[0], c[1], 0, 0, 0, 0, 0]),
        abort(0x2003, 0, AbortCode::LENGTH_TOO_LOW)
    );
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 2, 0, 0, 0]);
    assert!(h.req(seg(false, 1, &[1; 7])).is_empty());
    assert_eq!(
        h.one(seg(true, 2, &[1; 7])),
        abort(0x2003, 0, AbortCode::LENGTH_TOO_HIGH)
    );
}

#[test]
fn cia301_7_2_4_3_17_abort_from_the_client_during_a_block_download() {
    let mut h = Harness::new();
    h.one([0xC6, 0x03, 0x20, 0x00, 30, 0, 0, 0]);
    h.req(seg(false, 1, &[1; 7]));
    h.req(seg(false, 2, &[1; 7]));
    assert!(
        h.req([0x80, 0x03, 0x20, 0x00, 0x00, 0x00, 0x00, 0x08])
            .is_empty()
    );
    assert!(h.server.is_idle());
    assert_eq!(h.access.staged(), b"");
}

// ---- block upload ----

#[test]
fn cia301_7_2_4_3_12_block_upload_of_0_bytes() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]),
        [0xC6, 0x03, 0x20, 0x00, 0, 0, 0, 0]
    );
    assert_eq!(
        h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]),
        [[0x81, 0, 0, 0, 0, 0, 0, 0]]
    );
    assert_eq!(
        h.one([0xA2, 1, 127, 0, 0, 0, 0, 0]),
        [0xDD, 0, 0, 0, 0, 0, 0, 0]
    );
    assert!(h.req([0xA1, 0, 0, 0, 0, 0, 0, 0]).is_empty());
    assert!(h.server.is_idle());
    assert_eq!(h.server.next_deadline(), None);
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_1_byte() {
    let mut h = Harness::new();
    h.download(0x2003, 0, &[0xAB]).unwrap();
    assert_eq!(
        h.one([0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]),
        [0xC6, 0x03, 0x20, 0x00, 1, 0, 0, 0]
    );
    assert_eq!(
        h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]),
        [[0x81, 0xAB, 0, 0, 0, 0, 0, 0]]
    );
    let c = crc_bytes(&[0xAB]);
    assert_eq!(
        h.one([0xA2, 1, 127, 0, 0, 0, 0, 0]),
        [0xD9, c[0], c[1], 0, 0, 0, 0, 0]
    );
    assert!(h.req([0xA1, 0, 0, 0, 0, 0, 0, 0]).is_empty());
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_7_bytes() {
    let mut h = Harness::new();
    let data = pattern(7);
    h.download(0x2003, 0, &data).unwrap();
    assert_eq!(
        h.one([0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]),
        [0xC6, 0x03, 0x20, 0x00, 7, 0, 0, 0]
    );
    assert_eq!(h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]), [seg(true, 1, &data)]);
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xA2, 1, 127, 0, 0, 0, 0, 0]),
        [0xC1, c[0], c[1], 0, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_8_bytes() {
    let mut h = Harness::new();
    let data = pattern(8);
    h.download(0x2003, 0, &data).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]);
    assert_eq!(
        h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]),
        [seg(false, 1, &data[..7]), seg(true, 2, &data[7..])]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xA2, 2, 127, 0, 0, 0, 0, 0]),
        [0xD9, c[0], c[1], 0, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_889_bytes_is_one_full_block() {
    let mut h = Harness::new();
    let data = pattern(889);
    h.download(0x2003, 0, &data).unwrap();
    let (got, frames) = h.block_upload(0x2003, 0, 127, true).unwrap();
    assert_eq!(got, data);
    // Initiate response, 127 segments, end.
    assert_eq!(frames.len(), 129);
    assert_eq!(frames[127][0], 0xFF);
    let c = crc_bytes(&data);
    assert_eq!(frames[128], [0xC1, c[0], c[1], 0, 0, 0, 0, 0]);
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_100000_bytes() {
    let mut h = Harness::new();
    let data = pattern(100_000);
    h.block_download(0x2003, 0, &data, true).unwrap();
    let (got, frames) = h.block_upload(0x2003, 0, 127, true).unwrap();
    assert_eq!(got, data);
    assert_eq!(frames.len(), 1 + 14_286 + 1);
    let c = crc_bytes(&data);
    assert_eq!(frames[14_287], [0xC9, c[0], c[1], 0, 0, 0, 0, 0]);
}

#[test]
fn cia301_7_2_4_3_12_block_upload_without_crc_sends_zero() {
    let mut h = Harness::new();
    h.download(0x2003, 0, &[1, 2, 3]).unwrap();
    // cc = 0; the server still says it supports CRC (sc = 1) but does not use it.
    assert_eq!(
        h.one([0xA0, 0x03, 0x20, 0x00, 127, 0, 0, 0]),
        [0xC6, 0x03, 0x20, 0x00, 3, 0, 0, 0]
    );
    h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        h.one([0xA2, 1, 127, 0, 0, 0, 0, 0]),
        [0xD1, 0, 0, 0, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_13_client_block_size_is_used_and_can_change() {
    let mut h = Harness::new();
    let data = pattern(50); // 8 segments
    h.download(0x2003, 0, &data).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 3, 0, 0, 0]);
    let b1 = h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        b1,
        [
            seg(false, 1, &data[0..7]),
            seg(false, 2, &data[7..14]),
            seg(false, 3, &data[14..21])
        ]
    );
    let b2 = h.req([0xA2, 3, 2, 0, 0, 0, 0, 0]);
    assert_eq!(
        b2,
        [seg(false, 1, &data[21..28]), seg(false, 2, &data[28..35])]
    );
    let b3 = h.req([0xA2, 2, 5, 0, 0, 0, 0, 0]);
    assert_eq!(
        b3,
        [
            seg(false, 1, &data[35..42]),
            seg(false, 2, &data[42..49]),
            seg(true, 3, &data[49..50])
        ]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xA2, 3, 5, 0, 0, 0, 0, 0]),
        [0xD9, c[0], c[1], 0, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_13_server_repeats_segments_after_ackseq() {
    let mut h = Harness::new();
    let data = pattern(30); // 7, 7, 7, 7, 2
    h.download(0x2003, 0, &data).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 4, 0, 0, 0]);
    assert_eq!(h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]).len(), 4);
    // The client got segments 1 and 2 only.
    assert_eq!(
        h.req([0xA2, 2, 4, 0, 0, 0, 0, 0]),
        [
            seg(false, 1, &data[14..21]),
            seg(false, 2, &data[21..28]),
            seg(true, 3, &data[28..30])
        ]
    );
    // Lost the last one: repeat it alone.
    assert_eq!(
        h.req([0xA2, 2, 4, 0, 0, 0, 0, 0]),
        [seg(true, 1, &data[28..30])]
    );
    let c = crc_bytes(&data);
    assert_eq!(
        h.one([0xA2, 1, 4, 0, 0, 0, 0, 0]),
        [0xD5, c[0], c[1], 0, 0, 0, 0, 0]
    );
    assert!(h.req([0xA1, 0, 0, 0, 0, 0, 0, 0]).is_empty());
}

#[test]
fn cia301_7_2_4_3_12_protocol_switch_to_expedited_upload() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xA4, 0x00, 0x10, 0x00, 127, 21, 0, 0]),
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_3_12_protocol_switch_to_segmented_upload() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xA4, 0x08, 0x10, 0x00, 127, 7, 0, 0]),
        [0x41, 0x08, 0x10, 0x00, 7, 0, 0, 0]
    );
    assert_eq!(h.one([0x60, 0, 0, 0, 0, 0, 0, 0]), {
        let mut b = [0x01, 0, 0, 0, 0, 0, 0, 0];
        b[1..].copy_from_slice(b"cantwin");
        b
    });
    // Above the threshold, a block upload.
    assert_eq!(
        h.one([0xA4, 0x08, 0x10, 0x00, 127, 6, 0, 0]),
        [0xC6, 0x08, 0x10, 0x00, 7, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_17_block_upload_invalid_block_size() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xA4, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        [0x80, 0x00, 0x10, 0x00, 0x02, 0x00, 0x04, 0x05]
    );
    assert_eq!(
        h.one([0xA4, 0x00, 0x10, 0x00, 128, 0, 0, 0]),
        abort(0x1000, 0, AbortCode::INVALID_BLOCK_SIZE)
    );
    h.download(0x2003, 0, &pattern(20)).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 2, 0, 0, 0]);
    h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        h.one([0xA2, 2, 0, 0, 0, 0, 0, 0]),
        abort(0x2003, 0, AbortCode::INVALID_BLOCK_SIZE)
    );
}

#[test]
fn cia301_7_2_4_3_17_block_upload_ackseq_above_what_was_sent() {
    let mut h = Harness::new();
    h.download(0x2003, 0, &pattern(20)).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 2, 0, 0, 0]);
    h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        h.one([0xA2, 3, 2, 0, 0, 0, 0, 0]),
        abort(0x2003, 0, AbortCode::INVALID_SEQUENCE_NUMBER)
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_start_must_follow_the_initiate() {
    let mut h = Harness::new();
    h.one([0xA4, 0x08, 0x10, 0x00, 127, 0, 0, 0]);
    assert_eq!(
        h.one([0xA2, 0, 127, 0, 0, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::INVALID_COMMAND)
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_a_write_only_object() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xA4, 0x02, 0x20, 0x00, 127, 0, 0, 0]),
        abort(0x2002, 0, AbortCode::WRITE_ONLY)
    );
}

#[test]
fn cia301_7_2_4_3_14_block_upload_end_decodes() {
    let r = Response::decode(&[0xD9, 0x34, 0x12, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(
        r,
        Response::BlockUploadEnd {
            unused: 6,
            crc: 0x1234
        }
    );
}
