//! Reading and writing devices: object dictionaries and the models behind them.
//!
//! Every device is reached as the [`Twin`] the simulation hands out for its port: its
//! dictionary, its signals (terminals are found by their role and channel in the twin's
//! signal descriptions), its live values, faults, parameters and model summary.

use cantwin_bus::PortId;
use cantwin_scenario::BuiltDevice;
use cantwin_twin::{
    Context, Direction, Fault, FaultError, FaultKind, ObjectError, ParameterError, ParameterKey,
    Role, SignalDescription, SignalError, SignalId, SignalValue, Twin, ValueKind,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::core::{Core, err};

fn unsupported(device: &str, kind: &str, what: &str) -> PyErr {
    PyTypeError::new_err(format!("{device} is a {kind} device, which has no {what}"))
}

/// Run `f` on the twin of `device` now (`None` when the device is not a twin).
fn with_twin<R>(
    core: &mut Core,
    device: &str,
    f: impl FnOnce(&mut dyn Twin, &mut Context<'_>) -> R,
) -> PyResult<(BuiltDevice, Option<R>)> {
    let d = core.device(device)?;
    let port = d.port;
    let r = core.with_sim(|sim| sim.with_twin(port, f))?;
    Ok((d, r))
}

/// Run `f` on the twin of `device` without changing it.
fn read_twin<R>(
    core: &mut Core,
    device: &str,
    f: impl FnOnce(&dyn Twin) -> R,
) -> PyResult<(BuiltDevice, Option<R>)> {
    let d = core.device(device)?;
    let port: PortId = d.port;
    let r = core.with_sim(|sim| sim.twin(port).map(f))?;
    Ok((d, r))
}

fn object_error(
    device: &str,
    d: &BuiltDevice,
    index: u16,
    sub: u8,
    e: ObjectError,
    what: &str,
) -> PyErr {
    match e {
        ObjectError::NoDictionary => unsupported(device, &d.kind, what),
        ObjectError::Abort(code) => err(format!(
            "{device}: object 0x{index:04X} sub {sub}: abort {code}"
        )),
        ObjectError::Refused(why) => PyTypeError::new_err(format!("{device}: {why}")),
    }
}

pub(crate) fn read_object(core: &mut Core, device: &str, index: u16, sub: u8) -> PyResult<Vec<u8>> {
    let (d, r) = read_twin(core, device, |t| t.read_object(index, sub))?;
    r.unwrap_or(Err(ObjectError::NoDictionary))
        .map_err(|e| object_error(device, &d, index, sub, e, "object dictionary"))
}

pub(crate) fn write_object(
    core: &mut Core,
    device: &str,
    index: u16,
    sub: u8,
    data: &[u8],
) -> PyResult<()> {
    let (d, r) = with_twin(core, device, |t, cx| t.write_object(index, sub, data, cx))?;
    r.unwrap_or(Err(ObjectError::NoDictionary))
        .map_err(|e| object_error(device, &d, index, sub, e, "writable object dictionary"))
}

/// The terminal of `device` in `role` (`what` names them in errors) at `channel`, on
/// `module` when the device has expansion modules.
fn terminal(
    core: &mut Core,
    device: &str,
    role: fn(Role) -> bool,
    what: &str,
    module: Option<usize>,
    channel: u8,
) -> PyResult<SignalDescription> {
    let (d, signals) = read_twin(core, device, |t| t.signals())?;
    let terminals: Vec<SignalDescription> = signals
        .unwrap_or_default()
        .into_iter()
        .filter(|s| s.role.is_some_and(role) && s.terminal.is_some())
        .collect();
    if terminals.is_empty() {
        return Err(unsupported(device, &d.kind, what));
    }
    let modular = terminals
        .iter()
        .any(|s| s.terminal.is_some_and(|t| t.module.is_some()));
    let module = match (module, modular) {
        (Some(_), false) => {
            return Err(PyValueError::new_err(format!(
                "{device} has no expansion modules"
            )));
        }
        (None, true) => {
            return Err(PyValueError::new_err(format!(
                "{device}: its {what} are on expansion modules: give module="
            )));
        }
        (m, _) => m.and_then(|m| u32::try_from(m).ok()),
    };
    let on_module: Vec<&SignalDescription> = terminals
        .iter()
        .filter(|s| s.terminal.is_some_and(|t| t.module == module))
        .collect();
    if let Some(s) = on_module
        .iter()
        .find(|s| s.terminal.is_some_and(|t| t.channel == u32::from(channel)))
    {
        return Ok((*s).clone());
    }
    let channels: Vec<u32> = on_module
        .iter()
        .filter_map(|s| s.terminal.map(|t| t.channel))
        .collect();
    let place = module
        .map(|m| format!(" on module {m}"))
        .unwrap_or_default();
    Err(PyValueError::new_err(
        match (channels.iter().min(), channels.iter().max()) {
            (Some(lo), Some(hi)) => {
                format!("{device} has {what} {lo}-{hi}{place}, not {channel}")
            }
            _ => format!("{device} has no {what}{place}"),
        },
    ))
}

/// A signal error as the scripts word it: a signal the device lacks is named with its kind.
fn signal_error(device: &str, d: &BuiltDevice, e: &SignalError) -> PyErr {
    PyValueError::new_err(format!("{device}: {}", d.signal_message(e)))
}

/// Sets `signal` of `device` to `value` now.
fn set(core: &mut Core, device: &str, signal: &SignalId, value: SignalValue) -> PyResult<()> {
    let (d, r) = with_twin(core, device, |t, cx| t.set_signal(signal, &value, cx))?;
    r.unwrap_or_else(|| Err(SignalError::unknown(signal, Direction::Set, "")))
        .map_err(|e| signal_error(device, &d, &e))
}

/// Reads `signal` of `device`.
fn get(core: &mut Core, device: &str, signal: &SignalId) -> PyResult<SignalValue> {
    let (d, r) = read_twin(core, device, |t| t.read_signal(signal))?;
    r.unwrap_or_else(|| Err(SignalError::unknown(signal, Direction::Read, "")))
        .map_err(|e| signal_error(device, &d, &e))
}

pub(crate) fn set_digital_input(
    core: &mut Core,
    device: &str,
    channel: u8,
    on: bool,
    module: Option<usize>,
) -> PyResult<()> {
    let is = |r: Role| r == Role::DigitalInput;
    let s = terminal(core, device, is, "digital inputs", module, channel)?;
    set(core, device, &s.id, SignalValue::Bool(on))
}

pub(crate) fn set_analog_input(
    core: &mut Core,
    device: &str,
    channel: u8,
    value: f64,
    module: Option<usize>,
) -> PyResult<()> {
    let is = |r: Role| matches!(r, Role::AnalogInput { .. });
    let s = terminal(core, device, is, "analog inputs", module, channel)?;
    let value = match s.set {
        // Raw counts take whole numbers only.
        Some(ValueKind::Integer { min, max }) => {
            if value.fract() != 0.0 || !(min as f64..=max as f64).contains(&value) {
                return Err(PyValueError::new_err(format!(
                    "{device}: {} is a raw integer in {min}..={max}, not {value}",
                    s.id
                )));
            }
            SignalValue::Integer(value as i64)
        }
        _ => SignalValue::Real(value),
    };
    set(core, device, &s.id, value)
}

pub(crate) fn digital_output(
    core: &mut Core,
    device: &str,
    channel: u8,
    module: Option<usize>,
) -> PyResult<bool> {
    let is = |r: Role| r == Role::DigitalOutput;
    let s = terminal(core, device, is, "digital outputs", module, channel)?;
    match get(core, device, &s.id)? {
        SignalValue::Bool(b) => Ok(b),
        other => Err(err(format!("{device}: {} is {other}, not on or off", s.id))),
    }
}

pub(crate) fn analog_output(
    core: &mut Core,
    device: &str,
    module: usize,
    channel: u8,
) -> PyResult<i16> {
    let is = |r: Role| r == Role::AnalogOutput;
    let s = terminal(core, device, is, "analog outputs", Some(module), channel)?;
    match get(core, device, &s.id)? {
        SignalValue::Integer(v) => i16::try_from(v).map_err(|_| {
            err(format!(
                "{device}: {} = {v} is not a raw 16-bit value",
                s.id
            ))
        }),
        other => Err(err(format!(
            "{device}: {} is {other}, not raw counts",
            s.id
        ))),
    }
}

/// A signal's value in Python.
fn to_py<'py>(py: Python<'py>, value: &SignalValue) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        SignalValue::Bool(b) => pyo3::types::PyBool::new(py, *b).to_owned().into_any(),
        SignalValue::Integer(i) => i.into_pyobject(py)?.into_any(),
        SignalValue::Real(f) => f.into_pyobject(py)?.into_any(),
        SignalValue::Text(s) => s.into_pyobject(py)?.into_any(),
        SignalValue::List(a) => {
            let items = a
                .iter()
                .map(|v| to_py(py, v))
                .collect::<PyResult<Vec<_>>>()?;
            pyo3::types::PyList::new(py, items)?.into_any()
        }
    })
}

