//! Generators the fuzz targets of every crate share: random bytes, numbers below a bound,
//! classic frames and mutated text, all drawn from a seeded [`SplitMix64`] so that a case
//! replays from its seed. Not part of the stable interface.

use crate::frame::Frame;
use crate::id::{Id, StandardId};
use crate::rng::SplitMix64;

/// Up to `max` random bytes (the count is random too).
pub fn bytes(rng: &mut SplitMix64, max: usize) -> Vec<u8> {
    let n = (rng.next_u64() as usize) % (max + 1);
    (0..n).map(|_| rng.next_u64() as u8).collect()
}

/// A number below `n` (0 for `n` = 0).
pub fn below(rng: &mut SplitMix64, n: u64) -> u64 {
    rng.next_u64() % n.max(1)
}

/// A random classic frame; identifiers biased to `near` (seen on the bus) when given.
pub fn frame(rng: &mut SplitMix64, near: &[u16]) -> Frame {
    let raw: u16 = match (below(rng, 4), near.is_empty()) {
        (0, _) | (_, true) => below(rng, 0x800) as u16,
        (1, false) => {
            // A request to the node whose response was seen (0x580 + n → 0x600 + n).
            let x = near[below(rng, near.len() as u64) as usize];
            0x600 | (x & 0x7F)
        }
        (2, false) => [0x000, 0x080, 0x100][below(rng, 3) as usize],
        _ => {
            let x = near[below(rng, near.len() as u64) as usize];
            (x ^ (below(rng, 4) as u16)) & 0x7FF
        }
    };
    let id = Id::standard(raw).unwrap_or(Id::Standard(StandardId::MAX));
    if below(rng, 16) == 0 {
        return Frame::remote(id, below(rng, 9) as u8)
            .unwrap_or_else(|_| Frame::data_array(id, []));
    }
    let data = bytes(rng, 8);
    Frame::data(id, &data).unwrap_or_else(|_| Frame::data_array(id, []))
}

/// Mutates text: byte flips, deletions, duplications, digit and line swaps.
pub fn mutate(rng: &mut SplitMix64, seed: &str) -> Vec<u8> {
    let mut b = seed.as_bytes().to_vec();
    for _ in 0..1 + below(rng, 8) {
        if b.is_empty() {
            b.push(rng.next_u64() as u8);
            continue;
        }
        let i = below(rng, b.len() as u64) as usize;
        match below(rng, 6) {
            0 => b[i] = rng.next_u64() as u8,
            1 => {
                let end = (i + 1 + below(rng, 64) as usize).min(b.len());
                b.drain(i..end);
            }
            2 => {
                let end = (i + 1 + below(rng, 64) as usize).min(b.len());
                let chunk = b[i..end].to_vec();
                b.splice(i..i, chunk);
            }
            3 => {
                // A digit run replaced by an extreme number.
                let n = [
                    "0",
                    "255",
                    "65535",
                    "4294967295",
                    "-1",
                    "99999999999999999999",
                    "0x7FF",
                ][below(rng, 7) as usize];
                if b[i].is_ascii_digit() {
                    let end = (i..b.len())
                        .find(|&j| !b[j].is_ascii_digit())
                        .unwrap_or(b.len());
                    b.splice(i..end, n.bytes());
                }
            }
            4 => b.insert(
                i,
                [b'\n', b'=', b'[', b']', b'"', b'#', 0][below(rng, 7) as usize],
            ),
            _ => b.truncate(i),
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_replay_from_their_seed() {
        let mut r1 = SplitMix64::new(7);
        let mut r2 = SplitMix64::new(7);
        assert_eq!(mutate(&mut r1, "a = 1\n"), mutate(&mut r2, "a = 1\n"));
        assert_eq!(frame(&mut r1, &[0x585]), frame(&mut r2, &[0x585]));
    }
}
