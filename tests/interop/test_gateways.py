"""python-can's `socketcand` and `slcan` interfaces against cantwin's gateways."""

import time

import can
import pytest

# Bounded waits: a frame on a 500 kbit/s bus arrives within milliseconds; allow for a slow
# machine without ever hanging.
RECV_TIMEOUT = 5.0


def socketcand_bus(sim, bus="can0"):
    host, port = sim.socketcand_addr(bus)
    return can.Bus(interface="socketcand", channel=bus, host=host, port=port)


def slcan_bus(sim, bus="can0"):
    return can.Bus(
        interface="slcan",
        channel=sim.slcan_url(bus),
        bitrate=500000,
        sleep_after_open=0,
    )


def recv_matching(bus, predicate, timeout=RECV_TIMEOUT):
    """The first received message for which `predicate` holds, or None after `timeout`."""
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        msg = bus.recv(timeout=left)
        if msg is not None and predicate(msg):
            return msg


def recv_id(bus, arbitration_id, extended=False, timeout=RECV_TIMEOUT):
    return recv_matching(
        bus,
        lambda m: m.arbitration_id == arbitration_id
        and m.is_extended_id == extended
        and not m.is_error_frame,
        timeout,
    )


# --- socketcand ---------------------------------------------------------------------------


def test_socketcand_receives_generator_counter_frames(generators_sim):
    with socketcand_bus(generators_sim) as bus:
        first = recv_id(bus, 0x123)
        assert first is not None, "no frame 0x123 from the counter generator"
        second = recv_id(bus, 0x123)
        assert second is not None
        assert first.dlc == 8 and second.dlc == 8
        a = int.from_bytes(first.data, "little")
        b = int.from_bytes(second.data, "little")
        # The generator counts its frames; consecutive frames differ by one.
        assert b == a + 1


def test_socketcand_receives_extended_id(generators_sim):
    with socketcand_bus(generators_sim) as bus:
        msg = recv_id(bus, 0x1ABCDE0, extended=True)
        assert msg is not None, "no extended frame 0x1ABCDE0"
        assert msg.is_extended_id
        assert bytes(msg.data) == bytes.fromhex("DEADBEEF")


def test_socketcand_receives_zero_length_frame(generators_sim):
    # A zero-length frame (as a CANopen SYNC) must not kill python-can's parser.
    with socketcand_bus(generators_sim) as bus:
        first = recv_id(bus, 0x080)
        assert first is not None, "no zero-length frame 0x080"
        assert first.dlc == 0 and bytes(first.data) == b""
        # The bus is still alive afterwards.
        assert recv_id(bus, 0x080) is not None
        assert recv_id(bus, 0x123) is not None


def test_socketcand_frame_sent_is_seen_by_another_client(quiet_sim):
    with socketcand_bus(quiet_sim) as tx, socketcand_bus(quiet_sim) as rx:
        time.sleep(0.2)  # both clients attached before the frame goes out
        tx.send(can.Message(arbitration_id=0x321, data=[1, 2, 3], is_extended_id=False))
        msg = recv_id(rx, 0x321)
        assert msg is not None
        assert bytes(msg.data) == b"\x01\x02\x03"


def test_socketcand_zero_length_and_extended_frames_sent(quiet_sim):
    with socketcand_bus(quiet_sim) as tx, socketcand_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(can.Message(arbitration_id=0x0AA, data=[], is_extended_id=False))
        tx.send(can.Message(arbitration_id=0x18FF50E5, data=[0xF1], is_extended_id=True))
        empty = recv_id(rx, 0x0AA)
        assert empty is not None and empty.dlc == 0
        ext = recv_id(rx, 0x18FF50E5, extended=True)
        assert ext is not None and bytes(ext.data) == b"\xf1"


def test_socketcand_does_not_echo_own_frames(quiet_sim):
    with socketcand_bus(quiet_sim) as tx, socketcand_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(can.Message(arbitration_id=0x322, data=[9], is_extended_id=False))
        assert recv_id(rx, 0x322) is not None
        assert recv_id(tx, 0x322, timeout=0.5) is None


