//! `cantwin.Simulation`: a scenario built into a simulation, in virtual or paced time.

use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};

use cantwin_bus::{FaultRule, FrameSelector, PacedConfig, PacedSimulation, Simulation as BusSim};
use cantwin_can::{BitRate, ErrorState};
use cantwin_scenario::{BuildEnv, Registry, Scenario};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::capture::Capture;
use crate::core::{Core, Delivery, Mode, Shared, err, secs};
use crate::port::Port;

/// A scenario built into a simulation.
///
/// Build it with :py:meth:`Simulation.load` (a scenario file) or
/// :py:meth:`Simulation.from_toml` (scenario text). It starts in virtual time at 0 s: only
/// :py:meth:`advance` and python-can receivers waiting on a :py:class:`Port` move time on,
/// and bus time stands still while a Python thread that sent a frame or changed a device has
/// not started waiting (on a receive, a ``threading`` wait, ``time.sleep``), at most
/// ``reaction_time`` of wall time: a script that triggers and then waits finds the answer.
/// :py:meth:`start_paced` hands it to a thread that keeps bus time in step with the wall
/// clock until :py:meth:`stop_paced`.
#[pyclass(module = "cantwin._native", frozen)]
pub struct Simulation {
    pub(crate) shared: Arc<Shared>,
    file: PathBuf,
}

fn build(
    scenario: Scenario,
    state_dir: Option<PathBuf>,
    reaction_time: f64,
) -> PyResult<Simulation> {
    let reaction_time = secs(reaction_time)?.into();
    let registry = Registry::builtin();
    let built = scenario
        .build(&registry, &BuildEnv { state_dir })
        .map_err(|e| err(e.to_string()))?;
    let core = Core {
        mode: Mode::Virtual(built.sim),
        buses: built.buses,
        devices: built.devices,
        reaction_time,
        acting: Vec::new(),
        actors: Vec::new(),
        blocked: Vec::new(),
    };
    Ok(Simulation {
        shared: Arc::new(Shared {
            core: Mutex::new(core),
            changed: Condvar::new(),
            delivery: Arc::new(Delivery::default()),
        }),
        file: scenario.file.clone(),
    })
}

fn state_name(s: ErrorState) -> &'static str {
    match s {
        ErrorState::Active => "error-active",
        ErrorState::Passive => "error-passive",
        ErrorState::BusOff => "bus-off",
    }
}

#[pymethods]
impl Simulation {
    /// Load the scenario file `path` and build it.
    ///
    /// `state_dir` keeps what devices store (CANopen 0x1010) between runs; `reaction_time`
    /// (seconds, wall clock) bounds how long a receiver lets other Python threads answer a
    /// frame before the simulation runs on past it, and how long it waits for a thread that
    /// acted to start waiting before the simulation runs or a frame is handed over (see the
    /// package README).
    #[staticmethod]
    #[pyo3(signature = (path, *, state_dir=None, reaction_time=0.02))]
    fn load(path: PathBuf, state_dir: Option<PathBuf>, reaction_time: f64) -> PyResult<Self> {
        let scenario = Scenario::load(&path).map_err(|e| err(e.to_string()))?;
        build(scenario, state_dir, reaction_time)
    }

    /// Build a scenario from TOML text; `name` is the file name errors mention, and relative
    /// paths in the scenario (EDS files) resolve against its folder.
    #[staticmethod]
    #[pyo3(signature = (text, *, name="inline.toml", state_dir=None, reaction_time=0.02))]
    fn from_toml(
        text: &str,
        name: &str,
        state_dir: Option<PathBuf>,
        reaction_time: f64,
    ) -> PyResult<Self> {
        let scenario = Scenario::parse(text, name).map_err(|e| err(e.to_string()))?;
        build(scenario, state_dir, reaction_time)
    }

    /// The scenario file's path (the `name` given to :py:meth:`from_toml`).
    #[getter]
    fn file(&self) -> PathBuf {
        self.file.clone()
    }

    /// Bus time now, in seconds since the simulation started.
    #[getter]
    fn now(&self, py: Python<'_>) -> PyResult<f64> {
        let shared = Arc::clone(&self.shared);
        py.detach(move || {
            shared
                .lock()
                .with_sim(|s| s.now().since_start().as_secs_f64())
        })
    }

