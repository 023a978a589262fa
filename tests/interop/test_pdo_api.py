"""python-canopen's ordinary PDO API on every CANopen twin, with the EDS the twin exports.

A twin's EDS is generated from the same description as its object dictionary and PDO
mappings, so what python-canopen derives from the file must agree with the frames:

* every mapped TPDO entry decodes with `map[i].raw` (the EDS's data type has the size the
  mapping gives it), and `{v.name: v.raw for v in node.tpdo[n].map}` works;
* `map[i].raw = …` followed by `transmit()` sends an RPDO of exactly the mapped length, which
  the twin takes without an EMCY (no 0x8210/0x8220 length error);
* a write of a value outside the limits the EDS states aborts with 0x06090031 (too high) or
  0x06090032 (too low), or 0x06090030 (range exceeded) (CiA 301 §7.2.4.3.17).

The ADV200 also runs the manual's worked example (§1.6) through that API: RPDO1 enable +
start at 1500 rpm, then TPDO1's speed word reads 1500.
"""

import queue
import time

import can
import canopen
import pytest

from conftest import SCENARIOS, export_eds as export, start_sim, stop_process

# (scenario, device, node-ID)
TWINS = [
    ("cia301-device.toml", "node5", 5),
    ("eds-device.toml", "io6", 6),
    ("tm3-island.toml", "island", 3),
    ("adv200-example.toml", "drive", 12),
    ("adv200-ds402.toml", "drive", 2),
]

RANGE_ABORTS = {0x06090030, 0x06090031, 0x06090032}
SIGNED = {canopen.objectdictionary.INTEGER8, canopen.objectdictionary.INTEGER16, canopen.objectdictionary.INTEGER32}
UNSIGNED = {canopen.objectdictionary.UNSIGNED8, canopen.objectdictionary.UNSIGNED16, canopen.objectdictionary.UNSIGNED32}
BITS = {
    canopen.objectdictionary.INTEGER8: 8,
    canopen.objectdictionary.INTEGER16: 16,
    canopen.objectdictionary.INTEGER32: 32,
    canopen.objectdictionary.UNSIGNED8: 8,
    canopen.objectdictionary.UNSIGNED16: 16,
    canopen.objectdictionary.UNSIGNED32: 32,
}


class Twin:
    def __init__(self, net, node, sim, listener):
        self.net = net
        self.node = node
        self.sim = sim
        self.listener = listener

    def frames(self, seconds):
        """The frames the second client saw within `seconds`."""
        seen = []
        deadline = time.monotonic() + seconds
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return seen
            msg = self.listener.recv(timeout=left)
            if msg is not None:
                seen.append(msg)


@pytest.fixture(params=TWINS, ids=[f"{t[0].removesuffix('.toml')}-{t[1]}" for t in TWINS])
def twin(request, tmp_path):
    scenario, device, node_id = request.param
    eds = export(tmp_path, scenario, device)
    sim = start_sim(SCENARIOS / scenario)
    net = canopen.Network()
    listener = None
    try:
        host, port = sim.socketcand_addr("can0")
        net.connect(interface="socketcand", channel="can0", host=host, port=port)
        listener = can.Bus(interface="socketcand", channel="can0", host=host, port=port)
        node = net.add_node(node_id, canopen.import_od(str(eds), node_id))
        node.sdo.RESPONSE_TIMEOUT = 2.0
        yield Twin(net, node, sim, listener)
    finally:
        if listener is not None:
            listener.shutdown()
        net.disconnect()
        stop_process(sim.process)


def enabled(pdo):
    return pdo.enabled and pdo.cob_id is not None and pdo.map


def mapped_bytes(node, mapping_index):
    """The PDO length the device's mapping object gives, from SDO (not from the EDS)."""
    count = node.sdo.upload(mapping_index, 0)[0]
    bits = 0
    for sub in range(1, count + 1):
        entry = int.from_bytes(node.sdo.upload(mapping_index, sub), "little")
        bits += entry & 0xFF
    return bits // 8


def test_every_mapped_tpdo_entry_reads_with_map_raw(twin):
    node = twin.node
    node.tpdo.read(from_od=False)
    node.nmt.state = "OPERATIONAL"
    time.sleep(0.1)
    tpdos = [(n, p) for n, p in node.tpdo.map.items() if n <= 512 and enabled(p)]
    assert tpdos, "the twin has no enabled TPDO"
    # Synchronous TPDOs answer SYNC; event-driven ones come by themselves or by timer.
    twin.net.sync.start(0.01)
    try:
        for n, pdo in tpdos:
            if pdo.wait_for_reception(timeout=2.0) is None:
                continue
            values = {v.name: v.raw for v in pdo.map}
            assert len(values) == len(pdo.map)
            expected = mapped_bytes(node, 0x1A00 + n - 1)
            assert len(pdo.data) == expected, f"TPDO{n}: {len(pdo.data)} bytes, mapping says {expected}"
            for var in pdo.map:
                assert var.length == BITS.get(var.od.data_type, var.length), (
                    f"TPDO{n} {var.name}: mapped {var.length} bits of a {var.od.data_type:#x}"
                )
    finally:
        twin.net.sync.stop()


