//! The device twins in `bench memory`: scenarios of N twins of one kind on one bus, for the
//! resident memory each further twin adds to `cantwin sim`, and the heap of a TM3 coupler's
//! CiA 301 layer measured in process.
//!
//! Each scenario keeps the keys of its shipped example in `scenarios/` and gives every twin a
//! node-ID (or MAC ID) of its own, plus the shipped examples' listener, so that a lone twin's
//! frames are acknowledged as they are with many.

use anyhow::{Context, Result};
use cantwin_scenario::{BuildEnv, Registry, Scenario};
use cantwin_tm3::island::MAX_MODULES;

/// One kind of twin measured in `cantwin sim`.
#[derive(Debug, Clone, Copy)]
pub struct TwinFleet {
    /// The table's row.
    pub what: &'static str,
    /// The twins in the large scenario: every node-ID one bus allows (MAC IDs for DeviceNet).
    pub devices: u8,
    /// The `[[device]]` keys after `kind` of the twin with node-ID (or MAC ID) `n`.
    keys: fn(u8) -> String,
    /// The scenario kind.
    kind: &'static str,
}

/// A realistic full TM3 island: the most modules the coupler carries, digital and analog,
/// TM3 before the TM2 module as they are mounted.
pub const TM3_MODULES: [&str; MAX_MODULES] = [
    "TM3DI16",
    "TM3DI16",
    "TM3DI32K",
    "TM3DQ16T",
    "TM3DQ16T",
    "TM3DQ16R",
    "TM3DM24R",
    "TM3DM8R",
    "TM3AI8",
    "TM3AI4",
    "TM3TI4",
    "TM3AQ4",
    "TM3AM6",
    "TM2DDI8DT",
];

fn tm3_keys(n: u8) -> String {
    let modules: Vec<String> = TM3_MODULES.iter().map(|m| format!("\"{m}\"")).collect();
    format!("node_id = {n}\nmodules = [{}]\n", modules.join(", "))
}

/// The worked example (§1.6) at node-ID `n` instead of 12.
fn adv200_example_keys(n: u8) -> String {
    format!(
        "example = true\nparams = {{ 4006 = {n} }}\ndigital_inputs = [4]\nanalog_inputs = [0.0, 2.5]\n"
    )
}

fn adv200_ds402_keys(n: u8) -> String {
    format!("params = {{ 4000 = \"DS402\", 4004 = \"500k\", 4006 = {n} }}\n")
}

/// The worked example's wiring on DeviceNet at MAC ID `n`.
fn adv200_devicenet_keys(n: u8) -> String {
    format!(
        "example = true\nparams = {{ 4000 = \"DeviceNet\", 4006 = {n} }}\ndigital_inputs = [4]\nanalog_inputs = [0.0, 2.5]\n"
    )
}

/// The twins `bench memory` measures besides the `cia301` devices.
pub const FLEETS: &[TwinFleet] = &[
    TwinFleet {
        what: "TM3BCCO with 14 modules",
        devices: 127,
        keys: tm3_keys,
        kind: "tm3",
    },
    TwinFleet {
        what: "ADV200, CANopen worked example",
        devices: 127,
        keys: adv200_example_keys,
        kind: "adv200",
    },
    TwinFleet {
        what: "ADV200, DS402",
        devices: 127,
        keys: adv200_ds402_keys,
        kind: "adv200",
    },
    TwinFleet {
        // The card takes MAC IDs 1-63.
        what: "ADV200, DeviceNet",
        devices: 63,
        keys: adv200_devicenet_keys,
        kind: "adv200",
    },
];

impl TwinFleet {
    /// A scenario of `devices` such twins (node-IDs 1..=devices) and a listener on one
    /// 500 kbit/s bus, the shipped examples' bit rate.
    pub fn scenario_text(&self, devices: u8) -> String {
        let mut s =
            String::from("name = \"bench\"\n\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n");
        for n in 1..=devices {
            s.push_str(&format!(
                "\n[[device]]\nname = \"twin{n}\"\nkind = \"{kind}\"\nbus = \"can0\"\n{keys}",
                kind = self.kind,
                keys = (self.keys)(n),
            ));
        }
        s.push_str(
            "\n[[device]]\nname = \"listener\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x7FF\nperiod_ms = 1000\ncount = 0\n",
        );
        s
    }
}

/// `Device::heap_bytes` of the CiA 301 device inside a TM3 coupler with the 14 modules of
/// [`FLEETS`]; the coupler builds its dictionary description for itself, which is not counted.
pub fn tm3_device_heap() -> Result<usize> {
    let fleet = FLEETS
        .iter()
        .find(|f| f.kind == "tm3")
        .context("no TM3 scenario")?;
    let scenario = Scenario::parse(&fleet.scenario_text(1), "bench-tm3.toml")?;
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let port = built.device("twin1").context("the coupler")?.port;
    built
        .sim
        .twin(port)
        .and_then(|t| t.dictionary_heap_bytes())
        .context("twin1 has no CANopen stack")
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_bus::Recorder;
    use cantwin_can::Instant;
    use std::collections::HashSet;

    #[test]
    fn every_twin_of_the_largest_scenarios_is_on_the_bus_under_its_own_identifier() {
        for fleet in FLEETS {
            let text = fleet.scenario_text(fleet.devices);
            let mut built = Scenario::parse(&text, "bench.toml")
                .unwrap()
                .build(&Registry::builtin(), &BuildEnv::default())
                .unwrap();
            assert_eq!(built.devices.len(), usize::from(fleet.devices) + 1);
            let bus = built.bus("can0").unwrap();
            let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
            // Long enough for every boot-up (CANopen) or first duplicate MAC ID check
            // (DeviceNet) at 500 kbit/s.
            built.sim.run_until(Instant::from_nanos(100_000_000));
            let rec = built.sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
            let senders: HashSet<_> = rec.frames().map(|f| f.sender).collect();
            let ids: HashSet<_> = rec.frames().map(|f| f.frame.id()).collect();
            assert_eq!(senders.len(), usize::from(fleet.devices), "{}", fleet.what);
            assert!(ids.len() >= usize::from(fleet.devices), "{}", fleet.what);
            assert_eq!(rec.errors().count(), 0, "{}", fleet.what);
        }
    }

    #[test]
    fn a_full_tm3_island_holds_more_than_a_bare_device() {
        use cantwin_canopen::device::{Device, DeviceConfig};
        use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
        use cantwin_canopen::od::OdBuilder;
        let bare = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
            .build()
            .unwrap();
        let bare = Device::new(std::sync::Arc::new(bare), DeviceConfig::new(1))
            .unwrap()
            .heap_bytes();
        // The CiA 401 objects of 14 modules (0x6000, 0x6200, 0x6401, 0x6411 and their
        // settings) hold values a bare CiA 301 device has not.
        assert!(tm3_device_heap().unwrap() > bare);
    }
}
