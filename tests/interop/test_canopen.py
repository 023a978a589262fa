"""python-canopen against scenarios/cia301-device.toml through the socketcand gateway."""

import os
import struct
import threading
import time
import tomllib

import can
import canopen
import pytest

from conftest import CIA301_SCENARIO, NODE_ID

with open(CIA301_SCENARIO, "rb") as f:
    DEVICE = next(d for d in tomllib.load(f)["device"] if d["kind"] == "cia301")

DOMAIN_SIZE = DEVICE["domain_size"]
# The DOMAIN's power-on contents (see crates/scenario/src/kinds/cia301.rs).
DOMAIN_DEFAULT = bytes(i % 251 for i in range(DOMAIN_SIZE))

NMT_PRE_OPERATIONAL = "PRE-OPERATIONAL"


def wait_until(predicate, timeout=5.0, step=0.01):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


def u16(value):
    return struct.pack("<H", value)


def monitor_bus(sim):
    host, port = sim.socketcand_addr("can0")
    return can.Bus(interface="socketcand", channel="can0", host=host, port=port)


# --- NMT and heartbeat --------------------------------------------------------------------


def test_nmt_state_tracked_from_heartbeats(node):
    assert node.nmt.wait_for_heartbeat(timeout=2) == NMT_PRE_OPERATIONAL
    node.nmt.state = "OPERATIONAL"
    # The command was sent; the state python-canopen shows comes from the next heartbeats.
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    node.nmt.state = "STOPPED"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "STOPPED")
    node.nmt.state = "PRE-OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == NMT_PRE_OPERATIONAL)


def test_heartbeat_period_is_heartbeat_ms(cia301_sim):
    with monitor_bus(cia301_sim) as bus:
        stamps = []
        deadline = time.monotonic() + 3
        while len(stamps) < 6 and time.monotonic() < deadline:
            msg = bus.recv(timeout=1)
            if msg is not None and msg.arbitration_id == 0x700 + NODE_ID:
                assert bytes(msg.data) == b"\x7f"
                stamps.append(msg.timestamp)
    assert len(stamps) == 6
    # The gateway stamps frames with the bus time mapped to the wall clock, so the periods
    # are exact up to the timestamps' microseconds (and float rounding), whatever the load.
    periods = [b - a for a, b in zip(stamps, stamps[1:])]
    period_s = DEVICE["heartbeat_ms"] / 1000
    assert all(abs(p - period_s) < 2e-6 for p in periods), periods


def test_nmt_reset_node_sends_boot_up(node):
    node.nmt.wait_for_heartbeat(timeout=2)
    node.nmt.state = "RESET"
    node.nmt.wait_for_bootup(timeout=2)
    assert node.nmt.wait_for_heartbeat(timeout=2) == NMT_PRE_OPERATIONAL


def test_nmt_reset_communication_restores_heartbeat_time(node):
    node.sdo.download(0x1017, 0, u16(0))
    node.nmt.state = "RESET COMMUNICATION"
    node.nmt.wait_for_bootup(timeout=2)
    assert node.sdo.upload(0x1017, 0) == u16(DEVICE["heartbeat_ms"])


# --- SDO ------------------------------------------------------------------------------------


def test_sdo_expedited_upload_identity(node):
    assert node.sdo.upload(0x1000, 0) == struct.pack("<I", 0)
    assert node.sdo.upload(0x1018, 0) == b"\x04"
    assert node.sdo.upload(0x1018, 1) == struct.pack("<I", DEVICE["vendor_id"])
    assert node.sdo.upload(0x1018, 2) == struct.pack("<I", DEVICE["product_code"])
    assert node.sdo.upload(0x1018, 3) == struct.pack("<I", DEVICE["revision"])
    assert node.sdo.upload(0x1018, 4) == struct.pack("<I", DEVICE["serial"])


def test_sdo_expedited_download_then_upload(node):
    node.sdo.download(0x2002, 0, b"\x2a")
    assert node.sdo.upload(0x2002, 0) == b"\x2a"
    node.sdo.download(0x2100, 3, u16(0xBEEF))
    assert node.sdo.upload(0x2100, 3) == u16(0xBEEF)


def test_sdo_segmented_upload_long_device_name(node):
    name = node.sdo.upload(0x1008, 0)
    assert name.decode("ascii") == DEVICE["device_name"]
    assert len(name) > 4  # longer than an expedited transfer carries


def test_sdo_block_upload_long_device_name(node):
    with node.sdo.open(0x1008, 0, "rb", block_transfer=True) as f:
        name = f.read()
    assert name.decode("ascii") == DEVICE["device_name"]


def test_sdo_segmented_download_domain(node):
    data = bytes((7 * i + 1) & 0xFF for i in range(1000))
    node.sdo.download(0x2000, 0, data)
    assert node.sdo.upload(0x2000, 0) == data


