//! Reading and writing devices: object dictionaries and the models behind them.
//!
//! The scenario's kinds answer reads of their objects ([`DeviceKind::read_object`]); the
//! rest is reached through the node types the kinds build (the ADV200 drive, the TM3
//! coupler, the OpenDrive, the CiA 301 and EDS devices).

use cantwin_adv200::Adv200;
use cantwin_adv200::alarms::Alarm;
use cantwin_bus::{Bus, PortId};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::Device;
use cantwin_canopen::od::{ObjectDictionary, OdHooks, Value};
use cantwin_opendrive::{OpenDrive, ParId};
use cantwin_scenario::kinds::cia301::Cia301Node;
use cantwin_tm3::Tm3Coupler;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::sim::{Core, err};

fn abort(device: &str, index: u16, sub: u8, code: AbortCode) -> PyErr {
    err(format!(
        "{device}: object 0x{index:04X} sub {sub}: abort {code}"
    ))
}

fn unsupported(device: &str, kind: &str, what: &str) -> PyErr {
    PyTypeError::new_err(format!("{device} is a {kind} device, which has no {what}"))
}

/// The dictionary of the CANopen device behind `port`, whatever kind built it.
fn od_of(bus: &Bus, port: PortId) -> Option<&ObjectDictionary> {
    if let Some(n) = bus.node::<Cia301Node>(port) {
        return Some(n.device().od());
    }
    if let Some(d) = bus.node::<Device>(port) {
        return Some(d.od());
    }
    if let Some(c) = bus.node::<Tm3Coupler>(port) {
        return Some(c.device().od());
    }
    if let Some(a) = bus.node::<Adv200>(port) {
        return a.device().map(|d| d.od());
    }
    None
}

pub(crate) fn read_object(core: &mut Core, device: &str, index: u16, sub: u8) -> PyResult<Vec<u8>> {
    let d = core.device(device)?;
    let registry = &core.registry;
    let port = d.port;
    let result = match &mut core.mode {
        crate::sim::Mode::Virtual(sim) => read_in(sim, registry, &d.kind, port, index, sub),
        crate::sim::Mode::Paced(p) => p
            .handle()
            .with(|sim| read_in(sim, registry, &d.kind, port, index, sub))
            .map_err(|e| err(e.to_string()))?,
    };
    match result {
        Read::Bytes(b) => Ok(b),
        Read::Abort(code) => Err(abort(device, index, sub, code)),
        Read::NoDictionary => Err(unsupported(device, &d.kind, "object dictionary")),
    }
}

enum Read {
    Bytes(Vec<u8>),
    Abort(AbortCode),
    NoDictionary,
}

fn read_in(
    sim: &cantwin_bus::Simulation,
    registry: &cantwin_scenario::Registry,
    kind: &str,
    port: PortId,
    index: u16,
    sub: u8,
) -> Read {
    if let Some(b) = registry
        .get(kind)
        .and_then(|k| k.read_object(sim, port, index, sub))
    {
        return Read::Bytes(b);
    }
    match sim.bus(port.bus()).and_then(|b| od_of(b, port)) {
        Some(od) => match od.get(index, sub) {
            Ok(v) => Read::Bytes(v.to_le_bytes()),
            Err(code) => Read::Abort(code),
        },
        None => Read::NoDictionary,
    }
}

/// Decode `data` as the type of `index`/`sub` in `od`.
fn value_for(od: &ObjectDictionary, index: u16, sub: u8, data: &[u8]) -> Result<Value, AbortCode> {
    let id = od.locate(index, sub)?;
    let ty = od.sub_object(id).data_type;
    Value::from_le_bytes(ty, data).map_err(|_| AbortCode::TYPE_MISMATCH)
}

