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
//! | `motor_rated_frequency_hz` | 50 | motor rated frequency (base of P68) |
//! | `motor_rated_power_kw` | 4 | motor rated power |
//! | `motor_magnetising_current_pct` | 35 | magnetising current, % of rated current |
//! | `motor_starting_time_s` | 0.5 | mechanical starting time (inertia) |
//! | `motor_friction_torque_pct` | 2 | friction torque |
//! | `motor_thermal_time_constant_s` | 120 | I²t time constant |
//! | `software_version` | 0x0300 | read through message 2 mux 0x34 |
//! | `physics_period_ms` | 1 | the physics step |
//!
//! The drive's controller runs at the bit rate of C48 (manual §1.2, default 1 = 500
//! kbit/s). On a bus at another rate it is misconfigured, as a real drive would be: it
//! decodes nothing and answers nothing, and while error-active it destroys the others'
//! frames with error flags (the bus's bit-rate mismatch model); the build warns.
//!
//! Signals for scripts (`[[at]] action = "set"`, `[[expect]] signal = …`), served by the
//! drive as a twin:
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
//! changes, atomically, behind a first line with the image's FNV-1a checksum. A flash that
//! cannot be used (unreadable, truncated, damaged) is a build warning naming the file, and
//! the drive starts on its defaults (the manual gives no alarm for it).

use std::collections::BTreeMap;
use std::path::PathBuf;

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_can::Duration;
use cantwin_opendrive::params::{self, ParId};
use cantwin_opendrive::{DriveData, Flash, FlashStorage, MotorData, OpenDrive, bit_rate_of_c48};

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The OPEN DRIVE kind.
pub struct OpenDriveKind;

/// The drive's flash in a file: a first line with the FNV-1a checksum of the image, then
/// the image ([`Flash::to_text`]), replaced atomically.
struct FileFlash(PathBuf);

/// The first line of a flash file, before the checksum in hexadecimal.
const FLASH_SUM: &str = "# cantwin flash fnv1a ";

fn fnv1a(data: &[u8]) -> u32 {
    data.iter().fold(0x811C_9DC5u32, |h, b| {
        (h ^ u32::from(*b)).wrapping_mul(0x0100_0193)
    })
}

/// The image of a flash file, or why it cannot be used. A file without the checksum line
/// (written before it existed) is taken as it is.
fn flash_image(text: &str) -> Result<&str, String> {
    let Some(rest) = text.strip_prefix(FLASH_SUM) else {
        // A cut inside the checksum line itself.
        if FLASH_SUM.starts_with(text) || text.starts_with("# cantwin") {
            return Err("the file is truncated".into());
        }
        return Ok(text);
    };
    let (sum, image) = rest.split_once('\n').ok_or("the file is truncated")?;
    let sum = u32::from_str_radix(sum.trim(), 16).map_err(|_| "a damaged checksum line")?;
    if sum != fnv1a(image.as_bytes()) {
        return Err("checksum mismatch (the file is truncated or damaged)".into());
    }
    Ok(image)
}

