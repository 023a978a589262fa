//! `kind = "adv200"`: a Gefran ADV200 drive with the EXP-CAN/DN-ADV card (CANopen, CiA 402
//! or DeviceNet personality, PAR 4000), configured through its parameters as the manual tells a commissioning
//! engineer to, then powered up (the drive reset that makes fieldbus parameters effective).
//!
//! Keys (all optional):
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `example` | false | apply the settings of the manual's worked example (§1.6: node 12, 500 kbit/s, control word + ramp reference in, status word + speed + analog input 2 out) first |
//! | `params` | — | inline table of parameters by number, with a number or an enumeration name: `{ 4000 = "CANopen", 4004 = "500k", 4006 = 12 }` (applied after `example`) |
//! | `digital_inputs` | `[]` | digital inputs 1–8 that are on |
//! | `analog_inputs` | `[0.0, 0.0]` | analog inputs 1 and 2 in volts (±10 V) |
//! | `expedited_only` | true | the card's SDO server refuses segmented and block transfers (§1.1 item 11); `false` lifts the limit |
//! | `serial` | 1 | 0x1018 sub 4 (DeviceNet: Identity serial number) |
//! | `vendor_id` | 0 | 0x1018 sub 1, the CiA vendor-ID: the manual gives none and no public vendor-ID list or Gefran EDS file could be found to source it |
//! | `devicenet_vendor_id` | 0 | DeviceNet Identity attribute 1, the ODVA vendor ID (not sourced either) |
//!
//! Scripts read drive parameters with `[[expect]] value = { device, index = 0x2000 + PAR,
//! sub = 1, … }` in every personality (the §1.4 SDO mapping; the bytes are the parameter's
//! size), and the card's other CANopen objects while it runs CANopen or DS402.
//! `action = "inject"` with `fault = "FF04"` or `"FFB4"` … `"FFC3"` gives the card one of
//! the internal errors of the §1.5/§3.7.1 tables (found at the next drive reset: a
//! `power_off`/`power_on`); `action = "repair"` removes them.
//!
//! Drives whose cards run the same personality with the same PDC layout and `serial` share
//! one object dictionary description (each keeps its own values), so a scenario of many
//! alike drives holds it once.
//!
//! With the factory parameters (`Fieldbus baudrate` None, `Fieldbus address` 0) the card
//! stays off the bus in Opt Bus Fault FF02, as the real one does until it is configured. A card
//! whose baud rate differs from the bus's stays silent.
//!
//! "Save all parameters" (0x1010 sub 1) keeps the drive parameters and the card's
//! communication objects: without `--state-dir` in memory, across the drive's power cycles
//! for as long as the run lasts; with it in `STATE_DIR/<device name>/`; at power-up the saved
//! parameters take the place of those set here. A memory that cannot be read is a build
//! warning naming the file, and the drive raises Param error (EMCY 0xFF2D, §1.5).

use std::collections::BTreeMap;
use std::sync::Arc;

use cantwin_adv200::memory::Memory;
use cantwin_adv200::od::Descriptions;
use cantwin_adv200::params::def;
use cantwin_adv200::{Adv200, Adv200Config, example};
use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_canopen::storage::FileStorage;
use serde::Deserialize;

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The `adv200` kind. Its drives build their dictionaries at every drive reset, from the
/// descriptions the kind gives them all.
#[derive(Default)]
pub struct Adv200Kind {
    descriptions: Arc<Descriptions>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ParamValue {
    Int(i64),
    Name(String),
}

impl DeviceKind for Adv200Kind {
    fn name(&self) -> &'static str {
        "adv200"
    }

