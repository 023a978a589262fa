"""pytest fixtures for testing CAN software against cantwin twins in the test's process.

Installed with the package (entry point ``pytest11``). Name the scenario with a marker on
the test (or module, or class)::

    @pytest.mark.cantwin_scenario("scenarios/cia301-device.toml")
    def test_boot(canopen_network):
        node = canopen_network.add_node(5, canopen.ObjectDictionary())
        ...

or override the ``cantwin_scenario`` fixture (a path, or a :class:`cantwin.Simulation`
factory's TOML text starting with ``[``). Relative paths are resolved against the test
file's folder, then the current directory.

Fixtures:

* ``cantwin_mode``: ``"virtual"`` (default) or ``"paced"``; parametrize it to run a test
  both ways: ``@pytest.mark.parametrize("cantwin_mode", ["virtual", "paced"])``.
* ``cantwin_sim``: the :class:`cantwin.Simulation`, paced if ``cantwin_mode`` says so,
  stopped after the test.
* ``cantwin_channel``: the bus python-can attaches to (default: the scenario's first bus).
* ``canopen_network``: a connected :class:`canopen.Network` on that bus, disconnected after
  the test.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Union

import pytest

from ._native import Simulation

MODES = ("virtual", "paced")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "cantwin_scenario(path_or_toml): the scenario the cantwin_sim fixture builds",
    )


@pytest.fixture
def cantwin_scenario(request: pytest.FixtureRequest) -> Union[str, Path]:
    """The scenario: the ``cantwin_scenario`` marker's argument (a path or TOML text)."""
    marker = request.node.get_closest_marker("cantwin_scenario")
    if marker is None or not marker.args:
        pytest.fail(
            "no scenario: mark the test with @pytest.mark.cantwin_scenario(path) "
            "or override the cantwin_scenario fixture"
        )
    return marker.args[0]


@pytest.fixture
def cantwin_mode() -> str:
    """``"virtual"`` or ``"paced"``: how ``cantwin_sim`` runs."""
    return "virtual"


def _build(scenario: Union[str, Path], base: Path) -> Simulation:
    if isinstance(scenario, str) and scenario.lstrip().startswith(("[", "#", "name", "seed")):
        return Simulation.from_toml(scenario, name=str(base / "inline.toml"))
    path = Path(scenario)
    if not path.is_absolute() and (base / path).exists():
        path = base / path
    return Simulation.load(str(path))


@pytest.fixture
def cantwin_sim(
    request: pytest.FixtureRequest, cantwin_scenario: Union[str, Path], cantwin_mode: str
) -> Iterator[Simulation]:
    """The scenario built into a :class:`cantwin.Simulation`."""
    if cantwin_mode not in MODES:
        pytest.fail(f"cantwin_mode must be one of {MODES}, not {cantwin_mode!r}")
    sim = _build(cantwin_scenario, Path(str(request.node.fspath)).parent)
    if cantwin_mode == "paced":
        sim.start_paced()
    try:
        yield sim
    finally:
        if sim.paced:
            sim.stop_paced()


@pytest.fixture
def cantwin_channel(cantwin_sim: Simulation) -> str:
    """The bus python-can attaches to: the scenario's first bus."""
    return cantwin_sim.buses[0]


@pytest.fixture
def canopen_network(cantwin_sim: Simulation, cantwin_channel: str) -> Iterator["canopen.Network"]:  # noqa: F821
    """A python-canopen network on ``cantwin_channel`` through the ``cantwin`` interface."""
    canopen = pytest.importorskip("canopen")
    net = canopen.Network()
    net.connect(interface="cantwin", channel=cantwin_channel, sim=cantwin_sim)
    try:
        yield net
    finally:
        net.disconnect()
