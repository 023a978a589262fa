//! The seeded random source behind fault injection: [`cantwin_can::rng`]'s SplitMix64.

pub use cantwin_can::rng::SplitMix64;
