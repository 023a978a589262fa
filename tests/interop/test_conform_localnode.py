"""`cantwin conform` against python-canopen's `LocalNode`, a device implemented outside
cantwin, served through cantwin's socketcand gateway on the wall clock.

The LocalNode runs in this process on a quiet bus (one silent listener acknowledges the
frames); its dictionary is the EDS `cantwin eds export` writes for the CiA 301 twin (with a
smaller DOMAIN), so the runner and the LocalNode read the same file. The run must complete with a report (JUnit
XML and JSON, one entry per case of the catalogue), and it must report the LocalNode's gaps
that python-canopen's own source shows (docs/conformance.md lists them all, case by case).
"""

import json
import subprocess
import xml.etree.ElementTree as ET

import canopen
import pytest

from conftest import LOCAL_SCENARIOS, cantwin_bin, export_eds, start_sim, stop_process

NODE_ID = 5
# A wall-clock run waits out every unanswered request (the SDO timeout, 2 s for each
# missing boot-up) and measures periods: about 25 s here, bounded so that a hanging run
# fails instead of stalling the suite.
RUN_TIMEOUT = 180
# `sdo.abort-timeout` waits 10 s for a server timeout the LocalNode does not have
# (python-canopen's SdoServer keeps an unfinished transfer open forever): left out here,
# recorded in docs/conformance.md.
SKIPPED = "sdo.abort-timeout"


# The CiA 301 twin of scenarios/cia301-device.toml with a 300-byte DOMAIN instead of 64 KiB:
# the OD cases read and write back every entry, and 64 KiB each way in segments of a
# LocalNode on the wall clock would take half a minute. 300 bytes still take many segments.
TWIN = """
[[bus]]
name = "can0"
bit_rate = "500k"

[[device]]
name = "node5"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 100
domain_size = 300
"""


@pytest.fixture
def local_node(tmp_path):
    """A LocalNode with the CiA 301 twin's dictionary on a quiet bus behind socketcand."""
    scenario = tmp_path / "twin.toml"
    scenario.write_text(TWIN)
    # An absolute path: export_eds joins it to the scenarios folder, which leaves it as is.
    eds = export_eds(tmp_path, str(scenario), "node5")
    sim = start_sim(LOCAL_SCENARIOS / "quiet.toml")
    net = canopen.Network()
    try:
        host, port = sim.socketcand_addr("can0")
        net.connect(interface="socketcand", channel="can0", host=host, port=port, tcp_tune=True)
        node = canopen.LocalNode(NODE_ID, str(eds))
        net.add_node(node)
        # python-canopen's NmtSlave sends its boot-up message only when the application
        # resets it, and starts its heartbeat on the way to PRE-OPERATIONAL.
        node.nmt.send_command(0x81)
        node.nmt.send_command(0x80)
        yield (host, port), eds, node
    finally:
        net.disconnect()
        stop_process(sim.process)


def run_conform(addr, eds, tmp_path):
    host, port = addr
    junit = tmp_path / "localnode.xml"
    report = tmp_path / "localnode.json"
    done = subprocess.run(
        [
            cantwin_bin(),
            "conform",
            "--socketcand",
            f"{host}:{port}",
            "--bus",
            "can0",
            "--node-id",
            str(NODE_ID),
            "--eds",
            str(eds),
            "--junit",
            str(junit),
            "--json-report",
            str(report),
            "--skip",
            SKIPPED,
        ],
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    return done, junit, report


@pytest.mark.timeout(RUN_TIMEOUT + 60)
def test_conform_runs_every_case_against_the_local_node(local_node, tmp_path):
    addr, eds, _node = local_node
    done, junit, report = run_conform(addr, eds, tmp_path)
    # Mandatory cases fail (the LocalNode has gaps), and the run went to its end.
    assert done.returncode == 1, done.stdout + done.stderr
    assert "mandatory cases failed" in done.stderr, done.stderr
    result = json.loads(report.read_text())
    assert result.get("stopped") is None, result.get("stopped")
    cases = result["cases"]
    verdicts = {c["id"]: c["verdict"] for c in cases}
    catalogue = subprocess.run(
        [cantwin_bin(), "conform", "--list"], capture_output=True, text=True, check=True, timeout=30
    ).stdout
    listed = [line.split()[0] for line in catalogue.splitlines() if line.strip()]
    assert sorted(verdicts) == sorted(listed)
    suite = ET.parse(junit).getroot()
    assert len(suite.findall(".//testcase")) == len(listed)
    assert verdicts[SKIPPED] == "skipped"
    # Gaps python-canopen's source shows (canopen 2.4.1: nmt.py, sdo/server.py,
    # node/local.py). (NmtSlave.on_command puts a reset command's state, INITIALISING, into
    # its running heartbeat: 0x705 with 0x00, on the wire a boot-up message, once a period,
    # so the boot-up cases pass or fail with the heartbeat's timing: not asserted.)
    # SdoServer answers whatever the NMT state.
    assert verdicts["nmt.sdo-stopped"] == "fail", done.stdout
    # It aborts every block download with 0x05040001: reported as not supported.
    assert verdicts["sdo.block-download"] == "not-supported", done.stdout
    # SdoServer.block_upload answers a block upload initiate with an ordinary upload,
    # although the runner's pst = 0 allows no change of protocol (CiA 301 §7.2.4.3.13).
    details = {c["id"]: c["detail"] for c in cases}
    assert verdicts["sdo.block-upload"] == "fail", done.stdout
    assert "pst = 0" in details["sdo.block-upload"], details["sdo.block-upload"]
    # LocalNode stores what is written, with no check of limits or signatures and no
    # behaviour behind the communication objects (0x1003, 0x1010, PDO parameters).
    for case in (
        "sdo.abort-value-high",
        "emcy.history",
        "emcy.cob-id-change-valid",
        "store.wrong-signature",
        "pdo.mapping-procedure",
    ):
        assert verdicts[case] == "fail", (case, done.stdout)
    # What a LocalNode does right: expedited and segmented transfers of its own dictionary,
    # the answers its file promises, toggle checking. (Its heartbeat, a python-can periodic
    # task, passes the period case too, but no timing is asserted on this machine.)
    for case in (
        "eds.entries-exist",
        "eds.access-types",
        "sdo.expedited-upload",
        "sdo.segmented-upload",
        "sdo.segmented-download",
        "sdo.abort-toggle",
    ):
        assert verdicts[case] == "pass", (case, done.stdout)
