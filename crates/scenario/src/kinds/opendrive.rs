//! `kind = "opendrive"`: a TDE MACNO OPEN DRIVE with application 003 "Sensorless via CAN
//! bus" (CAL CMS messages 0–2), with its motor.
//!
//! Keys (all optional):
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `params` | — | inline table of parameters and connections stored in flash, in the manual's units: `{ P21 = 1.5, C48 = 1, P180 = 440 }` |
//! | `dip_s1` | false | DIP switch S1 at power-up; `true` is a 0 → 1 change: the defaults are loaded (but not the reserved values) and CAN is ignored |
//! | `inputs` | `[]` | logic inputs 1–8 that are on, e.g. `[4]` (input 4 is start with C04 = 0) |
//! | `reference_hz` | 0 | the terminal frequency reference |
//! | `load_torque_pct` | 0 | load torque, % of the motor's rated torque |
//! | `ambient_c` | 40 | ambient temperature around the heatsink |
//! | `motor_rated_frequency_hz` | 50 | motor rated frequency (base of P63, P68) |
//! | `motor_rated_power_kw` | 4 | motor rated power |
//! | `motor_magnetising_current_pct` | 35 | magnetising current, % of rated current |
//! | `motor_starting_time_s` | 0.5 | mechanical starting time (inertia) |
//! | `motor_friction_torque_pct` | 2 | friction torque |
//! | `motor_thermal_time_constant_s` | 120 | I²t time constant |
//! | `software_version` | 0x0300 | read through message 2 mux 0x34 |
//! | `physics_period_ms` | 1 | the physics step |
//!
//! The bus must run at the bit rate of C48 (default 1 = 500 kbit/s).
//!
//! Signals for scripts (`[[at]] action = "set"`, `[[expect]] signal = …`):
//!
//! | signal | set | read | meaning |
//! |---|---|---|---|
//! | `load_torque_pct` | number | number | the load, % of the motor's rated torque |
//! | `ambient_c` | number | number | the ambient temperature around the drive |
//! | `reference_hz` | number | — | the terminal frequency reference |
//! | `input.N` | bool | bool | logic input N (1–8) |
//! | `reset_alarms` | `true` | — | the keypad's alarm reset |
//! | `output_hz` | — | number | the output frequency, negative counter-clockwise |
//! | `motor_hz` | — | number | the motor's frequency (coasting while the drive is off) |
//! | `current_pct` | — | number | the motor current, % of its rated current |
//! | `running` | — | bool | whether the output stage is enabled |
//! | `alarms` | — | array | the active alarms, e.g. `["A3"]` |
//! | `heatsink_c`, `module_c` | — | number | heatsink and power module temperatures |
//! | `events_enabled` | — | bool | whether a client enabled message 1 |
//!
//! With `--state-dir`, the drive's flash (saved parameters, latched alarms, the DIP S1
//! position of the last power-up) is kept in `STATE_DIR/<device name>/flash.txt`: read when
//! the scenario is built (the `params` keys are applied on top), written whenever it
//! changes.

use std::collections::BTreeMap;
use std::path::PathBuf;

use cantwin_bus::{AnyNode, PortConfig, PortId, Simulation};
use cantwin_can::Duration;
use cantwin_opendrive::params::{self, ParId};
use cantwin_opendrive::{DriveData, Flash, FlashStorage, MotorData, OpenDrive, bit_rate_of_c48};

use crate::build::BuildEnv;
use crate::error::ScenarioError;
use crate::kinds::common::{signal_bool, signal_f64, signal_indices};
use crate::live::{LiveValue, Role};
use crate::model::BusSpec;
use crate::registry::{DeviceKind, Settings};

/// The OPEN DRIVE kind.
pub struct OpenDriveKind;

/// The largest terminal reference a dashboard may set: the drive clamps the reference to its
/// maximum frequency (P21 scale) anyway; this only refuses nonsense.
const REFERENCE_MAX_HZ: f64 = 500.0;

