//! The fuzz target of the EDS/DCF parser, driven by `cantwin fuzz`. Not part of the stable
//! interface.

use std::hint::black_box;

use cantwin_can::SplitMix64;
use cantwin_can::fuzz::{below, mutate};

/// Valid EDS files the target mutates: a drive, an I/O module, one with the quirks of
/// files in the field, and the ADV200's.
pub const SEEDS: [&str; 4] = [
    include_str!("../tests/corpus/drive.eds"),
    include_str!("../tests/corpus/io_module.eds"),
    include_str!("../tests/corpus/quirks.eds"),
    include_str!("../../adv200/eds/adv200-ds402.eds"),
];

/// One case: a mutated EDS file through the parser.
pub fn parser(rng: &mut SplitMix64) {
    let seed = SEEDS[below(rng, 4) as usize];
    let input = mutate(rng, seed);
    let _ = black_box(crate::parse_bytes(&input));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutations start from valid inputs, so the campaigns reach past the headers.
    #[test]
    fn every_seed_input_is_valid() {
        for eds in SEEDS {
            crate::parse_bytes(eds.as_bytes()).unwrap();
        }
    }
}
