"""tshark decodes a pcap recorded by `cantwin sim --pcap` with the CANopen dissector."""

import os
import shutil
import struct
import subprocess
import time

import canopen
import pytest

from conftest import CIA301_SCENARIO, NODE_ID, start_sim, stop_process

TSHARK = shutil.which("tshark")


@pytest.fixture
def tshark():
    if TSHARK is None:
        if os.environ.get("CI"):
            pytest.fail("tshark is not installed (required when CI is set)")
        pytest.skip("tshark is not installed")
    return TSHARK


def decode(tshark, pcap, fields, display_filter):
    """Rows of `fields` for the packets matching `display_filter`."""
    args = [
        tshark, "-r", str(pcap), "-d", "can.subdissector,canopen",
        "-Y", display_filter, "-T", "fields", "-E", "separator=|",
    ]
    for f in fields:
        args += ["-e", f]
    out = subprocess.run(args, capture_output=True, text=True, timeout=60, check=True)
    return [line.split("|") for line in out.stdout.splitlines() if line]


@pytest.fixture(scope="module")
def recorded_pcap(tmp_path_factory):
    """A run of scenarios/cia301-device.toml driven by python-canopen, recorded to a pcap:
    NMT start, an expedited SDO upload of 0x1018 sub 1, five SYNCs with their TPDOs, an
    EMCY raised through 0x2001 and an aborted SDO upload."""
    pcap = tmp_path_factory.mktemp("tshark") / "run.pcap"
    sim = start_sim(CIA301_SCENARIO, extra=["--pcap", str(pcap)])
    try:
        host, port = sim.socketcand_addr("can0")
        net = canopen.Network()
        net.connect(interface="socketcand", channel="can0", host=host, port=port)
        try:
            node = net.add_node(NODE_ID, canopen.ObjectDictionary())
            node.sdo.RESPONSE_TIMEOUT = 2.0
            node.sdo.upload(0x1018, 1)
            node.nmt.state = "OPERATIONAL"
            time.sleep(0.3)
            for _ in range(5):
                net.sync.transmit()
                time.sleep(0.05)
            node.sdo.download(0x2001, 0, struct.pack("<H", 0x5000))  # raise EMCY 0x5000
            with pytest.raises(canopen.SdoAbortedError):
                node.sdo.upload(0x6000, 0)
            time.sleep(0.05)
        finally:
            net.disconnect()
    finally:
        stop_process(sim.process)
    assert sim.process.returncode == 0, sim.stderr()
    assert pcap.exists() and pcap.stat().st_size > 24, sim.stderr()
    return pcap


def test_tshark_decodes_nmt_start_node(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, ["canopen.nmt_ctrl.cd", "canopen.nmt_ctrl.node_id"],
                  "canopen.nmt_ctrl.cd")
    # Command specifier 0x01 "start remote node" addressed to the device.
    assert (0x01, NODE_ID) in [(int(cd, 0), int(nid, 0)) for cd, nid in rows], rows


def test_tshark_decodes_heartbeat_state(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, ["canopen.node_id", "canopen.nmt_guard.state"],
                  "canopen.nmt_guard.state")
    states = [int(state, 0) for node_id, state in rows if int(node_id, 0) == NODE_ID]
    # Boot-up (0), pre-operational (0x7f) before the start command, operational (0x05)
    # after it, in that order.
    assert states[0] == 0x00, rows
    first_operational = states.index(0x05)
    assert set(states[1:first_operational]) == {0x7F}, rows
    assert set(states[first_operational:]) == {0x05}, rows


def test_tshark_decodes_sdo_upload_of_vendor_id(tshark, recorded_pcap):
    rows = decode(
        tshark, recorded_pcap,
        ["canopen.cob_id", "canopen.sdo.main_idx", "canopen.sdo.sub_idx", "canopen.sdo.data.bytes"],
        "canopen.sdo.main_idx == 0x1018",
    )
    cob_ids = [int(r[0], 16) for r in rows]
    # The request to the server (0x600 + node-ID) and its answer (0x580 + node-ID).
    assert 0x600 + NODE_ID in cob_ids and 0x580 + NODE_ID in cob_ids, rows
    answer = next(r for r in rows if int(r[0], 16) == 0x580 + NODE_ID)
    assert int(answer[2], 16) == 1
    vendor = struct.unpack("<I", bytes.fromhex(answer[3].replace(":", "")))[0]
    assert vendor == 0x00000CA7


def test_tshark_decodes_sync_and_tpdos(tshark, recorded_pcap):
    syncs = decode(tshark, recorded_pcap, ["canopen.cob_id"], "canopen.cob_id == 0x80")
    assert len(syncs) == 5, syncs
    rows = decode(tshark, recorded_pcap, ["canopen.cob_id", "canopen.pdo.data.bytes"],
                  "canopen.pdo.data.bytes")
    tpdo1 = [r[1] for r in rows if int(r[0], 16) == 0x180 + NODE_ID]
    assert len(tpdo1) == 5, rows
    # 0x2100 sub 1 counts SYNCs: the TPDO1 answering SYNC n carries n - 1.
    counts = [struct.unpack_from("<H", bytes.fromhex(d.replace(":", "")))[0] for d in tpdo1]
    assert counts == [0, 1, 2, 3, 4], counts


def test_tshark_decodes_emcy(tshark, recorded_pcap):
    rows = decode(
        tshark, recorded_pcap,
        ["canopen.cob_id", "canopen.em.err_code", "canopen.em.err_reg_ge"],
        "canopen.em.err_code",
    )
    assert [(int(c, 16), int(e, 0)) for c, e, _ in rows] == [(0x80 + NODE_ID, 0x5000)], rows
    assert rows[0][2] in ("1", "True"), rows


def test_tshark_decodes_sdo_abort_code(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, ["canopen.cob_id", "canopen.sdo.abort_code"],
                  "canopen.sdo.abort_code")
    assert [(int(c, 16), int(a, 0)) for c, a in rows] == [(0x580 + NODE_ID, 0x06020000)], rows
