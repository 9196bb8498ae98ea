"""The compiled path on python-can buses that are not SocketCAN (slcan, PCAN, Kvaser, Vector; python-can's virtual bus
here): while a link's writer is idle, its outlet sends by the bus's own send(unit, 0.0) (outlet.c write_pythoncan,
the twin of CanTransport.write_nowait). Held equal to the pure path on real virtual buses, frame for frame and count
for count; a bus that refuses a frame hands it, and the rest, to the writer, which counts what it cannot send."""

from __future__ import annotations

import itertools
import time
from types import ModuleType
from typing import Any

import can
import pytest
from can.interfaces.virtual import VirtualBus

from vstig_hw import Message, Op
from vstig_hw.gateway import Node
from vstig_hw.links.can import can_link
from vstig_hw.wire import encode

_channels = itertools.count()
_KEYS = 40


def _channel() -> str:
    return f"vstig-native-pythoncan-{next(_channels)}-{time.monotonic_ns()}"


def _put(key: int) -> can.Message:
    return can.Message(arbitration_id=0x605, is_extended_id=False, data=encode(Message(Op.PUT, key, key, 1, 5)))


def _relay(pure: bool, *, far_holds: int = 0) -> tuple[list[bytes], list[Any], dict[str, int], dict[str, int], bool]:
    """PUTs of distinct keys onto bus a, through an engine Node on a and b, to a reader on b whose queue holds
    `far_holds` frames (0: any number) and is read only at the end: (what b's reader got, the units b's writer
    was handed, b's link counters, b's transport counters, whether the Node took the compiled path)."""
    a, b = _channel(), _channel()
    sender = can.Bus(interface="virtual", channel=a)
    far = can.Bus(interface="virtual", channel=b, rx_queue_size=far_holds)
    node = Node([can_link("virtual", a, robot_id=200), can_link("virtual", b, robot_id=200)], 200, budget=None,
                pure=pure)
    handed: list[Any] = []
    try:
        node.open()
        node.outlets[1].writer.tap(handed.append)
        for key in range(_KEYS):
            sender.send(_put(key))
        link = node.links[1]
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and \
                link.counters["out"] + link.transport.counters["tx_dropped"] < _KEYS:
            time.sleep(0.01)
        got = [bytes(frame.data) for frame in iter(lambda: far.recv(0), None)]
        return got, handed, dict(link.counters), dict(link.transport.counters), node.compiled
    finally:
        node.close(drain=0.0)
        sender.shutdown()
        far.shutdown()


def test_the_outlets_send_by_the_bus_itself_and_count_as_the_pure_path(compiled: ModuleType) -> None:
    got_c, handed_c, link_c, bus_c, was_compiled = _relay(pure=False)
    got_p, handed_p, link_p, bus_p, was_pure_compiled = _relay(pure=True)
    assert was_compiled and not was_pure_compiled
    assert sorted(got_c) == sorted(got_p) and len(got_c) == _KEYS  # every PUT crossed, the same frames
    assert handed_c == []  # the C sent each one itself: nothing went through the writer's Python
    assert len(handed_p) == _KEYS  # the pure outlet hands each to the writer, whose write_nowait sends it
    assert (link_c["out"], bus_c["tx"]) == (link_p["out"], bus_p["tx"]) == (_KEYS, _KEYS)


def test_a_bus_that_refuses_a_frame_hands_it_and_the_rest_to_the_writer_as_the_pure_path(compiled: ModuleType) -> None:
    # the far reader holds one frame: python-can's virtual send raises for the next (CanOperationError), which
    # CanTransport takes for a lost bus: the frame, and every one while the bus is reopened, counted (tx_dropped)
    got_c, handed_c, link_c, bus_c, _ = _relay(pure=False, far_holds=1)
    got_p, handed_p, link_p, bus_p, _ = _relay(pure=True, far_holds=1)
    assert len(got_c) == len(got_p) == 1
    assert (link_c, bus_c) == (link_p, bus_p)
    assert bus_c["tx"] + bus_c["tx_dropped"] == _KEYS and bus_c["lost"] == 1
    assert (len(handed_c), len(handed_p)) == (_KEYS - 1, _KEYS)  # the C sent the first; the writer had the rest


