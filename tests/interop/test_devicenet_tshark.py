"""tshark decodes a pcap recorded by `cantwin sim --pcap` with its DeviceNet dissector, while
`cantwin dnet` browses, reads attributes (over the predefined explicit connection and over a
UCMM connection) and polls the ADV200 DeviceNet twin (MAC ID 12).

tshark 4.0 decodes the message group, message ID and MAC ID of every frame, the duplicate
MAC ID check, the UCMM open/close and the group 3 explicit header with its service; it shows
group 2 explicit bodies as raw data and does not reassemble fragments.
"""

import os
import shutil
import subprocess

import pytest

from conftest import SCENARIOS, cantwin_bin, start_sim, stop_process

TSHARK = shutil.which("tshark")
DEVICENET_SCENARIO = SCENARIOS / "adv200-devicenet.toml"
DRIVE = 12
SCANNER = 0


@pytest.fixture
def tshark():
    if TSHARK is None:
        if os.environ.get("CI"):
            pytest.fail("tshark is not installed (required when CI is set)")
        pytest.skip("tshark is not installed")
    return TSHARK


def decode(tshark, pcap, fields, display_filter=None):
    """Rows of `fields` (as strings, "" when absent) for the matching packets."""
    args = [tshark, "-r", str(pcap), "-d", "can.subdissector,devicenet",
            "-T", "fields", "-E", "separator=|"]
    if display_filter:
        args += ["-Y", display_filter]
    for f in fields:
        args += ["-e", f]
    out = subprocess.run(args, capture_output=True, text=True, timeout=60, check=True)
    return [line.split("|") for line in out.stdout.splitlines() if line]


