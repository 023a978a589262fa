"""The pytest plugin's fixtures with a scenario given as TOML text and both time modes."""

import pytest

SCENARIO = """
[[bus]]
name = "can1"
bit_rate = "250k"

[[device]]
name = "node9"
kind = "cia301"
bus = "can1"
node_id = 9
heartbeat_ms = 50
"""


@pytest.fixture
def cantwin_scenario():
    return SCENARIO


@pytest.mark.parametrize("cantwin_mode", ["virtual", "paced"])
def test_fixtures_build_the_scenario_and_connect_python_canopen(
    cantwin_sim, cantwin_mode, cantwin_channel, canopen_network
):
    import canopen

    assert cantwin_sim.paced == (cantwin_mode == "paced")
    assert cantwin_channel == "can1"
    node = canopen_network.add_node(9, canopen.ObjectDictionary())
    node.sdo.RESPONSE_TIMEOUT = 2.0
    assert node.sdo.upload(0x1017, 0) == (50).to_bytes(2, "little")
    assert node.nmt.wait_for_heartbeat(timeout=2) == "PRE-OPERATIONAL"
