"""python-canopen's LSS master (`network.lss`, CiA 305) commissions the device of
scenarios/lss-commissioning.toml, a cia301 twin with `lss = true` and no node-ID: switch
state global and selective, inquire, configure node-ID and bit timing, store; the twin boots
with the new node-ID when it leaves LSS configuration, takes a later one at NMT reset
communication, and with `--state-dir` keeps the stored one across runs.
"""

import threading

import canopen
import canopen.lss
import pytest

from conftest import SCENARIOS, start_sim, stop_process

SCENARIO = SCENARIOS / "lss-commissioning.toml"
# The LSS address of the scenario's device (0x1018 sub 1-4).
ADDRESS = (0x00000CA7, 305, 0x00010000, 0x30)
# CiA 301 bit timing table index of 500 kbit/s, the scenario bus's rate.
BIT_TIMING_500K = 2
TIMEOUT = 5.0


def connect(sim):
    host, port = sim.socketcand_addr("can0")
    net = canopen.Network()
    net.connect(interface="socketcand", channel="can0", host=host, port=port)
    return net


class BootUps:
    """Collects the boot-up messages (0x700 + node-ID, data 00) of `node_id`."""

    def __init__(self, net, node_id):
        self.seen = threading.Event()
        net.subscribe(0x700 + node_id, self._on)

    def _on(self, can_id, data, timestamp):
        if bytes(data) == b"\x00":
            self.seen.set()


def serial_of(net, node_id):
    node = net.add_node(node_id, canopen.ObjectDictionary())
    node.sdo.RESPONSE_TIMEOUT = 2.0
    return int.from_bytes(node.sdo.upload(0x1018, 4), "little")


@pytest.fixture
def lss_sim():
    sim = start_sim(SCENARIO)
    try:
        yield sim
    finally:
        stop_process(sim.process)


def test_network_lss_commissions_a_node_without_node_id(lss_sim):
    net = connect(lss_sim)
    try:
        lss = net.lss
        lss.RESPONSE_TIMEOUT = 2.0
        lss.send_switch_state_global(lss.CONFIGURATION_STATE)
        assert lss.inquire_node_id() == 0xFF
        assert lss.inquire_lss_address(canopen.lss.CS_INQUIRE_VENDOR_ID) == ADDRESS[0]
        assert lss.inquire_lss_address(canopen.lss.CS_INQUIRE_SERIAL_NUMBER) == ADDRESS[3]
        with pytest.raises(canopen.lss.LssError):
            lss.configure_node_id(200)
        with pytest.raises(canopen.lss.LssError):
            lss.configure_bit_timing(5)
        lss.configure_node_id(20)
        lss.configure_bit_timing(BIT_TIMING_500K)
        lss.store_configuration()
        boot = BootUps(net, 20)
        # Leaving LSS configuration with a node-ID, the node boots with it (CiA 305).
        lss.send_switch_state_global(lss.WAITING_STATE)
        assert boot.seen.wait(TIMEOUT), "no boot-up from node 20"
        assert serial_of(net, 20) == ADDRESS[3]

        # A configured node selected by its address takes a new node-ID at NMT reset
        # communication.
        assert lss.send_switch_state_selective(*ADDRESS)
        assert lss.inquire_node_id() == 20
        lss.configure_node_id(21)
        lss.send_switch_state_global(lss.WAITING_STATE)
        boot = BootUps(net, 21)
        net.nmt.send_command(0x82)
        assert boot.seen.wait(TIMEOUT), "no boot-up from node 21 after reset communication"
        assert serial_of(net, 21) == ADDRESS[3]
    finally:
        net.disconnect()


def test_stored_node_id_survives_runs_with_state_dir(tmp_path):
    state = ["--state-dir", str(tmp_path)]
    sim = start_sim(SCENARIO, extra=state)
    try:
        net = connect(sim)
        try:
            lss = net.lss
            lss.RESPONSE_TIMEOUT = 2.0
            lss.send_switch_state_global(lss.CONFIGURATION_STATE)
            lss.configure_node_id(33)
            lss.configure_bit_timing(BIT_TIMING_500K)
            lss.store_configuration()
            lss.send_switch_state_global(lss.WAITING_STATE)
            assert serial_of(net, 33) == ADDRESS[3]
        finally:
            net.disconnect()
    finally:
        stop_process(sim.process)

    # The next run boots as node 33 at once, without LSS.
    sim = start_sim(SCENARIO, extra=state)
    try:
        net = connect(sim)
        try:
            assert serial_of(net, 33) == ADDRESS[3]
            net.lss.RESPONSE_TIMEOUT = 2.0
            net.lss.send_switch_state_global(net.lss.CONFIGURATION_STATE)
            assert net.lss.inquire_node_id() == 33
        finally:
            net.disconnect()
    finally:
        stop_process(sim.process)


def test_network_lss_fast_scan_finds_the_node_without_node_id(lss_sim):
    net = connect(lss_sim)
    try:
        lss = net.lss
        # Each bit python-canopen reads as 1 costs one response timeout.
        lss.RESPONSE_TIMEOUT = 0.2
        found, address = lss.fast_scan()
        assert found, "fast_scan found no node"
        assert tuple(address) == ADDRESS
        # The node found is in LSS configuration.
        lss.RESPONSE_TIMEOUT = 2.0
        assert lss.inquire_node_id() == 0xFF
        lss.configure_node_id(40)
        boot = BootUps(net, 40)
        lss.send_switch_state_global(lss.WAITING_STATE)
        assert boot.seen.wait(TIMEOUT), "no boot-up from node 40"
        # Configured now: it takes no part in a fastscan.
        lss.RESPONSE_TIMEOUT = 0.2
        assert lss.fast_scan() == (False, None)
    finally:
        net.disconnect()
