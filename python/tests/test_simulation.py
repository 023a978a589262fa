"""The Simulation API without python-canopen: time, objects, faults, statistics, captures,
errors, and the python-can interface's own behaviour."""

import struct

import can
import pytest

import cantwin
from conftest import CIA301, SCENARIOS

MASTER_VANISHES = """
[[bus]]
name = "can0"
bit_rate = "500k"

[[device]]
name = "node5"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 100

[[device]]
name = "master"
kind = "generator"
bus = "can0"
id = 0x701
period_ms = 100
data = "05"
"""


def frames(bus, seconds):
    """Every frame `bus` receives in the next `seconds` of bus time."""
    got = []
    end = bus.sim.now + seconds
    while end - bus.sim.now > 1e-6:
        msg = bus.recv(end - bus.sim.now)
        if msg is None:  # the simulation ran to the timeout
            break
        got.append(msg)
    return got


def test_advance_runs_virtual_time_and_counts_frames():
    sim = cantwin.Simulation.load(CIA301)
    assert sim.now == 0.0 and not sim.paced
    sim.advance(10.0)
    assert sim.now == pytest.approx(10.0)
    stats = sim.stats("can0")
    # Boot-up, then a heartbeat every 100 ms (scenario heartbeat_ms = 100).
    assert 100 <= stats["frames"] <= 101
    assert stats["error_frames"] == 0 and 0 < stats["load_percent"] < 1


def test_same_scenario_gives_the_same_frames_at_the_same_times():
    def run():
        sim = cantwin.Simulation.load(CIA301)
        with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
            return [(m.arbitration_id, bytes(m.data), m.timestamp) for m in frames(bus, 1.0)]

    assert run() == run()


def test_heartbeat_loss_raises_emcy_8130_after_the_consumer_time():
    sim = cantwin.Simulation.from_toml(MASTER_VANISHES)
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
        # 0x1016 sub 1: consume node 1's heartbeat, 250 ms (CiA 301 §7.5.2.31); start node 5.
        bus.send(can.Message(arbitration_id=0x605, data=bytes.fromhex("23161001FA000100"), is_extended_id=False))
        bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x05], is_extended_id=False))
        sim.advance(1.0)
        sim.power("master", False)
        off_at = sim.now
        emcy = [m for m in frames(bus, 1.0) if m.arbitration_id == 0x85]
    assert emcy, "no EMCY after the master vanished"
    code = struct.unpack_from("<H", emcy[0].data)[0]
    assert code == 0x8130
    assert off_at < emcy[0].timestamp <= off_at + 0.25 + 0.11


def test_objects_read_and_written_locally():
    sim = cantwin.Simulation.load(CIA301)
    assert sim.read_object("node5", 0x1017, 0) == struct.pack("<H", 100)
    sim.write_object("node5", 0x2100, 2, struct.pack("<H", 0xBEEF))
    assert sim.read_object("node5", 0x2100, 2) == struct.pack("<H", 0xBEEF)
    with pytest.raises(cantwin.CantwinError, match="0x06020000"):
        sim.read_object("node5", 0x5FFF, 0)
    with pytest.raises(cantwin.CantwinError, match="0x06070010"):
        sim.write_object("node5", 0x2100, 2, b"\x01\x02\x03")
    with pytest.raises(KeyError, match='no device named "nope"'):
        sim.read_object("nope", 0x1000, 0)
    with pytest.raises(TypeError, match="generator"):
        sim.read_object("listener", 0x1000, 0)


def test_bad_scenarios_and_arguments_raise_clear_errors():
    with pytest.raises(cantwin.CantwinError, match="inline.toml"):
        cantwin.Simulation.from_toml("[[bus]]\nname = 1\n")
    with pytest.raises(cantwin.CantwinError):
        cantwin.Simulation.load(SCENARIOS / "does-not-exist.toml")
    sim = cantwin.Simulation.load(CIA301)
    with pytest.raises(ValueError):
        sim.advance(-1.0)
    with pytest.raises(ValueError):
        sim.drop_frames("can0", 1.5)
    with pytest.raises(KeyError, match='no bus named "can9"'):
        sim.stats("can9")
    with pytest.raises(can.CanInitializationError):
        can.Bus(interface="cantwin", channel="can9", sim=sim)


