//! The servo as a [`Twin`]: its dictionary, the motion signals front ends plot, the inputs
//! a host sets, and the faults a scenario injects.
//!
//! | signal | set | read | unit |
//! |---|---|---|---|
//! | `position` | — | 0x6064 position actual value | position units |
//! | `velocity` | — | 0x606C velocity actual value | position units/s |
//! | `torque` | — | 0x6077 torque actual value | ‰ of rated torque |
//! | `following_error` | — | 0x60F4 | position units |
//! | `current` | — | phase current | A |
//! | `state` | — | the power drive state (`"operation enabled"` …) | |
//! | `mode` | — | the mode in effect (`"csp"` …, `"none"`) | |
//! | `statusword` | — | 0x6041 | |
//! | `limit_switch.negative`, `limit_switch.positive`, `home_switch` | true: held active (pressed, stuck) | the 0x60FD input | |
//! | `load_torque` | a process torque on the shaft | the same | N·m |
//! | `dc_link` | the DC link voltage (mains sag, loss) | the same | V |
//!
//! Faults (internal defects, injected by a scenario's `inject` action): `"following_error"` jams the shaft (the position loop then builds
//! a real following error), `"limit_switch"` holds the positive limit switch active,
//! `"over_current"` shorts two motor phases (the inverter trips as soon as it switches
//! on), `"dc_link"` takes the mains away (the DC link falls to 0 V: under-voltage).
//! Repairing removes them all.

use cantwin_canopen::od::ObjectDictionary;
use cantwin_cia402::Mode;
use cantwin_cia402::physics::{HOME_SWITCH, NEGATIVE_LIMIT_SWITCH, POSITIVE_LIMIT_SWITCH};
use cantwin_twin::{
    Context, Direction, Fault, FaultError, FaultKind, LiveValue, ObjectError, Role,
    SignalDescription, SignalError, SignalId, SignalValue, SummaryEntry, Twin, ValueKind,
    write_through,
};

use crate::servo::Servo;

const KNOWN: &str = "position, velocity, torque, following_error, current, state, mode, statusword, limit_switch.negative, limit_switch.positive, home_switch, load_torque, dc_link";

const FAULTS: &str = "following_error, limit_switch, over_current, dc_link";

fn switch_bit(id: &str) -> Option<u32> {
    match id {
        "limit_switch.negative" => Some(NEGATIVE_LIMIT_SWITCH),
        "limit_switch.positive" => Some(POSITIVE_LIMIT_SWITCH),
        "home_switch" => Some(HOME_SWITCH),
        _ => None,
    }
}

impl Servo {
    fn mode_name(&self) -> &'static str {
        self.drive().mode().map_or("none", Mode::abbreviation)
    }
}