    /// Whether the simulation is paced to the wall clock.
    #[getter]
    fn paced(&self) -> bool {
        matches!(self.shared.lock().mode, Mode::Paced(_))
    }

    /// The buses' names, in file order.
    #[getter]
    fn buses(&self) -> Vec<String> {
        self.shared
            .lock()
            .buses
            .iter()
            .map(|(n, _)| n.clone())
            .collect()
    }

    /// The devices as ``(name, kind, bus)``, in file order.
    #[getter]
    fn devices(&self) -> Vec<(String, String, String)> {
        let core = self.shared.lock();
        core.devices
            .iter()
            .map(|d| (d.name.clone(), d.kind.clone(), core.bus_name(d.port.bus())))
            .collect()
    }

    /// Let `seconds` of bus time pass. In virtual time this runs every event due in that
    /// span at once; paced, it waits that long on the wall clock while the simulation runs.
    fn advance(&self, py: Python<'_>, seconds: f64) -> PyResult<()> {
        let d = secs(seconds)?;
        let thread = crate::turns::thread_ident(py)?;
        let shared = Arc::clone(&self.shared);
        py.detach(move || {
            let mut core = shared.lock();
            // The caller lets time pass itself: it waits (`crate::turns`).
            core.waits(thread);
            match &mut core.mode {
                Mode::Virtual(sim) => {
                    sim.run_for(d);
                    drop(core);
                    shared.changed.notify_all();
                }
                Mode::Paced(_) => {
                    drop(core);
                    std::thread::sleep(d.into());
                }
            }
        });
        Ok(())
    }

    /// Hand the simulation to a thread that paces bus time to the wall clock from now on.
    /// `max_lag` (seconds) is how far it may fall behind before the backlog is given up.
    #[pyo3(signature = (*, max_lag=0.05))]
    fn start_paced(&self, max_lag: f64) -> PyResult<()> {
        let max_lag = secs(max_lag)?;
        let mut core = self.shared.lock();
        let mode = std::mem::replace(&mut core.mode, Mode::Virtual(BusSim::new()));
        core.mode = match mode {
            Mode::Virtual(sim) => Mode::Paced(PacedSimulation::start(
                sim,
                PacedConfig {
                    max_lag,
                    ..PacedConfig::default()
                },
            )),
            paced @ Mode::Paced(_) => {
                core.mode = paced;
                return Err(err("the simulation is already paced"));
            }
        };
        drop(core);
        self.shared.changed.notify_all();
        Ok(())
    }

    /// Stop pacing: the simulation stays at the bus time it reached and goes on in virtual
    /// time.
    fn stop_paced(&self, py: Python<'_>) -> PyResult<()> {
        let shared = Arc::clone(&self.shared);
        py.detach(move || {
            let mut core = shared.lock();
            let mode = std::mem::replace(&mut core.mode, Mode::Virtual(BusSim::new()));
            let r = match mode {
                Mode::Paced(p) => match p.stop() {
                    Some(sim) => {
                        core.mode = Mode::Virtual(sim);
                        Ok(())
                    }
                    None => Err(err("the paced simulation did not hand its state back")),
                },
                v @ Mode::Virtual(_) => {
                    core.mode = v;
                    Err(err("the simulation is not paced"))
                }
            };
            drop(core);
            shared.changed.notify_all();
            r
        })
    }