# --- slcan over TCP -----------------------------------------------------------------------


def test_slcan_receives_generator_frames(generators_sim):
    with slcan_bus(generators_sim) as bus:
        std = recv_id(bus, 0x123)
        assert std is not None and std.dlc == 8
        ext = recv_id(bus, 0x1ABCDE0, extended=True)
        assert ext is not None and bytes(ext.data) == bytes.fromhex("DEADBEEF")
        empty = recv_id(bus, 0x080)
        assert empty is not None and empty.dlc == 0


def test_slcan_data_frame_reaches_socketcand_client(quiet_sim):
    with slcan_bus(quiet_sim) as tx, socketcand_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(
            can.Message(arbitration_id=0x601, data=[0x40, 0x00, 0x10, 0x00], is_extended_id=False)
        )
        msg = recv_id(rx, 0x601)
        assert msg is not None
        assert bytes(msg.data) == bytes([0x40, 0x00, 0x10, 0x00])


def test_slcan_receives_socketcand_client_frames(quiet_sim):
    with slcan_bus(quiet_sim) as rx, socketcand_bus(quiet_sim) as tx:
        time.sleep(0.2)
        sdo_response = [0x43, 0x00, 0x10, 0x00, 1, 2, 3, 4]
        tx.send(can.Message(arbitration_id=0x585, data=sdo_response, is_extended_id=False))
        tx.send(
            can.Message(arbitration_id=0x1FFFFFFF, data=[0xAB] * 8, is_extended_id=True)
        )
        msg = recv_id(rx, 0x585)
        assert msg is not None and bytes(msg.data) == bytes([0x43, 0, 0x10, 0, 1, 2, 3, 4])
        ext = recv_id(rx, 0x1FFFFFFF, extended=True)
        assert ext is not None and bytes(ext.data) == b"\xab" * 8


def test_slcan_remote_frame_reaches_another_slcan_client(quiet_sim):
    with slcan_bus(quiet_sim) as tx, slcan_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(
            can.Message(arbitration_id=0x705, is_remote_frame=True, dlc=1, is_extended_id=False)
        )
        msg = recv_matching(rx, lambda m: m.arbitration_id == 0x705)
        assert msg is not None
        assert msg.is_remote_frame and not msg.is_extended_id
        assert msg.dlc == 1


def test_slcan_extended_remote_frame_round_trip(quiet_sim):
    with slcan_bus(quiet_sim) as tx, slcan_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(
            can.Message(
                arbitration_id=0x0ABCDEF, is_extended_id=True, is_remote_frame=True, dlc=8
            )
        )
        msg = recv_matching(rx, lambda m: m.arbitration_id == 0x0ABCDEF)
        assert msg is not None
        assert msg.is_remote_frame and msg.is_extended_id and msg.dlc == 8


def test_socketcand_remote_frame_reaches_slcan_client(quiet_sim):
    # python-can writes a remote frame as `< send 705 1  >` (DLC without bytes); the server
    # reads that as a remote frame of that DLC.
    with socketcand_bus(quiet_sim) as tx, slcan_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(
            can.Message(arbitration_id=0x705, is_remote_frame=True, dlc=1, is_extended_id=False)
        )
        msg = recv_matching(rx, lambda m: m.arbitration_id == 0x705)
        assert msg is not None
        assert msg.is_remote_frame and not msg.is_extended_id and msg.dlc == 1


def test_slcan_remote_frame_not_forwarded_to_socketcand_client(quiet_sim):
    # socketcand's raw mode does not forward remote frames; the data frame after it arrives.
    with slcan_bus(quiet_sim) as tx, socketcand_bus(quiet_sim) as rx:
        time.sleep(0.2)
        tx.send(
            can.Message(arbitration_id=0x706, is_remote_frame=True, dlc=1, is_extended_id=False)
        )
        tx.send(can.Message(arbitration_id=0x707, data=[5], is_extended_id=False))
        msg = recv_matching(rx, lambda m: m.arbitration_id in (0x706, 0x707))
        assert msg is not None
        assert msg.arbitration_id == 0x707 and bytes(msg.data) == b"\x05"
