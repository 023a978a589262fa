//! The TM3 coupler as a [`Twin`]: its dictionary, the channels of its modules as signals,
//! what is fitted, the expansion bus's internal error and the rotary switches.
//!
//! Modules are numbered from 1, channels from 0:
//!
//! | signal | set | read | meaning |
//! |---|---|---|---|
//! | `module.M` | `"pulled"`, `"fitted"`, `"unresponsive"` | — | what is plugged in at position M |
//! | `digital_input.M.C` | bool | — | a physical input |
//! | `analog_input.M.C` | integer | — | a physical analog input, raw 16-bit |
//! | `internal_error` | bool | — | an internal communication error on the expansion bus |
//! | `rotary_switch` | integer | — | the node-ID switches (read at power-up) |
//! | `digital_output.M.C` | — | bool | the physical output, with the failure state applied |
//! | `analog_output.M.C` | — | integer | likewise, raw 16-bit |
//! | `failure_state` | — | bool | whether the outputs are at their safe positions |
//! | `nmt_state` | — | string | `"pre-operational"`, `"operational"`, `"stopped"`, `"initialising"` |

use cantwin_canopen::nmt::State;
use cantwin_canopen::od::ObjectDictionary;
use cantwin_twin::{
    Context, Direction, LiveValue, ObjectError, Role, SignalDescription, SignalError, SignalId,
    SignalValue, Twin, ValueKind, write_through,
};

use crate::coupler::{Fitted, Tm3Coupler};

const SIGNALS: &str = "module.M, digital_input.M.C, analog_input.M.C, internal_error, rotary_switch (set); digital_output.M.C, analog_output.M.C, failure_state, nmt_state (read)";

/// The words `module.M` takes.
const FITTED: [&str; 3] = ["pulled", "fitted", "unresponsive"];

/// `prefix.M.C` as (module, channel).
fn module_channel(id: &SignalId, prefix: &str) -> Option<(usize, u8)> {
    match id.indices(prefix)?.as_slice() {
        [m, c] => Some((usize::try_from(*m).ok()?, u8::try_from(*c).ok()?)),
        _ => None,
    }
}

fn raw16() -> ValueKind {
    ValueKind::Integer {
        min: i64::from(i16::MIN),
        max: i64::from(i16::MAX),
    }
}

