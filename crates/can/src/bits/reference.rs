//! Bit-by-bit references for the CRC-15 (ISO 11898-1 §10.4.2.6), the stuff-bit count
//! (§10.5) and the frame length, written as directly from the standard's wording as
//! possible. The fast paths of the parent module must agree with them on every input; the
//! property tests below hold them to that.

use super::{CRC15_POLY, INTERMISSION_BITS, StuffedRegion, TAIL_BITS};
use crate::frame::Frame;

/// Feed the `n` lowest bits of `value` (most significant first) into the CRC-15 register,
/// one shift of the register per bit as the standard describes it.
pub(super) fn crc15_bits(mut crc: u16, value: u64, n: u32) -> u16 {
    for i in (0..n).rev() {
        let bit = ((value >> i) & 1) as u16;
        let crc_next = bit ^ ((crc >> 14) & 1);
        crc = (crc << 1) & 0x7FFF;
        if crc_next != 0 {
            crc ^= CRC15_POLY;
        }
    }
    crc
}

/// The unstuffed region SOF … CRC, with the CRC fed bit by bit.
pub(super) fn stuffed_region(frame: &Frame) -> StuffedRegion {
    let (header, header_len) = super::header(frame);
    let mut crc = crc15_bits(0, header, header_len);
    let mut bits: u128 = u128::from(header) << (128 - header_len);
    let mut len = header_len;
    for &b in frame.data_bytes() {
        crc = crc15_bits(crc, u64::from(b), 8);
        bits |= u128::from(b) << (128 - len - 8);
        len += 8;
    }
    bits |= u128::from(crc) << (128 - len - 15);
    len += 15;
    StuffedRegion { bits, len, crc }
}

/// Stuff bits in the first `len` bits of `bits`, one bit at a time (the parent module's
/// walker, which also draws the stuffed bit stream).
pub(super) fn count_stuff_bits(bits: u128, len: u32) -> u32 {
    let mut stuffed = 0;
    super::stuff_bit_by_bit(bits, len, |_, stuff| stuffed += u32::from(stuff));
    stuffed
}

/// The frame's bits on the bus from the references above.
pub(super) fn frame_bits(frame: &Frame) -> u32 {
    let region = stuffed_region(frame);
    region.len + count_stuff_bits(region.bits, region.len) + TAIL_BITS + INTERMISSION_BITS
}

#[cfg(test)]
mod tests {
    use super::super as fast;
    use crate::Id;
    use crate::frame::Frame;
    use proptest::prelude::*;

    /// Standard and extended, data and remote frames, every DLC 0–8.
    fn any_frame() -> impl Strategy<Value = Frame> {
        let id = prop_oneof![
            (0u16..=0x7FF).prop_map(|r| Id::standard(r).unwrap()),
            (0u32..=0x1FFF_FFFF).prop_map(|r| Id::extended(r).unwrap()),
        ];
        (id, any::<bool>(), 0u8..=8, any::<[u8; 8]>()).prop_map(|(id, remote, dlc, data)| {
            if remote {
                Frame::remote(id, dlc).unwrap()
            } else {
                Frame::data(id, &data[..usize::from(dlc)]).unwrap()
            }
        })
    }

    /// Bit sequences rich in long runs, the ones that stuff: runs of 1–12 equal bits in
    /// alternation, left-aligned, with a random length cut.
    fn runs() -> impl Strategy<Value = (u128, u32)> {
        (
            proptest::collection::vec(1u32..=12, 1..40),
            any::<bool>(),
            0u32..=128,
        )
            .prop_map(|(lengths, first, len)| {
                let mut bits = 0u128;
                let mut at = 0u32;
                let mut value = first;
                for n in lengths {
                    for _ in 0..n {
                        if at < 128 {
                            bits |= u128::from(value) << (127 - at);
                            at += 1;
                        }
                    }
                    value = !value;
                }
                (bits, len)
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn frame_length_region_and_stuff_count_equal_the_reference(frame in any_frame()) {
            let region = fast::stuffed_region(&frame);
            prop_assert_eq!(region, super::stuffed_region(&frame));
            prop_assert_eq!(
                fast::count_stuff_bits(region.bits, region.len),
                super::count_stuff_bits(region.bits, region.len)
            );
            prop_assert_eq!(frame.bit_length(), super::frame_bits(&frame));
        }

        #[test]
        fn crc_equals_the_reference(crc in any::<u16>(), value in any::<u64>(), n in 0u32..=64) {
            prop_assert_eq!(fast::crc15_continue(crc, value, n), super::crc15_bits(crc, value, n));
            prop_assert_eq!(fast::crc15(value, n), super::crc15_bits(0, value, n));
        }

        #[test]
        fn stuff_count_equals_the_reference_on_random_bits(bits in any::<u128>(), len in 0u32..=128) {
            prop_assert_eq!(fast::count_stuff_bits(bits, len), super::count_stuff_bits(bits, len));
        }

        #[test]
        fn stuff_count_equals_the_reference_on_long_runs((bits, len) in runs()) {
            prop_assert_eq!(fast::count_stuff_bits(bits, len), super::count_stuff_bits(bits, len));
        }
    }
}