/// The drive's flash in a file.
struct FileFlash(PathBuf);

impl FlashStorage for FileFlash {
    fn store(&mut self, image: &str) -> Result<(), String> {
        std::fs::write(&self.0, image).map_err(|e| format!("{}: {e}", self.0.display()))
    }
}

fn positive(s: &Settings<'_>, key: &str, default: f64) -> Result<f64, ScenarioError> {
    let v: f64 = s.get_or(key, default)?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(s.error(key, format!("`{key}` must be a positive number")))
    }
}

fn non_negative(s: &Settings<'_>, key: &str, default: f64) -> Result<f64, ScenarioError> {
    let v: f64 = s.get_or(key, default)?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(s.error(key, format!("`{key}` must be zero or a positive number")))
    }
}

const SIGNALS: &str = "load_torque_pct, ambient_c, reference_hz, input.N, reset_alarms (set); load_torque_pct, ambient_c, input.N, output_hz, motor_hz, current_pct, running, alarms, heatsink_c, module_c, events_enabled (read)";

fn unknown(name: &str) -> String {
    format!("an opendrive device has no signal {name:?} (signals: {SIGNALS})")
}

/// `input.N` as N, 1–8.
fn input_of(name: &str) -> Option<u8> {
    match signal_indices(name, "input")?.as_slice() {
        [n] if (1..=8).contains(n) => u8::try_from(*n).ok(),
        _ => None,
    }
}