def dnet(host, port, *args):
    out = subprocess.run(
        [cantwin_bin(), "dnet", "--socketcand", f"{host}:{port}", *args],
        capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.fixture(scope="module")
def recorded_pcap(tmp_path_factory):
    """Browse MAC IDs 11–13, Get the Identity product name (8/8 on the predefined set),
    Get PAR 600 through the Parameter object (instance 600: a UCMM connection, 8/16), and
    poll the worked example's 4 bytes out, 6 bytes in (after reading the PDC channel
    parameters that name its words)."""
    pcap = tmp_path_factory.mktemp("dnet") / "run.pcap"
    sim = start_sim(DEVICENET_SCENARIO, extra=["--pcap", str(pcap)])
    try:
        host, port = sim.socketcand_addr("can0")
        out = dnet(host, port, "browse", "--from", "11", "--to", "13")
        assert "ADV200 EXP-CAN/DN-ADV" in out, out
        out = dnet(host, port, "get", str(DRIVE), "1", "1", "7", "--type", "short-string")
        assert out.strip() == '"ADV200 EXP-CAN/DN-ADV"', out
        dnet(host, port, "get", str(DRIVE), "0x0F", "600", "1", "--type", "i32")
        out = dnet(host, port, "poll", str(DRIVE), "--out", "0300E803", "--count", "3",
                   "--period-ms", "20")
        assert out.count("input ") == 3, out
    finally:
        stop_process(sim.process)
    assert sim.process.returncode == 0, sim.stderr()
    assert pcap.exists() and pcap.stat().st_size > 24, sim.stderr()
    return pcap


def expected_group(can_id):
    """(group, message ID, MAC ID) of an 11-bit DeviceNet identifier (Vol. 3 §2)."""
    if can_id < 0x400:
        return 1, can_id >> 6, can_id & 0x3F
    if can_id < 0x600:
        return 2, can_id & 0x07, (can_id >> 3) & 0x3F
    return 3, (can_id >> 6) & 0x07, can_id & 0x3F


def test_tshark_decodes_message_group_and_mac_id_of_every_frame(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, [
        "can.id", "devicenet.grp_msg1.id", "devicenet.grp_msg2.id",
        "devicenet.grp_msg3.id", "devicenet.src_mac_id",
    ])
    assert len(rows) > 40, rows
    for can_id, g1, g2, g3, mac in rows:
        group, msg, want_mac = expected_group(int(can_id, 0))
        decoded = {1: g1, 2: g2, 3: g3}[group]
        assert decoded != "", (can_id, g1, g2, g3)
        assert int(decoded, 0) == msg, (can_id, decoded)
        assert int(mac, 0) == want_mac, (can_id, mac)


def test_tshark_decodes_both_duplicate_mac_id_checks(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, [
        "devicenet.src_mac_id", "devicenet.dup_mac_id.rr", "devicenet.dup_mac_id.vendor",
        "devicenet.dup_mac_id.serial_number",
    ], "devicenet.grp_msg2.id == 7")
    seen = {(int(m, 0), int(rr, 0), int(v, 0), int(s, 0)) for m, rr, v, s in rows}
    # The drive (vendor 0, serial 1 as the scenario sets it) and each scanner run
    # (MAC ID 0, serial 0x00C0FFEE), requests (R/R bit 0).
    assert (DRIVE, 0, 0, 1) in seen, seen
    assert (SCANNER, 0, 0, 0x00C0FFEE) in seen, seen


def test_tshark_decodes_ucmm_open_and_close_with_body_formats(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, [
        "devicenet.grp_msg3.id", "devicenet.src_mac_id", "devicenet.dest_mac_id",
        "devicenet.rr", "devicenet.service",
        "devicenet.open_message.req_body_format",
        "devicenet.open_message.actual_body_format",
    ], "devicenet.grp_msg3.id >= 5")
    decoded = [(int(g, 0), int(s, 0), int(d, 0), int(rr, 0), int(svc, 0),
                req, act) for g, s, d, rr, svc, req, act in rows]
    # Open request: UCMM request message (6) from the scanner to the drive, service 0x4B,
    # body format 8/16 (1) asked; the answer on message 5 from the drive grants 8/16.
    assert (6, SCANNER, DRIVE, 0, 0x4B, "1", "") in decoded, decoded
    assert (5, DRIVE, SCANNER, 1, 0x4B, "", "1") in decoded, decoded
    # Close request and answer, service 0x4C.
    assert (6, SCANNER, DRIVE, 0, 0x4C, "", "") in decoded, decoded
    assert (5, DRIVE, SCANNER, 1, 0x4C, "", "") in decoded, decoded


def test_tshark_decodes_the_group_3_explicit_get_on_the_ucmm_connection(tshark, recorded_pcap):
    rows = decode(tshark, recorded_pcap, [
        "devicenet.grp_msg3.id", "devicenet.src_mac_id", "devicenet.dest_mac_id",
        "devicenet.rr", "devicenet.service", "devicenet.data",
    ], "devicenet.grp_msg3.id <= 4")
    decoded = [(int(g, 0), int(s, 0), int(d, 0), int(rr, 0), int(svc, 0), data)
               for g, s, d, rr, svc, data in rows]
    # Get_Attribute_Single (0x0E) on the connection's message 0: class 0x0F, instance 600
    # (0x0258, 16 bits in the 8/16 body), attribute 1 — tshark leaves the path as data.
    request = (0, SCANNER, DRIVE, 0, 0x0E, "0f580201")
    assert request in decoded, decoded
    # The drive's answer (a DWORD) comes from the drive's message ID 0, next after the
    # request (`dnet poll` reads the PDC channel parameters on such connections too).
    after = decoded[decoded.index(request) + 1:]
    answer = next((r for r in after if r[:5] == (0, DRIVE, SCANNER, 1, 0x0E)), None)
    assert answer is not None and len(answer[5]) == 8, decoded


def test_tshark_decodes_the_poll_exchange(tshark, recorded_pcap):
    commands = decode(tshark, recorded_pcap, ["devicenet.src_mac_id", "devicenet.data"],
                      "devicenet.grp_msg2.id == 5")
    responses = decode(tshark, recorded_pcap, ["devicenet.src_mac_id", "devicenet.data"],
                       "devicenet.grp_msg1.id == 15")
    # Poll command: group 2 message 5 to the drive with the worked example's 4 bytes.
    assert len(commands) >= 3, commands
    assert all(c == [str(DRIVE), "0300e803"] for c in commands), commands
    # Poll response: group 1 message 15 from the drive, 6 bytes ending with analog input 2
    # (2.5 V = 4096 counts, little-endian 00 10).
    assert len(responses) >= 3, responses
    assert all(m == str(DRIVE) and len(d) == 12 and d.endswith("0010")
               for m, d in responses), responses
