//! The state a simulation's Python objects share: the simulation in virtual or paced time,
//! the scenario's names, and the lock and condition variable around them.

use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use cantwin_bus::{BusId, PacedSimulation, PortId, Simulation as BusSim};
use cantwin_can::Duration;
use cantwin_scenario::BuiltDevice;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyKeyError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    cantwin,
    CantwinError,
    PyException,
    "A scenario that cannot be loaded, a device or object that does not answer, a stopped simulation."
);

/// Where the simulation runs.
pub(crate) enum Mode {
    /// Virtual time: only `advance` and waiting receivers move it.
    Virtual(BusSim),
    /// Paced to the wall clock on its own thread.
    Paced(PacedSimulation),
}

/// Frames handed to Python ports and not yet answered: the reaction rule of virtual time.
#[derive(Default)]
pub(crate) struct Delivery {
    /// A frame reached a Python port since Python last sent one.
    pub pending: AtomicBool,
    /// The bus time (ns) of that frame.
    pub at: AtomicU64,
}

/// A Python thread that acted on the simulation (sent a frame, changed a device) and has not
/// waited since: the turn rule of virtual time (`crate::turns`).
pub(crate) struct Acting {
    /// Its `threading.get_ident()`.
    pub thread: u64,
    /// When it acted last, or came back to Python from that act (wall clock).
    pub since: std::time::Instant,
    /// Whether it is back in Python: a thread still inside a call that released the GIL
    /// (a send) cannot be waiting yet, whatever its Python frames show.
    pub returned: bool,
}

/// The state of one simulation.
pub(crate) struct Core {
    pub mode: Mode,
    pub buses: Vec<(String, BusId)>,
    pub devices: Vec<BuiltDevice>,
    /// How long (wall clock) a receiver in virtual time lets other Python threads answer a
    /// frame before it lets the simulation run past it.
    pub reaction_time: std::time::Duration,
    /// The threads that acted and have not waited since (at most one entry per thread).
    pub acting: Vec<Acting>,
    /// Every thread that ever acted and still runs (at most [`ACTORS`]): the threads a frame
    /// handed to Python may wake (`crate::turns::note_woken`).
    pub actors: Vec<u64>,
    /// Those of [`Core::actors`] last seen blocked in a `Condition.wait`: one seen running
    /// after that has been woken since (`crate::turns::note_woken`).
    pub blocked: Vec<u64>,
}

/// How many acting threads [`Core::actors`] remembers; the oldest is forgotten first.
const ACTORS: usize = 16;

/// What the simulation's objects share: the core and a condition variable signalled when
/// Python sends a frame or the simulation changes mode.
pub(crate) struct Shared {
    pub core: Mutex<Core>,
    pub changed: Condvar,
    pub delivery: Arc<Delivery>,
}

impl Shared {
    pub fn lock(&self) -> MutexGuard<'_, Core> {
        self.core.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The core if no other thread holds it (one running the simulation, say).
    pub fn try_lock(&self) -> Option<MutexGuard<'_, Core>> {
        match self.core.try_lock() {
            Ok(core) => Some(core),
            Err(std::sync::TryLockError::Poisoned(p)) => Some(p.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => None,
        }
    }
}

pub(crate) fn err(message: impl Into<String>) -> PyErr {
    CantwinError::new_err(message.into())
}

pub(crate) fn secs(seconds: f64) -> PyResult<Duration> {
    if !seconds.is_finite() || seconds < 0.0 {
        return Err(PyValueError::new_err(format!(
            "a time must be a finite number of seconds >= 0, not {seconds}"
        )));
    }
    Ok(Duration::from_secs_f64(seconds))
}

impl Core {
    /// Note that `thread` acted just now; `returned`: it holds the GIL (module `turns`).
    pub fn acted(&mut self, thread: u64, returned: bool) {
        if !self.actors.contains(&thread) {
            if self.actors.len() == ACTORS {
                let gone = self.actors.remove(0);
                self.blocked.retain(|&t| t != gone);
            }
            self.actors.push(thread);
        }
        self.acting.retain(|a| a.thread != thread);
        self.acting.push(Acting {
            thread,
            since: std::time::Instant::now(),
            returned,
        });
    }

    /// Note whether `thread` was just seen blocked in a `Condition.wait`.
    pub fn seen_blocked(&mut self, thread: u64, blocked: bool) {
        self.blocked.retain(|&t| t != thread);
        if blocked && self.actors.contains(&thread) {
            self.blocked.push(thread);
        }
    }

    /// Note that `thread`, which acted inside a call that released the GIL, holds it again:
    /// its time to reach a wait starts now.
    pub fn returned(&mut self, thread: u64) {
        if let Some(a) = self.acting.iter_mut().find(|a| a.thread == thread) {
            a.returned = true;
            a.since = std::time::Instant::now();
        }
    }

    /// Note that `thread` waits now (in a receive, or letting bus time pass).
    pub fn waits(&mut self, thread: u64) {
        self.acting.retain(|a| a.thread != thread);
    }

    /// The threads bus time still waits for, with whether each is back in Python: those
    /// that acted and have not been seen waiting since (`crate::turns::settle` forgets the
    /// ones that ran too long).
    pub fn acting_threads(&self) -> Vec<(u64, bool)> {
        self.acting.iter().map(|a| (a.thread, a.returned)).collect()
    }

    /// Run `f` on the simulation (in paced mode, brought up to the wall clock first).
    pub fn with_sim<R>(&mut self, f: impl FnOnce(&mut BusSim) -> R) -> PyResult<R> {
        match &mut self.mode {
            Mode::Virtual(sim) => Ok(f(sim)),
            Mode::Paced(p) => p.handle().with(f).map_err(|e| err(e.to_string())),
        }
    }

    pub fn bus_id(&self, name: &str) -> PyResult<BusId> {
        self.buses
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, id)| *id)
            .ok_or_else(|| {
                let names: Vec<&str> = self.buses.iter().map(|(n, _)| n.as_str()).collect();
                PyKeyError::new_err(format!(
                    "no bus named {name:?} (buses: {})",
                    names.join(", ")
                ))
            })
    }

    pub fn device(&self, name: &str) -> PyResult<BuiltDevice> {
        self.devices
            .iter()
            .find(|d| d.name == name)
            .cloned()
            .ok_or_else(|| {
                let names: Vec<&str> = self.devices.iter().map(|d| d.name.as_str()).collect();
                PyKeyError::new_err(format!(
                    "no device named {name:?} (devices: {})",
                    names.join(", ")
                ))
            })
    }

    pub fn bus_name(&self, id: BusId) -> String {
        self.buses
            .iter()
            .find(|(_, b)| *b == id)
            .map(|(n, _)| n.clone())
            .unwrap_or_default()
    }

    /// Apply `f` to the bus of a device's port.
    pub fn on_port(
        &mut self,
        device: &str,
        f: impl FnOnce(&mut cantwin_bus::Bus, PortId) -> Result<(), cantwin_bus::BusError>,
    ) -> PyResult<()> {
        let port = self.device(device)?.port;
        self.with_sim(|sim| match sim.bus_mut(port.bus()) {
            Some(bus) => f(bus, port).map_err(|e| err(e.to_string())),
            None => Err(err("the device's bus is gone")),
        })?
    }
}
