"""python-canopen against the ADV200 DS402 twin (scenarios/adv200-ds402.toml).

The EDS is the one generated from the twin's object dictionary (crates/adv200/eds). The
card has no 0x6502, so BaseNode402's operation-mode helpers are not used: velocity mode is
the only mode (0x6060/0x6061 = 2).
"""

import threading
import time

import canopen
import pytest

from conftest import ROOT, SCENARIOS, start_sim, stop_process

EDS_DS402 = ROOT / "crates" / "adv200" / "eds" / "adv200-ds402.eds"
EDS_CANOPEN = ROOT / "crates" / "adv200" / "eds" / "adv200-canopen.eds"
NODE = 2


@pytest.fixture
def ds402_network():
    sim = start_sim(SCENARIOS / "adv200-ds402.toml")
    net = canopen.Network()
    try:
        host, port = sim.socketcand_addr("can0")
        net.connect(interface="socketcand", channel="can0", host=host, port=port)
        yield net
    finally:
        net.disconnect()
        stop_process(sim.process)


def test_adv200_eds_files_load_in_python_canopen():
    od = canopen.import_od(str(EDS_DS402), NODE)
    assert od[0x1000].default == 0x192
    assert od[0x6041].name == "Statusword"
    assert od[0x6042].data_type == canopen.objectdictionary.INTEGER16
    assert 0x6502 not in od
    # Drive parameters at 0x2000 + PAR sub 1: PAR 600 Dig ramp ref 1.
    assert od[0x2258][1].name == "Dig ramp ref 1"
    od = canopen.import_od(str(EDS_CANOPEN), 12)
    assert od[0x1000].default == 0
    assert 0x6040 not in od
    assert od[0x1400][2].default == 1


def test_adv200_ds402_state_setter_and_velocity_ramp(ds402_network):
    net = ds402_network
    node = canopen.BaseNode402(NODE, str(EDS_DS402))
    net.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 2.0
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine()
    assert node.rpdo[1].trans_type == 1 and node.tpdo[1].trans_type == 1

    speeds = []
    lock = threading.Lock()

    def on_tpdo1(pdo):
        with lock:
            speeds.append((time.monotonic(), pdo["vl control effort"].raw))

    node.tpdo[1].add_callback(on_tpdo1)
    node.nmt.state = "OPERATIONAL"
    # Both PDOs are synchronous: the master produces SYNC and sends RPDO1 every cycle.
    net.sync.start(0.01)
    node.rpdo[1]["vl target velocity"].raw = 0
    node.rpdo[1].start(0.01)
    try:
        assert node.tpdo[1].wait_for_reception(2.0) is not None
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        with lock:
            speeds.clear()
        start = time.monotonic()
        node.rpdo[1]["vl target velocity"].raw = 500
        # 0x6048 default: 1000 rpm per second.
        deadline = start + 5.0
        while time.monotonic() < deadline:
            with lock:
                if speeds and speeds[-1][1] == 500:
                    break
            time.sleep(0.02)
        with lock:
            seen = [v for _, v in speeds]
            t_end = next((t for t, v in speeds if v == 500), None)
        assert seen and seen[-1] == 500, seen
        assert seen == sorted(seen), "the actual velocity rises monotonically"
        assert any(0 < v < 500 for v in seen), "the velocity follows a ramp"
        # About half a second to 500 rpm (paced to the wall clock; generous bounds).
        assert t_end is not None and 0.3 < t_end - start < 2.0
        assert node.sdo[0x6043].raw == 500
        assert node.statusword & 0x0400, "target reached"
    finally:
        node.rpdo[1].stop()
        net.sync.stop()
