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
//! Signals for scripts (`[[at]] action = "set"`, `[[expect]] signal = …`); modules are
//! numbered from 1, channels from 0:
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

use cantwin_bus::{AnyNode, PortConfig, PortId, Simulation};
use cantwin_canopen::nmt::State;
use cantwin_tm3::catalogue;
use cantwin_tm3::coupler::{CouplerConfig, Fitted, Tm3Coupler};
use cantwin_tm3::island::{Island, MAX_MODULES, ModuleSlot};
use cantwin_tm3::od::IslandDescription;
use std::sync::{Mutex, PoisonError};

use crate::build::BuildEnv;
use crate::error::ScenarioError;
use crate::kinds::common::{signal_bool, signal_indices, signal_int};
use crate::live::{LiveValue, Role};
use crate::model::BusSpec;
use crate::registry::{DeviceKind, Settings};

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

const SIGNALS: &str = "module.M, digital_input.M.C, analog_input.M.C, internal_error, rotary_switch (set); digital_output.M.C, analog_output.M.C, failure_state, nmt_state (read)";

/// `prefix.M.C` as (module, channel).
fn module_channel(name: &str, prefix: &str) -> Option<(usize, u8)> {
    match signal_indices(name, prefix)?.as_slice() {
        [m, c] => Some((usize::try_from(*m).ok()?, u8::try_from(*c).ok()?)),
        _ => None,
    }
}

fn unknown(name: &str) -> String {
    format!("a tm3 device has no signal {name:?} (signals: {SIGNALS})")
}

