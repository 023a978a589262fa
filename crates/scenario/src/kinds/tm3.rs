//! `kind = "tm3"`: a Schneider TM3 CANopen bus coupler (TM3BCCO) with its expansion
//! modules, CiA 301 + CiA 401 (see `cantwin-tm3`).
//!
//! Keys:
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `node_id` | required, 1–127 | the rotary switches at power-up |
//! | `modules` | `[]` | the configured modules in bus order (at most 14), e.g. `["TM3DI16", "TM3DQ16T", "TM3AI4"]` |
//! | `optional` | `[]` | positions (1-based) whose module is optional: absent is status 3, not an error |
//! | `missing` | `[]` | positions with no module fitted at power-up (a configuration error unless optional) |
//! | `configured` | true | false: the coupler holds no configuration (bus status 3; 0xFF04 in OPERATIONAL) |
//! | `digital_inputs` | `[]` | inputs that are on: `[[module, channel], ...]`, channels from 0 |
//! | `analog_inputs` | `[]` | analog input values: `[[module, channel, value], ...]`, raw 16-bit |
//!
//! The object dictionary (and the EDS, `cantwin_tm3::eds`) follows from `modules`;
//! `[[expect]] value = …` reads it. Couplers with the same `modules` share one object
//! dictionary description (each keeps its own values), so a scenario of many alike
//! couplers builds it once.
//!
//! Signals for scripts (`[[at]] action = "set"`, `[[expect]] signal = …`), served by the
//! coupler as a twin; modules are numbered from 1, channels from 0:
//!
//! | signal | set | read | meaning |
//! |---|---|---|---|
//! | `module.M` | `"pulled"`, `"fitted"`, `"unresponsive"` | — | what is plugged in at position M: pulling a working module is a runtime error at once (EMCY 0x7003); what is fitted is checked again at the next power-up |
//! | `digital_input.M.C` | bool | — | a physical input |
//! | `analog_input.M.C` | integer | — | a physical analog input, raw 16-bit |
//! | `internal_error` | bool | — | an internal communication error on the expansion bus (EMCY 0x1000) |
//! | `rotary_switch` | integer | — | the node-ID switches (read at power-up) |
//! | `digital_output.M.C` | — | bool | the physical output, with the failure state applied |
//! | `analog_output.M.C` | — | integer | likewise, raw 16-bit |
//! | `failure_state` | — | bool | whether the outputs are at their safe positions |
//! | `nmt_state` | — | string | `"pre-operational"`, `"operational"`, `"stopped"`, `"initialising"` |

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_tm3::catalogue;
use cantwin_tm3::coupler::{CouplerConfig, Fitted, Tm3Coupler};
use cantwin_tm3::island::{Island, MAX_MODULES, ModuleSlot};
use cantwin_tm3::od::IslandDescription;
use std::sync::{Mutex, PoisonError};

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The TM3 coupler kind. It remembers the descriptions it built, to share them between
/// couplers carrying the same modules.
#[derive(Default)]
pub struct Tm3Kind {
    descriptions: Mutex<Vec<IslandDescription>>,
}

impl Tm3Kind {
    /// The description of `island`'s dictionary, built once and shared.
    fn description_for(&self, island: &Island) -> Result<IslandDescription, String> {
        // A poisoned lock only means another build panicked; the list is still valid.
        let mut known = self
            .descriptions
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(d) = known.iter().find(|d| d.fits(island)) {
            return Ok(d.clone());
        }
        let d = IslandDescription::new(island).map_err(|e| e.to_string())?;
        known.push(d.clone());
        Ok(d)
    }
}

fn positions(s: &Settings<'_>, key: &str, modules: usize) -> Result<Vec<usize>, ScenarioError> {
    let v: Vec<usize> = s.get_or(key, Vec::new())?;
    for &p in &v {
        if !(1..=modules).contains(&p) {
            return Err(s.error(
                key,
                format!("position {p} is not one of the {modules} configured modules"),
            ));
        }
    }
    Ok(v)
}