def test_sdo_segmented_upload_64k_domain(node):
    assert node.sdo.upload(0x2000, 0) == DOMAIN_DEFAULT


def test_sdo_block_upload_64k_domain(node):
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as f:
        data = f.read()
    assert len(data) == DOMAIN_SIZE
    assert data == DOMAIN_DEFAULT


def test_sdo_block_download_64k_domain(node):
    data = os.urandom(DOMAIN_SIZE)
    with node.sdo.open(
        0x2000, 0, "wb", size=len(data), block_transfer=True
    ) as f:
        f.write(data)
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as f:
        assert f.read() == data


def test_sdo_segmented_download_64k_domain(node):
    data = os.urandom(DOMAIN_SIZE)
    node.sdo.download(0x2000, 0, data)
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as f:
        assert f.read() == data


# --- SDO aborts (CiA 301 §7.2.4.3.17, table 22) ---------------------------------------------


@pytest.mark.parametrize(
    "index, sub, code",
    [
        (0x6000, 0, 0x06020000),  # object does not exist
        (0x1018, 9, 0x06090011),  # sub-index does not exist
    ],
)
def test_sdo_upload_abort_code(node, index, sub, code):
    with pytest.raises(canopen.SdoAbortedError) as e:
        node.sdo.upload(index, sub)
    assert e.value.code == code


@pytest.mark.parametrize(
    "index, sub, data, code",
    [
        (0x1000, 0, struct.pack("<I", 1), 0x06010002),  # read-only
        (0x1018, 1, struct.pack("<I", 1), 0x06010002),  # const
        (0x6000, 0, b"\x01", 0x06020000),  # object does not exist
        (0x2002, 0, b"\xc8", 0x06090031),  # value too high (limit 100)
        (0x2002, 0, b"\x01\x02", 0x06070012),  # length too high
        (0x1017, 0, b"\x01", 0x06070013),  # length too low
    ],
)
def test_sdo_download_abort_code(node, index, sub, data, code):
    with pytest.raises(canopen.SdoAbortedError) as e:
        node.sdo.download(index, sub, data)
    assert e.value.code == code


def test_sdo_download_domain_larger_than_object_aborts(node):
    with pytest.raises(canopen.SdoAbortedError) as e:
        node.sdo.download(0x2000, 0, bytes(DOMAIN_SIZE + 1))
    assert e.value.code == 0x06070012


# --- PDO and SYNC -------------------------------------------------------------------------


def test_tpdos_follow_each_sync_from_python_canopen(cia301_sim, network, node):
    node.nmt.state = "OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    tpdo_ids = [0x180 + NODE_ID, 0x280 + NODE_ID, 0x380 + NODE_ID, 0x480 + NODE_ID]
    with monitor_bus(cia301_sim) as monitor:
        network.sync.start(0.05)
        try:
            frames = []
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                msg = monitor.recv(timeout=0.5)
                if msg is not None and msg.arbitration_id in [0x80, *tpdo_ids]:
                    frames.append(msg)
        finally:
            network.sync.stop()
    # Between two SYNCs: exactly TPDO1..4, each 4 bytes (two UNSIGNED16 inputs).
    sync_at = [i for i, m in enumerate(frames) if m.arbitration_id == 0x80]
    assert len(sync_at) >= 10, [hex(m.arbitration_id) for m in frames]
    counters = []
    for a, b in zip(sync_at, sync_at[1:]):
        between = frames[a + 1 : b]
        assert sorted(m.arbitration_id for m in between) == tpdo_ids
        assert all(m.dlc == 4 for m in between)
        tpdo1 = next(m for m in between if m.arbitration_id == tpdo_ids[0])
        counters.append(struct.unpack_from("<H", tpdo1.data)[0])
    # 0x2100 sub 1 counts SYNCs: each TPDO1 carries one more than the one before.
    assert all(b == a + 1 for a, b in zip(counters, counters[1:])), counters


def test_rpdo_writes_outputs(cia301_sim, network, node):
    node.nmt.state = "OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    network.send_message(0x300 + NODE_ID, u16(0x1234) + u16(0x5678))  # RPDO2
    assert wait_until(lambda: node.sdo.upload(0x2200, 3) == u16(0x1234), timeout=2)
    assert node.sdo.upload(0x2200, 4) == u16(0x5678)


# --- EMCY ---------------------------------------------------------------------------------


def emcy_logged(node, code, timeout=2.0):
    """The first EMCY with `code` in the node's log, waiting up to `timeout` (python-canopen's
    own `wait` misses an EMCY that arrived before it was called)."""
    found = []

    def seen():
        found[:] = [e for e in node.emcy.log if e.code == code]
        return bool(found)

    return found[0] if wait_until(seen, timeout) else None