impl FlashStorage for FileFlash {
    fn store(&mut self, image: &str) -> Result<(), String> {
        let text = format!("{FLASH_SUM}{:08x}\n{image}", fnv1a(image.as_bytes()));
        super::common::replace_file(&self.0, text.as_bytes())
            .map_err(|e| format!("{}: {e}", self.0.display()))
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

impl DeviceKind for OpenDriveKind {
    fn name(&self) -> &'static str {
        "opendrive"
    }

    fn summary(&self) -> &'static str {
        "TDE MACNO OPEN DRIVE, application 003: CAL CMS messages 0-2 (P180-P187), V/f drive and motor"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
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
            // A flash that cannot be read leaves the drive on its defaults; the manual gives
            // no alarm for it, so the user hears of it as a warning naming the file.
            let unusable = |why: String| {
                s.warn(format!(
                    "the drive's flash {} cannot be used: {why}; the drive starts on its defaults",
                    file.display()
                ))
            };
            match std::fs::read(&file) {
                Ok(bytes) => match String::from_utf8(bytes).map_err(|e| e.to_string()) {
                    Ok(text) if text.trim().is_empty() => unusable("the file is empty".into()),
                    Ok(text) => match flash_image(&text)
                        .and_then(|image| Flash::from_text(image).map_err(|e| e.to_string()))
                    {
                        Ok(flash) => node.drive_mut().set_flash(flash),
                        Err(e) => unusable(e),
                    },
                    Err(e) => unusable(format!("not text ({e})")),
                },
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => unusable(e.to_string()),
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
        // A C48 other than the bus's rate is the drive's misconfiguration, not the
        // scenario's: the build puts its controller at C48's rate (`controller_bit_rate`),
        // where it decodes nothing and the bus sees error frames.
        if bit_rate_of_c48(node.drive().saved_param(params::C48)) != Some(bus.bit_rate) {
            s.warn(format!(
                "the drive's C48 = {} runs at {:?}, but bus {:?} runs at {:?}: the drive does not communicate",
                node.drive().saved_param(params::C48),
                node.bit_rate(),
                bus.name,
                bus.bit_rate
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
        Ok((BoxedNode::twin(node), PortConfig::default()))
    }
}

#[cfg(test)]
mod tests {
    use cantwin_bus::Recorder;
    use cantwin_can::{Frame, Instant};
    use cantwin_opendrive::OpenDrive;

    use crate::kinds::common::testing::{
        build_error, built, read_signal, recorded, set_signal, shipped, try_build,
    };
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
        use cantwin_opendrive::params::P68;
        let dir = std::env::temp_dir().join(format!("cantwin-opendrive-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let env = BuildEnv {
            state_dir: Some(dir.clone()),
        };
        let scenario = Scenario::parse(DEVICE, "t.toml").unwrap();
        let mut built = scenario.build(&Registry::builtin(), &env).unwrap();
        let port = built.device("drive").unwrap().port;
        let bus = built.bus("can0").unwrap();
        // Max frequency 55.00 Hz, then save (message 2 mux 0x00, 0x3A), handed to the
        // drive as if received.
        for frame in [[0x00u8, 0x7C, 0x15], [0x3A, 0x01, 0x00]] {
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
        assert!(text.contains("P68 = 1100"), "{text}");
        let built = scenario.build(&Registry::builtin(), &env).unwrap();
        let node = built.sim.node::<OpenDrive>(port).unwrap();
        assert_eq!(node.drive().saved_param(P68), 1100);
        assert!(built.warnings.is_empty(), "{:?}", built.warnings);
        // Replaced atomically: no temporary file stays behind.
        assert!(!dir.join("drive").join("flash.txt.tmp").exists());
        // A flash that cannot be used is a warning naming the file; the drive starts on its
        // defaults. Every cut of the saved file is one (its checksum line).
        let file = dir.join("drive").join("flash.txt");
        let whole = std::fs::read(&file).unwrap();
        for cut in 0..whole.len() {
            std::fs::write(&file, &whole[..cut]).unwrap();
            let built = scenario.build(&Registry::builtin(), &env).unwrap();
            assert_eq!(built.warnings.len(), 1, "cut {cut}: {:?}", built.warnings);
        }
        let default = cantwin_opendrive::params::def(P68).unwrap().default;
        for (what, bytes) in [
            ("empty", &b""[..]),
            ("binary", &[0xFF, 0xFE, 0x00, 0x9C][..]),
            ("damaged", &b"P68 = 12x0\n"[..]),
        ] {
            std::fs::write(&file, bytes).unwrap();
            let built = scenario.build(&Registry::builtin(), &env).unwrap();
            assert_eq!(built.warnings.len(), 1, "{what}: {:?}", built.warnings);
            assert!(
                built.warnings[0].contains(&file.display().to_string()),
                "{what}: {}",
                built.warnings[0]
            );
            let node = built.sim.node::<OpenDrive>(port).unwrap();
            assert_eq!(node.drive().saved_param(P68), default, "{what}");
        }
        std::fs::remove_file(&file).unwrap();
        std::fs::create_dir(&file).unwrap();
        let built = scenario.build(&Registry::builtin(), &env).unwrap();
        assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn signals_set_the_load_and_reset_read_outputs_and_alarms() {
        use cantwin_twin::SignalValue as Value;
        let mut built = built(&(DEVICE.to_string() + "inputs = [4]\nreference_hz = 20.0\n"));
        let port = built.device("drive").unwrap().port;
        let read = |b: &crate::Built, name: &str| read_signal(b, port, name);
        let set = |b: &mut crate::Built, name: &str, value| set_signal(b, port, name, value);
        built.sim.run_until(Instant::from_nanos(2_000_000_000));
        assert_eq!(read(&built, "running"), Ok(Value::Bool(true)));
        assert_eq!(read(&built, "input.4"), Ok(Value::Bool(true)));
        // A jammed load: overcurrent A2 at the next physics step.
        set(&mut built, "load_torque_pct", Value::Real(500.0)).unwrap();
        built.sim.run_until(Instant::from_nanos(2_010_000_000));
        assert_eq!(
            read(&built, "alarms"),
            Ok(Value::List(vec![Value::Text("A2".into())]))
        );
        set(&mut built, "reset_alarms", Value::Bool(true)).unwrap();
        assert_eq!(read(&built, "alarms"), Ok(Value::List(vec![])));
        let e = set(&mut built, "load_torque_pct", Value::Bool(true)).unwrap_err();
        assert!(e.contains("takes a number"), "{e}");
        let e = set(&mut built, "input.9", Value::Bool(true)).unwrap_err();
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
        let e = error_of("inputs = [9]\n", "500k");
        assert!(e.contains("logic input 9"), "{e}");
        let e = error_of("load_torque = 3\n", "500k");
        assert!(e.contains("unknown key `load_torque`"), "{e}");
        // C48 = 3 is 125 kbit/s.
        let text = DEVICE.replace("500k", "125k") + "params = { C48 = 3 }\n";
        assert!(try_build(&text).unwrap().warnings.is_empty());
    }

    #[test]
    fn manual_1_2_c48_other_than_the_bus_rate_does_not_communicate() {
        // C48 = 1 (500 kbit/s, the default) on a 125 kbit/s bus: a misconfigured drive.
        let text = DEVICE.replace("500k", "125k")
            + "[[device]]\nname = \"master\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x7FF\nperiod_ms = 1000\n";
        let mut built = try_build(&text).unwrap();
        assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
        assert!(
            built.warnings[0].contains("C48 = 1")
                && built.warnings[0].contains("does not communicate"),
            "{}",
            built.warnings[0]
        );
        let bus = built.bus("can0").unwrap();
        let drive = built.device("drive").unwrap().port;
        let master = built.device("master").unwrap().port;
        let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        let start = Frame::std(440, &[0x00, 0xA8, 0x88, 0x13]).unwrap();
        built.sim.transmit(master, start).unwrap();
        built.sim.run_until(Instant::from_nanos(50_000_000));
        let recorder = built.sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
        // No answer on P181, error frames on the bus, nothing reached the drive.
        assert!(recorder.frames().all(|f| f.frame.id().as_raw() != 439));
        assert!(recorder.errors().next().is_some());
        let node = built.sim.node::<OpenDrive>(drive).unwrap();
        assert_eq!(node.drive().can_reference(), 0);
        assert!(!node.drive().commands().can_start);
    }
}
