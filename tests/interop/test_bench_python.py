"""`cantwin bench python` end to end, kept short: a few round trips and one 64 KiB transfer
each way per server. The figures themselves are recorded by the full benchmark; this checks
that the benchmark runs against this build and that what it measures on the bus is right."""

import json
import os
import subprocess
import sys

import pytest

from conftest import ROOT, cantwin_bin


# Two 64 KiB transfers each way take about 25 s of paced bus time and python-canopen.
@pytest.mark.timeout(240)
def test_bench_python_runs_and_measures_both_servers():
    env = dict(os.environ, CANTWIN_PYTHON=sys.executable)
    out = subprocess.run(
        [cantwin_bin(), "--json", "bench", "python", "--requests", "30", "--transfers", "1",
         "--file", str(ROOT / "BENCHMARKS.md")],
        env=env, capture_output=True, text=True, timeout=200,
    )
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["bench"] == "python"
    twin, local = result["servers"]["twin"], result["servers"]["local"]
    # The twin answers inside the call that delivers the request: from the end of the request
    # to the end of the answer is the answer frame alone, an 8-byte standard frame at
    # 1 Mbit/s (108 bits before stuffing + 3 of intermission, at most 24 stuff bits).
    assert 111 <= twin["answer_on_the_bus_us"] <= 136
    # The LocalNode's answer crosses the gateway to its process and back before its frame.
    assert local["answer_on_the_bus_us"] > twin["answer_on_the_bus_us"]
    for server in (twin, local):
        assert 0 < server["round_trip_median_us"] <= server["round_trip_p99_us"]
        # 9,363 segments of 7 bytes, each a request and an answer of at least 111 µs.
        assert server["upload_64k_s"] > 2.0 and server["download_64k_s"] > 2.0
    assert result["twin_alone_median_us"] > 0
    bare = result["bare_client_us"]
    assert 111 <= bare["bus"] <= 136
