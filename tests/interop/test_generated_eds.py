"""Every twin's EDS, generated from its object dictionary by `cantwin eds export`, loads in
python-canopen (`canopen.import_od`); python-canopen then reads every object of the device
with it, and `node.tpdo.read()` returns the device's real TPDO mapping."""

import struct

import canopen
import pytest

from conftest import SCENARIOS, export_eds as export, start_sim, stop_process

# (scenario, device, node-ID, bus)
TWINS = [
    ("cia301-device.toml", "node5", 5, "can0"),
    ("tm3-island.toml", "island", 3, "can0"),
]


@pytest.fixture(params=TWINS, ids=[t[1] for t in TWINS])
def twin(request, tmp_path):
    scenario, device, node_id, bus = request.param
    eds = export(tmp_path, scenario, device)
    sim = start_sim(SCENARIOS / scenario)
    net = canopen.Network()
    try:
        host, port = sim.socketcand_addr(bus)
        net.connect(interface="socketcand", channel=bus, host=host, port=port)
        node = net.add_node(node_id, canopen.import_od(str(eds), node_id))
        yield node
    finally:
        net.disconnect()
        stop_process(sim.process)


def readable_variables(od):
    for obj in od.values():
        variables = [obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else list(obj.values())
        for var in variables:
            if "r" in var.access_type:
                yield var


def test_generated_eds_loads_and_every_object_reads(twin):
    count = 0
    for var in readable_variables(twin.object_dictionary):
        # The pre-defined error field holds as many entries as errors occurred: one beyond
        # them has no data (CiA 301 §7.5.2.4, abort 0x08000024).
        if var.index == 0x1003 and var.subindex > twin.sdo.upload(0x1003, 0)[0]:
            with pytest.raises(canopen.SdoAbortedError) as aborted:
                twin.sdo.upload(var.index, var.subindex)
            assert aborted.value.code == 0x08000024
            count += 1
            continue
        # Large DOMAINs read with block transfer; everything else as python-canopen chooses.
        if var.data_type == canopen.objectdictionary.DOMAIN:
            with twin.sdo.open(var.index, var.subindex, "rb", block_transfer=True) as f:
                data = f.read()
        else:
            data = twin.sdo.upload(var.index, var.subindex)
            # python-canopen decodes the raw bytes with the EDS's type: the sizes must agree.
            var.decode_raw(data)
        assert data is not None, f"{var.index:#06x}sub{var.subindex}"
        count += 1
    assert count > 30


def test_tpdo_read_returns_the_device_mapping(twin):
    twin.tpdo.read(from_od=False)
    checked = 0
    for n, pdo in twin.tpdo.map.items():
        if n > 4:
            break
        raw = twin.sdo.upload(0x1A00 + n - 1, 0)
        entries = raw[0]
        expected = []
        for sub in range(1, entries + 1):
            (value,) = struct.unpack("<I", twin.sdo.upload(0x1A00 + n - 1, sub))
            expected.append((value >> 16, (value >> 8) & 0xFF))
        got = [(v.index, v.subindex) for v in pdo.map]
        assert got == expected, f"TPDO{n}"
        checked += 1
    assert checked >= 1
