"""Engines talk through our CAN links on python-can's in-process `virtual` bus."""

from __future__ import annotations

import itertools
import time

import can
import pytest

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.links import Heard, Link, parse
from vstig_hw.links.can import can_link
from vstig_hw.transports.base import TransportError

_channels = itertools.count()


def _fresh_channel() -> str:
    return f"vstig-test-{next(_channels)}-{time.monotonic_ns()}"


def _step(nodes: list[tuple[Stigmergy, Link[can.Message]]], budget: int) -> None:
    for engine, link in nodes:
        link.send_many(engine.drain(budget))
    for engine, link in nodes:
        for heard in link.receive(0.01):
            engine.receive(heard.message)


@pytest.mark.parametrize(("fd", "extended"), [(False, False), (True, False), (False, True), (True, True)])
def test_five_engines_agree_on_the_highest_id_over_virtual_can(fd: bool, extended: bool) -> None:
    channel = _fresh_channel()
    nodes = []
    for robot in (3, 9, 27, 81, 243):
        link = can_link("virtual", channel, robot_id=robot, fd=fd, extended=extended)
        link.open()
        engine = Stigmergy(robot, onconflict=larger_value_wins)
        engine.put(1, robot)
        nodes.append((engine, link))
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            _step(nodes, budget=4)
            values = [engine.get(1) for engine, _ in nodes]
            if values == [243] * 5:
                break
        assert values == [243] * 5
        stats = [link.stats() for _, link in nodes]
        assert all(s["in"] > 0 and s["out"] > 0 and s["tx_dropped"] == 0 for s in stats)
        assert not any(key.startswith("drop_") for s in stats for key in s)
    finally:
        for _, link in nodes:
            link.close()


def _hear_a_foreign_frame_then_ours(spec: str) -> tuple[list[Heard], dict[str, int]]:
    """A stranger sends 0x123 (no scheme's ID) then a GET from node 0x2A; what a link built from `spec` heard."""
    channel = _fresh_channel()
    ours = parse(spec.format(channel=channel)).build(robot_id=1)
    stranger = can.Bus(interface="virtual", channel=channel)
    ours.open()
    try:
        stranger.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=bytes(8)))  # not our scheme
        stranger.send(can.Message(arbitration_id=0x72A, is_extended_id=False, data=bytes.fromhex("8001000200030004")))
        heard: list[Heard] = []
        deadline = time.monotonic() + 10
        while not heard and time.monotonic() < deadline:
            heard = ours.receive(0.05)
        return heard, dict(ours.stats())
    finally:
        ours.close()
        stranger.shutdown()


def test_heard_names_the_sender_and_foreign_frames_are_filtered_out() -> None:
    heard, stats = _hear_a_foreign_frame_then_ours("can:virtual:{channel}")
    assert [(h.message, h.sender) for h in heard] == [(Message(Op.GET, 1, 2, 3, 4), 0x2A)]
    assert stats["rx"] == 1 and "drop_unknown_id" not in stats  # the can_filters kept 0x123 away from us


def test_unknown_interface_is_one_clear_line() -> None:
    link = can_link("no-such-interface", "can0", robot_id=1)
    with pytest.raises(TransportError) as caught:
        link.open()
    assert "no-such-interface" in str(caught.value) and "\n" not in str(caught.value)


def test_a_bus_that_dies_underneath_is_reopened_and_traffic_resumes() -> None:
    channel = _fresh_channel()
    ours = can_link("virtual", channel, robot_id=1)
    peer = can.Bus(interface="virtual", channel=channel)
    ours.open()
    try:
        bus = ours.transport.bus  # type: ignore[attr-defined]
        bus.shutdown()  # the adapter vanishes: python-can now raises on every call
        ours.send(Message(Op.PUT, 1, 1, 1, 1))  # dropped and counted, not raised
        got: list[Message] = []
        deadline = time.monotonic() + 20
        while not got and time.monotonic() < deadline:
            peer.send(can.Message(arbitration_id=0x602, is_extended_id=False, data=bytes.fromhex("0001000500010002")))
            got = [h.message for h in ours.receive(0.05)]
        assert got and got[0] == Message(Op.PUT, 1, 5, 1, 2)
        counters = ours.transport.counters
        assert counters["lost"] == 1 and counters["reconnects"] == 1 and counters["tx_dropped"] == 1
        assert ours.transport.connected
    finally:
        ours.close()
        peer.shutdown()


@pytest.mark.parametrize(
    ("first", "second"),
    [("extended=1&stigmergy=1", "extended=1&stigmergy=2"),  # 29-bit: the ID's stigmergy field
     ("id_base=0x200", "id_base=0x400")],                    # 11-bit: one base per stigmergy
)
def test_two_stigmergies_share_one_bus_without_crosstalk(first: str, second: str) -> None:
    """Links built from specs: each hears only its own stigmergy, and counts the other's frames."""
    channel = _fresh_channel()
    links = [parse(f"can:virtual:{channel}?{query}").build(robot_id=robot)
             for query, robot in ((first, 5), (second, 6), (first, 7), (second, 8))]
    for link in links:
        link.open()
    try:
        a1, b1, a2, b2 = links
        a1.send(Message(Op.PUT, 1, 100, 1, 5))
        b1.send(Message(Op.PUT, 1, 200, 1, 6))
        heard: dict[int, list[Message]] = {7: [], 8: []}
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not (heard[7] and heard[8]):
            heard[7] += [h.message for h in a2.receive(0.01)]
            heard[8] += [h.message for h in b2.receive(0.01)]
        time.sleep(0.05)  # anything crossing over would have arrived by now
        heard[7] += [h.message for h in a2.receive(0.01)]
        heard[8] += [h.message for h in b2.receive(0.01)]
        assert [m.value for m in heard[7]] == [100]
        assert [m.value for m in heard[8]] == [200]
    finally:
        for link in links:
            link.close()


def test_filter_off_lets_foreign_ids_in_and_counts_them() -> None:
    """filter=0: the acceptance filter is off, so a foreign ID reaches the framing as drop_unknown_id."""
    heard, stats = _hear_a_foreign_frame_then_ours("can:virtual:{channel}?filter=0")
    assert [h.message for h in heard] == [Message(Op.GET, 1, 2, 3, 4)]
    assert stats["rx"] == 2 and stats["drop_unknown_id"] == 1


def test_a_frame_that_just_arrived_ends_the_read_and_a_backlog_is_read_whole() -> None:
    """A read asks the bus again only after a frame that waited (its timestamp is older than a millisecond): a
    python-can recv(0) that finds nothing costs as much as a frame. Every frame is read either way."""
    channel = _fresh_channel()
    ours = can_link("virtual", channel, robot_id=1)
    peer = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)  # the frames' own stamps
    ours.open()

    def send(stamp: float, count: int) -> None:
        for key in range(count):
            peer.send(can.Message(timestamp=stamp, arbitration_id=0x602, is_extended_id=False,
                                  data=bytes([0, key, 0, 5, 0, 1, 0, 2])))

    try:
        send(time.time() + 3600, 3)  # "just arrived", as far as the reader can tell: one frame per read
        assert [len(ours.read(1.0)) for _ in range(3)] == [1, 1, 1]
        send(time.time() - 1.0, 3)  # waited a second: the read takes the queue whole
        assert len(ours.read(1.0)) == 3
        assert ours.transport.counters["rx"] == 6
    finally:
        ours.close()
        peer.shutdown()
