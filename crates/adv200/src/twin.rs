//! The ADV200 drive as a [`Twin`]: its terminals as signals, the card's internal faults and
//! the drive's alarms, its parameters by number, its drive model's summary and the
//! DeviceNet EDS of its DeviceNet personality.

use cantwin_canopen::od::ObjectDictionary;
use cantwin_devicenet::Application;
use cantwin_devicenet::eds::{
    CipType, DeviceEds, EdsDate, EdsParam, EdsTime, FileSection, descriptor,
};
use cantwin_twin::{
    Context, DataSheetError, Direction, Fault, FaultError, FaultKind, FileDate, LiveValue,
    ObjectError, ParameterError, ParameterKey, Role, SignalDescription, SignalError, SignalId,
    SignalValue, SummaryEntry, Twin, ValueKind,
};

use crate::alarms::{Alarm, CardFault};
use crate::card::Adv200;
use crate::params::{ParamAccess, ParamType, catalog};

/// The digital inputs, the analog inputs and the digital outputs the drive has.
const DIGITAL_INPUTS: u8 = 8;
const ANALOG_INPUTS: u8 = 2;
const DIGITAL_OUTPUTS: u8 = 4;
/// The analog inputs' range in volts.
const VOLTS: f64 = 10.0;

/// `prefix.K` with K in 1..=max.
fn terminal(id: &SignalId, prefix: &str, max: u8) -> Option<u8> {
    match id.indices(prefix)?.as_slice() {
        [k] if (1..=u32::from(max)).contains(k) => u8::try_from(*k).ok(),
        _ => None,
    }
}

/// A parameter number from `key`.
fn number(key: &ParameterKey) -> Result<u16, ParameterError> {
    match key {
        ParameterKey::Number(n) => Ok(*n),
        ParameterKey::Name(s) => s
            .trim()
            .parse()
            .map_err(|_| ParameterError::BadKey(format!("{s:?} is not a parameter number"))),
    }
}