def test_every_rpdo_transmits_its_mapped_length(twin):
    node = twin.node
    emcy_id = 0x80 + node.id
    node.rpdo.read(from_od=False)
    node.nmt.state = "OPERATIONAL"
    time.sleep(0.1)
    rpdos = [(n, p) for n, p in node.rpdo.map.items() if n <= 512 and enabled(p)]
    assert rpdos, "the twin has no enabled RPDO"
    twin.frames(0.2)  # drain what the start produced
    for n, pdo in rpdos:
        for var in pdo.map:
            if var.od.data_type in UNSIGNED | SIGNED:
                low = var.od.min if var.od.min is not None else 0
                var.raw = max(low, 0) if var.od.max is None else min(max(low, 0), var.od.max)
        pdo.transmit()
        expected = mapped_bytes(node, 0x1600 + n - 1)
        seen = twin.frames(0.3)
        sent = [m for m in seen if m.arbitration_id == pdo.cob_id]
        assert sent, f"RPDO{n} was not seen on the bus"
        assert len(sent[0].data) == expected, f"RPDO{n}: {len(sent[0].data)} bytes, mapping says {expected}"
        length_errors = [
            m for m in seen if m.arbitration_id == emcy_id and len(m.data) >= 2 and m.data[1] == 0x82
        ]
        assert not length_errors, f"RPDO{n} raised a PDO length EMCY: {length_errors}"


def limited_variables(od):
    for obj in od.values():
        variables = [obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else list(obj.values())
        for var in variables:
            if var.index < 0x2000 or "w" not in var.access_type:
                continue
            if var.data_type not in BITS or (var.max is None and var.min is None):
                continue
            yield var


def test_out_of_range_writes_abort_with_the_eds_limits(twin):
    node = twin.node
    probed = 0
    for var in limited_variables(node.object_dictionary):
        bits = BITS[var.data_type]
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if var.data_type in SIGNED else (0, (1 << bits) - 1)
        for value in (
            var.max + 1 if var.max is not None and var.max < hi else None,
            var.min - 1 if var.min is not None and var.min > lo else None,
        ):
            if value is None:
                continue
            data = value.to_bytes(bits // 8, "little", signed=var.data_type in SIGNED)
            with pytest.raises(canopen.SdoAbortedError) as aborted:
                node.sdo.download(var.index, var.subindex, data)
            assert aborted.value.code in RANGE_ABORTS, (
                f"{var.index:#06x}sub{var.subindex} = {value}: abort {aborted.value.code:#010x}"
            )
            probed += 1
        if probed >= 12:
            break
    if probed == 0:
        pytest.skip("the EDS states no limits inside the type's range")


def test_adv200_worked_example_through_the_pdo_api(tmp_path):
    """§1.6: RPDO1 = control word (enable + start) and Ramp ref 1 = 1500 rpm; TPDO1's second
    word is the actual speed, 1500 rpm once the ramp is done."""
    eds = export(tmp_path, "adv200-example.toml", "drive")
    sim = start_sim(SCENARIOS / "adv200-example.toml")
    net = canopen.Network()
    try:
        host, port = sim.socketcand_addr("can0")
        net.connect(interface="socketcand", channel="can0", host=host, port=port)
        node = net.add_node(12, canopen.import_od(str(eds), 12))
        node.sdo.RESPONSE_TIMEOUT = 2.0
        node.tpdo.read(from_od=False)
        node.rpdo.read(from_od=False)
        node.nmt.state = "OPERATIONAL"
        rpdo = node.rpdo[1]
        rpdo.map[0].raw = 0x0003
        rpdo.map[1].raw = 1500
        net.sync.start(0.01)
        rpdo.start(0.01)
        speeds = queue.Queue()
        node.tpdo[1].add_callback(lambda pdo: speeds.put({v.name: v.raw for v in pdo.map}))
        deadline = time.monotonic() + 20.0
        last = None
        while time.monotonic() < deadline:
            try:
                last = speeds.get(timeout=1.0)
            except queue.Empty:
                continue
            if list(last.values())[1] == 1500:
                break
        assert last is not None, "no TPDO1"
        assert list(last.values())[1] == 1500, f"TPDO1 read {last}"
        rpdo.stop()
        net.sync.stop()
    finally:
        net.disconnect()
        stop_process(sim.process)