impl DeviceKind for OpenDriveKind {
    fn name(&self) -> &'static str {
        "opendrive"
    }

    fn set_signal(
        &self,
        sim: &mut Simulation,
        port: PortId,
        name: &str,
        value: &toml::Value,
    ) -> Result<(), String> {
        let node = sim
            .node_mut::<OpenDrive>(port)
            .ok_or_else(|| "not an opendrive device".to_string())?;
        let drive = node.drive_mut();
        if let Some(n) = input_of(name) {
            drive.set_input(n, signal_bool(name, value)?);
            return Ok(());
        }
        match name {
            "load_torque_pct" => drive.set_load_torque_pct(signal_f64(name, value)?),
            "ambient_c" => drive.set_ambient_c(signal_f64(name, value)?),
            "reference_hz" => drive.set_analog_reference_hz(signal_f64(name, value)?),
            "reset_alarms" if signal_bool(name, value)? => drive.reset_alarms(),
            "reset_alarms" => return Err("signal \"reset_alarms\" takes true".into()),
            _ => return Err(unknown(name)),
        }
        Ok(())
    }

    fn read_signal(
        &self,
        sim: &Simulation,
        port: PortId,
        name: &str,
    ) -> Result<toml::Value, String> {
        use toml::Value::{Array, Boolean, Float, String as Text};
        let node = sim
            .node::<OpenDrive>(port)
            .ok_or_else(|| "not an opendrive device".to_string())?;
        let d = node.drive();
        if let Some(n) = input_of(name) {
            return Ok(Boolean(d.input(n)));
        }
        Ok(match name {
            "load_torque_pct" => Float(d.load_torque_pct()),
            "ambient_c" => Float(d.ambient_c()),
            "output_hz" => Float(d.output_hz()),
            "motor_hz" => Float(d.motor_hz()),
            "current_pct" => Float(d.current_pct()),
            "running" => Boolean(d.is_running()),
            "alarms" => Array(
                (0..16u8)
                    .filter(|n| d.alarms().contains(*n))
                    .map(|n| Text(format!("A{n}")))
                    .collect(),
            ),
            "heatsink_c" => Float(d.heatsink_c()),
            "module_c" => Float(d.module_c()),
            "events_enabled" => Boolean(node.events_enabled()),
            _ => return Err(unknown(name)),
        })
    }

    fn summary(&self) -> &'static str {
        "TDE MACNO OPEN DRIVE, application 003: CAL CMS messages 0-2 (P180-P187), V/f drive and motor"
    }

    /// The motor (speed as its frequency in Hz, current in % of its rated current), the
    /// output frequency, DC bus, heatsink and I²t state, logic inputs 1–8 and the terminal
    /// frequency reference.
    fn live_values(
        &self,
        sim: &cantwin_bus::Simulation,
        port: cantwin_bus::PortId,
    ) -> Vec<LiveValue> {
        let Some(node) = sim.node::<OpenDrive>(port) else {
            return Vec::new();
        };
        let d = node.drive();
        let mut v = vec![
            LiveValue::measured("speed", d.motor_hz(), "Hz"),
            LiveValue::measured("current", d.current_pct(), "%"),
            LiveValue::measured("output frequency", d.output_hz(), "Hz"),
            LiveValue::measured("DC bus", d.dc_bus_v(), "V"),
            LiveValue::measured("heatsink", d.heatsink_c(), "°C"),
            LiveValue::measured("motor thermal", d.motor_thermal() * 100.0, "%"),
        ];
        v.extend(
            (1..=8)
                .map(|n| LiveValue::digital(format!("input.{n}"), d.input(n), Role::DigitalInput)),
        );
        v.push(LiveValue {
            name: "reference_hz".into(),
            value: d.analog_reference_hz(),
            unit: "Hz",
            role: Role::AnalogInput {
                min: 0.0,
                max: REFERENCE_MAX_HZ,
            },
        });
        v
    }

    fn build(
        &self,
        s: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(Box<dyn AnyNode>, PortConfig), ScenarioError> {
        let defaults = MotorData::default();
        let motor = MotorData {
            rated_frequency_hz: positive(
                s,
                "motor_rated_frequency_hz",
                defaults.rated_frequency_hz,
            )?,
            rated_power_kw: positive(s, "motor_rated_power_kw", defaults.rated_power_kw)?,
            magnetising_current_pct: non_negative(
                s,
                "motor_magnetising_current_pct",
                defaults.magnetising_current_pct,
            )?,
            starting_time_s: positive(s, "motor_starting_time_s", defaults.starting_time_s)?,
            friction_torque_pct: non_negative(
                s,
                "motor_friction_torque_pct",
                defaults.friction_torque_pct,
            )?,
            thermal_time_constant_s: positive(
                s,
                "motor_thermal_time_constant_s",
                defaults.thermal_time_constant_s,
            )?,
        };
        let hardware = DriveData {
            software_version: s
                .get_or("software_version", DriveData::default().software_version)?,
            ..DriveData::default()
        };
        let period_ms = positive(s, "physics_period_ms", 1.0)?;
        let mut node = OpenDrive::new(motor, hardware)
            .with_physics_period(Duration::from_secs_f64(period_ms / 1e3));

        if let Some(dir) = &env.state_dir {
            let dir = dir.join(&s.device().name);
            let file = dir.join("flash.txt");
            let cannot = |e: String| {
                s.error(
                    "name",
                    format!("cannot keep the drive's flash in {}: {e}", file.display()),
                )
            };
            std::fs::create_dir_all(&dir).map_err(|e| cannot(e.to_string()))?;
            match std::fs::read_to_string(&file) {
                Ok(text) => {
                    let flash = Flash::from_text(&text).map_err(|e| cannot(e.to_string()))?;
                    node.drive_mut().set_flash(flash);
                }
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(cannot(e.to_string())),
            }
            node = node.with_storage(Box::new(FileFlash(file)));
        }

        let table: BTreeMap<String, f64> = s.get_or("params", BTreeMap::new())?;
        for (name, value) in &table {
            let id: ParId = name
                .parse()
                .map_err(|e: params::ParamError| s.error("params", e.to_string()))?;
            let def = params::def(id).ok_or_else(|| s.error("params", format!("no {name}")))?;
            let internal = (value * 10f64.powi(i32::from(def.decimals))).round();
            if !internal.is_finite() || internal.abs() > f64::from(i32::MAX) {
                return Err(s.error("params", format!("{name} = {value} is not a number")));
            }
            node.set_stored_param(id, internal as i32).map_err(|_| {
                let scale = 10f64.powi(i32::from(def.decimals));
                s.error(
                    "params",
                    format!(
                        "{name} = {value} is outside {}..={} {}",
                        f64::from(def.min) / scale,
                        f64::from(def.max) / scale,
                        def.unit
                    ),
                )
            })?;
        }
        let c48 = node.drive().saved_param(params::C48);
        if bit_rate_of_c48(c48) != Some(bus.bit_rate) {
            return Err(s.error(
                "params",
                format!(
                    "the drive's C48 = {c48} runs at {:?}, but bus {:?} runs at {:?}",
                    node.bit_rate(),
                    bus.name,
                    bus.bit_rate
                ),
            ));
        }

        let inputs: Vec<u8> = s.get_or("inputs", Vec::new())?;
        let reference = non_negative(s, "reference_hz", 0.0)?;
        let load = non_negative(s, "load_torque_pct", 0.0)?;
        let ambient: f64 = s.get_or("ambient_c", 40.0)?;
        let dip_s1: bool = s.get_or("dip_s1", false)?;
        let drive = node.drive_mut();
        for n in inputs {
            if !(1..=8).contains(&n) {
                return Err(s.error("inputs", format!("logic input {n} is not one of 1-8")));
            }
            drive.set_input(n, true);
        }
        drive.set_analog_reference_hz(reference);
        drive.set_load_torque_pct(load);
        drive.set_ambient_c(ambient);
        drive.set_dip_s1(dip_s1);
        Ok((Box::new(node), PortConfig::default()))
    }
}

