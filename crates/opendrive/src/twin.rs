//! The OPEN DRIVE as a [`Twin`]: the load, the ambient, the terminals and the keypad's
//! alarm reset as signals; the drive model's outputs and alarms; its parameters by name.
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
//! | `alarms` | — | list | the active alarms, e.g. `["A3"]` |
//! | `heatsink_c`, `module_c` | — | number | heatsink and power module temperatures |
//! | `events_enabled` | — | bool | whether a client enabled message 1 |

use cantwin_twin::{
    Context, Direction, LiveValue, ParameterError, ParameterKey, Role, SignalDescription,
    SignalError, SignalId, SignalValue, SummaryEntry, Twin, ValueKind,
};

use crate::node::OpenDrive;
use crate::params::ParId;

/// The largest terminal reference a host may set: the drive clamps the reference to its
/// maximum frequency (P21 scale) anyway; this only refuses nonsense.
const REFERENCE_MAX_HZ: f64 = 500.0;

/// The logic inputs.
const INPUTS: u8 = 8;

const SIGNALS: &str = "load_torque_pct, ambient_c, reference_hz, input.N, reset_alarms (set); load_torque_pct, ambient_c, input.N, output_hz, motor_hz, current_pct, running, alarms, heatsink_c, module_c, events_enabled (read)";

/// `input.N` as N, 1–8.
fn input_of(id: &SignalId) -> Option<u8> {
    match id.indices("input")?.as_slice() {
        [n] if (1..=u32::from(INPUTS)).contains(n) => u8::try_from(*n).ok(),
        _ => None,
    }
}

fn par_id(key: &ParameterKey) -> Result<ParId, ParameterError> {
    match key {
        ParameterKey::Name(s) => s.trim().parse().map_err(|_| {
            ParameterError::BadKey(format!("{s:?} is not an OpenDrive parameter (P61, C48, …)"))
        }),
        ParameterKey::Number(n) => Err(ParameterError::BadKey(format!(
            "OpenDrive parameters are named with their class: \"P{n}\" or \"C{n}\""
        ))),
    }
}

fn real(min: f64, max: f64) -> ValueKind {
    ValueKind::Real { min, max }
}

impl Twin for OpenDrive {
    /// C48 in flash (manual §1.2), read at power-up: a drive set to another rate than its
    /// bus's does not communicate, and the bus sees its error frames.
    fn controller_bit_rate(&self) -> Option<cantwin_can::BitRate> {
        Some(self.bit_rate())
    }

