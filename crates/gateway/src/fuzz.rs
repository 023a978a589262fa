//! The fuzz targets of the gateways' line parsers, driven by `cantwin fuzz`. Not part of the
//! stable interface.

use std::hint::black_box;

use cantwin_can::SplitMix64;
use cantwin_can::fuzz::{below, bytes, mutate};

/// Valid socketcand protocol elements the socketcand target mutates.
pub const SOCKETCAND_SEEDS: &[&str] = &[
    "< open can0 >",
    "< send 123 8 11 22 33 44 55 66 77 88 >",
    "< rawmode >",
    "< frame 123 23.424242 11 22 33 44 >",
    "< hi >",
    "< ok >",
    "< error bad >",
    "< add 1 0 123 8 11 22 33 44 55 66 77 88 >",
    "< echo >",
];

/// One case: random bytes or a mutated seed through the socketcand client and server
/// parsers.
pub fn socketcand(rng: &mut SplitMix64) {
    use crate::socketcand::wire::{parse_command, parse_server_message};
    let input = if below(rng, 4) == 0 {
        bytes(rng, 64)
    } else {
        let seed = SOCKETCAND_SEEDS[below(rng, SOCKETCAND_SEEDS.len() as u64) as usize];
        mutate(rng, seed)
    };
    let _ = black_box(parse_command(&input));
    let _ = black_box(parse_server_message(&input));
}

/// Valid slcan lines the slcan target mutates.
pub const SLCAN_SEEDS: &[&str] = &[
    "t12381122334455667788",
    "T1234567F2AABB",
    "r1230",
    "R123456780",
    "S6",
    "O",
    "C",
    "V",
    "F",
    "Z1",
];

/// One case: random bytes or a mutated seed through the slcan command and frame parsers.
pub fn slcan(rng: &mut SplitMix64) {
    use crate::slcan::wire::{parse_command, parse_frame};
    let input = if below(rng, 4) == 0 {
        bytes(rng, 40)
    } else {
        let seed = SLCAN_SEEDS[below(rng, SLCAN_SEEDS.len() as u64) as usize];
        mutate(rng, seed)
    };
    let _ = black_box(parse_command(&input));
    let _ = black_box(parse_frame(&input));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutations start from valid inputs, so the campaigns reach past the headers.
    #[test]
    fn every_seed_input_is_valid() {
        for c in SOCKETCAND_SEEDS {
            let ok = crate::socketcand::wire::parse_command(c.as_bytes()).is_ok()
                || crate::socketcand::wire::parse_server_message(c.as_bytes()).is_ok();
            assert!(ok, "{c}");
        }
        for c in SLCAN_SEEDS {
            assert!(
                crate::slcan::wire::parse_command(c.as_bytes()).is_ok(),
                "{c}"
            );
        }
    }
}