pub(crate) fn write_object(
    core: &mut Core,
    device: &str,
    index: u16,
    sub: u8,
    data: &[u8],
) -> PyResult<()> {
    let d = core.device(device)?;
    let port = d.port;
    let data = data.to_vec();
    let r = core.with_sim(move |sim| {
        let bus = sim.bus_mut(port.bus())?;
        fn set<H: OdHooks>(
            dev: &mut Device<H>,
            index: u16,
            sub: u8,
            data: &[u8],
        ) -> Result<(), AbortCode> {
            let v = value_for(dev.od(), index, sub, data)?;
            dev.set_value(index, sub, &v)
        }
        if bus.node::<Cia301Node>(port).is_some() {
            return bus.with_node::<Cia301Node, _>(port, |n, _, _| {
                set(n.device_mut(), index, sub, &data)
            });
        }
        if bus.node::<Device>(port).is_some() {
            return bus.with_node::<Device, _>(port, |n, _, _| set(n, index, sub, &data));
        }
        if bus.node::<Tm3Coupler>(port).is_some() {
            return bus.with_node::<Tm3Coupler, _>(port, |n, _, _| {
                set(n.device_mut(), index, sub, &data)
            });
        }
        None
    })?;
    match r {
        Some(Ok(())) => Ok(()),
        Some(Err(code)) => Err(abort(device, index, sub, code)),
        None if d.kind == "adv200" => Err(PyTypeError::new_err(format!(
            "{device}: the ADV200's objects are its parameters: use set_param"
        ))),
        None => Err(unsupported(device, &d.kind, "writable object dictionary")),
    }
}

/// Run `f` on the node of `device` if it is a `T`.
fn with_node<T: 'static, R>(
    core: &mut Core,
    device: &str,
    what: &str,
    f: impl FnOnce(&mut T) -> R,
) -> PyResult<R> {
    let d = core.device(device)?;
    let port = d.port;
    core.with_sim(|sim| {
        sim.bus_mut(port.bus())
            .and_then(|b| b.with_node::<T, _>(port, |n, _, _| f(n)))
    })?
    .ok_or_else(|| unsupported(device, &d.kind, what))
}

fn channel_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

pub(crate) fn set_digital_input(
    core: &mut Core,
    device: &str,
    channel: u8,
    on: bool,
    module: Option<usize>,
) -> PyResult<()> {
    let kind = core.device(device)?.kind;
    match (kind.as_str(), module) {
        ("adv200", None) => {
            if !(1..=8).contains(&channel) {
                return Err(PyValueError::new_err(format!(
                    "the ADV200 has digital inputs 1-8, not {channel}"
                )));
            }
            with_node::<Adv200, _>(core, device, "digital inputs", |n| {
                n.set_digital_input(channel, on)
            })
        }
        ("opendrive", None) => {
            if !(1..=8).contains(&channel) {
                return Err(PyValueError::new_err(format!(
                    "the OpenDrive has digital inputs 1-8, not {channel}"
                )));
            }
            with_node::<OpenDrive, _>(core, device, "digital inputs", |n| {
                n.drive_mut().set_input(channel, on)
            })
        }
        ("tm3", Some(m)) => with_node::<Tm3Coupler, _>(core, device, "digital inputs", |n| {
            n.set_digital_input(m, channel, on)
        })?
        .map_err(channel_error),
        ("tm3", None) => Err(PyValueError::new_err(
            "a TM3 input is on an expansion module: give module=",
        )),
        (_, Some(_)) => Err(PyValueError::new_err(format!(
            "{device} has no expansion modules"
        ))),
        (k, None) => Err(unsupported(device, k, "digital inputs")),
    }
}

pub(crate) fn set_analog_input(
    core: &mut Core,
    device: &str,
    channel: u8,
    value: f64,
    module: Option<usize>,
) -> PyResult<()> {
    let kind = core.device(device)?.kind;
    match (kind.as_str(), module) {
        ("adv200", None) => {
            if !(1..=2).contains(&channel) || !(-10.0..=10.0).contains(&value) {
                return Err(PyValueError::new_err(
                    "the ADV200 has analog inputs 1-2, in -10..=10 V",
                ));
            }
            with_node::<Adv200, _>(core, device, "analog inputs", |n| {
                n.set_analog_input(channel, value)
            })
        }
        ("tm3", Some(m)) => {
            if value.fract() != 0.0 || !(f64::from(i16::MIN)..=f64::from(i16::MAX)).contains(&value)
            {
                return Err(PyValueError::new_err(
                    "a TM3 analog input is a raw 16-bit integer",
                ));
            }
            with_node::<Tm3Coupler, _>(core, device, "analog inputs", |n| {
                n.set_analog_input(m, channel, value as i16)
            })?
            .map_err(channel_error)
        }
        ("tm3", None) => Err(PyValueError::new_err(
            "a TM3 input is on an expansion module: give module=",
        )),
        (_, Some(_)) => Err(PyValueError::new_err(format!(
            "{device} has no expansion modules"
        ))),
        (k, None) => Err(unsupported(device, k, "analog inputs")),
    }
}

