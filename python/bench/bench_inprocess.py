"""Benchmark (not a test) of the cantwin Python package, in one run:

* the wall time of a 60 s heartbeat-loss scenario in virtual time (node 5 consumes the
  master's heartbeat, the master powers off at 30 s, EMCY 0x8130 follows);
* python-canopen expedited SDO uploads per second through the in-process ``cantwin``
  interface (virtual and paced time) and through the socketcand gateway of
  ``cantwin sim --socketcand`` (a subprocess), against the same CiA 301 twin at 1 Mbit/s.

Run with the interop virtualenv after tests/interop/run.sh built the package into it, with a
release ``cantwin`` binary for the gateway:

    cargo build --release --bin cantwin
    CANTWIN_BIN=target/release/cantwin target/interop-venv/bin/python \\
        python/bench/bench_inprocess.py 2000 --write

``--write`` records the figures in BENCHMARKS.md (section ``python-inprocess``).
"""

import datetime
import os
import platform
import re
import statistics
import struct
import sys
import tempfile
import time
from pathlib import Path

import can
import canopen

import cantwin

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "interop"))
from conftest import start_sim, stop_process  # noqa: E402  (the interop suite's launcher)

HEARTBEAT_LOSS = """
name = "bench: heartbeat loss"
[[bus]]
name = "can0"
bit_rate = "500k"
[[device]]
name = "node5"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 100
[[device]]
name = "master"
kind = "generator"
bus = "can0"
id = 0x701
period_ms = 100
data = "05"
"""

SDO = """
name = "bench: SDO round trips"
[[bus]]
name = "can0"
bit_rate = "1M"
[[device]]
name = "twin"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 0
"""


def heartbeat_loss():
    """Wall seconds for the 60 s scenario; checks the EMCY so a broken run cannot pass."""
    start = time.perf_counter()
    sim = cantwin.Simulation.from_toml(HEARTBEAT_LOSS)
    with can.Bus(interface="cantwin", channel="can0", sim=sim) as bus:
        bus.send(can.Message(arbitration_id=0x605, data=bytes.fromhex("23161001FA000100"), is_extended_id=False))
        bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x05], is_extended_id=False))
        sim.advance(30.0)
        sim.power("master", False)
        emcy = None
        while sim.now < 60.0:
            msg = bus.recv(60.0 - sim.now)
            if msg is None:
                break
            if msg.arbitration_id == 0x85 and emcy is None:
                emcy = struct.unpack_from("<H", msg.data)[0]
    elapsed = time.perf_counter() - start
    assert emcy == 0x8130 and sim.now >= 59.999, (emcy, sim.now)
    return elapsed


def sdo_rate(connect, n):
    """Expedited uploads of 0x1000 per second through a network `connect` opens."""
    net = canopen.Network()
    connect(net)
    try:
        node = net.add_node(5, canopen.ObjectDictionary())
        node.sdo.RESPONSE_TIMEOUT = 2.0
        for _ in range(50):  # warm-up
            node.sdo.upload(0x1000, 0)
        start = time.perf_counter()
        for _ in range(n):
            node.sdo.upload(0x1000, 0)
        return n / (time.perf_counter() - start)
    finally:
        net.disconnect()


def run(n):
    loss = sorted(heartbeat_loss() for _ in range(5))
    rates = {}
    sim = cantwin.Simulation.from_toml(SDO)
    rates["in-process, virtual time"] = sdo_rate(
        lambda net: net.connect(interface="cantwin", channel="can0", sim=sim), n
    )
    sim = cantwin.Simulation.from_toml(SDO)
    sim.start_paced()
    try:
        rates["in-process, paced"] = sdo_rate(
            lambda net: net.connect(interface="cantwin", channel="can0", sim=sim), n
        )
    finally:
        sim.stop_paced()
    with tempfile.TemporaryDirectory() as tmp:
        scenario = Path(tmp) / "bench.toml"
        scenario.write_text(SDO)
        gateway = start_sim(scenario)
        try:
            host, port = gateway.socketcand_addr("can0")
            rates["socketcand gateway (cantwin sim)"] = sdo_rate(
                lambda net: net.connect(
                    interface="socketcand", channel="can0", host=host, port=port, tcp_tune=True
                ),
                n,
            )
        finally:
            stop_process(gateway.process)
    return loss, rates


def section(n, loss, rates):
    gateway = rates["socketcand gateway (cantwin sim)"]
    rows = "\n".join(
        f"| {name} | {rate:,.0f} | {rate / gateway:.1f}× |" for name, rate in rates.items()
    )
    return f"""<!-- bench:python-inprocess -->
## python-inprocess — the `cantwin` Python package

**60 s heartbeat-loss scenario in virtual time** (node 5 consumes the master's 100 ms
heartbeat, the master powers off at 30 s, EMCY 0x8130 arrives through the `cantwin`
python-can interface): median **{statistics.median(loss) * 1000:.1f} ms** of wall time over 5
runs (min {loss[0] * 1000:.1f} ms, max {loss[-1] * 1000:.1f} ms), build included. Aim: well
under 1 s.

**python-canopen expedited SDO uploads** of 0x1000 from the CiA 301 twin on a 1 Mbit/s bus,
{n} per way, in one run:

| way | uploads/s | vs socketcand |
|---|---|---|
{rows}

Measured {datetime.date.today().isoformat()} on {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, python-canopen {canopen.__version__}.
Reproduce: `CANTWIN_BIN=target/release/cantwin target/interop-venv/bin/python python/bench/bench_inprocess.py {n} --write`
<!-- /bench:python-inprocess -->"""


def main():
    args = [a for a in sys.argv[1:] if a != "--write"]
    n = int(args[0]) if args else 2000
    loss, rates = run(n)
    text = section(n, loss, rates)
    print(text)
    if "--write" in sys.argv:
        path = ROOT / "BENCHMARKS.md"
        doc = path.read_text()
        pattern = re.compile(r"<!-- bench:python-inprocess -->.*?<!-- /bench:python-inprocess -->", re.S)
        doc = pattern.sub(lambda _: text, doc) if pattern.search(doc) else doc.rstrip("\n") + "\n\n" + text + "\n"
        path.write_text(doc)


if __name__ == "__main__":
    main()