impl DeviceKind for Tm3Kind {
    fn name(&self) -> &'static str {
        "tm3"
    }

    fn summary(&self) -> &'static str {
        "Schneider TM3 CANopen bus coupler TM3BCCO with up to 14 TM3/TM2 I/O modules (CiA 401)"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let node_id: u8 = s.require("node_id")?;
        if !(1..=127).contains(&node_id) {
            return Err(s.error("node_id", "`node_id` must be 1-127"));
        }
        let refs: Vec<String> = s.get_or("modules", Vec::new())?;
        if refs.len() > MAX_MODULES {
            return Err(s.error(
                "modules",
                format!("{} modules, the coupler carries at most 14", refs.len()),
            ));
        }
        let optional = positions(s, "optional", refs.len())?;
        let missing = positions(s, "missing", refs.len())?;
        let mut slots = Vec::with_capacity(refs.len());
        for (k, r) in refs.iter().enumerate() {
            let spec = catalogue::find(r).ok_or_else(|| {
                let known: Vec<&str> = catalogue::CATALOGUE.iter().map(|m| m.reference).collect();
                s.error(
                    "modules",
                    format!("unknown module {r:?}; known: {}", known.join(", ")),
                )
            })?;
            slots.push(ModuleSlot {
                spec,
                optional: optional.contains(&(k + 1)),
            });
        }
        let island = Island::new(slots).map_err(|e| s.error("modules", e.to_string()))?;
        let mut config = CouplerConfig::new(node_id, island);
        config.configured = s.get_or("configured", true)?;
        let shared = self
            .description_for(&config.island)
            .map_err(|e| s.error("modules", format!("object dictionary: {e}")))?;
        let mut coupler = Tm3Coupler::with_description(config, &shared)
            .map_err(|e| s.error("modules", e.to_string()))?;
        for p in missing {
            // Before power-up: only what is fitted changes.
            let mut out = cantwin_can::Outbox::new();
            coupler
                .fit(p, Fitted::Empty, cantwin_can::Instant::ZERO, &mut out)
                .map_err(|e| s.error("missing", e.to_string()))?;
        }
        let di: Vec<(usize, u8)> = s.get_or("digital_inputs", Vec::new())?;
        for (m, ch) in di {
            coupler
                .set_digital_input(m, ch, true)
                .map_err(|e| s.error("digital_inputs", e.to_string()))?;
        }
        let ai: Vec<(usize, u8, i16)> = s.get_or("analog_inputs", Vec::new())?;
        for (m, ch, v) in ai {
            coupler
                .set_analog_input(m, ch, v)
                .map_err(|e| s.error("analog_inputs", e.to_string()))?;
        }
        Ok((BoxedNode::twin(coupler), PortConfig::default()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::common::testing::{read_signal, set_signal, shipped, try_build};
    use cantwin_can::{Frame, Instant};
    use cantwin_canopen::nmt::State;

    #[test]
    fn the_shipped_island_boots_takes_its_inputs_and_sets_outputs() {
        let mut built = shipped("tm3-island.toml");
        let port = built.device("island").unwrap().port;
        let listener = built.device("listener").unwrap().port;
        built.sim.run_until(Instant::from_nanos(1_000_000));
        built
            .sim
            .transmit(listener, Frame::std(0, &[1, 3]).unwrap())
            .unwrap();
        built.sim.run_until(Instant::from_nanos(2_000_000));
        built
            .sim
            .transmit(listener, Frame::std(0x203, &[0x05]).unwrap())
            .unwrap();
        built.sim.run_until(Instant::from_nanos(3_000_000));
        let c = built.sim.node::<Tm3Coupler>(port).unwrap();
        assert_eq!(c.state(), State::Operational);
        assert_eq!(c.device().od().get_unsigned(0x6000, 1), Some(0b0010_0001));
        assert_eq!(c.device().od().get_unsigned(0x6000, 4), Some(0b0001_0000));
        assert_eq!(
            c.device().od().get(0x6401, 7),
            Ok(cantwin_canopen::od::Value::Integer16(215))
        );
        assert_eq!(c.device().od().get_unsigned(0x1000, 0), Some(0x008F_0191));
        assert_eq!(c.digital_output(2, 0), Ok(true));
        assert_eq!(c.digital_output(2, 1), Ok(false));
        assert_eq!(c.digital_output(2, 2), Ok(true));
        assert_eq!(c.manufacturer_status(), 0);
    }

    const DEVICE: &str = "name = \"t\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[device]]\nname = \"io\"\nkind = \"tm3\"\nbus = \"can0\"\n";

    fn error(extra: &str) -> String {
        match build(extra) {
            Ok(_) => panic!("{extra} was accepted"),
            Err(e) => e.to_string(),
        }
    }

    fn build(extra: &str) -> Result<crate::Built, ScenarioError> {
        try_build(&(DEVICE.to_string() + extra))
    }

    #[test]
    fn settings_errors_name_the_key() {
        let e = error("node_id = 5\nmodules = [\"TM3DI8\", \"TM3XX\"]\n");
        assert!(e.contains("TM3XX") && e.contains("modules"), "{e}");
        let e = error("node_id = 5\nmodules = [\"TM3DI8\"]\nmissing = [2]\n");
        assert!(e.contains("missing") && e.contains("position 2"), "{e}");
        let e = error("node_id = 5\nmodules = [\"TM3DI8\"]\ndigital_inputs = [[1, 8]]\n");
        assert!(e.contains("digital_inputs"), "{e}");
        let e = error("node_id = 0\n");
        assert!(e.contains("node_id"), "{e}");
    }

    #[test]
    fn signals_pull_a_module_and_read_outputs_and_unknown_ones_are_refused() {
        let mut built = build("node_id = 5\nmodules = [\"TM3DI8\", \"TM3DQ8R\"]\n").unwrap();
        let port = built.device("io").unwrap().port;
        built.sim.run_until(Instant::from_nanos(1_000_000));
        use cantwin_twin::SignalValue;
        let v = |s: &str| SignalValue::Text(s.into());
        let read = |b: &crate::Built, name: &str| read_signal(b, port, name);
        let set = |b: &mut crate::Built, name: &str, value| set_signal(b, port, name, value);
        assert_eq!(read(&built, "nmt_state"), Ok(v("pre-operational")));
        set(&mut built, "module.2", v("pulled")).unwrap();
        built.sim.run_until(Instant::from_nanos(2_000_000));
        let c = built.sim.node::<Tm3Coupler>(port).unwrap();
        // Module 2 runtime error (status 2, bits 2-3), bus status 2 (bits 30-31).
        assert_eq!(c.manufacturer_status(), 0x8000_0008);
        assert_eq!(
            read(&built, "digital_output.2.0"),
            Ok(SignalValue::Bool(false))
        );
        let e = set(&mut built, "module.2", v("gone")).unwrap_err();
        assert!(e.contains("\"pulled\""), "{e}");
        let e = set(&mut built, "module.9", v("pulled")).unwrap_err();
        assert!(e.contains("no module 9"), "{e}");
        let e = read(&built, "speed").unwrap_err();
        assert!(e.contains("signals: module.M"), "{e}");
        let e = read(&built, "digital_output.2.9").unwrap_err();
        assert!(e.contains("no channel 9"), "{e}");
    }

    /// Couplers with the same modules share one description, whichever are optional or
    /// missing; a coupler with other modules gets its own. Values stay per coupler.
    #[test]
    fn couplers_with_the_same_modules_share_their_description() {
        let coupler = |name: &str, node: u8, extra: &str| {
            format!(
                "[[device]]\nname = \"{name}\"\nkind = \"tm3\"\nbus = \"can0\"\nnode_id = {node}\n{extra}\n"
            )
        };
        let text = "name = \"t\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n".to_string()
            + &coupler("a", 1, "modules = [\"TM3DI8\", \"TM3AI4\"]")
            + &coupler(
                "b",
                2,
                "modules = [\"TM3DI8\", \"TM3AI4\"]\noptional = [2]\nmissing = [2]",
            )
            + &coupler("c", 3, "modules = [\"TM3DI8\"]");
        let mut built = try_build(&text).unwrap();
        built.sim.run_until(Instant::from_nanos(1_000_000));
        let coupler = |name: &str| {
            let port = built.device(name).unwrap().port;
            built.sim.node::<Tm3Coupler>(port).unwrap()
        };
        assert!(std::sync::Arc::ptr_eq(
            coupler("a").description(),
            coupler("b").description()
        ));
        assert!(!std::sync::Arc::ptr_eq(
            coupler("a").description(),
            coupler("c").description()
        ));
        let od = |name: &str| coupler(name).device().od();
        assert_eq!(od("a").get_unsigned(0x1014, 0), Some(0x81));
        assert_eq!(od("b").get_unsigned(0x1014, 0), Some(0x82));
        // Module 2 of b is optional and absent (status 3), a's is working.
        assert_eq!(coupler("a").manufacturer_status(), 0);
        assert_eq!(coupler("b").manufacturer_status(), 0x0000_000C);
    }

    #[test]
    fn a_missing_module_is_a_configuration_error_at_power_up() {
        let mut built =
            build("node_id = 5\nmodules = [\"TM3DI8\", \"TM3DQ8R\"]\nmissing = [2]\n").unwrap();
        let port = built.device("io").unwrap().port;
        built.sim.run_until(Instant::from_nanos(1_000_000));
        let c = built.sim.node::<Tm3Coupler>(port).unwrap();
        // Module 2: status 1 (bits 2-3), bus status 1 (bits 30-31).
        assert_eq!(c.manufacturer_status(), 0x4000_0004);
    }
}
