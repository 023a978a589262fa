"""A connection flood on the web dashboard leaves the socketcand gateway of the same process
its reserve: with the process held to 1,024 descriptors and 1,100 connections opened on the
dashboard, a new python-canopen client through socketcand still completes an SDO upload
within a second.

The flood runs in a child process: python-can's socketcand bus waits with select(), which
takes no descriptor numbered 1,024 or above.
"""

import os
import resource
import socket
import subprocess
import sys
import time

import canopen

from conftest import SCENARIOS, start_sim, stop_process

FLOOD = 1100
CAP = 64  # --web-max-connections' default

# Opens N connections to PORT, each with a request head that never ends, and prints how
# many the server still holds open half a second later; then keeps them until killed.
HOLDER = r"""
import socket, sys, time
port, n = int(sys.argv[1]), int(sys.argv[2])
held = []
for _ in range(n):
    try:
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
    except OSError:
        break
    try:
        s.send(b"GET / HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n" % port)
    except OSError:
        pass
    held.append(s)
time.sleep(0.5)
still_open = 0
for s in held:
    s.setblocking(False)
    try:
        while s.recv(4096):
            pass
    except BlockingIOError:
        still_open += 1
    except OSError:
        pass
print(len(held), still_open, flush=True)
time.sleep(60)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_web_flood_leaves_the_socketcand_gateway_a_reserve_for_python_canopen():
    port = free_port()
    sim = start_sim(SCENARIOS / "plant.toml", extra=["--web", f"127.0.0.1:{port}"])
    holder = None
    try:
        pid = sim.process.pid
        resource.prlimit(pid, resource.RLIMIT_NOFILE, (1024, 1024))
        deadline = time.monotonic() + 10
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the dashboard did not start"
                time.sleep(0.05)
        holder = subprocess.Popen(
            [sys.executable, "-c", HOLDER, str(port), str(FLOOD)],
            stdout=subprocess.PIPE,
            text=True,
        )
        opened, still_open = map(int, holder.stdout.readline().split())
        descriptors = len(os.listdir(f"/proc/{pid}/fd"))
        assert opened == FLOOD, f"only {opened} connections could be opened"
        assert still_open <= CAP, f"{still_open} of {FLOOD} connections held open"

        host, sc_port = sim.socketcand_addr("can0")
        started = time.monotonic()
        network = canopen.Network()
        network.connect(interface="socketcand", channel="can0", host=host, port=sc_port)
        try:
            node = network.add_node(5)
            node.sdo.RESPONSE_TIMEOUT = 1.0
            device_type = node.sdo.upload(0x1000, 0)
            took = time.monotonic() - started
        finally:
            network.disconnect()
        assert len(device_type) == 4
        print(
            f"flood of {FLOOD}: {still_open} held, {descriptors} descriptors in the simulator; "
            f"python-canopen SDO upload through socketcand in {took * 1000:.0f} ms"
        )
        assert took < 1.0, f"the SDO upload took {took:.3f} s"
    finally:
        if holder is not None:
            holder.kill()
            holder.wait()
        stop_process(sim.process)