    /// The kind-specific little-endian bytes of object `index`/`sub` of `device`'s object
    /// dictionary (CANopen devices, the ADV200 card, the TM3 coupler; a `master`'s results).
    fn read_object<'py>(
        &self,
        py: Python<'py>,
        device: &str,
        index: u16,
        sub: u8,
    ) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
        let mut core = self.shared.lock();
        let bytes = crate::devices::read_object(&mut core, device, index, sub)?;
        Ok(pyo3::types::PyBytes::new(py, &bytes))
    }

    /// Store `data` (little-endian, the object's size) in object `index`/`sub` of `device`
    /// as the device's own application does: no access check, event-driven TPDOs mapping the
    /// object become due.
    fn write_object(
        &self,
        py: Python<'_>,
        device: &str,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::write_object(&mut core, device, index, sub, data)
    }

    /// Switch digital input `channel` of `device` on or off: ADV200 inputs 1-8; TM3
    /// `channel` 0-based on expansion `module` (1-based); OpenDrive inputs 1-8.
    #[pyo3(signature = (device, channel, on, *, module=None))]
    fn set_digital_input(
        &self,
        py: Python<'_>,
        device: &str,
        channel: u8,
        on: bool,
        module: Option<usize>,
    ) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::set_digital_input(&mut core, device, channel, on, module)
    }

    /// Set analog input `channel` of `device`: ADV200 inputs 1-2 in volts (±10 V); TM3
    /// `channel` 0-based on `module` (1-based), raw 16-bit value.
    #[pyo3(signature = (device, channel, value, *, module=None))]
    fn set_analog_input(
        &self,
        py: Python<'_>,
        device: &str,
        channel: u8,
        value: f64,
        module: Option<usize>,
    ) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::set_analog_input(&mut core, device, channel, value, module)
    }

    /// Digital output `channel` of `device`: ADV200 outputs 1-4; TM3 `channel` 0-based on
    /// `module` (1-based).
    #[pyo3(signature = (device, channel, *, module=None))]
    fn digital_output(&self, device: &str, channel: u8, module: Option<usize>) -> PyResult<bool> {
        let mut core = self.shared.lock();
        crate::devices::digital_output(&mut core, device, channel, module)
    }

    /// Analog output `channel` (0-based) of TM3 expansion `module` (1-based), raw 16-bit.
    fn analog_output(&self, device: &str, module: usize, channel: u8) -> PyResult<i16> {
        let mut core = self.shared.lock();
        crate::devices::analog_output(&mut core, device, module, channel)
    }

    /// A drive's model values: for an ADV200 ``speed_rpm``, ``current_a``, ``thermal``,
    /// ``alarms``, ``nmt_state``, ``power_state`` (CiA 402) and ``opt_bus_faults``; for an
    /// OpenDrive ``params`` of note and its inputs.
    fn drive<'py>(&self, py: Python<'py>, device: &str) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.shared.lock();
        crate::devices::drive(py, &mut core, device)
    }

    /// A drive parameter: ADV200 `PAR` number, OpenDrive parameter name (``"P61"``).
    fn param(&self, device: &str, number: crate::devices::ParKey) -> PyResult<i64> {
        let mut core = self.shared.lock();
        crate::devices::param(&mut core, device, &number)
    }

    /// Set a drive parameter from its keypad (no fieldbus involved): ADV200 `PAR` number
    /// (effective as the drive's manual says: fieldbus settings at the next drive reset),
    /// OpenDrive parameter name.
    fn set_param(
        &self,
        py: Python<'_>,
        device: &str,
        number: crate::devices::ParKey,
        value: i64,
    ) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::set_param(&mut core, device, &number, value)
    }

    /// Raise a drive alarm by its manual's name (ADV200: "External fault", "Overvoltage",
    /// …): the fault reaction and EMCY follow as on the real drive.
    fn raise_alarm(&self, py: Python<'_>, device: &str, alarm: &str) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::raise_alarm(&mut core, device, alarm)
    }

    /// Set the physical quantity `name` of `device` (an input, a load, a module pulled out)
    /// to `value` now, as ``[[at]] action = "set"`` in scenario scripts does: the kind's
    /// signal names (``"digital_input.4"``, ``"analog_input.2"``, …; the error lists them).
    fn set_signal(
        &self,
        py: Python<'_>,
        device: &str,
        name: &str,
        value: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::set_signal(&mut core, device, name, value)
    }

    /// Read the physical quantity `name` of `device` (an output, an alarm), as
    /// ``[[expect]] signal = …`` in scenario scripts does.
    fn read_signal<'py>(
        &self,
        py: Python<'py>,
        device: &str,
        name: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        let mut core = self.shared.lock();
        crate::devices::read_signal(py, &mut core, device, name)
    }

    /// The live values of `device`'s model by name (measurements, inputs, outputs; digital
    /// ones 0 or 1), as the dashboards show them.
    fn live_values<'py>(&self, py: Python<'py>, device: &str) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.shared.lock();
        crate::devices::live_values(py, &mut core, device)
    }

    /// Give `device` the internal defect `fault` in its kind's words, or repair it with
    /// `None` (``action = "inject"``/``"repair"`` in scenario scripts).
    #[pyo3(signature = (device, fault))]
    fn inject(&self, py: Python<'_>, device: &str, fault: Option<&str>) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        crate::devices::inject(&mut core, device, fault)
    }

    /// Power `device` on or off (`power_on`/`power_off` in scenario scripts).
    fn power(&self, py: Python<'_>, device: &str, on: bool) -> PyResult<()> {
        self.shared
            .lock_acting(py)?
            .on_port(device, |bus, port| bus.set_powered(port, on))
    }

    /// Cut or restore `device`'s connection to the wires (`disconnect`/`connect`).
    fn connect(&self, py: Python<'_>, device: &str, connected: bool) -> PyResult<()> {
        self.shared
            .lock_acting(py)?
            .on_port(device, |bus, port| bus.set_connected(port, connected))
    }

    /// Force `device`'s controller bus-off (`bus_off`).
    fn bus_off(&self, py: Python<'_>, device: &str) -> PyResult<()> {
        self.shared
            .lock_acting(py)?
            .on_port(device, |bus, port| bus.force_bus_off(port))
    }

    /// Make `device`'s controller babble `frame` (``"ID#DATA"``), or stop with `None`
    /// (`babble`/`babble_stop`).
    #[pyo3(signature = (device, frame))]
    fn babble(&self, py: Python<'_>, device: &str, frame: Option<&str>) -> PyResult<()> {
        let frame = frame
            .map(cantwin_scenario::script::parse_frame)
            .transpose()
            .map_err(PyValueError::new_err)?;
        self.shared
            .lock_acting(py)?
            .on_port(device, |bus, port| bus.set_babble(port, frame))
    }

    /// Misconfigure `device`'s bit rate (``"250k"``…), or fix it with `None`
    /// (`bit_rate_mismatch`/`bit_rate_fix`).
    #[pyo3(signature = (device, bit_rate))]
    fn bit_rate_mismatch(
        &self,
        py: Python<'_>,
        device: &str,
        bit_rate: Option<&str>,
    ) -> PyResult<()> {
        let rate = bit_rate
            .map(str::parse::<BitRate>)
            .transpose()
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        self.shared
            .lock_acting(py)?
            .on_port(device, |bus, port| bus.set_bit_rate_mismatch(port, rate))
    }

    /// Drop a `fraction` of the transmission attempts on `bus` (only `sender`'s if given,
    /// at most `count` of them): the `drop` action.
    #[pyo3(signature = (bus, fraction, *, sender=None, count=None))]
    fn drop_frames(
        &self,
        py: Python<'_>,
        bus: &str,
        fraction: f64,
        sender: Option<&str>,
        count: Option<u64>,
    ) -> PyResult<()> {
        self.fault(py, bus, false, fraction, sender, count)
    }

    /// Corrupt a `fraction` of the transmission attempts on `bus` (an error frame follows):
    /// the `corrupt` action.
    #[pyo3(signature = (bus, fraction, *, sender=None, count=None))]
    fn corrupt_frames(
        &self,
        py: Python<'_>,
        bus: &str,
        fraction: f64,
        sender: Option<&str>,
        count: Option<u64>,
    ) -> PyResult<()> {
        self.fault(py, bus, true, fraction, sender, count)
    }

    /// Remove every fault rule of `bus` (`clear_faults`).
    fn clear_faults(&self, py: Python<'_>, bus: &str) -> PyResult<()> {
        let mut core = self.shared.lock_acting(py)?;
        let id = core.bus_id(bus)?;
        core.with_sim(|sim| sim.bus_mut(id).map(cantwin_bus::Bus::clear_faults))?;
        Ok(())
    }

    /// Statistics of `bus` since the start: ``frames``, ``dropped_frames``,
    /// ``error_frames``, ``bits``, ``busy_time`` (s), ``load_percent`` and
    /// ``window_load_percent`` (the last load window).
    fn stats<'py>(&self, py: Python<'py>, bus: &str) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.shared.lock();
        let id = core.bus_id(bus)?;
        let values = core.with_sim(|sim| {
            sim.bus(id).map(|b| {
                let s = b.stats();
                let now = b.now();
                (
                    s.frames(),
                    s.dropped_frames(),
                    s.error_frames(),
                    s.bits(),
                    s.busy_time().as_secs_f64(),
                    s.load_percent(now),
                    s.window_load_percent(now),
                )
            })
        })?;
        let (frames, dropped, errors, bits, busy, load, window) =
            values.ok_or_else(|| err("the bus is gone"))?;
        let d = PyDict::new(py);
        d.set_item("frames", frames)?;
        d.set_item("dropped_frames", dropped)?;
        d.set_item("error_frames", errors)?;
        d.set_item("bits", bits)?;
        d.set_item("busy_time", busy)?;
        d.set_item("load_percent", load)?;
        d.set_item("window_load_percent", window)?;
        Ok(d)
    }

    /// `device`'s controller: ``tec``, ``rec``, ``state`` (``"error-active"``,
    /// ``"error-passive"``, ``"bus-off"``), ``powered``, ``connected``, ``queued`` and
    /// its frame counters ``tx_frames``, ``rx_frames``, ``tx_errors``, ``tx_dropped``.
    fn controller<'py>(&self, py: Python<'py>, device: &str) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.shared.lock();
        let port = core.device(device)?.port;
        let status = core.with_sim(|sim| match sim.bus(port.bus()) {
            Some(b) => b.port_status(port).map_err(|e| err(e.to_string())),
            None => Err(err("the device's bus is gone")),
        })??;
        let d = PyDict::new(py);
        d.set_item("tec", status.counters.tec())?;
        d.set_item("rec", status.counters.rec())?;
        d.set_item("state", state_name(status.counters.state()))?;
        d.set_item("powered", status.powered)?;
        d.set_item("connected", status.connected)?;
        d.set_item("queued", status.queued)?;
        d.set_item("tx_frames", status.stats.tx_frames)?;
        d.set_item("rx_frames", status.stats.rx_frames)?;
        d.set_item("tx_errors", status.stats.tx_errors)?;
        d.set_item("tx_dropped", status.stats.tx_dropped)?;
        Ok(d)
    }

    /// Record `bus` (every bus if `None`) into a capture file from now on: frames, and error
    /// frames and controller events as SocketCAN error frames; the format comes
    /// from `format` (``"pcap"``, ``"pcapng"``, ``"candump"``) or the file's extension
    /// (``.pcap``, ``.pcapng``, ``.log``). Frames are stamped at their end of frame, in bus
    /// time since the Unix epoch (virtual time) or wall time (paced). Close the returned
    /// :py:class:`Capture` (or use it as a context manager) to complete the file.
    #[pyo3(signature = (path, *, bus=None, format=None))]
    fn capture(&self, path: PathBuf, bus: Option<&str>, format: Option<&str>) -> PyResult<Capture> {
        crate::capture::start(&self.shared, path, bus, format)
    }

    /// Attach a new node to `bus` for Python: frames it sends arbitrate and take bus time
    /// like any node's; it receives every other frame on the bus (at most `rx_capacity`
    /// buffered, further ones are lost and counted). :py:class:`cantwin.can_interface.CantwinBus`
    /// is the python-can interface built on it. The calling thread is the port's owner: it
    /// answers what it receives itself (``Port.recv``'s `wait_for_answers`).
    #[pyo3(signature = (bus, *, rx_capacity=4096))]
    fn attach(&self, py: Python<'_>, bus: &str, rx_capacity: usize) -> PyResult<Port> {
        let owner = crate::turns::thread_ident(py)?;
        crate::port::attach(&self.shared, bus, rx_capacity, owner)
    }

    fn __repr__(&self) -> String {
        let core = self.shared.lock();
        format!(
            "Simulation(file={:?}, buses={}, devices={}, paced={})",
            self.file.display().to_string(),
            core.buses.len(),
            core.devices.len(),
            matches!(core.mode, Mode::Paced(_))
        )
    }
}

impl Simulation {
    fn fault(
        &self,
        py: Python<'_>,
        bus: &str,
        corrupt: bool,
        fraction: f64,
        sender: Option<&str>,
        count: Option<u64>,
    ) -> PyResult<()> {
        if !(0.0..=1.0).contains(&fraction) {
            return Err(PyValueError::new_err(format!(
                "fraction must be in 0..=1, not {fraction}"
            )));
        }
        let mut core = self.shared.lock_acting(py)?;
        let id = core.bus_id(bus)?;
        let sel = FrameSelector::Fraction(fraction);
        let mut rule = if corrupt {
            FaultRule::corrupt(sel)
        } else {
            FaultRule::drop(sel)
        };
        if let Some(d) = sender {
            rule = rule.from_port(core.device(d)?.port);
        }
        if let Some(n) = count {
            rule = rule.times(n);
        }
        core.with_sim(|sim| sim.bus_mut(id).map(|b| b.inject(rule)))?
            .ok_or_else(|| err("the bus is gone"))
    }
}
