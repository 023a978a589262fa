"""Periodic frames through the ``cantwin`` interface run in bus time: python-canopen's
``network.sync.start(period)`` sends one SYNC per period of bus time, in virtual and in
paced time, and ``sync.stop()`` ends it."""

import can

import cantwin
import pytest

from conftest import CIA301, NODE_ID, wait_until

MODES = ["virtual", "paced"]
pytestmark = pytest.mark.cantwin_scenario(str(CIA301))


class Frames(can.Listener):
    def __init__(self, arbitration_id):
        self.arbitration_id = arbitration_id
        self.stamps = []

    def on_message_received(self, msg):
        if msg.arbitration_id == self.arbitration_id:
            self.stamps.append(msg.timestamp)


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_sync_start_sends_sync_every_period_of_bus_time(cantwin_sim, canopen_network, node):
    node.nmt.state = "OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    syncs = Frames(0x80)
    # TPDO1 is synchronous (transmission type 1): one per SYNC (CiA 301 §7.2.2.2).
    tpdos = Frames(0x180 + NODE_ID)
    canopen_network.notifier.add_listener(syncs)
    canopen_network.notifier.add_listener(tpdos)
    try:
        canopen_network.sync.start(0.1)
        assert wait_until(lambda: len(tpdos.stamps) >= 6), tpdos.stamps
        canopen_network.sync.stop()
        stamps = tpdos.stamps[:6]
        gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        assert all(abs(g - 0.1) <= 0.001 for g in gaps), gaps
        # Stopped: no SYNC over five periods of bus time (one already queued may still go).
        count = len(syncs.stamps)
        end = cantwin_sim.now + 0.5
        assert wait_until(lambda: cantwin_sim.now >= end)
        assert len(syncs.stamps) <= count + 1, syncs.stamps
        sync_gaps = [b - a for a, b in zip(syncs.stamps, syncs.stamps[1:])]
        assert all(abs(g - 0.1) <= 0.001 for g in sync_gaps), sync_gaps
    finally:
        canopen_network.sync.stop()
        canopen_network.notifier.remove_listener(syncs)
        canopen_network.notifier.remove_listener(tpdos)


def received(bus, arbitration_id, seconds):
    """(bus time, data) of every `arbitration_id` frame `bus` receives in `seconds`."""
    got = []
    end = bus.sim.now + seconds
    while end - bus.sim.now > 1e-6:
        msg = bus.recv(end - bus.sim.now)
        if msg is None:
            break
        if msg.arbitration_id == arbitration_id:
            got.append((msg.timestamp, bytes(msg.data)))
    return got


def test_send_periodic_keeps_period_duration_order_modify_and_stop_in_bus_time():
    sim = cantwin.Simulation.load(str(CIA301))
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as sender, can.Bus(
        interface="cantwin", channel="can0", sim=sim
    ) as listener:
        msgs = [can.Message(arbitration_id=0x123, data=[i], is_extended_id=False) for i in (1, 2)]
        started = sim.now
        # The messages in turn, one per period; none at or after the duration's end.
        sender.send_periodic(msgs, 0.05, duration=0.3)
        got = received(listener, 0x123, 0.5)
        assert [d for _, d in got] == [b"\x01", b"\x02"] * 3, got
        assert all(abs(t - started - 0.05 * i) < 0.001 for i, (t, _) in enumerate(got)), got

        task = sender.send_periodic(msgs[0], 0.02)
        assert len(received(listener, 0x123, 0.1)) == 5
        task.modify_data(can.Message(arbitration_id=0x123, data=[9], is_extended_id=False))
        # A frame already queued for the wire goes out as it was; the next ones carry the new data.
        assert [d for _, d in received(listener, 0x123, 0.1)][1:] == [b"\x09"] * 4
        task.stop()
        assert len(received(listener, 0x123, 0.1)) <= 1
        assert received(listener, 0x123, 0.1) == []
        task.start()
        assert len(received(listener, 0x123, 0.1)) == 5
        # python-can tracks a task until its first stop(); a restarted one is stopped by hand.
        task.stop()
        sender.send_periodic(msgs[1], 0.02)
        sender.stop_all_periodic_tasks()
        received(listener, 0x123, 0.01)
        assert received(listener, 0x123, 0.1) == []
        with pytest.raises(ValueError):
            sender.send_periodic(msgs[0], 0.0)
