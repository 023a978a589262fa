//! The fuzz targets of the scenario parser and of the twins it builds, driven by
//! `cantwin fuzz`. Not part of the stable interface.

use std::hint::black_box;

use cantwin_bus::{PortConfig, Recorder};
use cantwin_can::fuzz::{below, frame, mutate};
use cantwin_can::{Duration, Id, ListenOnly, SplitMix64};

use crate::model::Scenario;
use crate::registry::{BuildEnv, Registry};

/// The shipped scenario of the generic CiA 301 device.
pub const SCENARIO_CIA301: &str = include_str!("../../../scenarios/cia301-device.toml");
/// The shipped OPEN DRIVE scenario.
pub const SCENARIO_OPENDRIVE: &str = include_str!("../../../scenarios/opendrive.toml");
/// The shipped ADV200 DeviceNet scenario.
pub const SCENARIO_ADV200_DNET: &str = include_str!("../../../scenarios/adv200-devicenet.toml");
/// The shipped ADV200 CiA 402 scenario.
pub const SCENARIO_ADV200_DS402: &str = include_str!("../../../scenarios/adv200-ds402.toml");
/// The shipped TM3 island scenario.
pub const SCENARIO_TM3: &str = include_str!("../../../scenarios/tm3-island.toml");

/// One case: a mutated scenario file parsed and, when it parses, built.
pub fn parse_and_build(rng: &mut SplitMix64) {
    let seed = [
        SCENARIO_CIA301,
        SCENARIO_OPENDRIVE,
        SCENARIO_ADV200_DNET,
        SCENARIO_TM3,
    ][below(rng, 4) as usize];
    let input = mutate(rng, seed);
    let Ok(text) = String::from_utf8(input) else {
        return;
    };
    if let Ok(s) = Scenario::parse(&text, "fuzz.toml") {
        let _ = black_box(s.build(&Registry::builtin(), &BuildEnv::default()));
    }
}

/// One case: builds the scenario `text`, lets it run 20 ms, then sends 1–64 random frames
/// at random times over 50 ms (identifiers biased to those the twins sent) and runs 100 ms
/// more. Panics if the seed scenario itself does not parse or build.
pub fn twin(rng: &mut SplitMix64, text: &str) {
    let Ok(s) = Scenario::parse(text, "fuzz.toml") else {
        panic!("the seed scenario does not parse");
    };
    let Ok(mut built) = s.build(&Registry::builtin(), &BuildEnv::default()) else {
        panic!("the seed scenario does not build");
    };
    let Some((_, bus_id)) = built.buses.first().cloned() else {
        return;
    };
    let Some(bus) = built.sim.bus_mut(bus_id) else {
        return;
    };
    // A port that only listens (and acknowledges), through which the fuzzer sends.
    let port = bus.attach(ListenOnly, PortConfig::default().with_queue_depth(128));
    let tap = bus.add_tap(Recorder::new());
    built.sim.run_for(Duration::from_millis(20));
    let mut near: Vec<u16> = built
        .sim
        .bus(bus_id)
        .and_then(|b| b.tap::<Recorder>(tap))
        .map(|r| {
            r.frames()
                .filter_map(|f| match f.frame.id() {
                    Id::Standard(s) => Some(s.as_raw()),
                    Id::Extended(_) => None,
                })
                .collect()
        })
        .unwrap_or_default();
    near.sort_unstable();
    near.dedup();
    let n = 1 + below(rng, 64);
    let mut times: Vec<u64> = (0..n).map(|_| below(rng, 50_000_000)).collect();
    times.sort_unstable();
    let start = built.sim.now();
    for t in times {
        built.sim.run_until(start + Duration::from_nanos(t));
        let f = frame(rng, &near);
        // A full queue is an answer too (the frame is dropped and counted).
        let _ = built.sim.transmit(port, f);
    }
    built.sim.run_for(Duration::from_millis(100));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutations start from valid inputs, so the campaigns reach past the headers.
    #[test]
    fn every_seed_input_is_valid() {
        for s in [
            SCENARIO_CIA301,
            SCENARIO_OPENDRIVE,
            SCENARIO_ADV200_DNET,
            SCENARIO_ADV200_DS402,
            SCENARIO_TM3,
        ] {
            Scenario::parse(s, "seed.toml")
                .unwrap()
                .build(&Registry::builtin(), &BuildEnv::default())
                .unwrap();
        }
    }
}