pub(crate) fn digital_output(
    core: &mut Core,
    device: &str,
    channel: u8,
    module: Option<usize>,
) -> PyResult<bool> {
    let kind = core.device(device)?.kind;
    match (kind.as_str(), module) {
        ("adv200", None) => {
            if !(1..=4).contains(&channel) {
                return Err(PyValueError::new_err(format!(
                    "the ADV200 has digital outputs 1-4, not {channel}"
                )));
            }
            with_node::<Adv200, _>(core, device, "digital outputs", |n| {
                n.digital_output(channel)
            })
        }
        ("tm3", Some(m)) => with_node::<Tm3Coupler, _>(core, device, "digital outputs", |n| {
            n.digital_output(m, channel)
        })?
        .map_err(channel_error),
        ("tm3", None) => Err(PyValueError::new_err(
            "a TM3 output is on an expansion module: give module=",
        )),
        (_, Some(_)) => Err(PyValueError::new_err(format!(
            "{device} has no expansion modules"
        ))),
        (k, None) => Err(unsupported(device, k, "digital outputs")),
    }
}

pub(crate) fn analog_output(
    core: &mut Core,
    device: &str,
    module: usize,
    channel: u8,
) -> PyResult<i16> {
    with_node::<Tm3Coupler, _>(core, device, "analog outputs", |n| {
        n.analog_output(module, channel)
    })?
    .map_err(channel_error)
}

pub(crate) fn drive<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = core.device(device)?.kind;
    let d = PyDict::new(py);
    match kind.as_str() {
        "adv200" => {
            let (speed, current, thermal, alarms, nmt, power, faults) =
                with_node::<Adv200, _>(core, device, "drive model", |n| {
                    let drive = n.drive();
                    (
                        drive.speed(),
                        drive.current(),
                        drive.thermal(),
                        drive.alarms().iter().map(|a| a.name()).collect::<Vec<_>>(),
                        n.nmt_state().map(|s| format!("{s:?}")),
                        n.power_state().map(|s| format!("{s:?}")),
                        n.opt_bus_faults(),
                    )
                })?;
            d.set_item("speed_rpm", speed)?;
            d.set_item("current_a", current)?;
            d.set_item("thermal", thermal)?;
            d.set_item("alarms", alarms)?;
            d.set_item("nmt_state", nmt)?;
            d.set_item("power_state", power)?;
            d.set_item("opt_bus_faults", faults)?;
        }
        "opendrive" => {
            let inputs = with_node::<OpenDrive, _>(core, device, "drive model", |n| {
                (1..=8).map(|k| n.drive().input(k)).collect::<Vec<bool>>()
            })?;
            d.set_item("inputs", inputs)?;
        }
        k => return Err(unsupported(device, k, "drive model")),
    }
    Ok(d)
}

/// A parameter key from Python: an ADV200 `PAR` number, or an OpenDrive name (`"P61"`,
/// `"C48"`).
#[derive(FromPyObject)]
pub(crate) enum ParKey {
    /// A number.
    Number(u16),
    /// A name.
    Name(String),
}

impl ParKey {
    fn number(&self) -> PyResult<u16> {
        match self {
            ParKey::Number(n) => Ok(*n),
            ParKey::Name(s) => s
                .trim()
                .parse()
                .map_err(|_| PyValueError::new_err(format!("{s:?} is not a parameter number"))),
        }
    }

    fn opendrive(&self) -> PyResult<ParId> {
        match self {
            ParKey::Name(s) => s.trim().parse().map_err(|_| {
                PyValueError::new_err(format!("{s:?} is not an OpenDrive parameter (P61, C48, …)"))
            }),
            ParKey::Number(n) => Err(PyValueError::new_err(format!(
                "OpenDrive parameters are named with their class: \"P{n}\" or \"C{n}\""
            ))),
        }
    }
}

pub(crate) fn param(core: &mut Core, device: &str, key: &ParKey) -> PyResult<i64> {
    let kind = core.device(device)?.kind;
    match kind.as_str() {
        "adv200" => {
            let number = key.number()?;
            with_node::<Adv200, _>(core, device, "parameters", |n| n.param(number))?
                .map_err(|e| PyValueError::new_err(format!("PAR {number}: {e}")))
        }
        "opendrive" => {
            let id = key.opendrive()?;
            with_node::<OpenDrive, _>(core, device, "parameters", |n| {
                i64::from(n.drive().param(id))
            })
        }
        k => Err(unsupported(device, k, "parameters")),
    }
}