impl DeviceKind for Tm3Kind {
    fn name(&self) -> &'static str {
        "tm3"
    }

    fn read_object(&self, sim: &Simulation, port: PortId, index: u16, sub: u8) -> Option<Vec<u8>> {
        let c = sim.node::<Tm3Coupler>(port)?;
        c.device()
            .od()
            .get(index, sub)
            .ok()
            .map(|v| v.to_le_bytes())
    }

    fn set_signal(
        &self,
        sim: &mut Simulation,
        port: PortId,
        name: &str,
        value: &toml::Value,
    ) -> Result<(), String> {
        let bus = sim
            .bus_mut(port.bus())
            .ok_or_else(|| "the device's bus is gone".to_string())?;
        let r = bus.with_node::<Tm3Coupler, _>(port, |c, now, out| -> Result<(), String> {
            if let Some(m) = signal_indices(name, "module").and_then(|v| match v.as_slice() {
                [m] => usize::try_from(*m).ok(),
                _ => None,
            }) {
                let configured = m
                    .checked_sub(1)
                    .and_then(|i| c.config().island.modules().get(i))
                    .map(|slot| slot.spec)
                    .ok_or_else(|| format!("no module {m}"))?;
                let what = match value.as_str() {
                    Some("pulled") => Fitted::Empty,
                    Some("fitted") => Fitted::Module(configured),
                    Some("unresponsive") => Fitted::Unresponsive,
                    _ => {
                        return Err(format!(
                            "signal {name:?} takes \"pulled\", \"fitted\" or \"unresponsive\", not {value}"
                        ));
                    }
                };
                return c.fit(m, what, now, out).map_err(|e| e.to_string());
            }
            if let Some((m, ch)) = module_channel(name, "digital_input") {
                return c
                    .set_digital_input(m, ch, signal_bool(name, value)?)
                    .map_err(|e| e.to_string());
            }
            if let Some((m, ch)) = module_channel(name, "analog_input") {
                return c
                    .set_analog_input(m, ch, signal_int(name, value)?)
                    .map_err(|e| e.to_string());
            }
            match name {
                "internal_error" => {
                    c.set_internal_error(signal_bool(name, value)?, now, out);
                    Ok(())
                }
                "rotary_switch" => {
                    let id: u8 = signal_int(name, value)?;
                    if !(1..=127).contains(&id) {
                        return Err(format!("signal {name:?} takes 1-127, not {id}"));
                    }
                    c.set_rotary_switch(id, now, out);
                    Ok(())
                }
                _ => Err(unknown(name)),
            }
        });
        r.ok_or_else(|| "not a tm3 coupler".to_string())?
    }

    fn read_signal(
        &self,
        sim: &Simulation,
        port: PortId,
        name: &str,
    ) -> Result<toml::Value, String> {
        let c = sim
            .node::<Tm3Coupler>(port)
            .ok_or_else(|| "not a tm3 coupler".to_string())?;
        if let Some((m, ch)) = module_channel(name, "digital_output") {
            return c
                .digital_output(m, ch)
                .map(toml::Value::Boolean)
                .map_err(|e| e.to_string());
        }
        if let Some((m, ch)) = module_channel(name, "analog_output") {
            return c
                .analog_output(m, ch)
                .map(|v| toml::Value::Integer(i64::from(v)))
                .map_err(|e| e.to_string());
        }
        match name {
            "failure_state" => Ok(toml::Value::Boolean(c.in_failure_state())),
            "nmt_state" => Ok(toml::Value::String(
                match c.state() {
                    State::Initialising => "initialising",
                    State::PreOperational => "pre-operational",
                    State::Operational => "operational",
                    State::Stopped => "stopped",
                }
                .to_string(),
            )),
            _ => Err(unknown(name)),
        }
    }

    fn summary(&self) -> &'static str {
        "Schneider TM3 CANopen bus coupler TM3BCCO with up to 14 TM3/TM2 I/O modules (CiA 401)"
    }

    /// Every channel of every configured module, named as the signals are
    /// (`digital_input.M.C`, `digital_output.M.C`, `analog_input.M.C`, `analog_output.M.C`:
    /// module 1-based as in the scenario, channel 0-based), analog values in raw 16-bit counts.
    fn live_values(
        &self,
        sim: &cantwin_bus::Simulation,
        port: cantwin_bus::PortId,
    ) -> Vec<LiveValue> {
        let Some(c) = sim.node::<Tm3Coupler>(port) else {
            return Vec::new();
        };
        let mut v = Vec::new();
        for (k, slot) in c.config().island.modules().iter().enumerate() {
            let m = k + 1;
            let spec = slot.spec;
            for ch in 0..spec.digital_inputs {
                let on = c.digital_input(m, ch).unwrap_or(false);
                v.push(LiveValue::digital(
                    format!("digital_input.{m}.{ch}"),
                    on,
                    Role::DigitalInput,
                ));
            }
            for ch in 0..spec.digital_outputs {
                let on = c.digital_output(m, ch).unwrap_or(false);
                v.push(LiveValue::digital(
                    format!("digital_output.{m}.{ch}"),
                    on,
                    Role::DigitalOutput,
                ));
            }
            for ch in 0..spec.analog_inputs {
                v.push(LiveValue {
                    name: format!("analog_input.{m}.{ch}"),
                    value: f64::from(c.analog_input(m, ch).unwrap_or(0)),
                    unit: "",
                    role: Role::AnalogInput {
                        min: f64::from(i16::MIN),
                        max: f64::from(i16::MAX),
                    },
                });
            }
            for ch in 0..spec.analog_outputs {
                v.push(LiveValue {
                    name: format!("analog_output.{m}.{ch}"),
                    value: f64::from(c.analog_output(m, ch).unwrap_or(0)),
                    unit: "",
                    role: Role::AnalogOutput,
                });
            }
        }
        v
    }

    fn canopen_node_id(
        &self,
        sim: &cantwin_bus::Simulation,
        port: cantwin_bus::PortId,
    ) -> Option<u8> {
        Some(sim.node::<Tm3Coupler>(port)?.device().node_id())
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(Box<dyn AnyNode>, PortConfig), ScenarioError> {
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
        Ok((Box::new(coupler), PortConfig::default()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::common::testing::{shipped, try_build};
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
        let kind = Tm3Kind::default();
        let v = |s: &str| toml::Value::String(s.into());
        assert_eq!(
            kind.read_signal(&built.sim, port, "nmt_state"),
            Ok(v("pre-operational"))
        );
        kind.set_signal(&mut built.sim, port, "module.2", &v("pulled"))
            .unwrap();
        built.sim.run_until(Instant::from_nanos(2_000_000));
        let c = built.sim.node::<Tm3Coupler>(port).unwrap();
        // Module 2 runtime error (status 2, bits 2-3), bus status 2 (bits 30-31).
        assert_eq!(c.manufacturer_status(), 0x8000_0008);
        assert_eq!(
            kind.read_signal(&built.sim, port, "digital_output.2.0"),
            Ok(toml::Value::Boolean(false))
        );
        let e = kind
            .set_signal(&mut built.sim, port, "module.2", &v("gone"))
            .unwrap_err();
        assert!(e.contains("\"pulled\""), "{e}");
        let e = kind
            .set_signal(&mut built.sim, port, "module.9", &v("pulled"))
            .unwrap_err();
        assert!(e.contains("no module 9"), "{e}");
        let e = kind.read_signal(&built.sim, port, "speed").unwrap_err();
        assert!(e.contains("signals: module.M"), "{e}");
        let e = kind
            .read_signal(&built.sim, port, "digital_output.2.9")
            .unwrap_err();
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
