//! The CRC-15 of classic CAN (ISO 11898-1 §10.4.2.6; CAN 2.0 part A §3.1.1.6), a byte at a
//! time through a 256-entry table.
//!
//! The standard defines the CRC as a 15-bit shift register fed one bit at a time: the next
//! bit XOR the register's top bit decides whether the polynomial is XORed in after the shift.
//! The register is linear, so feeding `k ≤ 8` bits `v` is the same as XORing `v` into the
//! register's top `k` bits and then shifting `k` times with zero input. The low `15 - k` bits
//! only move up during those shifts and never reach the top before the last one, so they
//! cannot trigger a feedback: all feedback comes from the top `k` bits, and its effect is the
//! table entry of those bits. The table lists, for every byte `i`, the register `i << 7`
//! after eight zero-input shifts. For `k < 8` the same entry serves: `k` top bits `x` are
//! the register `x << 7` after `8 - k` shifts, which move them up without feedback.

/// The CRC-15 generator polynomial x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1 (§10.4.2.6).
pub const CRC15_POLY: u16 = 0x4599;

/// The 15 bits of the CRC register.
const MASK: u16 = 0x7FFF;

/// For every byte `i`: the register `i << 7` after eight shifts with zero input.
static TABLE: [u16; 256] = table();

const fn table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 7;
        let mut shift = 0;
        while shift < 8 {
            let feedback = crc & 0x4000 != 0;
            crc = (crc << 1) & MASK;
            if feedback {
                crc ^= CRC15_POLY;
            }
            shift += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// Feed the `k` (1 to 8) lowest bits of `v` (most significant first) into the register: the
/// register's top `k` bits XOR `v` select the feedback, the rest shifts up by `k`. Only the
/// register's low 15 bits take part, as in the bit-serial register.
fn step(crc: u16, v: u8, k: u32) -> u16 {
    let top = ((u32::from(crc) >> (15 - k)) ^ u32::from(v)) & ((1 << k) - 1);
    ((crc << k) & MASK) ^ TABLE[usize::from(top as u8)]
}

/// Feed the `n` lowest bits of `value` (most significant first) into the CRC-15 register:
/// the `n mod 8` leading bits in one partial step, then whole bytes. Bits above bit 63 are
/// taken as zero.
pub(super) fn crc15_bits(mut crc: u16, value: u64, n: u32) -> u16 {
    let mut left = n - n % 8;
    if n % 8 != 0 {
        crc = step(crc, value.checked_shr(left).unwrap_or(0) as u8, n % 8);
    }
    while left > 0 {
        left -= 8;
        crc = step(crc, value.checked_shr(left).unwrap_or(0) as u8, 8);
    }
    crc
}

/// Feed one byte into the CRC-15 register.
pub(super) fn crc15_byte(crc: u16, byte: u8) -> u16 {
    step(crc, byte, 8)
}

/// The CRC-15 of a bit sequence given as the `n` lowest bits of `value`, most significant
/// first (n ≤ 64; call repeatedly through [`crc15_continue`] for longer sequences; a larger
/// `n` feeds zeros ahead of the 64 bits).
pub fn crc15(value: u64, n: u32) -> u16 {
    crc15_bits(0, value, n)
}

/// Continue a CRC-15 computation with `n` more bits.
pub fn crc15_continue(crc: u16, value: u64, n: u32) -> u16 {
    crc15_bits(crc, value, n)
}

#[cfg(test)]
mod tests {
    use super::super::reference;
    use super::*;

    #[test]
    fn check_value_of_the_standard_catalogue() {
        // CRC-15/CAN (poly 0x4599, init 0, no reflection, no final XOR) of the ASCII
        // string "123456789" is 0x059E.
        let bytes = b"123456789".iter().fold(0, |crc, &b| crc15_byte(crc, b));
        assert_eq!(bytes, 0x059E);
        let words = crc15_continue(crc15(0x3132_3334_3536_3738, 64), 0x39, 8);
        assert_eq!(words, 0x059E);
    }

    #[test]
    fn every_partial_step_equals_the_bit_serial_register() {
        // Widths 1-8: every register value (bit 15 included, which the serial register
        // drops) with the inputs all zeros and all ones, and every input with registers
        // spread over the whole range.
        let check = |crc: u16, v: u16, k: u32| {
            assert_eq!(
                step(crc, v as u8, k),
                reference::crc15_bits(crc, u64::from(v), k),
                "crc {crc:#06x}, {k} bits {v:#x}"
            );
        };
        for k in 1..=8u32 {
            for crc in 0..=u16::MAX {
                check(crc, 0, k);
                check(crc, (1 << k) - 1, k);
            }
            for v in 0..(1u16 << k) {
                for crc in (0..=u16::MAX).step_by(251) {
                    check(crc, v, k);
                }
            }
        }
    }

    #[test]
    fn no_bits_leave_the_register_as_it_is() {
        assert_eq!(crc15_continue(0xFFFF, u64::MAX, 0), 0xFFFF);
        assert_eq!(crc15(u64::MAX, 0), 0);
    }

    #[test]
    fn lengths_beyond_64_bits_feed_leading_zeros() {
        let zeros_first = crc15_continue(crc15_continue(0x1234, 0, 8), u64::MAX, 64);
        assert_eq!(crc15_continue(0x1234, u64::MAX, 72), zeros_first);
    }
}