    fn signals(&self) -> Vec<SignalDescription> {
        let any = real(f64::MIN, f64::MAX);
        let mut v = vec![
            SignalDescription::input(SignalId::new("load_torque_pct"), any.clone())
                .readable(any.clone())
                .unit("%"),
            SignalDescription::input(SignalId::new("ambient_c"), any.clone())
                .readable(any.clone())
                .unit("°C"),
            SignalDescription::input(SignalId::new("reference_hz"), real(0.0, REFERENCE_MAX_HZ))
                .unit("Hz")
                .role(Role::AnalogInput {
                    min: 0.0,
                    max: REFERENCE_MAX_HZ,
                }),
        ];
        v.extend((1..=INPUTS).map(|n| {
            SignalDescription::input(SignalId::indexed("input", &[u32::from(n)]), ValueKind::Bool)
                .readable(ValueKind::Bool)
                .role(Role::DigitalInput)
                .terminal(None, u32::from(n))
        }));
        v.push(SignalDescription::input(
            SignalId::new("reset_alarms"),
            ValueKind::Bool,
        ));
        for (name, unit) in [
            ("output_hz", "Hz"),
            ("motor_hz", "Hz"),
            ("current_pct", "%"),
            ("heatsink_c", "°C"),
            ("module_c", "°C"),
        ] {
            v.push(SignalDescription::output(SignalId::new(name), any.clone()).unit(unit));
        }
        for name in ["running", "events_enabled"] {
            v.push(SignalDescription::output(
                SignalId::new(name),
                ValueKind::Bool,
            ));
        }
        v.push(SignalDescription::output(
            SignalId::new("alarms"),
            ValueKind::List,
        ));
        v
    }

    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        _cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        let drive = self.drive_mut();
        if let Some(n) = input_of(id) {
            drive.set_input(n, value.to_bool(id)?);
            return Ok(());
        }
        match id.as_str() {
            "load_torque_pct" => drive.set_load_torque_pct(value.to_f64(id)?),
            "ambient_c" => drive.set_ambient_c(value.to_f64(id)?),
            "reference_hz" => drive.set_analog_reference_hz(value.to_f64(id)?),
            "reset_alarms" if value.to_bool(id)? => drive.reset_alarms(),
            "reset_alarms" => {
                return Err(SignalError::OutOfRange {
                    signal: id.clone(),
                    range: "true".into(),
                    got: value.clone(),
                });
            }
            _ => return Err(SignalError::unknown(id, Direction::Set, SIGNALS)),
        }
        Ok(())
    }

    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        use SignalValue::{Bool, List, Real, Text};
        let d = self.drive();
        if let Some(n) = input_of(id) {
            return Ok(Bool(d.input(n)));
        }
        Ok(match id.as_str() {
            "load_torque_pct" => Real(d.load_torque_pct()),
            "ambient_c" => Real(d.ambient_c()),
            "output_hz" => Real(d.output_hz()),
            "motor_hz" => Real(d.motor_hz()),
            "current_pct" => Real(d.current_pct()),
            "running" => Bool(d.is_running()),
            "alarms" => List(
                (0..16u8)
                    .filter(|n| d.alarms().contains(*n))
                    .map(|n| Text(format!("A{n}")))
                    .collect(),
            ),
            "heatsink_c" => Real(d.heatsink_c()),
            "module_c" => Real(d.module_c()),
            "events_enabled" => Bool(self.events_enabled()),
            _ => return Err(SignalError::unknown(id, Direction::Read, SIGNALS)),
        })
    }

    /// The motor (speed as its frequency in Hz, current in % of its rated current), the
    /// output frequency, DC bus, heatsink and I²t state, logic inputs 1–8 and the terminal
    /// frequency reference.
    fn live_values(&self) -> Vec<LiveValue> {
        let d = self.drive();
        let mut v = vec![
            LiveValue::measured("speed", d.motor_hz(), "Hz"),
            LiveValue::measured("current", d.current_pct(), "%"),
            LiveValue::measured("output frequency", d.output_hz(), "Hz"),
            LiveValue::measured("DC bus", d.dc_bus_v(), "V"),
            LiveValue::measured("heatsink", d.heatsink_c(), "°C"),
            LiveValue::measured("motor thermal", d.motor_thermal() * 100.0, "%"),
        ];
        v.extend(
            (1..=INPUTS)
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

    fn parameter(&self, key: &ParameterKey) -> Result<i64, ParameterError> {
        Ok(i64::from(self.drive().param(par_id(key)?)))
    }

    fn set_parameter(
        &mut self,
        key: &ParameterKey,
        value: i64,
        _cx: &mut Context<'_>,
    ) -> Result<(), ParameterError> {
        let id = par_id(key)?;
        let v = i32::try_from(value)
            .map_err(|_| ParameterError::Refused(format!("{value} does not fit a parameter")))?;
        self.drive_mut()
            .set_param(id, v)
            .map_err(|e| ParameterError::Refused(format!("{id} = {value}: {e}")))
    }

    /// `inputs`: logic inputs 1–8.
    fn summary(&self) -> Vec<SummaryEntry> {
        let inputs = (1..=INPUTS)
            .map(|k| SignalValue::Bool(self.drive().input(k)))
            .collect();
        vec![SummaryEntry::new("inputs", Some(SignalValue::List(inputs)))]
    }
}
