"""python-canopen against the TM3 coupler of scenarios/tm3-island.toml: it loads the EDS
generated for the island, remaps a TPDO, sets outputs by RPDO and reads inputs by TPDO."""

import os
import subprocess
import tomllib

import canopen
import pytest

from conftest import ROOT, SCENARIOS, start_sim, stop_process

TM3_SCENARIO = SCENARIOS / "tm3-island.toml"

with open(TM3_SCENARIO, "rb") as f:
    ISLAND = next(d for d in tomllib.load(f)["device"] if d["kind"] == "tm3")

NODE = ISLAND["node_id"]


@pytest.fixture(scope="module")
def eds_file(tmp_path_factory):
    """The island's EDS, generated from its object dictionary."""
    # run.sh builds the example program; without it, cargo builds and runs it.
    program = os.environ.get("CANTWIN_TM3_EDS")
    command = [program] if program else ["cargo", "run", "-q", "-p", "cantwin-tm3", "--example", "tm3_eds", "--"]
    text = subprocess.run(
        [*command, *ISLAND["modules"]],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
    ).stdout
    path = tmp_path_factory.mktemp("tm3") / "TM3BCCO.eds"
    path.write_text(text)
    return path


@pytest.fixture
def tm3(eds_file):
    sim = start_sim(TM3_SCENARIO)
    net = canopen.Network()
    host, port = sim.socketcand_addr("can0")
    net.connect(interface="socketcand", channel="can0", host=host, port=port)
    try:
        yield net.add_node(NODE, str(eds_file))
    finally:
        net.disconnect()
        stop_process(sim.process)


def test_eds_loads_and_describes_the_island(tm3):
    od = tm3.object_dictionary
    assert od[0x1018][1].default == 0x0500005A
    assert od[0x1018][2].default == 811044
    assert len(od[0x6000]) == 1 + 5  # sub 0 and five input bytes
    assert od[0x6200][1].pdo_mappable
    assert tm3.sdo[0x1008].raw == "TM3BCCO"
    assert tm3.sdo[0x1000].raw == 0x008F0191
    assert tm3.sdo[0x1027][1].raw == od[0x1027][1].default


def test_remapped_tpdo_carries_inputs_and_rpdo_sets_outputs(tm3):
    tm3.nmt.state = "PRE-OPERATIONAL"
    tm3.tpdo.read()
    tm3.rpdo.read()
    tpdo = tm3.tpdo[1]
    tpdo.clear()
    # Inputs of module 1 (0x6000 sub 1-2) and of the TM3DM24R's second byte (sub 4).
    tpdo.add_variable(0x6000, 1)
    tpdo.add_variable(0x6000, 2)
    tpdo.add_variable(0x6000, 4)
    tpdo.trans_type = 255
    tpdo.enabled = True
    tm3.tpdo.save()
    assert tm3.sdo[0x1A00][0].raw == 3
    assert tm3.sdo[0x1A00][3].raw == 0x60000408

    tm3.nmt.state = "OPERATIONAL"
    # Entering OPERATIONAL sends every event-driven TPDO once.
    assert tpdo.wait_for_reception(timeout=5) is not None
    inputs = [var.raw for var in tpdo.map]
    # digital_inputs = [[1, 0], [1, 5], [3, 12]] in the scenario.
    assert inputs == [0b0010_0001, 0, 0b0001_0000]

    rpdo = tm3.rpdo[1]
    assert [(v.index, v.subindex) for v in rpdo.map] == [(0x6200, 1)]
    rpdo.map[0].raw = 0x05
    rpdo.transmit()
    for _ in range(50):
        if tm3.sdo[0x6200][1].raw == 0x05:
            break
    assert tm3.sdo[0x6200][1].raw == 0x05
    assert tm3.sdo[0x1002].raw == 0
