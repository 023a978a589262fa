"""cantwin: digital twins of CAN devices on a virtual CAN bus, inside the Python process.

Build a :class:`Simulation` from a scenario (a file or TOML text), run it in virtual time
with :meth:`Simulation.advance` or paced to the wall clock with
:meth:`Simulation.start_paced`, read and write its devices, inject faults, read bus
statistics and record captures. python-can code reaches the buses through the ``cantwin``
interface (:class:`cantwin.can_interface.CantwinBus`)::

    import can, cantwin

    sim = cantwin.Simulation.load("scenarios/cia301-device.toml")
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
        bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x00], is_extended_id=False))
        print(bus.recv(1.0))   # runs the simulation until a frame arrives (virtual time)

pytest gets the ``cantwin_sim`` and ``canopen_network`` fixtures from
:mod:`cantwin.pytest_plugin`.
"""

from __future__ import annotations

import threading

from ._native import CantwinError, Capture, Port, Simulation

__all__ = ["CantwinError", "Capture", "Port", "Simulation", "share", "shared", "unshare"]

_lock = threading.Lock()
_shared: dict[str, Simulation] = {}


def share(sim: Simulation, name: str = "default") -> None:
    """Make `sim` reachable by `name`, for python-can configurations that can only name
    things: ``can.Bus(interface="cantwin", channel="can0", sim="default")``."""
    with _lock:
        _shared[name] = sim


def unshare(name: str = "default") -> None:
    """Forget the simulation shared under `name` (no error if there is none)."""
    with _lock:
        _shared.pop(name, None)


def shared(name: str = "default") -> Simulation:
    """The simulation shared under `name`; :class:`KeyError` if there is none."""
    with _lock:
        try:
            return _shared[name]
        except KeyError:
            known = ", ".join(sorted(_shared)) or "none"
            raise KeyError(
                f"no simulation shared as {name!r} (shared: {known}); call cantwin.share(sim, {name!r})"
            ) from None
