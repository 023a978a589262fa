"""Commissioning the ADV200 twin with python-canopen, as a test suite would run it against
the real drive, with no CAN hardware and no sockets: the pytest plugin builds the scenario
(scenarios/adv200-example.toml, the worked example of the EXP-CAN/DN-ADV manual §1.6) and
connects a python-canopen Network through the in-process ``cantwin`` interface.

Run with ``pytest python/examples`` once the package is installed.
"""

import os
import struct
from pathlib import Path

import canopen
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = Path(os.environ.get("CANTWIN_SCENARIOS", ROOT / "scenarios"))
EDS_CANOPEN = ROOT / "crates" / "adv200" / "eds" / "adv200-canopen.eds"

pytestmark = pytest.mark.cantwin_scenario(str(SCENARIOS / "adv200-example.toml"))

NODE = 12  # PAR 4006 Fieldbus address in the worked example
PAR_MOTOR_SPEED = 260  # read at 0x2000 + PAR sub 1 (§1.1.5)
ENABLE, START = 0x0001, 0x0002  # control word bits through WordDecomp (§1.6.2)


@pytest.fixture
def drive(canopen_network):
    node = canopen.RemoteNode(NODE, str(EDS_CANOPEN))
    canopen_network.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 2.0
    return node


def test_identity_and_parameters_over_sdo(cantwin_sim, drive):
    # The card answers expedited SDO only (§1.1 item 11): every object here is ≤ 4 bytes.
    device_type = struct.unpack("<I", drive.sdo.upload(0x1000, 0))[0]
    assert device_type == struct.unpack("<I", cantwin_sim.read_object("drive", 0x1000, 0))[0]
    assert drive.sdo.upload(0x1018, 4) == struct.pack("<I", 1)  # serial = 1 (scenario default)
    # PAR 4006 Fieldbus address reads back through the parameter objects.
    address = drive.sdo.upload(0x2000 + 4006, 1)
    assert int.from_bytes(address, "little", signed=True) == NODE
    assert cantwin_sim.param("drive", 4006) == NODE


def test_run_to_1500_rpm_with_pdos_and_sync(cantwin_sim, canopen_network, drive):
    drive.nmt.state = "OPERATIONAL"
    # TPDO1 as the drive reports it over SDO: synchronous, 0x18C.
    drive.tpdo.read()
    tpdo1 = drive.tpdo[1]
    assert drive.tpdo[1].cob_id == 0x180 + NODE and drive.tpdo[1].trans_type == 1

    # RPDO1 (0x20C): word 1 control word, word 2 Ramp ref 1 in rpm; both PDOs act at SYNC.
    target = 1500
    speed = None
    for _ in range(400):
        canopen_network.send_message(0x200 + NODE, struct.pack("<Hh", ENABLE | START, target))
        data = after_sync(canopen_network, tpdo1)
        status, speed, analog2 = struct.unpack_from("<Hhh", data)
        if speed == target:
            break
        cantwin_sim.advance(0.05)  # 50 ms of bus time between cycles
    assert speed == target
    assert status & 0x0003 == 0x0003  # Enable state, Drive ok
    assert status & 0x0100  # digital input 4 is on in the scenario
    assert cantwin_sim.drive("drive")["speed_rpm"] == pytest.approx(target)
    # Word 3 is analog input 2 (PAR 1550); the scenario sets it to 2.5 V.
    assert analog2 != 0

    # Stop: the ramp takes the speed back to 0. "Speed is zero" (bit 2) comes on as soon as
    # the speed falls below the zero-speed threshold, so it may lead the last ramp steps.
    for _ in range(400):
        canopen_network.send_message(0x200 + NODE, struct.pack("<Hh", ENABLE, 0))
        status, speed, _ = struct.unpack_from("<Hhh", after_sync(canopen_network, tpdo1))
        if speed == 0:
            break
        cantwin_sim.advance(0.05)
    assert speed == 0 and status & 0x0004


def test_external_fault_shows_in_the_status_word(cantwin_sim, canopen_network, drive):
    drive.nmt.state = "OPERATIONAL"
    drive.tpdo.read()
    tpdo1 = drive.tpdo[1]
    canopen_network.send_message(0x200 + NODE, struct.pack("<Hh", ENABLE, 0))
    status, _, _ = struct.unpack_from("<Hhh", after_sync(canopen_network, tpdo1))
    assert status & 0x0002  # Drive ok
    cantwin_sim.raise_alarm("drive", "External fault")
    cantwin_sim.advance(0.01)
    status, _, _ = struct.unpack_from("<Hhh", after_sync(canopen_network, tpdo1))
    assert not status & 0x0002
    assert cantwin_sim.drive("drive")["alarms"]


def after_sync(network, pdo):
    """SYNC, then the data of the TPDO it triggers, with python-canopen's own wait in the
    order a script for the real drive has it."""
    network.sync.transmit()
    assert pdo.wait_for_reception(timeout=2) is not None, "no TPDO after SYNC"
    return bytes(pdo.data)
