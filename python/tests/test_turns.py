"""The turn rule of virtual time: bus time waits for a Python thread that sent a frame until
that thread waits (package README, "Time"), with python-can alone and a Notifier thread."""

import threading
import time

import can

import cantwin
from conftest import CIA301, NODE_ID

TPDO1 = 0x180 + NODE_ID
SYNC = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
NMT_START = can.Message(arbitration_id=0x000, data=[0x01, NODE_ID], is_extended_id=False)


class Tpdo1(can.Listener):
    """Sets `arrived` at each TPDO1 (the Notifier's thread) and notes its bus time."""

    def __init__(self):
        self.arrived = threading.Event()
        self.times = []

    def on_message_received(self, msg):
        if msg.arbitration_id == TPDO1:
            self.times.append(msg.timestamp)
            self.arrived.set()


def started(reaction_time):
    """The CiA 301 twin operational, a python-can bus with a Notifier and a TPDO1 listener."""
    sim = cantwin.Simulation.load(str(CIA301), reaction_time=reaction_time)
    bus = can.Bus(interface="cantwin", channel="can0", sim=sim)
    bus.send(NMT_START)
    # The node-guarding-free twin answers SYNC with TPDO1 once operational (CiA 301
    # §7.2.2.2, transmission type 1): let the command reach it first.
    sim.advance(0.01)
    tpdo = Tpdo1()
    notifier = can.Notifier(bus, [tpdo], timeout=0.5)
    return sim, bus, notifier, tpdo


def spin(seconds):
    """Run Python code (never wait) for `seconds` of wall time."""
    end = time.perf_counter() + seconds
    n = 0
    while time.perf_counter() < end:
        n += 1
    return n


def test_bus_time_stands_still_until_the_sender_waits():
    sim, bus, notifier, tpdo = started(reaction_time=0.5)
    try:
        at = sim.now
        bus.send(SYNC)
        # Computing, not waiting: the Notifier must not run the simulation meanwhile.
        spin(0.003)
        assert sim.now == at and tpdo.times == []
        assert tpdo.arrived.wait(timeout=2)
        # The answer comes at the bus time the device gives it, right after the SYNC.
        assert at < tpdo.times[0] < at + 0.001
    finally:
        notifier.stop()
        bus.shutdown()


def test_a_sleeping_sender_waits():
    # A reaction time above the sleep: only seeing the thread blocked in time.sleep lets the
    # simulation run before the sleep ends.
    sim, bus, notifier, tpdo = started(reaction_time=0.5)
    try:
        bus.send(SYNC)
        time.sleep(0.2)
        assert tpdo.times, "the simulation did not run while the sender slept"
    finally:
        notifier.stop()
        bus.shutdown()


def test_a_sender_that_never_waits_holds_time_for_the_reaction_time_at_most():
    sim, bus, notifier, tpdo = started(reaction_time=0.02)
    try:
        bus.send(SYNC)
        # Never wait: the Notifier runs the simulation once the reaction time is over and
        # hands the TPDO over at the next switch of the GIL.
        end = time.monotonic() + 2.0
        while not tpdo.times and time.monotonic() < end:
            spin(0.001)
        assert tpdo.times
    finally:
        notifier.stop()
        bus.shutdown()


def test_a_device_change_waits_for_its_thread_too():
    sim, bus, notifier, tpdo = started(reaction_time=0.5)
    emcy = threading.Event()

    class Emcy(can.Listener):
        def on_message_received(self, msg):
            if msg.arbitration_id == 0x080 + NODE_ID:
                emcy.set()

    notifier.add_listener(Emcy())
    try:
        at = sim.now
        # The twin's EMCY trigger object (scenarios/cia301-device.toml): the EMCY goes out
        # when the simulation runs, which is once this thread waits.
        sim.write_object("node5", 0x2001, 0, (0x5000).to_bytes(2, "little"))
        spin(0.003)
        assert sim.now == at and not emcy.is_set()
        assert emcy.wait(timeout=2)
    finally:
        notifier.stop()
        bus.shutdown()


QUIET = """
[[bus]]
name = "can0"
bit_rate = "500k"

[[device]]
name = "node5"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 0
"""


def test_recv_timeout_is_bus_time_in_virtual_time():
    sim = cantwin.Simulation.from_toml(QUIET)
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
        boot_up = bus.recv(0.1)
        assert boot_up is not None and boot_up.arbitration_id == 0x700 + NODE_ID
        at = sim.now
        # Nothing else is ever sent: the wait ends after half a second of bus time, however
        # little wall time that takes (python-can's own loop would count the wall clock).
        assert bus.recv(0.5) is None
        assert 0.5 <= sim.now - at < 0.5 + 1e-3
        # A filter that nothing passes: the same bound.
        bus.set_filters([{"can_id": 0x123, "can_mask": 0x7FF}])
        at = sim.now
        assert bus.recv(0.25) is None
        assert 0.25 <= sim.now - at < 0.25 + 1e-3


def test_a_ports_owner_runs_on_at_once_and_another_thread_gives_it_its_reaction_time():
    # The thread that attached a port answers what it receives itself: its next receive runs
    # the simulation on at once. A receive on another thread (python-can's Notifier) gives
    # the owner its reaction time to answer the frame first (module documentation of
    # cantwin.can_interface). The reaction time is far above what the first receive may
    # take, and far below the timeout of the second one.
    sim = cantwin.Simulation.from_toml(QUIET, reaction_time=0.4)
    port = sim.attach("can0")
    boot_up = port.recv(0.1)
    assert boot_up is not None and boot_up[0] == 0x700 + NODE_ID
    start = time.monotonic()
    assert port.recv(0.5) is None
    assert time.monotonic() - start < 0.2, "the owner waited for an answer from itself"

    port.send(0x600 + NODE_ID, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]))
    answer = port.recv(0.1)
    assert answer is not None and answer[0] == 0x580 + NODE_ID
    got = []

    def other():
        start = time.monotonic()
        got.append((port.recv(0.5), time.monotonic() - start))

    t = threading.Thread(target=other)
    t.start()
    t.join(timeout=5)
    frame, took = got[0]
    assert frame is None
    assert took >= 0.3, "another thread's receive did not wait for the owner's answer"


def test_a_burst_longer_than_the_transmit_queue_goes_out_whole_and_in_order():
    # A port's transmit queue holds 32 frames, as a socket's FIFO does; a sender that finds it
    # full waits for room while the bus runs on (virtual time), then queues the rest.
    sim = cantwin.Simulation.from_toml(QUIET)
    sender = sim.attach("can0")
    listener = sim.attach("can0")
    for k in range(40):
        sender.send(0x300, bytes([k]))
    assert sender.tx_frames >= 8, "the full queue did not drain while the sender waited"
    got = []
    while len(got) < 40:
        frame = listener.recv(0.1)
        if frame is None:
            break
        if frame[0] == 0x300:
            got.append(frame[4][0])
    assert got == list(range(40))
