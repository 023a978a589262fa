"""Shared helpers of the package's tests: the repository's scenarios, and polling with a
wall-clock bound so that a broken twin fails a test instead of hanging it."""

import os
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = Path(os.environ.get("CANTWIN_SCENARIOS", ROOT / "scenarios"))
CIA301 = SCENARIOS / "cia301-device.toml"
# The node-ID of the device in scenarios/cia301-device.toml.
NODE_ID = 5


def wait_until(predicate, timeout=5.0, step=0.005):
    """Poll `predicate` until it is true or `timeout` seconds (wall clock) passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return bool(predicate())


@pytest.fixture
def node(canopen_network):
    """The CiA 301 device as a python-canopen RemoteNode (objects addressed by index)."""
    import canopen

    remote = canopen_network.add_node(NODE_ID, canopen.ObjectDictionary())
    remote.sdo.RESPONSE_TIMEOUT = 2.0
    return remote
