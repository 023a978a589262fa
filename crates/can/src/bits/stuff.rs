//! Counting stuff bits (ISO 11898-1 §10.5) run by run rather than bit by bit.
//!
//! The rule: after five consecutive equal bits the transmitter inserts a bit of the opposite
//! value, and that stuff bit counts as the first of the next five. Take a maximal run of
//! `n` equal bits of the region. The count of equal bits in a row it starts from is
//!
//! * `c = 1` if a stuff bit comes just before it: that stuff bit complements the previous
//!   run's last bit, so it has this run's value;
//! * `c = 0` otherwise (the region's first bit, or a bit of the other value before it).
//!
//! The run's `k`-th bit makes the count `c + k`, and the first stuff bit follows the bit
//! where it reaches 5. That stuff bit has the other value, so it breaks the count: the next
//! one follows five bits later, at `c + k = 10`, then 15, and so on. So the run holds
//! `(n + c) / 5` stuff bits (integer division), and the last one follows the run's last bit,
//! starting the next run with `c = 1`, exactly when `n + c` is a multiple of 5. A stuff bit
//! after the region's last bit is still sent, before the CRC delimiter, and counted.
//!
//! A run of three bits or fewer reaches at most `c + n = 4`: it holds no stuff bit and hands
//! no carry to the next run. Only runs of four bits or more can stuff. Masks computed once
//! over the whole region give the first and the last bit of every such run, and the loop
//! below takes one iteration per such run, not one per bit: none or a few for most frames,
//! 22 for the frame with the most stuff bits. The only thing passed from one iteration to
//! the next is the carry, and it counts only when the next run starts right where the
//! previous one ended.

/// The number of stuff bits a transmitter inserts into a left-aligned bit sequence of `len`
/// bits (§10.5: after five consecutive equal bits, a complementary bit; the stuff bit starts
/// the next run). Only the first `len` bits of `bits` count, and `len` stops at 128.
pub fn count_stuff_bits(bits: u128, len: u32) -> u32 {
    if len == 0 {
        return 0;
    }
    let len = len.min(128);
    // Reversed, bit i of the word is bit i of the sequence, so the loop walks the masks from
    // the lowest bit up: a trailing-zero count and clearing the lowest set bit cost less on
    // a u128 than finding and clearing the highest one.
    let seq = bits.reverse_bits();
    let region = u128::MAX >> (128 - len);
    // Bit i is the last of its run: the next bit differs, or the region ends there.
    let ends = ((seq ^ (seq >> 1)) & (region >> 1)) | (1 << (len - 1));
    // Bit i equals bit i + 1, inside the region.
    let same = region & !ends;
    // Bits i … i + 3 are equal.
    let fours = same & (same >> 1) & (same >> 2);
    // The first and the last bit of each run of four or more: a run from s to e puts s to
    // e - 3 in `fours`, and two such runs are at least three bits apart there.
    let mut firsts = fours & !(fours << 1);
    let mut lasts = ends & (fours << 3);

    let mut stuffed = 0;
    // Whether the previous long run ended on a stuff bit, and where the run after it starts.
    let (mut carry, mut next) = (false, u32::MAX);
    while firsts != 0 {
        let first = firsts.trailing_zeros();
        let last = lasts.trailing_zeros();
        let n = last + 1 - first;
        // (n + c) / 5 stuff bits, and a carry when 5 divides n + c. With r = n mod 5 + c,
        // that is n / 5 + r / 5, and a carry when r is 0 or 5: the carry, which chains the
        // iterations, costs an add and two comparisons, and no branch.
        let c = u32::from(carry & (first == next));
        let r = n % 5 + c;
        stuffed += n / 5 + r / 5;
        carry = (r == 0) | (r == 5);
        next = last + 1;
        firsts &= firsts - 1;
        lasts &= lasts - 1;
    }
    stuffed
}

#[cfg(test)]
mod tests {
    use super::super::reference;
    use super::*;

    /// `n` copies of the bit `value`, left-aligned after `at` bits of `bits`.
    fn run(bits: u128, at: u32, n: u32, value: bool) -> u128 {
        (0..n).fold(bits, |b, i| b | (u128::from(value) << (127 - at - i)))
    }

    #[test]
    fn a_single_run_holds_one_stuff_bit_per_five_bits() {
        // n equal bits from the region's start: (n + 0) / 5 stuff bits, whatever follows.
        for n in 1..=128 {
            for value in [false, true] {
                let bits = run(0, 0, n, value);
                let after = if n < 128 { !value } else { value };
                let bits = run(bits, n, 128 - n, after);
                assert_eq!(count_stuff_bits(bits, n), n / 5, "{n} x {value}");
            }
        }
    }

    #[test]
    fn a_run_after_a_stuff_bit_starts_counting_at_one() {
        // Five zeros end on a stuff bit (a one); m ones then start their count at one.
        for m in 1..=20 {
            let (bits, len) = (run(0, 5, m, true), 5 + m);
            assert_eq!(
                count_stuff_bits(bits, len),
                1 + (m + 1) / 5,
                "then {m} ones"
            );
            assert_eq!(
                count_stuff_bits(bits, len),
                reference::count_stuff_bits(bits, len)
            );
        }
        // Six zeros do not end on a stuff bit: m ones then start at zero.
        for m in 1..=20 {
            let (bits, len) = (run(0, 6, m, true), 6 + m);
            assert_eq!(count_stuff_bits(bits, len), 1 + m / 5, "6 zeros, {m} ones");
        }
    }

    #[test]
    fn the_densest_stuffing_chains_carries_through_runs_of_four() {
        // 00000 then runs of four in alternation: every run ends on a stuff bit.
        let mut bits = 0;
        let mut value = true;
        for at in (5..125).step_by(4) {
            bits = run(bits, at, 4, value);
            value = !value;
        }
        assert_eq!(count_stuff_bits(bits, 125), 1 + 30);
        assert_eq!(reference::count_stuff_bits(bits, 125), 31);
    }

    #[test]
    fn only_the_first_len_bits_count() {
        // Zeros beyond `len`, or ones, change nothing; nor does a length beyond 128.
        assert_eq!(count_stuff_bits(0, 4), 0);
        assert_eq!(count_stuff_bits(u128::MAX >> 4, 4), 0);
        assert_eq!(count_stuff_bits(!(u128::MAX >> 4), 4), 0);
        assert_eq!(count_stuff_bits(0, 0), 0);
        assert_eq!(count_stuff_bits(0, 128), 25);
        assert_eq!(count_stuff_bits(0, u32::MAX), 25);
    }
}