def test_emcy_raised_and_cleared_through_trigger_object(node):
    node.sdo.download(0x2001, 0, u16(0x5000))
    emcy = emcy_logged(node, 0x5000)
    assert emcy is not None, node.emcy.log
    assert emcy.register & 0x01  # generic error
    assert emcy.data == bytes(5)
    assert [e.code for e in node.emcy.active] == [0x5000]
    assert node.sdo.upload(0x1001, 0)[0] & 0x01
    assert node.sdo.upload(0x1003, 0) == b"\x01"
    assert node.sdo.upload(0x1003, 1)[:2] == u16(0x5000)
    node.sdo.download(0x2001, 0, u16(0))
    reset = emcy_logged(node, 0x0000)
    assert reset is not None, node.emcy.log
    assert reset.register == 0
    assert node.emcy.active == []


def test_emcy_on_short_rpdo(network, node):
    node.nmt.state = "OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    network.send_message(0x200 + NODE_ID, b"\x01\x02")  # RPDO1 maps 4 bytes
    emcy = emcy_logged(node, 0x8210)  # PDO not processed due to length error
    assert emcy is not None, node.emcy.log
    assert emcy.register & 0x10  # communication error
    assert [e.code for e in node.emcy.active] == [0x8210]


# --- slcan: remote frames -----------------------------------------------------------------


def test_node_guarding_rtr_through_slcan_toggles(cia301_sim, node):
    # With a producer heartbeat time the device does not answer guarding (CiA 301 §7.2.8.3.2):
    # switch heartbeat off first.
    node.sdo.download(0x1017, 0, u16(0))
    with can.Bus(
        interface="slcan", channel=cia301_sim.slcan_url(), bitrate=500000, sleep_after_open=0
    ) as bus:
        time.sleep(0.2)
        answers = []
        for _ in range(4):
            guard = 0x700 + NODE_ID
            bus.send(
                can.Message(arbitration_id=guard, is_remote_frame=True, dlc=1, is_extended_id=False)
            )
            deadline = time.monotonic() + 2
            while time.monotonic() < deadline:
                msg = bus.recv(timeout=0.5)
                if msg is not None and msg.arbitration_id == guard and not msg.is_remote_frame:
                    answers.append(msg.data[0])
                    break
    # State 127 (pre-operational) with the toggle bit alternating, starting at 0.
    assert answers == [0x7F, 0xFF, 0x7F, 0xFF]


def test_python_canopen_node_guarding_over_slcan(cia301_sim):
    net = canopen.Network()
    net.connect(
        interface="slcan", channel=cia301_sim.slcan_url(), bitrate=500000, sleep_after_open=0
    )
    try:
        remote = net.add_node(NODE_ID, canopen.ObjectDictionary())
        remote.sdo.RESPONSE_TIMEOUT = 2.0
        remote.sdo.download(0x1017, 0, u16(0))
        seen = []
        remote.nmt.add_heartbeat_callback(seen.append)
        remote.nmt.start_node_guarding(0.05)
        try:
            assert remote.nmt.wait_for_heartbeat(timeout=2) == NMT_PRE_OPERATIONAL
            remote.nmt.state = "OPERATIONAL"
            assert wait_until(lambda: remote.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
        finally:
            remote.nmt.stop_node_guarding()
        assert 127 in seen and 5 in seen
    finally:
        net.disconnect()


# --- parameter storage --------------------------------------------------------------------


def test_stored_parameters_survive_restart_with_state_dir(tmp_path):
    from conftest import start_sim, stop_process

    def run(action):
        sim = start_sim(CIA301_SCENARIO, extra=["--state-dir", str(tmp_path)])
        try:
            host, port = sim.socketcand_addr("can0")
            net = canopen.Network()
            net.connect(interface="socketcand", channel="can0", host=host, port=port)
            try:
                remote = net.add_node(NODE_ID, canopen.ObjectDictionary())
                remote.sdo.RESPONSE_TIMEOUT = 2.0
                return action(remote)
            finally:
                net.disconnect()
        finally:
            stop_process(sim.process)

    def store(remote):
        remote.sdo.download(0x1017, 0, u16(250))
        remote.sdo.download(0x2002, 0, b"\x21")
        remote.sdo.download(0x1010, 1, b"save")  # CiA 301 §7.5.2.10: store all parameters

    run(store)
    assert any(tmp_path.iterdir()), "nothing stored in the state directory"
    # A stored heartbeat time wins over the scenario's heartbeat_ms.
    assert run(lambda r: (r.sdo.upload(0x1017, 0), r.sdo.upload(0x2002, 0))) == (
        u16(250),
        b"\x21",
    )