impl Twin for Tm3Coupler {
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        Some(self.device().od())
    }

    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        _cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        write_through(self.device_mut(), index, sub, data)
    }

    fn canopen_node_id(&self) -> Option<u8> {
        Some(self.device().node_id())
    }

    /// The CiA 301 device's heap; the island's own state is not counted.
    fn dictionary_heap_bytes(&self) -> Option<usize> {
        Some(self.device().heap_bytes())
    }

    fn signals(&self) -> Vec<SignalDescription> {
        let mut v = Vec::new();
        for (k, slot) in self.config().island.modules().iter().enumerate() {
            let m = k as u32 + 1;
            let spec = slot.spec;
            v.push(SignalDescription::input(
                SignalId::indexed("module", &[m]),
                ValueKind::Text(FITTED.to_vec()),
            ));
            for ch in 0..u32::from(spec.digital_inputs) {
                v.push(
                    SignalDescription::input(
                        SignalId::indexed("digital_input", &[m, ch]),
                        ValueKind::Bool,
                    )
                    .role(Role::DigitalInput)
                    .terminal(Some(m), ch),
                );
            }
            for ch in 0..u32::from(spec.digital_outputs) {
                v.push(
                    SignalDescription::output(
                        SignalId::indexed("digital_output", &[m, ch]),
                        ValueKind::Bool,
                    )
                    .role(Role::DigitalOutput)
                    .terminal(Some(m), ch),
                );
            }
            for ch in 0..u32::from(spec.analog_inputs) {
                v.push(
                    SignalDescription::input(SignalId::indexed("analog_input", &[m, ch]), raw16())
                        .role(Role::AnalogInput {
                            min: f64::from(i16::MIN),
                            max: f64::from(i16::MAX),
                        })
                        .terminal(Some(m), ch),
                );
            }
            for ch in 0..u32::from(spec.analog_outputs) {
                v.push(
                    SignalDescription::output(
                        SignalId::indexed("analog_output", &[m, ch]),
                        raw16(),
                    )
                    .role(Role::AnalogOutput)
                    .terminal(Some(m), ch),
                );
            }
        }
        v.push(SignalDescription::input(
            SignalId::new("internal_error"),
            ValueKind::Bool,
        ));
        v.push(SignalDescription::input(
            SignalId::new("rotary_switch"),
            ValueKind::Integer { min: 1, max: 127 },
        ));
        v.push(SignalDescription::output(
            SignalId::new("failure_state"),
            ValueKind::Bool,
        ));
        v.push(SignalDescription::output(
            SignalId::new("nmt_state"),
            ValueKind::Text(vec![
                "initialising",
                "pre-operational",
                "operational",
                "stopped",
            ]),
        ));
        v
    }

    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        if let Some(m) = id.indices("module").and_then(|v| match v.as_slice() {
            [m] => usize::try_from(*m).ok(),
            _ => None,
        }) {
            let configured = m
                .checked_sub(1)
                .and_then(|i| self.config().island.modules().get(i))
                .map(|slot| slot.spec)
                .ok_or_else(|| SignalError::refused(id, format!("no module {m}")))?;
            let what = match value {
                SignalValue::Text(t) if t == "pulled" => Fitted::Empty,
                SignalValue::Text(t) if t == "fitted" => Fitted::Module(configured),
                SignalValue::Text(t) if t == "unresponsive" => Fitted::Unresponsive,
                _ => {
                    return Err(SignalError::WrongType {
                        signal: id.clone(),
                        expected: "\"pulled\", \"fitted\" or \"unresponsive\"".into(),
                        got: value.clone(),
                    });
                }
            };
            return self
                .fit(m, what, cx.now, cx.out)
                .map_err(|e| SignalError::refused(id, e));
        }
        if let Some((m, ch)) = module_channel(id, "digital_input") {
            return self
                .set_digital_input(m, ch, value.to_bool(id)?)
                .map_err(|e| SignalError::refused(id, e));
        }
        if let Some((m, ch)) = module_channel(id, "analog_input") {
            return self
                .set_analog_input(m, ch, value.to_int(id)?)
                .map_err(|e| SignalError::refused(id, e));
        }
        match id.as_str() {
            "internal_error" => {
                self.set_internal_error(value.to_bool(id)?, cx.now, cx.out);
                Ok(())
            }
            "rotary_switch" => {
                let node_id: u8 = value.to_int(id)?;
                if !(1..=127).contains(&node_id) {
                    return Err(SignalError::OutOfRange {
                        signal: id.clone(),
                        range: "1-127".into(),
                        got: value.clone(),
                    });
                }
                self.set_rotary_switch(node_id, cx.now, cx.out);
                Ok(())
            }
            _ => Err(SignalError::unknown(id, Direction::Set, SIGNALS)),
        }
    }

    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        if let Some((m, ch)) = module_channel(id, "digital_output") {
            return self
                .digital_output(m, ch)
                .map(SignalValue::Bool)
                .map_err(|e| SignalError::refused(id, e));
        }
        if let Some((m, ch)) = module_channel(id, "analog_output") {
            return self
                .analog_output(m, ch)
                .map(|v| SignalValue::Integer(i64::from(v)))
                .map_err(|e| SignalError::refused(id, e));
        }
        match id.as_str() {
            "failure_state" => Ok(SignalValue::Bool(self.in_failure_state())),
            "nmt_state" => Ok(SignalValue::Text(
                match self.state() {
                    State::Initialising => "initialising",
                    State::PreOperational => "pre-operational",
                    State::Operational => "operational",
                    State::Stopped => "stopped",
                }
                .to_string(),
            )),
            _ => Err(SignalError::unknown(id, Direction::Read, SIGNALS)),
        }
    }

    /// Every channel of every configured module, named as the signals are
    /// (`digital_input.M.C`, `digital_output.M.C`, `analog_input.M.C`, `analog_output.M.C`:
    /// module 1-based, channel 0-based), analog values in raw 16-bit counts.
    fn live_values(&self) -> Vec<LiveValue> {
        let mut v = Vec::new();
        for (k, slot) in self.config().island.modules().iter().enumerate() {
            let m = k + 1;
            let spec = slot.spec;
            for ch in 0..spec.digital_inputs {
                let on = self.digital_input(m, ch).unwrap_or(false);
                v.push(LiveValue::digital(
                    format!("digital_input.{m}.{ch}"),
                    on,
                    Role::DigitalInput,
                ));
            }
            for ch in 0..spec.digital_outputs {
                let on = self.digital_output(m, ch).unwrap_or(false);
                v.push(LiveValue::digital(
                    format!("digital_output.{m}.{ch}"),
                    on,
                    Role::DigitalOutput,
                ));
            }
            for ch in 0..spec.analog_inputs {
                v.push(LiveValue {
                    name: format!("analog_input.{m}.{ch}"),
                    value: f64::from(self.analog_input(m, ch).unwrap_or(0)),
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
                    value: f64::from(self.analog_output(m, ch).unwrap_or(0)),
                    unit: "",
                    role: Role::AnalogOutput,
                });
            }
        }
        v
    }
}