    fn summary(&self) -> &'static str {
        "Gefran ADV200 drive with the EXP-CAN card: params by number, example, digital_inputs, analog_inputs, expedited_only, serial, vendor_id, devicenet_vendor_id"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let config = Adv200Config {
            expedited_only: s.get_or("expedited_only", true)?,
            bus_bit_rate: Some(bus.bit_rate.bits_per_second()),
            serial: s.get_or("serial", 1)?,
            vendor_id: s.get_or("vendor_id", cantwin_adv200::od::VENDOR_ID)?,
            devicenet_vendor_id: s
                .get_or("devicenet_vendor_id", cantwin_adv200::devicenet::VENDOR_ID)?,
        };
        let mut node = Adv200::with_descriptions(config, Arc::clone(&self.descriptions));
        if s.get_or("example", false)? {
            example::configure(&mut node).map_err(|e| s.error("example", e.to_string()))?;
        }
        let params: BTreeMap<String, ParamValue> = s.get_or("params", BTreeMap::new())?;
        for (key, value) in params {
            let par: u16 = key
                .trim()
                .parse()
                .map_err(|_| s.error("params", format!("`{key}` is not a parameter number")))?;
            let Some(d) = def(par) else {
                return Err(s.error("params", format!("the drive has no parameter {par}")));
            };
            let result = match &value {
                ParamValue::Int(v) => node.set_param(par, *v),
                ParamValue::Name(n) => node.set_param_str(par, n),
            };
            result.map_err(|e| {
                let shown = match &value {
                    ParamValue::Int(v) => v.to_string(),
                    ParamValue::Name(n) => format!("{n:?}"),
                };
                s.error(
                    "params",
                    format!(
                        "PAR {par} {} = {shown}: {e} (range {}..={})",
                        d.name, d.min, d.max
                    ),
                )
            })?;
        }
        let inputs: Vec<u8> = s.get_or("digital_inputs", Vec::new())?;
        for k in inputs {
            if !(1..=8).contains(&k) {
                return Err(s.error(
                    "digital_inputs",
                    format!("digital input {k} is not one of 1-8"),
                ));
            }
            node.set_digital_input(k, true);
        }
        let analog: Vec<f64> = s.get_or("analog_inputs", Vec::new())?;
        if analog.len() > 2 || analog.iter().any(|v| !(-10.0..=10.0).contains(v)) {
            return Err(s.error(
                "analog_inputs",
                "`analog_inputs` is at most two voltages in -10..=10",
            ));
        }
        for (k, v) in analog.iter().enumerate() {
            node.set_analog_input(k as u8 + 1, *v);
        }
        if let Some(storage) =
            super::common::in_state_dir(s, env, "the drive parameters", FileStorage::new)?
        {
            for problem in storage.check() {
                s.warn(format!(
                    "{problem}; the drive keeps the parameters it has and raises Param error (EMCY 0xFF2D)"
                ));
            }
            node.set_memory(Memory::new(Box::new(storage)));
        }
        Ok((BoxedNode::twin(node), PortConfig::default()))
    }
}

#[cfg(test)]
mod tests {
    use cantwin_adv200::Adv200;
    use cantwin_adv200::params::par;
    use cantwin_bus::Recorder;
    use cantwin_can::{Frame, Instant};

    use crate::kinds::common::testing::{build_error, built, recorded, set_signal, shipped};

    const DEVICE: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n[[device]]\nname = \"drive\"\nkind = \"adv200\"\nbus = \"can0\"\n";

    fn error_of(extra: &str) -> String {
        build_error(&(DEVICE.to_string() + extra))
    }

