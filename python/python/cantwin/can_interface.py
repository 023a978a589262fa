"""The ``cantwin`` interface of python-can: a node on a bus of a :class:`cantwin.Simulation`
in the same process, no sockets involved.

::

    bus = can.Bus(interface="cantwin", channel="can0", sim=sim)

``sim`` is a :class:`cantwin.Simulation` or the name it was shared under with
:func:`cantwin.share` (default ``"default"``). Frames sent here arbitrate and take bus time
like any node's; the node acknowledges frames and receives every frame on the bus but its
own. Message timestamps are bus time in seconds since the simulation started (the end of
the frame).

In virtual time, :meth:`recv` runs the simulation instead of sleeping: by up to `timeout`
of bus time, stopping as soon as a frame for this node arrives. Bus time waits for Python:

* after a thread sent a frame (or changed a device through the simulation), the simulation
  does not run, and no frame is handed to a receiver, until that thread waits (in
  :meth:`recv`, on a ``threading`` condition, event, queue or join, or blocked in
  ``time.sleep`` or I/O), at most the simulation's ``reaction_time`` (wall clock). So
  ``network.sync.transmit()`` followed by ``node.tpdo[1].wait_for_reception()``, or
  ``node.nmt.state = "OPERATIONAL"`` followed by ``node.nmt.wait_for_heartbeat()``, gets the
  answer it waits for;
* after a frame reached Python on a thread other than the one that opened the bus
  (python-can's Notifier), the simulation waits up to ``reaction_time`` for another thread
  to answer before it runs on, so python-canopen's Notifier thread and the thread that
  answers (an SDO client, say) behave as on a fast host.

Paced to the wall clock, only the first rule applies, to the handing over of frames.

Periodic frames (:meth:`~can.BusABC.send_periodic`, and through it python-canopen's
``network.sync.start(period)`` and ``pdo.start(period)``) are sent by the node itself on
the simulation's clock, in both modes: one every `period` of bus time, however fast or slow
the simulation runs against the wall clock. The task's ``stop()``, ``start()`` and
``modify_data()`` act at once. Only a task with a ``modifier_callback``, which must run
Python code for every frame, falls back to python-can's thread on the wall clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Callable, Optional, Union

import can
from can.broadcastmanager import (
    CyclicSendTaskABC,
    LimitedDurationCyclicSendTaskABC,
    ModifiableCyclicTaskABC,
    RestartableCyclicTaskABC,
)

from ._native import CantwinError, Simulation

__all__ = ["CantwinBus"]


def _resolve(sim: Union[Simulation, str, None]) -> Simulation:
    from . import shared

    if sim is None:
        return shared("default")
    if isinstance(sim, str):
        return shared(sim)
    if isinstance(sim, Simulation):
        return sim
    raise TypeError(f"sim must be a cantwin.Simulation or a shared name, not {type(sim).__name__}")


def _frame(msg: can.Message) -> tuple[int, bytes, bool, bool, int]:
    if msg.is_fd:
        raise ValueError("the simulated buses are classic CAN: no CAN FD frames")
    if msg.is_error_frame:
        raise ValueError("error frames cannot be sent")
    data = b"" if msg.is_remote_frame else bytes(msg.data)
    return (msg.arbitration_id, data, msg.is_extended_id, msg.is_remote_frame, msg.dlc)


class CantwinCyclicSendTask(
    LimitedDurationCyclicSendTaskABC, ModifiableCyclicTaskABC, RestartableCyclicTaskABC
):
    """A periodic transmission kept by the node on the simulation's clock (bus time)."""

    def __init__(
        self,
        bus: "CantwinBus",
        messages: Union[Sequence[can.Message], can.Message],
        period: float,
        duration: Optional[float],
        autostart: bool,
    ) -> None:
        super().__init__(messages, period, duration)
        self._frames = [_frame(m) for m in self.messages]
        self._bus = bus
        self._key: Optional[int] = None
        if autostart:
            self.start()

    def start(self) -> None:
        """Send from now on: the first frame now, then one per period (bus time); a
        duration counts from now."""
        if self._key is not None:
            return
        try:
            self._key = self._bus._port.start_periodic(self._frames, self.period, self.duration)
        except CantwinError as e:
            raise can.CanOperationError(str(e)) from e

    def stop(self) -> None:
        """Send no more frames."""
        key, self._key = self._key, None
        if key is not None:
            try:
                self._bus._port.stop_periodic(key)
            except CantwinError as e:
                raise can.CanOperationError(str(e)) from e

    def modify_data(self, messages: Union[Sequence[can.Message], can.Message]) -> None:
        """Send `messages` from the next period on (python-can's rules: same identifier,
        same count)."""
        super().modify_data(messages)
        self._frames = [_frame(m) for m in self.messages]
        if self._key is not None:
            try:
                self._bus._port.modify_periodic(self._key, self._frames)
            except CantwinError as e:
                raise can.CanOperationError(str(e)) from e