pub(crate) fn set_param(core: &mut Core, device: &str, key: &ParKey, value: i64) -> PyResult<()> {
    let kind = core.device(device)?.kind;
    match kind.as_str() {
        "adv200" => {
            let number = key.number()?;
            with_node::<Adv200, _>(core, device, "parameters", |n| n.set_param(number, value))?
                .map_err(|e| PyValueError::new_err(format!("PAR {number} = {value}: {e}")))
        }
        "opendrive" => {
            let id = key.opendrive()?;
            let v = i32::try_from(value)
                .map_err(|_| PyValueError::new_err(format!("{value} does not fit a parameter")))?;
            with_node::<OpenDrive, _>(core, device, "parameters", |n| {
                n.drive_mut().set_param(id, v)
            })?
            .map_err(|e| PyValueError::new_err(format!("{id} = {value}: {e}")))
        }
        k => Err(unsupported(device, k, "keypad parameters")),
    }
}

pub(crate) fn raise_alarm(core: &mut Core, device: &str, alarm: &str) -> PyResult<()> {
    let kind = core.device(device)?.kind;
    match kind.as_str() {
        "adv200" => {
            let a = Alarm::from_name(alarm).ok_or_else(|| {
                let names: Vec<String> = Alarm::all().into_iter().map(Alarm::name).collect();
                PyValueError::new_err(format!(
                    "the ADV200 has no alarm {alarm:?} (alarms: {})",
                    names.join(", ")
                ))
            })?;
            with_node::<Adv200, _>(core, device, "alarms", |n| n.raise_alarm(a))
        }
        k => Err(unsupported(device, k, "alarms")),
    }
}

/// A Python value as the TOML value a scenario script would give.
fn to_toml(value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if let Ok(b) = value.extract::<bool>() {
        return Ok(toml::Value::Boolean(b));
    }
    if let Ok(i) = value.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    if let Ok(s) = value.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    Err(PyTypeError::new_err(
        "a signal value is a bool, an int, a float or a str",
    ))
}

fn to_py<'py>(py: Python<'py>, value: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        toml::Value::Boolean(b) => pyo3::types::PyBool::new(py, *b).to_owned().into_any(),
        toml::Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        toml::Value::Float(f) => f.into_pyobject(py)?.into_any(),
        toml::Value::String(s) => s.into_pyobject(py)?.into_any(),
        toml::Value::Array(a) => {
            let items = a
                .iter()
                .map(|v| to_py(py, v))
                .collect::<PyResult<Vec<_>>>()?;
            pyo3::types::PyList::new(py, items)?.into_any()
        }
        other => other.to_string().into_pyobject(py)?.into_any(),
    })
}

/// Run `f` with the kind of `device`, its port and the simulation.
fn with_kind<R>(
    core: &mut Core,
    device: &str,
    f: impl FnOnce(&dyn cantwin_scenario::DeviceKind, &mut cantwin_bus::Simulation, PortId) -> R,
) -> PyResult<R> {
    let d = core.device(device)?;
    let Core { mode, registry, .. } = core;
    let kind = registry
        .get(&d.kind)
        .ok_or_else(|| err(format!("{device}: unknown kind {:?}", d.kind)))?;
    match mode {
        crate::sim::Mode::Virtual(sim) => Ok(f(kind, sim, d.port)),
        crate::sim::Mode::Paced(p) => p
            .handle()
            .with(|sim| f(kind, sim, d.port))
            .map_err(|e| err(e.to_string())),
    }
}

pub(crate) fn set_signal(
    core: &mut Core,
    device: &str,
    name: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let value = to_toml(value)?;
    with_kind(core, device, |k, sim, port| {
        k.set_signal(sim, port, name, &value)
    })?
    .map_err(|e| PyValueError::new_err(format!("{device}: {e}")))
}

pub(crate) fn read_signal<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
    name: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let v = with_kind(core, device, |k, sim, port| k.read_signal(sim, port, name))?
        .map_err(|e| PyValueError::new_err(format!("{device}: {e}")))?;
    to_py(py, &v)
}

pub(crate) fn live_values<'py>(
    py: Python<'py>,
    core: &mut Core,
    device: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let values = with_kind(core, device, |k, sim, port| k.live_values(sim, port))?;
    let d = PyDict::new(py);
    for v in values {
        d.set_item(v.name, v.value)?;
    }
    Ok(d)
}

pub(crate) fn inject(core: &mut Core, device: &str, fault: Option<&str>) -> PyResult<()> {
    with_kind(core, device, |k, sim, port| k.inject(sim, port, fault))?
        .map_err(|e| PyValueError::new_err(format!("{device}: {e}")))
}
