"""Fixtures for the interop suite: a `cantwin sim` subprocess with its gateways.

`run.sh` sets CANTWIN_BIN (the built binary) and CANTWIN_SCENARIOS (the repository's
scenarios folder). Every wait is bounded so that a broken server fails a test instead of
hanging the suite.
"""

import os
import queue
import shutil
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
LOCAL_SCENARIOS = HERE / "scenarios"
SCENARIOS = Path(os.environ.get("CANTWIN_SCENARIOS", ROOT / "scenarios"))

# How long `cantwin sim` may take to print its listening lines.
START_TIMEOUT = 20.0
# How long it may take to exit after SIGTERM before it is killed.
STOP_TIMEOUT = 5.0

# python-canopen waits 0.3 s for an SDO response by default; a loaded test machine can take
# longer to schedule the server and the client's Notifier, and a client that times out sends
# an abort the next transfer then collides with. Every client of the suite waits 2 s.
try:
    from canopen.sdo.client import SdoClient

    SdoClient.RESPONSE_TIMEOUT = 2.0
except ImportError:  # the suite's python-can-only tests need no SDO client
    pass


def cantwin_bin() -> str:
    path = os.environ.get("CANTWIN_BIN")
    if path:
        return path
    found = shutil.which("cantwin")
    if found:
        return found
    pytest.fail("CANTWIN_BIN is not set and cantwin is not on PATH (run tests/interop/run.sh)")


def export_eds(tmp_path: Path, scenario: str, device: str) -> Path:
    """The EDS `cantwin eds export` writes for `device` of `scenarios/SCENARIO`."""
    out = tmp_path / f"{device}.eds"
    subprocess.run(
        [cantwin_bin(), "eds", "export", "--scenario", str(SCENARIOS / scenario), "--device", device, "-o", str(out)],
        check=True,
        timeout=60,
    )
    return out


@dataclass
class Sim:
    """A running `cantwin sim`: where its gateways listen."""

    process: subprocess.Popen
    socketcand: dict = field(default_factory=dict)  # bus name -> (host, port)
    slcan: dict = field(default_factory=dict)  # bus name -> (host, port)
    stderr_lines: list = field(default_factory=list)

    def socketcand_addr(self, bus: str = "can0"):
        return self.socketcand[bus]

    def slcan_url(self, bus: str = "can0") -> str:
        host, port = self.slcan[bus]
        return f"socket://{host}:{port}"

    def stderr(self) -> str:
        return "\n".join(self.stderr_lines)


def _split_addr(text: str):
    host, _, port = text.rpartition(":")
    return host.strip("[]"), int(port)


def _pump(stream, sink_queue, sink_list):
    for raw in iter(stream.readline, ""):
        line = raw.rstrip("\n")
        if sink_queue is not None:
            sink_queue.put(line)
        if sink_list is not None:
            sink_list.append(line)
    if sink_queue is not None:
        sink_queue.put(None)


def stop_process(process: subprocess.Popen) -> None:
    """Stop as Ctrl-C does (so recordings are completed), then kill after STOP_TIMEOUT:
    never leave the simulator behind. `cantwin sim` stops cleanly on SIGINT."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=STOP_TIMEOUT)


def start_sim(scenario: Path, *, socketcand=True, slcan=False, extra=()) -> Sim:
    """Start `cantwin sim` on ephemeral ports and wait for one listening line per gateway."""
    args = [cantwin_bin(), "sim", str(scenario)]
    if socketcand:
        args += ["--socketcand", "0"]
    if slcan:
        args += ["--slcan", "0"]
    args += list(extra)
    process = subprocess.Popen(
        args,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        bufsize=1,
    )
    sim = Sim(process=process)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_pump, args=(process.stdout, lines, None), daemon=True).start()
    threading.Thread(
        target=_pump, args=(process.stderr, None, sim.stderr_lines), daemon=True
    ).start()

    # The scenario's bus count is not known here; stop waiting once every requested gateway
    # has announced at least one bus and no further line arrives shortly after.
    deadline = time.monotonic() + START_TIMEOUT
    settle = None
    while True:
        now = time.monotonic()
        wanted = (not socketcand or sim.socketcand) and (not slcan or sim.slcan)
        if wanted and settle is None:
            settle = now + 0.2
        limit = settle if settle is not None else deadline
        if now >= limit:
            if wanted:
                return sim
            stop_process(process)
            pytest.fail(
                f"cantwin sim did not announce its gateways within {START_TIMEOUT} s:\n"
                + sim.stderr()
            )
        try:
            line = lines.get(timeout=max(0.0, limit - now))
        except queue.Empty:
            continue
        if line is None:
            stop_process(process)
            pytest.fail(
                f"cantwin sim exited early (status {process.poll()}):\n" + sim.stderr()
            )
        parts = line.split()
        if len(parts) == 3 and parts[0] == "socketcand":
            sim.socketcand[parts[2]] = _split_addr(parts[1])
        elif len(parts) == 3 and parts[0] == "slcan":
            sim.slcan[parts[2]] = _split_addr(parts[1])


@pytest.fixture
def generators_sim():
    """Generator devices on can0 behind socketcand and slcan."""
    sim = start_sim(LOCAL_SCENARIOS / "generators.toml", slcan=True)
    try:
        yield sim
    finally:
        stop_process(sim.process)


@pytest.fixture
def quiet_sim():
    """A bus with a single silent listener (so frames are acknowledged) behind both gateways."""
    sim = start_sim(LOCAL_SCENARIOS / "quiet.toml", slcan=True)
    try:
        yield sim
    finally:
        stop_process(sim.process)


CIA301_SCENARIO = SCENARIOS / "cia301-device.toml"
# The node-ID of the device in scenarios/cia301-device.toml.
NODE_ID = 5


@pytest.fixture
def cia301_sim():
    """scenarios/cia301-device.toml behind socketcand and slcan."""
    sim = start_sim(CIA301_SCENARIO, slcan=True)
    try:
        yield sim
    finally:
        stop_process(sim.process)


@pytest.fixture
def network(cia301_sim):
    """A python-canopen network on the device's bus through the socketcand gateway."""
    import canopen

    host, port = cia301_sim.socketcand_addr("can0")
    net = canopen.Network()
    net.connect(interface="socketcand", channel="can0", host=host, port=port)
    try:
        yield net
    finally:
        net.disconnect()


@pytest.fixture
def node(network):
    """The device as a python-canopen RemoteNode (no EDS: objects addressed by index)."""
    import canopen

    remote = network.add_node(NODE_ID, canopen.ObjectDictionary())
    remote.sdo.RESPONSE_TIMEOUT = 2.0
    return remote
