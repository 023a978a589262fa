"""Benchmark (not a test): python-canopen expedited SDO upload round trip through cantwin's
socketcand gateway, against python-canopen's own LocalNode on python-can's in-process
`virtual` bus.

Run with the interop virtualenv: `python tests/interop/bench_sdo_roundtrip.py [N]`
(CANTWIN_BIN as for the tests). Prints the median and 99th percentile per round trip.
"""

import statistics
import sys
import time

import canopen
from canopen.objectdictionary import ODVariable
from canopen.objectdictionary.datatypes import UNSIGNED32

from conftest import CIA301_SCENARIO, NODE_ID, start_sim, stop_process


def measure(node, n):
    node.sdo.upload(0x1000, 0)  # warm up
    samples = []
    for _ in range(n):
        t = time.perf_counter()
        node.sdo.upload(0x1000, 0)
        samples.append(time.perf_counter() - t)
    samples.sort()
    return statistics.median(samples), samples[int(len(samples) * 0.99) - 1]


def cantwin(n):
    sim = start_sim(CIA301_SCENARIO)
    try:
        host, port = sim.socketcand_addr("can0")
        net = canopen.Network()
        net.connect(interface="socketcand", channel="can0", host=host, port=port, tcp_tune=True)
        try:
            return measure(net.add_node(NODE_ID, canopen.ObjectDictionary()), n)
        finally:
            net.disconnect()
    finally:
        stop_process(sim.process)


def local_node(n):
    od = canopen.ObjectDictionary()
    var = ODVariable("Device type", 0x1000, 0)
    var.data_type = UNSIGNED32
    var.default = 0
    od.add_object(var)
    server_net = canopen.Network()
    client_net = canopen.Network()
    server_net.connect(interface="virtual", channel="bench", receive_own_messages=False)
    client_net.connect(interface="virtual", channel="bench", receive_own_messages=False)
    try:
        server_net.create_node(NODE_ID, od)
        return measure(client_net.add_node(NODE_ID, od), n)
    finally:
        client_net.disconnect()
        server_net.disconnect()


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    runs = [("cantwin socketcand gateway", cantwin), ("python-canopen LocalNode", local_node)]
    for name, run in runs:
        median, p99 = run(n)
        print(f"{name:28} {n} uploads: median {median * 1e6:7.0f} µs, p99 {p99 * 1e6:7.0f} µs")


if __name__ == "__main__":
    main()