impl Twin for Servo {
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        Some(self.device().od())
    }

    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        self.settle(cx.now);
        write_through(self.device_mut(), index, sub, data)?;
        self.after_device();
        Ok(())
    }

    fn canopen_node_id(&self) -> Option<u8> {
        Some(self.device().node_id())
    }

    fn dictionary_heap_bytes(&self) -> Option<usize> {
        Some(self.device().heap_bytes())
    }

    fn signals(&self) -> Vec<SignalDescription> {
        let real = || ValueKind::Real {
            min: f64::MIN,
            max: f64::MAX,
        };
        let mut v = vec![
            SignalDescription::output("position".into(), real()).role(Role::Measured),
            SignalDescription::output("velocity".into(), real()).role(Role::Measured),
            SignalDescription::output("torque".into(), real())
                .unit("‰")
                .role(Role::Measured),
            SignalDescription::output("following_error".into(), real()).role(Role::Measured),
            SignalDescription::output("current".into(), real())
                .unit("A")
                .role(Role::Measured),
            SignalDescription::output("state".into(), ValueKind::Text(Vec::new())),
            SignalDescription::output("mode".into(), ValueKind::Text(Vec::new())),
            SignalDescription::output(
                "statusword".into(),
                ValueKind::Integer {
                    min: 0,
                    max: 0xFFFF,
                },
            ),
        ];
        for name in [
            "limit_switch.negative",
            "limit_switch.positive",
            "home_switch",
        ] {
            v.push(
                SignalDescription::input(name.into(), ValueKind::Bool)
                    .readable(ValueKind::Bool)
                    .role(Role::DigitalInput),
            );
        }
        v.push(
            SignalDescription::input("load_torque".into(), real())
                .readable(real())
                .unit("N·m"),
        );
        v.push(
            SignalDescription::input(
                "dc_link".into(),
                ValueKind::Real {
                    min: 0.0,
                    max: 1000.0,
                },
            )
            .readable(real())
            .unit("V"),
        );
        v
    }

    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        self.settle(cx.now);
        if let Some(bit) = switch_bit(id.as_str()) {
            let on = value.to_bool(id)?;
            let d = self.drive_mut();
            let forced = d.forced_inputs();
            d.force_inputs(if on { forced | bit } else { forced & !bit });
        } else {
            match id.as_str() {
                "load_torque" => self.drive_mut().motor_mut().load_torque = value.to_f64(id)?,
                "dc_link" => {
                    let v = value.to_f64(id)?;
                    if !(0.0..=1000.0).contains(&v) {
                        return Err(SignalError::OutOfRange {
                            signal: id.clone(),
                            range: "0–1000 V".into(),
                            got: value.clone(),
                        });
                    }
                    self.drive_mut().inverter_mut().dc_link = v;
                }
                _ => return Err(SignalError::unknown(id, Direction::Set, KNOWN)),
            }
        }
        self.changed(cx.now);
        Ok(())
    }

    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        let d = self.drive();
        if let Some(bit) = switch_bit(id.as_str()) {
            return Ok(SignalValue::Bool(d.digital_inputs() & bit != 0));
        }
        let od = self.device().od();
        let int = |index: u16| {
            od.get(index, 0)
                .ok()
                .and_then(|v| v.as_i128())
                .map_or(0, |v| v as i64)
        };
        use cantwin_cia402::index::*;
        Ok(match id.as_str() {
            "position" => SignalValue::Real(d.position()),
            "velocity" => SignalValue::Real(d.velocity()),
            "torque" => SignalValue::Real(d.torque()),
            "following_error" => SignalValue::Real(d.following_error()),
            "current" => SignalValue::Real(d.motor().state.current),
            "state" => SignalValue::Text(d.state().name().into()),
            "mode" => SignalValue::Text(self.mode_name().into()),
            "statusword" => SignalValue::Integer(int(STATUSWORD)),
            "load_torque" => SignalValue::Real(d.motor().load_torque),
            "dc_link" => SignalValue::Real(d.inverter().dc_link),
            _ => return Err(SignalError::unknown(id, Direction::Read, KNOWN)),
        })
    }

    fn live_values(&self) -> Vec<LiveValue> {
        let d = self.drive();
        let inputs = d.digital_inputs();
        vec![
            LiveValue::measured("position", d.position(), ""),
            LiveValue::measured("velocity", d.velocity(), ""),
            LiveValue::measured("torque", d.torque(), "‰"),
            LiveValue::measured("following_error", d.following_error(), ""),
            LiveValue::measured("current", d.motor().state.current, "A"),
            LiveValue::digital(
                "limit_switch.negative",
                inputs & NEGATIVE_LIMIT_SWITCH != 0,
                Role::DigitalInput,
            ),
            LiveValue::digital(
                "limit_switch.positive",
                inputs & POSITIVE_LIMIT_SWITCH != 0,
                Role::DigitalInput,
            ),
            LiveValue::digital("home_switch", inputs & HOME_SWITCH != 0, Role::DigitalInput),
        ]
    }

    fn inject(&mut self, fault: &Fault, cx: &mut Context<'_>) -> Result<(), FaultError> {
        if fault.kind != FaultKind::Internal {
            return Err(FaultError::None { kind: fault.kind });
        }
        self.settle(cx.now);
        let d = self.drive_mut();
        match fault.name.as_str() {
            "following_error" => d.motor_mut().jammed = true,
            "limit_switch" => {
                let forced = d.forced_inputs();
                d.force_inputs(forced | POSITIVE_LIMIT_SWITCH);
            }
            "over_current" => d.inverter_mut().phase_short = true,
            "dc_link" => d.inverter_mut().dc_link = 0.0,
            _ => {
                return Err(FaultError::Unknown {
                    fault: fault.clone(),
                    reason: format!("no fault {:?} (faults: {FAULTS})", fault.name),
                });
            }
        }
        self.changed(cx.now);
        Ok(())
    }

    fn repair(&mut self, kind: FaultKind, cx: &mut Context<'_>) -> Result<(), FaultError> {
        if kind != FaultKind::Internal {
            return Err(FaultError::None { kind });
        }
        self.settle(cx.now);
        let nominal = self.drive().config().inverter.dc_link_nominal;
        let d = self.drive_mut();
        d.motor_mut().jammed = false;
        d.force_inputs(0);
        d.inverter_mut().phase_short = false;
        d.inverter_mut().dc_link = nominal;
        self.changed(cx.now);
        Ok(())
    }

    fn summary(&self) -> Vec<SummaryEntry> {
        let d = self.drive();
        vec![
            SummaryEntry::new("state", Some(SignalValue::Text(d.state().name().into()))),
            SummaryEntry::new("mode", Some(SignalValue::Text(self.mode_name().into()))),
            SummaryEntry::new("position", Some(SignalValue::Real(d.position()))),
            SummaryEntry::new("velocity", Some(SignalValue::Real(d.velocity()))),
            SummaryEntry::new("torque", Some(SignalValue::Real(d.torque()))),
            SummaryEntry::new(
                "following_error",
                Some(SignalValue::Real(d.following_error())),
            ),
            SummaryEntry::new(
                "error_code",
                Some(SignalValue::Integer(i64::from(d.error_code()))),
            ),
        ]
    }
}