def _stats_after(pure: bool, frames: list[can.Message], until: str) -> tuple[dict[str, int], dict[str, int]]:
    """`frames` onto bus a of an engine Node on a and b, until a's transport counts `until`: (a's link counters, a's
    transport counters)."""
    a, b = _channel(), _channel()
    sender = can.Bus(interface="virtual", channel=a)
    node = Node([can_link("virtual", a, robot_id=200, kernel_filter=False), can_link("virtual", b, robot_id=200)],
                200, budget=None, pure=pure)  # no filter: the error frame reaches the link
    try:
        node.open()
        for frame in frames:
            sender.send(frame)
        transport: Any = node.links[0].transport
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not transport.counters[until]:
            time.sleep(0.01)
        time.sleep(0.1)  # what else the read took is counted too
        return dict(node.links[0].counters), dict(transport.counters)
    finally:
        node.close(drain=0.0)
        sender.shutdown()


def test_the_delivery_reads_the_bus_as_the_transport_does_error_frames_too(compiled: ModuleType) -> None:
    frames = [_put(1), can.Message(arbitration_id=0x20000004, is_error_frame=True, data=bytes(8)), _put(2)]
    link, bus = _stats_after(pure=False, frames=frames, until="bus_errors")
    assert (link, bus) == _stats_after(pure=True, frames=frames, until="bus_errors")
    assert bus["bus_errors"] == 1 and bus["rx"] == 3 and link["in"] == 2


class _BusOff(VirtualBus):
    """A virtual bus that says it is off the bus, as a PCAN or Kvaser adapter's `state` does."""

    @property
    def state(self) -> can.BusState:
        return can.BusState.ERROR


@pytest.mark.parametrize("pure", [False, True])
def test_a_bus_that_says_it_is_off_is_lost_while_the_delivery_reads_it(compiled: ModuleType, pure: bool) -> None:
    # the delivery reading in C hands the transport's own read a turn every second: its look at the bus's state
    a = _channel()
    node = Node([can_link("virtual", a, robot_id=200), can_link("virtual", _channel(), robot_id=200)], 200,
                budget=None, pure=pure)
    try:
        node.open()
        time.sleep(0.3)  # the read's first look at the state was taken: the next is a turn the delivery hands over
        transport: Any = node.links[0].transport
        transport.bus.__class__ = _BusOff
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not transport.counters["bus_off"]:
            time.sleep(0.01)
        assert transport.counters["bus_off"] >= 1 and transport.counters["lost"] >= 1
    finally:
        node.close(drain=0.0)


_ID_SLOT = can.Message.__dict__["arbitration_id"]  # can.Message's own slot (its member descriptor)


class _Renamed(can.Message):
    """A frame whose class answers `arbitration_id` itself (a property over can.Message's slot): read by its name,
    it is the frame it says it is; at can.Message's slot offset, the ID stored there."""

    __slots__ = ()

    @property
    def arbitration_id(self) -> int:
        return 0x605

    @arbitration_id.setter
    def arbitration_id(self, value: int) -> None:
        _ID_SLOT.__set__(self, 0x7FF)  # the slot holds an ID no vstig frame has


def test_frames_are_read_by_their_class_own_attributes_after_can_messages(compiled: ModuleType) -> None:
    # the C reads a can.Message's fields at its slots' offsets (resolved on the first class met): a frame of
    # another class, met after, is read by name, as the Python framing reads it
    receiver = compiled.Receiver("can", {})
    assert receiver.feed(_put(3)) == [Message(Op.PUT, 3, 3, 1, 5)]
    renamed = _Renamed(arbitration_id=0, is_extended_id=False, data=_put(4).data)
    assert _ID_SLOT.__get__(renamed) == 0x7FF
    assert receiver.feed(renamed) == [Message(Op.PUT, 4, 4, 1, 5)]