class CantwinBus(can.BusABC):
    """A python-can bus attached to a bus of a :class:`cantwin.Simulation`.

    :param channel: the scenario's bus name (``"can0"``).
    :param sim: the simulation, or the name it was shared under (default ``"default"``).
    :param rx_capacity: frames buffered for :meth:`recv`; further ones are lost (counted in
        :attr:`overruns`).
    """

    def __init__(
        self,
        channel: Any = "can0",
        can_filters: Optional[can.typechecking.CanFilters] = None,
        sim: Union[Simulation, str, None] = None,
        rx_capacity: int = 4096,
        **kwargs: object,
    ) -> None:
        self._sim = _resolve(sim)
        try:
            self._port = self._sim.attach(str(channel), rx_capacity=rx_capacity)
        except (KeyError, CantwinError) as e:
            raise can.CanInitializationError(str(e)) from e
        # The thread that opened the bus (which attached the port) answers what it receives
        # itself; frames received on other threads (python-can's Notifier) are answered by
        # this one, which gets its reaction time.
        self.channel = str(channel)
        self.channel_info = f"cantwin {self.channel}"
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    @property
    def sim(self) -> Simulation:
        """The simulation this bus is attached to."""
        return self._sim

    @property
    def overruns(self) -> int:
        """Frames lost because the receive buffer was full."""
        return self._port.overruns

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        """Queue `msg` for transmission at the current bus time. With the transmit queue full
        it waits for room, at most `timeout` seconds (default 1 s; bus time in virtual time)."""
        if msg.is_fd:
            raise can.CanOperationError("the simulated buses are classic CAN: no CAN FD frames")
        if msg.is_error_frame:
            raise can.CanOperationError("error frames cannot be sent")
        try:
            self._port.send(
                msg.arbitration_id,
                bytes(msg.data) if not msg.is_remote_frame else b"",
                extended=msg.is_extended_id,
                remote=msg.is_remote_frame,
                dlc=msg.dlc,
                timeout=timeout,
            )
        except (ValueError, CantwinError) as e:
            raise can.CanOperationError(str(e)) from e

    def recv(self, timeout: Optional[float] = None) -> Optional[can.Message]:
        """The next frame that passes the filters, or ``None`` after `timeout` seconds: of bus
        time in virtual time (python-can's own loop counts the wall clock, and would run the
        simulation for as much bus time as it can in that wall time), of wall time paced."""
        if self.filters is None:
            # Every frame passes: one receive, which keeps the timeout itself (bus time in
            # virtual time, wall time paced). The path python-canopen's Notifier takes for
            # every frame.
            return self._recv_internal(timeout)[0]
        if self._sim.paced:
            return super().recv(timeout)
        end = None if timeout is None else self._sim.now + timeout
        while True:
            left = None if end is None else max(0.0, end - self._sim.now)
            msg, already_filtered = self._recv_internal(left)
            if msg is not None and (already_filtered or self._matches_filters(msg)):
                return msg
            if end is not None and (msg is None or self._sim.now >= end):
                return None

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        # Frames received on a thread other than the one that opened the bus wait for
        # answers (the port's owner, the module documentation).
        try:
            got = self._port.recv(timeout)
        except CantwinError as e:
            raise can.CanOperationError(str(e)) from e
        if got is None:
            return None, False
        arbitration_id, extended, remote, dlc, data, at = got
        msg = can.Message(
            timestamp=at,
            arbitration_id=arbitration_id,
            is_extended_id=extended,
            is_remote_frame=remote,
            dlc=dlc,
            data=None if remote else data,
            channel=self.channel,
            is_rx=True,
        )
        return msg, False

    def _send_periodic_internal(
        self,
        msgs: Union[Sequence[can.Message], can.Message],
        period: float,
        duration: Optional[float] = None,
        autostart: bool = True,
        modifier_callback: Optional[Callable[[can.Message], None]] = None,
    ) -> CyclicSendTaskABC:
        """Periodic frames sent by the node in bus time (module documentation); with a
        `modifier_callback`, python-can's thread on the wall clock."""
        if modifier_callback is not None:
            return super()._send_periodic_internal(
                msgs, period, duration, autostart, modifier_callback
            )
        return CantwinCyclicSendTask(self, msgs, period, duration, autostart)

    def shutdown(self) -> None:
        """Detach the node from the bus."""
        if self._is_shutdown:
            return
        super().shutdown()
        self._port.close()

    @staticmethod
    def _detect_available_configs() -> list[dict[str, Any]]:
        # The buses exist only inside a Simulation object: nothing to detect.
        return []