pub(crate) fn drive<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let (d, summary) = read_twin(core, device, |t| t.summary())?;
    let summary = summary.unwrap_or_default();
    if summary.is_empty() {
        return Err(unsupported(device, &d.kind, "drive model"));
    }
    let dict = PyDict::new(py);
    for entry in summary {
        match &entry.value {
            Some(v) => dict.set_item(entry.name, to_py(py, v)?)?,
            None => dict.set_item(entry.name, py.None())?,
        }
    }
    Ok(dict)
}

/// A parameter key from Python: a number (an ADV200 `PAR`) or a name (an OpenDrive `"P61"`,
/// `"C48"`); the device says which it takes.
#[derive(FromPyObject)]
pub(crate) enum ParKey {
    /// A number.
    Number(u16),
    /// A name.
    Name(String),
}

impl ParKey {
    fn key(&self) -> ParameterKey {
        match self {
            ParKey::Number(n) => ParameterKey::Number(*n),
            ParKey::Name(s) => ParameterKey::Name(s.clone()),
        }
    }
}

fn parameter_error(device: &str, d: &BuiltDevice, e: ParameterError, what: &str) -> PyErr {
    match e {
        ParameterError::None => unsupported(device, &d.kind, what),
        ParameterError::BadKey(m) | ParameterError::Refused(m) => PyValueError::new_err(m),
    }
}

