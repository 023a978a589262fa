//! The value restrictions of the manual's object tables hold for the object, whatever SDO
//! transfer carries the value: expedited, segmented (CiA 301 §7.2.4.3.4-7) or block
//! (§7.2.4.3.9-11) downloads are refused alike with 0x06090030, and the object keeps its
//! value.
#![allow(clippy::unwrap_used)]

mod harness;

use cantwin_can::Instant;
use cantwin_tm3::coupler::Tm3Coupler;
use harness::*;

const INVALID: u32 = 0x0609_0030;

const FULL: &[&str] = &["TM3DI16", "TM3DQ16T", "TM3AI4", "TM3AQ2"];

type Writer = fn(&mut Tm3Coupler, Instant, u16, u8, &[u8]) -> Result<(), u32>;

const TRANSFERS: [(&str, Writer); 3] = [
    ("expedited", write),
    ("segmented", write_segmented),
    ("block", write_block),
];

/// Every transfer type refuses `bad` and accepts `good` for `index`/`sub`; a refused value
/// leaves the object as it was.
fn restricted(index: u16, sub: u8, good: &[u32], bad: &[u32], width: usize) {
    for (name, w) in TRANSFERS {
        let mut c = coupler(FULL);
        let t = ms(1);
        let before = read_u32(&mut c, t, index, sub).unwrap();
        for &v in bad {
            let bytes = &v.to_le_bytes()[..width];
            assert_eq!(
                w(&mut c, t, index, sub, bytes),
                Err(INVALID),
                "{name} {v:#x}"
            );
            assert_eq!(read_u32(&mut c, t, index, sub), Ok(before), "{name} {v:#x}");
        }
        for &v in good {
            let bytes = &v.to_le_bytes()[..width];
            assert_eq!(w(&mut c, t, index, sub, bytes), Ok(()), "{name} {v:#x}");
            assert_eq!(read_u32(&mut c, t, index, sub), Ok(v), "{name} {v:#x}");
        }
    }
}

#[test]
fn manual_1006_cycle_period_limits_hold_for_segmented_and_block_downloads() {
    restricted(
        0x1006,
        0,
        &[10_000, 250_000, 10_000_000, 0],
        &[1, 9_999, 10_500, 10_001_000, u32::MAX],
        4,
    );
}

#[test]
fn manual_1005_1014_no_29_bit_identifiers_on_any_transfer() {
    restricted(0x1005, 0, &[0x81], &[0x2000_0080], 4);
    // 1014H bit 31 is "reserved" (0) in the manual, not CiA 301's "EMCY not valid".
    restricted(0x1014, 0, &[0x83], &[0x2000_0083, 0x8000_0083], 4);
}

#[test]
fn manual_1016_bits_31_24_are_0_on_any_transfer() {
    restricted(0x1016, 1, &[0x0001_00FA], &[0x0101_00FA, 0x8001_00FA], 4);
}

#[test]
fn manual_1400_transmission_types_241_254_refused_on_any_transfer() {
    restricted(0x1400, 2, &[0, 240, 255], &[241, 254], 1);
}

#[test]
fn manual_1800_no_29_bit_no_rtr_and_types_241_254_refused_on_any_transfer() {
    // TPDO5 is unused (bit 31 set), so its identifier may change.
    restricted(0x1804, 1, &[0x8000_0190], &[0xA000_0190, 0xC000_0190], 4);
    restricted(0x1800, 2, &[0, 1, 240, 255], &[241, 252, 253, 254], 1);
}