impl Twin for Adv200 {
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        self.device().map(|d| d.od())
    }

    /// Drive parameters at 0x2000 + PAR sub 1 in every personality (the §1.4 SDO mapping;
    /// the bytes are the parameter's size), the card's other objects while it runs CANopen
    /// or DS402; the objects the drive serves through the dictionary's hooks (parameters,
    /// the CiA 402 statusword and actual values) as an upload reads them.
    fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, ObjectError> {
        let parameter = (0x2000..=0x5FFF).contains(&index) && sub == 1;
        if !parameter && self.dictionary().is_none() {
            return Err(ObjectError::NoDictionary);
        }
        Ok(self.object_bytes(index, sub)?)
    }

    fn write_object(
        &mut self,
        _index: u16,
        _sub: u8,
        _data: &[u8],
        _cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        Err(ObjectError::Refused(
            "the ADV200's objects are its parameters: use set_param".into(),
        ))
    }

    /// The card's node-ID while it runs CANopen or DS402.
    fn canopen_node_id(&self) -> Option<u8> {
        self.device().map(|d| d.node_id())
    }

    fn signals(&self) -> Vec<SignalDescription> {
        let mut v: Vec<SignalDescription> = (1..=DIGITAL_INPUTS)
            .map(|k| {
                SignalDescription::input(
                    SignalId::indexed("digital_input", &[u32::from(k)]),
                    ValueKind::Bool,
                )
                .role(Role::DigitalInput)
                .terminal(None, u32::from(k))
            })
            .collect();
        v.extend((1..=ANALOG_INPUTS).map(|k| {
            SignalDescription::input(
                SignalId::indexed("analog_input", &[u32::from(k)]),
                ValueKind::Real {
                    min: -VOLTS,
                    max: VOLTS,
                },
            )
            .unit("V")
            .role(Role::AnalogInput {
                min: -VOLTS,
                max: VOLTS,
            })
            .terminal(None, u32::from(k))
        }));
        v.extend((1..=DIGITAL_OUTPUTS).map(|k| {
            SignalDescription::output(
                SignalId::indexed("digital_output", &[u32::from(k)]),
                ValueKind::Bool,
            )
            .role(Role::DigitalOutput)
            .terminal(None, u32::from(k))
        }));
        v
    }

    /// `digital_output.K` (K 1–4): the drive's relay and digital outputs.
    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        match terminal(id, "digital_output", DIGITAL_OUTPUTS) {
            Some(k) => Ok(SignalValue::Bool(self.digital_output(k))),
            None => Err(SignalError::unknown(
                id,
                Direction::Read,
                "digital_output.1–4",
            )),
        }
    }

    /// `digital_input.K` (K 1–8, true or false) and `analog_input.K` (K 1–2, volts within
    /// ±10 V): the drive's terminals.
    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        _cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        if let Some(k) = terminal(id, "digital_input", DIGITAL_INPUTS) {
            self.set_digital_input(k, value.to_bool(id)?);
            Ok(())
        } else if let Some(k) = terminal(id, "analog_input", ANALOG_INPUTS) {
            let volts = value.to_f64(id)?;
            if !(-VOLTS..=VOLTS).contains(&volts) {
                return Err(SignalError::OutOfRange {
                    signal: id.clone(),
                    range: "-10–10 V".into(),
                    got: value.clone(),
                });
            }
            self.set_analog_input(k, volts);
            Ok(())
        } else {
            Err(SignalError::unknown(
                id,
                Direction::Set,
                "digital_input.1–8, analog_input.1–2",
            ))
        }
    }

    /// The motor speed (rpm) and current (A), the thermal load, digital inputs 1–8,
    /// analog inputs 1–2 (±10 V) and digital outputs 1–4.
    fn live_values(&self) -> Vec<LiveValue> {
        let d = self.drive();
        let mut v = vec![
            LiveValue::measured("speed", d.speed(), "rpm"),
            LiveValue::measured("current", d.current(), "A"),
            LiveValue::measured("thermal", d.thermal() * 100.0, "%"),
        ];
        v.extend((1..=DIGITAL_INPUTS).map(|k| {
            LiveValue::digital(
                format!("digital_input.{k}"),
                d.digital_input(k),
                Role::DigitalInput,
            )
        }));
        v.extend((1..=ANALOG_INPUTS).map(|k| LiveValue {
            name: format!("analog_input.{k}"),
            value: d.analog_input(k),
            unit: "V",
            role: Role::AnalogInput {
                min: -VOLTS,
                max: VOLTS,
            },
        }));
        v.extend((1..=DIGITAL_OUTPUTS).map(|k| {
            LiveValue::digital(
                format!("digital_output.{k}"),
                self.digital_output(k),
                Role::DigitalOutput,
            )
        }));
        v
    }

    /// An internal card fault (`"FF04"`, `"FFB4"` … `"FFC3"`, found at the next drive
    /// reset) or a drive alarm by its name (`"External fault"`, at once).
    fn inject(&mut self, fault: &Fault, _cx: &mut Context<'_>) -> Result<(), FaultError> {
        match fault.kind {
            FaultKind::Internal => {
                let f = fault
                    .name
                    .parse::<CardFault>()
                    .map_err(|reason| FaultError::Unknown {
                        fault: fault.clone(),
                        reason,
                    })?;
                self.inject_card_fault(f);
            }
            FaultKind::Alarm => {
                let a = Alarm::from_name(&fault.name).ok_or_else(|| {
                    let names: Vec<String> = Alarm::all().into_iter().map(Alarm::name).collect();
                    FaultError::Unknown {
                        fault: fault.clone(),
                        reason: format!(
                            "the ADV200 has no alarm {:?} (alarms: {})",
                            fault.name,
                            names.join(", ")
                        ),
                    }
                })?;
                self.raise_alarm(a);
            }
        }
        Ok(())
    }

    /// Repairs the card (effective at the next drive reset); alarms are reset as the drive
    /// resets them.
    fn repair(&mut self, kind: FaultKind, _cx: &mut Context<'_>) -> Result<(), FaultError> {
        match kind {
            FaultKind::Internal => {
                self.clear_card_faults();
                Ok(())
            }
            FaultKind::Alarm => Err(FaultError::None { kind }),
        }
    }

    fn parameter(&self, key: &ParameterKey) -> Result<i64, ParameterError> {
        let number = number(key)?;
        self.param(number)
            .map_err(|e| ParameterError::Refused(format!("PAR {number}: {e}")))
    }

    fn set_parameter(
        &mut self,
        key: &ParameterKey,
        value: i64,
        _cx: &mut Context<'_>,
    ) -> Result<(), ParameterError> {
        let number = number(key)?;
        self.set_param(number, value)
            .map_err(|e| ParameterError::Refused(format!("PAR {number} = {value}: {e}")))
    }

    /// The DeviceNet EDS of the card's object model (DeviceNet personality only): the
    /// Identity object, the polled I/O sizes of the PDC layout placed at the last drive
    /// reset, and every drive parameter as a Parameter object instance.
    fn data_sheet(&self, written: &FileDate) -> Result<String, DataSheetError> {
        let slave = self.devicenet().ok_or_else(|| {
            DataSheetError::Unavailable(
                "does not run the DeviceNet personality (PAR 4000 Fieldbus type = DeviceNet)"
                    .into(),
            )
        })?;
        let (input, output) = slave.app().poll_sizes();
        let params = catalog()
            .iter()
            .map(|d| {
                // The Parameter object answers every value as a DWORD (manual §3.4.1).
                let ty = if d.ty.signed() {
                    CipType::Dint
                } else {
                    CipType::Udint
                };
                let mut p = EdsParam::new(d.par, d.name.clone(), ty, 4);
                p.units = d.unit.to_string();
                p.min = Some(d.min);
                p.max = Some(d.max);
                p.default = Some(d.default);
                if d.access == ParamAccess::Ro {
                    p.descriptor = descriptor::READ_ONLY | descriptor::MONITOR;
                }
                let mut help = Vec::new();
                if let ParamType::Src { .. } = d.ty {
                    help.push("the number of the parameter feeding it (0 = Null)");
                }
                if d.after_reset {
                    help.push("takes effect at the next drive reset");
                }
                p.help = help.join("; ");
                if let ParamType::Enum(values) = d.ty {
                    p.enums = values
                        .iter()
                        .map(|(v, n)| (i64::from(*v), (*n).to_string()))
                        .collect();
                }
                p
            })
            .collect();
        let eds = DeviceEds {
            file: FileSection {
                description: "ADV200 with the EXP-CAN/DN-ADV card, DeviceNet (generated from the twin's object model)".into(),
                date: EdsDate {
                    month: written.month,
                    day: written.day,
                    year: written.year,
                },
                time: EdsTime {
                    hour: written.hour,
                    minute: written.minute,
                    second: written.second,
                },
                revision: (1, 0),
            },
            identity: slave.config().identity.clone(),
            vendor_name: "Gefran".into(),
            product_type_name: "AC Drive".into(),
            catalog: Some("EXP-CAN/DN-ADV".into()),
            polled: (input > 0 || output > 0).then_some((input, output)),
            params,
        };
        Ok(cantwin_devicenet::eds::write(&eds))
    }

    /// `speed_rpm`, `current_a`, `thermal` (0–1), `alarms` (names), `nmt_state` and
    /// `power_state` (when the card runs CANopen or DS402), `opt_bus_faults` (sub-codes).
    fn summary(&self) -> Vec<SummaryEntry> {
        let d = self.drive();
        let alarms = d
            .alarms()
            .iter()
            .map(|a| SignalValue::Text(a.name()))
            .collect();
        let faults = self
            .opt_bus_faults()
            .into_iter()
            .map(|c| SignalValue::Integer(i64::from(c)))
            .collect();
        vec![
            SummaryEntry::new("speed_rpm", Some(SignalValue::Real(d.speed()))),
            SummaryEntry::new("current_a", Some(SignalValue::Real(d.current()))),
            SummaryEntry::new("thermal", Some(SignalValue::Real(d.thermal()))),
            SummaryEntry::new("alarms", Some(SignalValue::List(alarms))),
            SummaryEntry::new(
                "nmt_state",
                self.nmt_state()
                    .map(|s| SignalValue::Text(format!("{s:?}"))),
            ),
            SummaryEntry::new(
                "power_state",
                self.power_state()
                    .map(|s| SignalValue::Text(format!("{s:?}"))),
            ),
            SummaryEntry::new("opt_bus_faults", Some(SignalValue::List(faults))),
        ]
    }
}
