"""Benchmark (not a test): python-canopen's expedited SDO upload round trip to cantwin's CiA 301
device twin, side by side in the same run with python-canopen's own LocalNode attached to the
same cantwin bus (1 Mbit/s) as a socketcand client.

Both servers sit behind the same gateway on the same simulated bus, so the ratio compares the
servers: the twin answers on the bus itself, the LocalNode's answer crosses the gateway twice
more and python-canopen's server code. Requests alternate between the two to share any
disturbance of the machine.

Run with the interop virtualenv (tests/interop/run.sh creates it; CANTWIN_BIN as for the tests,
a release build for the recorded figures):

    CANTWIN_BIN=target/release/cantwin target/interop-venv/bin/python \\
        tests/interop/bench_sdo_roundtrip.py 10000 --write

Prints median and 99th percentile per round trip and their ratio; `--write` records them in
BENCHMARKS.md (section `python`).
"""

import datetime
import os
import platform
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import canopen
from canopen.objectdictionary import ODVariable
from canopen.objectdictionary.datatypes import UNSIGNED32

from conftest import ROOT, start_sim, stop_process

TWIN_NODE = 5
LOCAL_NODE = 6

SCENARIO = """
name = "bench: python-canopen round trips"
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


def local_od():
    od = canopen.ObjectDictionary()
    var = ODVariable("Device type", 0x1000, 0)
    var.data_type = UNSIGNED32
    var.default = 0x00000191
    od.add_object(var)
    return od


def percentile(sorted_samples, p):
    return sorted_samples[max(0, int(len(sorted_samples) * p) - 1)]


def run(n):
    with tempfile.TemporaryDirectory() as tmp:
        scenario = Path(tmp) / "bench.toml"
        scenario.write_text(SCENARIO)
        sim = start_sim(scenario)
        try:
            host, port = sim.socketcand_addr("can0")
            server = canopen.Network()
            client = canopen.Network()
            server.connect(interface="socketcand", channel="can0", host=host, port=port, tcp_tune=True)
            client.connect(interface="socketcand", channel="can0", host=host, port=port, tcp_tune=True)
            try:
                server.create_node(LOCAL_NODE, local_od())
                twin = client.add_node(TWIN_NODE, canopen.ObjectDictionary())
                local = client.add_node(LOCAL_NODE, local_od())
                for node in (twin, local):  # warm up
                    for _ in range(20):
                        node.sdo.upload(0x1000, 0)
                samples = {"twin": [], "local": []}
                for _ in range(n):
                    for name, node in (("twin", twin), ("local", local)):
                        t = time.perf_counter()
                        node.sdo.upload(0x1000, 0)
                        samples[name].append(time.perf_counter() - t)
                return {k: sorted(v) for k, v in samples.items()}
            finally:
                client.disconnect()
                server.disconnect()
        finally:
            stop_process(sim.process)


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    n = int(args[0]) if args else 2000
    s = run(n)
    rows = []
    for key, label in (("twin", "cantwin CiA 301 twin"), ("local", "python-canopen LocalNode")):
        med, p99 = statistics.median(s[key]), percentile(s[key], 0.99)
        rows.append((label, med, p99))
        print(f"{label:28} {n} uploads: median {med * 1e6:7.0f} µs, p99 {p99 * 1e6:7.0f} µs")
    ratio = rows[1][1] / rows[0][1]
    print(f"median ratio LocalNode / twin: {ratio:.2f} (floor 1.3); twin median < 1 ms: {rows[0][1] < 1e-3}")
    if "--write" in sys.argv:
        write(n, rows, ratio)


def write(n, rows, ratio):
    table = "| server | median | p99 |\n|---|---|---|\n" + "\n".join(
        f"| {label} | {med * 1e6:.0f} µs | {p99 * 1e6:.0f} µs |" for label, med, p99 in rows
    )
    body = (
        "## python — python-canopen SDO round trips through the socketcand gateway\n\n"
        f"{n} expedited uploads of 0x1000 by python-canopen (interface `socketcand`) on a "
        "1 Mbit/s cantwin bus, alternating between cantwin's CiA 301 twin and python-canopen's "
        "own LocalNode attached to the same bus as a second socketcand client. Floor: the twin "
        "≥ 1.3× faster than the LocalNode (median), median < 1 ms.\n\n"
        f"{table}\n\n**median ratio LocalNode / twin: {ratio:.2f}**\n\n"
        f"Measured {datetime.date.today()} on {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, "
        f"python-canopen {canopen.__version__}.\n"
        "Reproduce: `CANTWIN_BIN=target/release/cantwin target/interop-venv/bin/python "
        "tests/interop/bench_sdo_roundtrip.py 10000 --write`"
    )
    path = ROOT / "BENCHMARKS.md"
    text = path.read_text() if path.exists() else "# Benchmarks\n"
    section = f"<!-- bench:python -->\n{body}\n<!-- /bench:python -->"
    pattern = re.compile(r"<!-- bench:python -->.*?<!-- /bench:python -->", re.S)
    text = pattern.sub(lambda _: section, text) if pattern.search(text) else text.rstrip() + "\n\n" + section + "\n"
    path.write_text(text)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
