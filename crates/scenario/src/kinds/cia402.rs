//! `kind = "cia402"`: a generic CiA 402 servo drive (see `cantwin-servo`): a CiA 301 device
//! whose dictionary holds the CiA 402 objects, running every operating mode of the profile
//! on a motor and load model in virtual time.
//!
//! Keys (SI units unless named):
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `node_id` | required, 1–127 | the node-ID |
//! | `eds` | none | a vendor's CiA 402 EDS, relative to the scenario file: the dictionary is the file's (its factor group sets the units; its 0x608F, 0x6502, 0x6075 and 0x6076 defaults replace `encoder_increments`, `modes`, `rated_current` and `rated_torque`), the behaviour the profile's |
//! | `modes` | every mode | the supported modes (0x6502), as `["pp", "vl", "pv", "tq", "hm", "ip", "csp", "csv", "cst"]` |
//! | `encoder_increments` | 4096 | increments per motor revolution (0x608F; one position unit is one increment) |
//! | `motor_inertia`, `load_inertia` | 0.5e-4, 1.0e-4 | kg·m² |
//! | `viscous_friction` | 1e-4 | N·m per rad/s |
//! | `coulomb_friction` | 0.02 | N·m |
//! | `rated_torque`, `peak_torque` | 1.27, 3.81 | N·m (0x6076 is the rated torque) |
//! | `rated_current` | 3.0 | A (0x6075) |
//! | `position_kp`, `velocity_kp`, `velocity_ki` | 100, 0.05, 5.0 | the controller gains: 1/s, N·m·s/rad, N·m/rad |
//! | `negative_limit_switch`, `positive_limit_switch`, `home_switch` | none | where the switches are, in position units: active below, above, and above (with `home_switch_below = true`, below) |
//! | `dc_link` | 325 | the DC link voltage, V |
//! | `trip_current` | 12 | the inverter's over-current trip, A |
//! | `loop_period_us` | 250 | the control loop period |
//! | `heartbeat_ms` | 0 | 0x1017's default (built-in dictionary) |
//! | `sdo_timeout_ms` | 1000 | the SDO server's timeout |
//!
//! Signals and faults are the twin's (`cantwin_servo` twin module): `position`,
//! `velocity`, `torque`, `following_error`, `current`, `state`, `mode`, `statusword` to
//! read; `limit_switch.negative`, `limit_switch.positive`, `home_switch`, `load_torque`,
//! `dc_link` to set; faults `"following_error"` (the shaft jams), `"limit_switch"` (the
//! positive limit switch sticks), `"over_current"` (a phase short), `"dc_link"` (mains
//! lost) for the `inject` action, all removed by `repair`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_can::Duration;
use cantwin_cia402::physics::Switches;
use cantwin_cia402::{Mode, SupportedModes};
use cantwin_servo::{Servo, ServoConfig};

use super::common::{check_node_id, sdo_timeout};
use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The `cia402` kind.
pub struct Cia402Kind;

fn resolve(scenario: &Path, file: &str) -> PathBuf {
    let file = Path::new(file);
    match scenario.parent() {
        Some(dir) if !file.is_absolute() => dir.join(file),
        _ => file.to_path_buf(),
    }
}

fn modes(s: &Settings<'_>) -> Result<SupportedModes, ScenarioError> {
    let Some(names) = s.get::<Vec<String>>("modes")? else {
        return Ok(SupportedModes::of(&Mode::ALL));
    };
    let mut list = Vec::new();
    for n in &names {
        let m = Mode::ALL
            .into_iter()
            .find(|m| m.abbreviation() == n)
            .ok_or_else(|| {
                s.error(
                    "modes",
                    format!(
                        "unknown mode {n:?}; the modes are pp, vl, pv, tq, hm, ip, csp, csv, cst"
                    ),
                )
            })?;
        list.push(m);
    }
    if list.is_empty() {
        return Err(s.error("modes", "a drive supports at least one mode"));
    }
    Ok(SupportedModes::of(&list))
}

fn positive(s: &Settings<'_>, key: &str, default: f64) -> Result<f64, ScenarioError> {
    let v: f64 = s.get_or(key, default)?;
    if !(v.is_finite() && v > 0.0) {
        return Err(s.error(key, format!("`{key}` must be greater than 0, not {v}")));
    }
    Ok(v)
}

fn non_negative(s: &Settings<'_>, key: &str, default: f64) -> Result<f64, ScenarioError> {
    let v: f64 = s.get_or(key, default)?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(s.error(key, format!("`{key}` must be 0 or more, not {v}")));
    }
    Ok(v)
}