def test_power_off_silences_a_device_and_bus_off_shows_in_its_controller():
    sim = cantwin.Simulation.load(CIA301)
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
        assert any(m.arbitration_id == 0x705 for m in frames(bus, 0.5))
        sim.power("node5", False)
        assert not any(m.arbitration_id == 0x705 for m in frames(bus, 0.5))
        assert sim.controller("node5")["powered"] is False
        sim.power("node5", True)
        sim.bus_off("node5")
        assert sim.controller("node5")["state"] == "bus-off"


def test_dropped_frames_are_counted():
    sim = cantwin.Simulation.load(CIA301)
    sim.drop_frames("can0", 1.0, sender="node5", count=5)
    sim.advance(1.0)
    assert sim.stats("can0")["dropped_frames"] == 5
    sim.clear_faults("can0")


def test_capture_records_frames_readable_by_python_can(tmp_path):
    sim = cantwin.Simulation.load(CIA301)
    path = tmp_path / "run.log"
    with sim.capture(path):
        sim.advance(1.0)
    records = list(can.CanutilsLogReader(str(path)))
    assert len(records) == sim.stats("can0")["frames"]
    assert {r.arbitration_id for r in records} == {0x705}
    # Controller events are recorded as SocketCAN error frames, as `cantwin sim --capture`
    # records them (linux/can/error.h CAN_ERR_BUSOFF = 0x40).
    pcap = tmp_path / "bus-off.pcapng"
    with sim.capture(pcap, bus="can0"):
        sim.bus_off("node5")
        sim.advance(0.1)
    log = tmp_path / "bus-off.log"
    with sim.capture(log):
        sim.bus_off("listener")
        sim.advance(0.1)
    ids = [line.split()[2].split("#")[0] for line in log.read_text().splitlines()]
    # CAN_ERR_FLAG | CAN_ERR_BUSOFF.
    assert ids[0] == "20000040", ids[:5]
    assert pcap.stat().st_size > 0
    with pytest.raises(ValueError, match="format"):
        sim.capture(tmp_path / "x.bin")


def test_frames_sent_from_python_take_bus_time_and_arbitrate():
    sim = cantwin.Simulation.from_toml(MASTER_VANISHES)
    sim.advance(0.05)
    buses = [can.Bus(interface="cantwin", channel="can0", sim=sim) for _ in range(3)]
    a, b, c = buses
    try:
        # Queued at the same bus instant by two nodes: the lower identifier wins arbitration
        # (ISO 11898-1 §10.4.4.2), the other follows when the bus is idle again.
        a.send(can.Message(arbitration_id=0x300, data=[1] * 8, is_extended_id=False))
        b.send(can.Message(arbitration_id=0x200, data=[2] * 8, is_extended_id=False))
        got = [m for m in frames(c, 0.01) if m.arbitration_id in (0x200, 0x300)]
    finally:
        for bus in buses:
            bus.shutdown()
    assert [m.arbitration_id for m in got] == [0x200, 0x300]
    # An 8-byte standard frame at 500 kbit/s is at least 111 bits: 222 µs on the wire.
    assert got[1].timestamp - got[0].timestamp >= 222e-6


def test_paced_time_follows_the_wall_clock_and_hands_back_to_virtual_time():
    import time

    sim = cantwin.Simulation.load(CIA301)
    start = time.monotonic()
    sim.start_paced()
    with pytest.raises(cantwin.CantwinError, match="already paced"):
        sim.start_paced()
    sim.advance(0.3)
    assert sim.paced
    sim.stop_paced()
    wall = time.monotonic() - start
    reached = sim.now
    # Bus time never runs ahead of the wall clock; on a loaded host it may fall behind
    # (the backlog beyond max_lag is given up, crates/bus paced module), never stand still.
    assert 0.05 < reached <= wall
    with pytest.raises(cantwin.CantwinError, match="not paced"):
        sim.stop_paced()
    sim.advance(5.0)
    assert sim.now == pytest.approx(reached + 5.0)


def test_a_shared_simulation_is_named_in_the_bus_arguments():
    sim = cantwin.Simulation.load(CIA301)
    cantwin.share(sim, "bench")
    try:
        with can.Bus(interface="cantwin", channel="can0", sim="bench") as bus:
            assert bus.sim is sim
            assert any(m.arbitration_id == 0x705 for m in frames(bus, 0.3))
    finally:
        cantwin.unshare("bench")
    with pytest.raises(KeyError, match="bench"):
        can.Bus(interface="cantwin", channel="can0", sim="bench")