pub(crate) fn param(core: &mut Core, device: &str, key: &ParKey) -> PyResult<i64> {
    let key = key.key();
    let (d, r) = read_twin(core, device, |t| t.parameter(&key))?;
    r.unwrap_or(Err(ParameterError::None))
        .map_err(|e| parameter_error(device, &d, e, "parameters"))
}

pub(crate) fn set_param(core: &mut Core, device: &str, key: &ParKey, value: i64) -> PyResult<()> {
    let key = key.key();
    let (d, r) = with_twin(core, device, |t, cx| t.set_parameter(&key, value, cx))?;
    r.unwrap_or(Err(ParameterError::None))
        .map_err(|e| parameter_error(device, &d, e, "keypad parameters"))
}

pub(crate) fn raise_alarm(core: &mut Core, device: &str, alarm: &str) -> PyResult<()> {
    let fault = Fault::alarm(alarm);
    let (d, r) = with_twin(core, device, |t, cx| t.inject(&fault, cx))?;
    match r.unwrap_or(Err(FaultError::None {
        kind: FaultKind::Alarm,
    })) {
        Ok(()) => Ok(()),
        Err(FaultError::None { .. }) => Err(unsupported(device, &d.kind, "alarms")),
        Err(e) => Err(PyValueError::new_err(e.to_string())),
    }
}

/// A Python value as the signal value a scenario script would give.
fn to_signal(value: &Bound<'_, PyAny>) -> PyResult<SignalValue> {
    if let Ok(b) = value.extract::<bool>() {
        return Ok(SignalValue::Bool(b));
    }
    if let Ok(i) = value.extract::<i64>() {
        return Ok(SignalValue::Integer(i));
    }
    if let Ok(f) = value.extract::<f64>() {
        return Ok(SignalValue::Real(f));
    }
    if let Ok(s) = value.extract::<String>() {
        return Ok(SignalValue::Text(s));
    }
    Err(PyTypeError::new_err(
        "a signal value is a bool, an int, a float or a str",
    ))
}

pub(crate) fn set_signal(
    core: &mut Core,
    device: &str,
    name: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let value = to_signal(value)?;
    set(core, device, &SignalId::new(name), value)
}

pub(crate) fn read_signal<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
    name: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let v = get(core, device, &SignalId::new(name))?;
    to_py(py, &v)
}

pub(crate) fn live_values<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let (_, values) = read_twin(core, device, |t| t.live_values())?;
    let d = PyDict::new(py);
    for v in values.unwrap_or_default() {
        d.set_item(v.name, v.value)?;
    }
    Ok(d)
}

pub(crate) fn inject(core: &mut Core, device: &str, fault: Option<&str>) -> PyResult<()> {
    let (d, r) = with_twin(core, device, |t, cx| match fault {
        Some(f) => t.inject(&Fault::internal(f), cx),
        None => t.repair(FaultKind::Internal, cx),
    })?;
    r.unwrap_or(Err(FaultError::None {
        kind: FaultKind::Internal,
    }))
    .map_err(|e| PyValueError::new_err(format!("{device}: {}", d.fault_message(&e))))
}