    #[test]
    fn state_dir_memory_that_cannot_be_read_is_a_warning_and_param_error() {
        use crate::{BuildEnv, Registry, Scenario};
        use cantwin_adv200::alarms::Alarm;
        let dir = std::env::temp_dir().join(format!("cantwin-adv200-kind-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let file = dir.join("drive").join(cantwin_canopen::storage::STORE_FILE);
        std::fs::create_dir_all(&file).unwrap();
        let env = BuildEnv {
            state_dir: Some(dir.clone()),
        };
        let text = DEVICE.to_string() + "example = true\n";
        let scenario = Scenario::parse(&text, "t.toml").unwrap();
        let mut built = scenario.build(&Registry::builtin(), &env).unwrap();
        assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
        let w = &built.warnings[0];
        assert!(
            w.contains(&file.display().to_string()) && w.contains("Param error"),
            "{w}"
        );
        built.sim.run_until(Instant::from_nanos(10_000_000));
        let port = built.device("drive").unwrap().port;
        let node = built.sim.node::<Adv200>(port).unwrap();
        assert!(node.drive().alarms().contains(&Alarm::ParamError));
        // The worked example's parameters are still in effect: node 12.
        assert_eq!(node.param(par::FIELDBUS_ADDRESS), Ok(12));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn vendor_ids_are_scenario_options_for_canopen_and_devicenet() {
        let mut b = built(
            &(DEVICE.to_string()
                + "example = true\nvendor_id = 0x12345678\ndevicenet_vendor_id = 777\n"),
        );
        b.sim.run_until(Instant::from_nanos(10_000_000));
        let port = b.device("drive").unwrap().port;
        let node = b.sim.node::<Adv200>(port).unwrap();
        assert_eq!(
            node.object_bytes(0x1018, 1),
            Ok(0x1234_5678u32.to_le_bytes().to_vec())
        );
        // Without the option: 0, and the DeviceNet identity takes its own.
        let mut b = built_default();
        b.sim.run_until(Instant::from_nanos(10_000_000));
        let port = b.device("drive").unwrap().port;
        let node = b.sim.node::<Adv200>(port).unwrap();
        assert_eq!(node.object_bytes(0x1018, 1), Ok(vec![0, 0, 0, 0]));
        let dnet = "params = { 4000 = \"DeviceNet\", 4004 = \"500k\", 4006 = 12 }\n";
        for (option, vendor) in [("devicenet_vendor_id = 777\n", 777), ("", 0)] {
            let mut b = built(&(DEVICE.to_string() + dnet + option));
            b.sim.run_until(Instant::from_nanos(10_000_000));
            let port = b.device("drive").unwrap().port;
            let node = b.sim.node::<Adv200>(port).unwrap();
            let slave = node.devicenet().unwrap();
            assert_eq!(slave.config().identity.vendor, vendor);
        }
        assert!(error_of("vendor_id = \"x\"\n").contains("vendor_id"));
    }

    fn built_default() -> crate::Built {
        built(&(DEVICE.to_string() + "example = true\n"))
    }

    #[test]
    fn the_shipped_example_boots_as_node_12_and_runs_the_motor() {
        let mut built = shipped("adv200-example.toml");
        let bus = built.bus("can0").unwrap();
        let drive = built.device("drive").unwrap().port;
        let master = built.device("master").unwrap().port;
        let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        built.sim.run_until(Instant::from_nanos(1_000_000));
        // NMT start node 12.
        let start = Frame::std(0, &[0x01, 0x0C]).unwrap();
        built.sim.transmit(master, start).unwrap();
        built.sim.run_until(Instant::from_nanos(2_000_000));
        let rpdo = Frame::std(0x20C, &[0x03, 0x00, 0xE8, 0x03]).unwrap();
        built.sim.transmit(master, rpdo).unwrap();
        for k in 1..=12u64 {
            built.sim.run_until(Instant::from_nanos(k * 100_000_000));
            built
                .sim
                .transmit(master, Frame::std(0x80, &[]).unwrap())
                .unwrap();
        }
        built.sim.run_until(Instant::from_nanos(1_300_000_000));
        let node = built.sim.node::<Adv200>(drive).unwrap();
        assert_eq!(node.param(par::MOTOR_SPEED), Ok(1000));
        let frames: Vec<String> = recorded(&built, bus, tap)
            .iter()
            .filter(|f| f.id().as_raw() == 0x18C)
            .map(ToString::to_string)
            .collect();
        // Analog input 2 at 2.5 V = 4096 counts; digital input 4 on (status bit 8).
        assert_eq!(frames.last().map(String::as_str), Some("18C#0301E8030010"));
    }

    #[test]
    fn the_shipped_devicenet_scenario_checks_its_mac_id_at_power_up() {
        let mut built = shipped("adv200-devicenet.toml");
        let bus = built.bus("can0").unwrap();
        let drive = built.device("drive").unwrap().port;
        let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        built.sim.run_until(Instant::from_nanos(3_000_000_000));
        let node = built.sim.node::<Adv200>(drive).unwrap();
        assert_eq!(node.param(par::FIELDBUS_TYPE), Ok(2));
        assert!(node.devicenet().is_some());
        let frames: Vec<String> = recorded(&built, bus, tap)
            .iter()
            .map(ToString::to_string)
            .collect();
        // Two duplicate MAC ID check requests (group 2 message 7 of MAC 12 = 0x467), 1 s
        // apart, then the node is on-line and silent until a master allocates it.
        assert_eq!(frames.len(), 2, "{frames:?}");
        assert!(frames.iter().all(|f| f.starts_with("467#")), "{frames:?}");
    }

    #[test]
    fn params_by_number_and_name_reach_the_drive() {
        let text = DEVICE.to_string()
            + "params = { 4000 = \"DS402\", 4004 = \"500k\", 4006 = 7, 600 = -100 }\ndigital_inputs = [3]\nanalog_inputs = [1.0]\n";
        let built = built(&text);
        let port = built.device("drive").unwrap().port;
        let node = built.sim.node::<Adv200>(port).unwrap();
        assert_eq!(node.param(par::FIELDBUS_TYPE), Ok(3));
        assert_eq!(node.param(par::FIELDBUS_ADDRESS), Ok(7));
        assert_eq!(node.param(par::DIG_RAMP_REF_1), Ok(-100));
    }

    #[test]
    fn bad_settings_are_reported_with_their_key() {
        let e = error_of("params = { 4006 = 300 }\n");
        assert!(e.contains("PAR 4006 Fieldbus address = 300"), "{e}");
        let e = error_of("params = { 4004 = \"2M\" }\n");
        assert!(e.contains("Fieldbus baudrate"), "{e}");
        let e = error_of("params = { 1 = 0 }\n");
        assert!(e.contains("no parameter 1"), "{e}");
        let e = error_of("digital_inputs = [9]\n");
        assert!(e.contains("digital input 9"), "{e}");
        let e = error_of("analog_inputs = [11.0]\n");
        assert!(e.contains("analog_inputs"), "{e}");
        let e = error_of("speed = 3\n");
        assert!(e.contains("unknown key `speed`"), "{e}");
    }

    /// Drives whose cards are alike share one description; another personality or serial
    /// gets its own. Values stay per drive.
    #[test]
    fn alike_drives_share_their_description() {
        let drive = |name: &str, keys: &str| {
            format!("[[device]]\nname = \"{name}\"\nkind = \"adv200\"\nbus = \"can0\"\n{keys}\n")
        };
        let text = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n".to_string()
            + &drive("a", "example = true\nparams = { 4006 = 12 }")
            + &drive("b", "example = true\nparams = { 4006 = 13 }")
            + &drive("c", "example = true\nparams = { 4006 = 14 }\nserial = 7")
            + &drive(
                "d",
                "params = { 4000 = \"DS402\", 4004 = \"500k\", 4006 = 15 }",
            );
        let mut built = built(&text);
        built.sim.run_until(Instant::from_nanos(1_000_000));
        let device = |name: &str| {
            let port = built.device(name).unwrap().port;
            built.sim.node::<Adv200>(port).unwrap().device().unwrap()
        };
        let description = |name: &str| device(name).od().description();
        assert!(std::sync::Arc::ptr_eq(description("a"), description("b")));
        assert!(!std::sync::Arc::ptr_eq(description("a"), description("c")));
        assert!(!std::sync::Arc::ptr_eq(description("a"), description("d")));
        assert_eq!(device("a").node_id(), 12);
        assert_eq!(device("b").node_id(), 13);
        assert_eq!(device("b").od().get_unsigned(0x1014, 0), Some(0x8D));
        assert_eq!(device("c").od().get_unsigned(0x1018, 4), Some(7));
    }

    #[test]
    fn live_values_show_the_terminals_and_signals_set_them() {
        use cantwin_twin::SignalValue;
        let mut b = shipped("adv200-example.toml");
        let port = b.device("drive").unwrap().port;
        let value = |b: &crate::Built, name: &str| {
            b.sim
                .twin(port)
                .unwrap()
                .live_values()
                .into_iter()
                .find(|v| v.name == name)
                .map(|v| v.value)
        };
        let set = |b: &mut crate::Built, name: &str, v| set_signal(b, port, name, v);
        // The scenario wires digital input 4 and 2.5 V on analog input 2.
        assert_eq!(value(&b, "digital_input.4"), Some(1.0));
        assert_eq!(value(&b, "digital_input.2"), Some(0.0));
        assert!((value(&b, "analog_input.2").unwrap() - 2.5).abs() < 1e-3);
        assert!(value(&b, "speed").is_some() && value(&b, "current").is_some());
        set(&mut b, "digital_input.2", SignalValue::Bool(true)).unwrap();
        assert_eq!(value(&b, "digital_input.2"), Some(1.0));
        set(&mut b, "analog_input.1", SignalValue::Real(-4.0)).unwrap();
        assert!((value(&b, "analog_input.1").unwrap() + 4.0).abs() < 1e-3);
        let e = set(&mut b, "analog_input.1", SignalValue::Real(12.0)).unwrap_err();
        assert!(e.contains("-10–10 V"), "{e}");
        let e = set(&mut b, "digital_input.9", SignalValue::Bool(true)).unwrap_err();
        assert!(e.contains("digital_input.1–8"), "{e}");
    }
}