#[cfg(test)]
mod tests {
    use cantwin_bus::Recorder;
    use cantwin_can::{Frame, Instant};
    use cantwin_opendrive::OpenDrive;

    use crate::kinds::common::testing::{build_error, built, recorded, shipped, try_build};
    use crate::{Registry, Scenario};

    const DEVICE: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n[[device]]\nname = \"drive\"\nkind = \"opendrive\"\nbus = \"can0\"\n";

    fn error_of(extra: &str, bit_rate: &str) -> String {
        build_error(&(DEVICE.replace("500k", bit_rate) + extra))
    }

    #[test]
    fn the_shipped_scenario_answers_message_0_and_runs() {
        let mut built = shipped("opendrive.toml");
        let bus = built.bus("can0").unwrap();
        let drive = built.device("drive").unwrap().port;
        let listener = built.device("listener").unwrap().port;
        let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        let start = Frame::std(440, &[0x00, 0xA8, 0x88, 0x13]).unwrap();
        built.sim.transmit(listener, start).unwrap();
        built.sim.run_until(Instant::from_nanos(4_000_000_000));
        let frames: Vec<String> = recorded(&built, bus, tap)
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(frames, ["1B8#00A88813", "1B7#00A98813"]);
        let node = built.sim.node::<OpenDrive>(drive).unwrap();
        assert!((node.drive().output_hz() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn settings_reach_the_drive() {
        let text = DEVICE.to_string()
            + "params = { P21 = 1.5, P180 = 256 }\ninputs = [4]\nreference_hz = 20.0\ndip_s1 = false\n";
        let built = built(&text);
        let port = built.device("drive").unwrap().port;
        let node = built.sim.node::<OpenDrive>(port).unwrap();
        use cantwin_opendrive::params::{P21, P180};
        assert_eq!(node.drive().param(P21), 150);
        assert_eq!(node.drive().param(P180), 256);
        assert!(node.drive().input(4));
        assert_eq!(node.drive().reference_hz(), 20.0);
    }

    #[test]
    fn state_dir_keeps_the_saved_parameters_between_runs() {
        use crate::BuildEnv;
        use cantwin_opendrive::params::P63;
        let dir = std::env::temp_dir().join(format!("cantwin-opendrive-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let env = BuildEnv {
            state_dir: Some(dir.clone()),
        };
        let scenario = Scenario::parse(DEVICE, "t.toml").unwrap();
        let mut built = scenario.build(&Registry::builtin(), &env).unwrap();
        let port = built.device("drive").unwrap().port;
        let bus = built.bus("can0").unwrap();
        // Max frequency 60.00 Hz, then save (message 2 mux 0x00, 0x3A), handed to the
        // drive as if received.
        for frame in [[0x00u8, 0x70, 0x17], [0x3A, 0x01, 0x00]] {
            built
                .sim
                .bus_mut(bus)
                .unwrap()
                .with_node::<OpenDrive, _>(port, |d, now, out| {
                    use cantwin_can::Node;
                    d.on_frame(&Frame::std(1100, &frame).unwrap(), now, out);
                })
                .unwrap();
        }
        built.sim.run_until(Instant::from_nanos(10_000_000));
        let text = std::fs::read_to_string(dir.join("drive").join("flash.txt")).unwrap();
        assert!(text.contains("P63 = 1200"), "{text}");
        let built = scenario.build(&Registry::builtin(), &env).unwrap();
        let node = built.sim.node::<OpenDrive>(port).unwrap();
        assert_eq!(node.drive().saved_param(P63), 1200);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn signals_set_the_load_and_reset_read_outputs_and_alarms() {
        use crate::registry::DeviceKind;
        use toml::Value;
        let mut built = built(&(DEVICE.to_string() + "inputs = [4]\nreference_hz = 20.0\n"));
        let port = built.device("drive").unwrap().port;
        let kind = super::OpenDriveKind;
        built.sim.run_until(Instant::from_nanos(2_000_000_000));
        assert_eq!(
            kind.read_signal(&built.sim, port, "running"),
            Ok(Value::Boolean(true))
        );
        assert_eq!(
            kind.read_signal(&built.sim, port, "input.4"),
            Ok(Value::Boolean(true))
        );
        // A jammed load: overcurrent A2 at the next physics step.
        kind.set_signal(
            &mut built.sim,
            port,
            "load_torque_pct",
            &Value::Float(500.0),
        )
        .unwrap();
        built.sim.run_until(Instant::from_nanos(2_010_000_000));
        assert_eq!(
            kind.read_signal(&built.sim, port, "alarms"),
            Ok(Value::Array(vec![Value::String("A2".into())]))
        );
        kind.set_signal(&mut built.sim, port, "reset_alarms", &Value::Boolean(true))
            .unwrap();
        assert_eq!(
            kind.read_signal(&built.sim, port, "alarms"),
            Ok(Value::Array(vec![]))
        );
        let e = kind
            .set_signal(
                &mut built.sim,
                port,
                "load_torque_pct",
                &Value::Boolean(true),
            )
            .unwrap_err();
        assert!(e.contains("takes a number"), "{e}");
        let e = kind
            .set_signal(&mut built.sim, port, "input.9", &Value::Boolean(true))
            .unwrap_err();
        assert!(e.contains("signals: load_torque_pct"), "{e}");
    }

    #[test]
    fn bad_settings_are_reported_with_their_key() {
        let e = error_of("params = { P21 = 300.0 }\n", "500k");
        assert!(
            e.contains("params") && e.contains("P21 = 300 is outside 0.01..=199.99"),
            "{e}"
        );
        let e = error_of("params = { P99 = 1 }\n", "500k");
        assert!(e.contains("no parameter or connection P99"), "{e}");
        let e = error_of("", "125k");
        assert!(e.contains("C48 = 1"), "{e}");
        let e = error_of("inputs = [9]\n", "500k");
        assert!(e.contains("logic input 9"), "{e}");
        let e = error_of("load_torque = 3\n", "500k");
        assert!(e.contains("unknown key `load_torque`"), "{e}");
        // C48 = 3 is 125 kbit/s.
        let text = DEVICE.replace("500k", "125k") + "params = { C48 = 3 }\n";
        assert!(try_build(&text).is_ok());
    }
}