/// The drive's configuration from the keys.
fn config(s: &Settings<'_>, node_id: u8) -> Result<ServoConfig, ScenarioError> {
    let mut c = ServoConfig::new(node_id);
    let d = &mut c.drive;
    d.modes = modes(s)?;
    let increments: u32 = s.get_or("encoder_increments", 4096)?;
    if increments == 0 {
        return Err(s.error(
            "encoder_increments",
            "`encoder_increments` must be at least 1",
        ));
    }
    d.encoder = increments;
    let m = &mut d.mechanics;
    m.inertia = positive(s, "motor_inertia", 0.5e-4)? + non_negative(s, "load_inertia", 1.0e-4)?;
    m.viscous = non_negative(s, "viscous_friction", m.viscous)?;
    m.coulomb = non_negative(s, "coulomb_friction", m.coulomb)?;
    m.rated_torque = positive(s, "rated_torque", m.rated_torque)?;
    m.peak_torque = positive(s, "peak_torque", m.rated_torque * 3.0)?;
    m.rated_current = positive(s, "rated_current", m.rated_current)?;
    m.torque_constant = m.rated_torque / m.rated_current;
    let g = &mut d.gains;
    g.position_kp = non_negative(s, "position_kp", g.position_kp)?;
    g.velocity_kp = non_negative(s, "velocity_kp", g.velocity_kp)?;
    g.velocity_ki = non_negative(s, "velocity_ki", g.velocity_ki)?;
    let rad = |units: f64| units / f64::from(increments) * core::f64::consts::TAU;
    let at = |key: &str| -> Result<Option<f64>, ScenarioError> { Ok(s.get::<f64>(key)?.map(rad)) };
    d.switches = Switches {
        negative_limit: at("negative_limit_switch")?,
        positive_limit: at("positive_limit_switch")?,
        home: at("home_switch")?,
        home_below: s.get_or("home_switch_below", false)?,
        home_end: None,
    };
    d.inverter.dc_link_nominal = positive(s, "dc_link", d.inverter.dc_link_nominal)?;
    d.inverter.trip_current = positive(s, "trip_current", d.inverter.trip_current)?;
    let loop_us: u64 = s.get_or("loop_period_us", 250)?;
    if !(50..=10_000).contains(&loop_us) {
        return Err(s.error("loop_period_us", "`loop_period_us` is 50–10000"));
    }
    d.loop_period = Duration::from_micros(loop_us);
    c.heartbeat_ms = s.get_or("heartbeat_ms", 0)?;
    c.sdo_timeout = sdo_timeout(s)?;
    Ok(c)
}

impl DeviceKind for Cia402Kind {
    fn name(&self) -> &'static str {
        "cia402"
    }

    fn summary(&self) -> &'static str {
        "CiA 402 servo drive, every operating mode: node_id, eds, modes, motor and load, gains, switches"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let node_id: u8 = s.require("node_id")?;
        check_node_id(s, node_id)?;
        let config = config(s, node_id)?;
        let servo = match s.get::<String>("eds")? {
            None => Servo::new(config).map_err(|e| s.error("node_id", e.to_string()))?,
            Some(file) => {
                let path = resolve(s.file(), &file);
                let bytes = std::fs::read(&path)
                    .map_err(|e| s.error("eds", format!("cannot read {}: {e}", path.display())))?;
                let loaded = cantwin_eds::load_bytes(&bytes);
                let desc = cantwin_eds::to_od(&loaded.eds).map_err(|e| {
                    s.error(
                        "eds",
                        format!("{}: not a usable object dictionary: {e}", path.display()),
                    )
                })?;
                let desc = cantwin_servo::od::hooked(&desc)
                    .map_err(|e| s.error("eds", format!("{}: {e}", path.display())))?;
                Servo::with_description(Arc::clone(&desc), config)
                    .map_err(|e| s.error("eds", format!("{}: {e}", path.display())))?
            }
        };
        let port = PortConfig {
            queue_depth: super::eds::TX_QUEUE_DEPTH,
            ..PortConfig::default()
        };
        Ok((BoxedNode::twin(servo), port))
    }
}

#[cfg(test)]
mod tests {
    use super::super::common::testing::*;
    use cantwin_can::Instant;
    use cantwin_twin::SignalValue;

    const DEVICE: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[device]]\nname = \"axis\"\nkind = \"cia402\"\nbus = \"can0\"\n";

    #[test]
    fn settings_errors_name_the_key() {
        let e = build_error(&(DEVICE.to_string() + "node_id = 0\n"));
        assert!(e.contains("node_id"), "{e}");
        let e = build_error(&(DEVICE.to_string() + "node_id = 3\nmodes = [\"pp\", \"xx\"]\n"));
        assert!(e.contains("modes") && e.contains("xx"), "{e}");
        let e = build_error(&(DEVICE.to_string() + "node_id = 3\nrated_torque = 0\n"));
        assert!(e.contains("rated_torque"), "{e}");
        let e = build_error(&(DEVICE.to_string() + "node_id = 3\nencoder_resolution = 4\n"));
        assert!(e.contains("encoder_resolution"), "{e}");
        let e = build_error(&(DEVICE.to_string() + "node_id = 3\neds = \"nowhere.eds\"\n"));
        assert!(e.contains("nowhere.eds"), "{e}");
    }

    #[test]
    fn a_built_axis_reads_its_signals() {
        let mut built = built(&(DEVICE.to_string() + "node_id = 3\nmodes = [\"csp\", \"pp\"]\n"));
        let port = built.device("axis").unwrap().port;
        built.sim.run_until(Instant::from_nanos(5_000_000));
        assert_eq!(
            read_signal(&built, port, "state"),
            Ok(SignalValue::Text("switch on disabled".into()))
        );
        assert_eq!(
            read_signal(&built, port, "mode"),
            Ok(SignalValue::Text("none".into()))
        );
        assert_eq!(
            read_signal(&built, port, "statusword"),
            Ok(SignalValue::Integer(0x0240))
        );
        set_signal(
            &mut built,
            port,
            "limit_switch.positive",
            SignalValue::Bool(true),
        )
        .unwrap();
        assert_eq!(
            read_signal(&built, port, "limit_switch.positive"),
            Ok(SignalValue::Bool(true))
        );
        assert!(
            read_signal(&built, port, "speed")
                .unwrap_err()
                .to_string()
                .contains("following_error")
        );
    }
}
