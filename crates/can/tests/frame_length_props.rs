#![allow(clippy::unwrap_used)]
//! Property tests (ISO 11898-1 §10.5): every frame's length lies between its unstuffed
//! length and its worst-case stuffed length, and the computed stream round-trips.

use cantwin_can::{Frame, Id, bits};
use proptest::prelude::*;

fn any_frame() -> impl Strategy<Value = Frame> {
    let id = prop_oneof![
        (0u16..=0x7FF).prop_map(|r| Id::standard(r).unwrap()),
        (0u32..=0x1FFF_FFFF).prop_map(|r| Id::extended(r).unwrap()),
    ];
    (
        id,
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
        0u8..=8,
    )
        .prop_map(|(id, remote, data, dlc)| {
            if remote {
                Frame::remote(id, dlc).unwrap()
            } else {
                Frame::data(id, &data).unwrap()
            }
        })
}

/// Remove stuff bits from a stuffed stream, failing on a stuff violation.
fn destuff(stream: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let (mut run, mut last, mut skip) = (0, 2u8, false);
    for &b in stream {
        if skip {
            if b == last {
                return None;
            }
            skip = false;
            last = b;
            run = 1;
            continue;
        }
        out.push(b);
        if b == last {
            run += 1;
        } else {
            last = b;
            run = 1;
        }
        if run == 5 {
            skip = true;
        }
    }
    Some(out)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn length_between_unstuffed_and_worst_case(frame in any_frame()) {
        let len = frame.bit_length();
        prop_assert!(len >= bits::unstuffed_bits(&frame) + bits::INTERMISSION_BITS);
        prop_assert!(len <= bits::worst_case_bits(&frame));
    }

    #[test]
    fn stuffed_stream_has_no_run_of_six_and_destuffs(frame in any_frame()) {
        let stream = bits::stuffed_bit_stream(&frame);
        let mut run = 0;
        let mut last = 2u8;
        for &b in &stream {
            if b == last { run += 1 } else { last = b; run = 1 }
            prop_assert!(run <= 5);
        }
        prop_assert_eq!(
            stream.len() as u32 + bits::TAIL_BITS + bits::INTERMISSION_BITS,
            frame.bit_length()
        );
        let region = bits::stuffed_region(&frame);
        let plain: Vec<u8> = (0..region.len).map(|i| ((region.bits >> (127 - i)) & 1) as u8).collect();
        prop_assert_eq!(destuff(&stream), Some(plain));
    }

    #[test]
    fn crc_of_region_including_crc_is_zero(frame in any_frame()) {
        // A CRC register fed the data and then its own CRC ends at zero (§10.4.2.6).
        let region = bits::stuffed_region(&frame);
        let mut crc = 0u16;
        let mut i = 0;
        while i < region.len {
            let n = (region.len - i).min(64);
            let chunk = (region.bits << i) >> (128 - n);
            crc = bits::crc15_continue(crc, chunk as u64, n);
            i += n;
        }
        prop_assert_eq!(crc, 0);
    }
}
