//! The native part of the `cantwin` Python package: a scenario built into a simulation that
//! Python drives in virtual time or paces to the wall clock, reads and writes devices of,
//! injects faults into, records and attaches its own CAN nodes to.
//!
//! Everything lives behind one mutex per simulation ([`core::Shared`]); every call that runs the
//! simulation or waits releases the GIL, so python-can's Notifier thread and the test's own
//! thread take turns as two nodes of a real bus would.

mod capture;
mod core;
mod devices;
mod port;
mod sim;
mod turns;

use pyo3::prelude::*;

/// The extension module `cantwin._native`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<sim::Simulation>()?;
    m.add_class::<port::Port>()?;
    m.add_class::<capture::Capture>()?;
    m.add("CantwinError", m.py().get_type::<core::CantwinError>())?;
    Ok(())
}
