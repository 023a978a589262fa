"""python-canopen against the CiA 301 twin through the in-process ``cantwin`` interface:
SDO (expedited, segmented, block), NMT, PDO and EMCY, each in virtual and in paced time."""

import struct

import can

import pytest

from conftest import CIA301, NODE_ID, wait_until

MODES = ["virtual", "paced"]
pytestmark = pytest.mark.cantwin_scenario(str(CIA301))


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_sdo_expedited_upload_and_download(cantwin_sim, node):
    # 0x1018 sub 1..4 from the scenario (CiA 301 §7.5.2.21).
    assert node.sdo.upload(0x1018, 1) == struct.pack("<I", 0x00000CA7)
    assert node.sdo.upload(0x1018, 2) == struct.pack("<I", 301)
    # 0x2002 sub 0: a set point limited to 0..100.
    node.sdo.download(0x2002, 0, struct.pack("<B", 42))
    assert node.sdo.upload(0x2002, 0) == struct.pack("<B", 42)
    assert cantwin_sim.read_object("node5", 0x2002, 0) == bytes([42])


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_sdo_segmented_upload_and_download(cantwin_sim, node):
    name = node.sdo.upload(0x1008, 0).decode()
    assert name.startswith("cantwin generic CiA 301 device") and len(name) > 4
    data = bytes(range(256)) * 8
    node.sdo.download(0x2000, 0, data, force_segment=True)
    assert node.sdo.upload(0x2000, 0) == data
    assert cantwin_sim.read_object("node5", 0x2000, 0) == data


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_sdo_block_upload_and_download(cantwin_sim, node):
    data = bytes((i * 7) & 0xFF for i in range(20000))
    with node.sdo.open(0x2000, 0, "wb", size=len(data), block_transfer=True) as f:
        f.write(data)
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as f:
        assert f.read() == data


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_sdo_abort_is_raised_as_sdo_abort(node):
    import canopen

    with pytest.raises(canopen.SdoAbortedError) as e:
        node.sdo.upload(0x5FFF, 0)
    assert e.value.code == 0x06020000  # object does not exist (CiA 301 table 22)


class Frames(can.Listener):
    """A python-can listener keeping the frames of one identifier."""

    def __init__(self, arbitration_id):
        self.arbitration_id = arbitration_id
        self.data = []

    def on_message_received(self, msg):
        if msg.arbitration_id == self.arbitration_id:
            self.data.append(bytes(msg.data))

    def stop(self):
        pass


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_nmt_states_follow_commands_in_heartbeats(node):
    assert node.nmt.wait_for_heartbeat(timeout=2) == "PRE-OPERATIONAL"
    for state in ["OPERATIONAL", "STOPPED", "PRE-OPERATIONAL"]:
        node.nmt.state = state
        assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == state), state
    # The boot-up (CiA 301 §7.2.8.3.2.2: 0x700 + node-ID, data 00), waited for after the
    # command as on a real bus: bus time waits until this thread waits.
    node.nmt.state = "RESET"
    node.nmt.wait_for_bootup(timeout=2)
    assert node.nmt.wait_for_heartbeat(timeout=2) == "PRE-OPERATIONAL"


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_pdo_sync_answers_with_tpdo_and_rpdo_writes_outputs(cantwin_sim, canopen_network, node):
    node.nmt.state = "OPERATIONAL"
    assert wait_until(lambda: node.nmt.wait_for_heartbeat(timeout=2) == "OPERATIONAL")
    # RPDO2 (0x300 + node) maps 0x2200 sub 3 and 4.
    canopen_network.send_message(0x300 + NODE_ID, struct.pack("<2H", 0x1234, 0x5678))
    assert wait_until(
        lambda: cantwin_sim.read_object("node5", 0x2200, 4) == struct.pack("<H", 0x5678)
    )
    assert node.sdo.upload(0x2200, 3) == struct.pack("<H", 0x1234)
    listener = Frames(0x180 + NODE_ID)
    got = listener.data
    canopen_network.notifier.add_listener(listener)
    try:
        # TPDO1 is synchronous (transmission type 1): one per SYNC, 0x2100 sub 1 counts them.
        for _ in range(3):
            count = len(got)
            canopen_network.sync.transmit()
            assert wait_until(lambda: len(got) > count), got
    finally:
        canopen_network.notifier.remove_listener(listener)
    counters = [struct.unpack_from("<H", d)[0] for d in got]
    assert counters == sorted(counters) and len(set(counters)) == len(counters)


@pytest.mark.parametrize("cantwin_mode", MODES)
def test_emcy_raised_and_cleared(node):
    node.sdo.download(0x2001, 0, struct.pack("<H", 0x5000))
    assert wait_until(lambda: any(e.code == 0x5000 for e in node.emcy.log))
    assert [e.code for e in node.emcy.active] == [0x5000]
    node.sdo.download(0x2001, 0, struct.pack("<H", 0))
    assert wait_until(lambda: any(e.code == 0x0000 for e in node.emcy.log))
    assert node.emcy.active == []
