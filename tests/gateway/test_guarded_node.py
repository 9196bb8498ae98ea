"""A Node with a guard on real python-can virtual buses: refusals counted on the link, read-only links confined."""

from __future__ import annotations

import contextlib
import itertools
import time
from collections.abc import Iterator

import can
import pytest
from test_node import BusRobot, bus_link, run_until

from vstig_hw import Message, Op, encode
from vstig_hw.gateway import Mode, Node
from vstig_hw.gateway.guard import Guard, IdSet, LinkPolicy
from vstig_hw.links import Heard

_ids = itertools.count()


@pytest.fixture
def channels() -> tuple[str, str]:
    n = next(_ids)
    return f"guard-a-{n}", f"guard-b-{n}"


def inject(bus: can.BusABC, msg: Message, sender: int) -> None:
    """A frame as robot `sender` would send it (the default 11-bit scheme: 0x600 | op << 8 | sender)."""
    bus.send(can.Message(arbitration_id=0x600 | int(msg.op) << 8 | sender, data=encode(msg), is_extended_id=False))


@contextlib.contextmanager
def jump_attack(a: str, b: str, guard: Guard | None) -> Iterator[tuple[Node, BusRobot, BusRobot]]:
    """Key 3 written on bus a and learnt on bus b, then an attacker on bus a forges it 30,000 ahead."""
    left, right = BusRobot(5, a), BusRobot(9, b)
    attacker = can.Bus(interface="virtual", channel=a)
    try:
        with Node([bus_link(a), bus_link(b)], robot_id=100, guard=guard) as node:
            left.engine.put(3, 1)
            run_until(node, lambda: right.engine.entry(3) is not None, [left, right])
            inject(attacker, Message(Op.PUT, 3, 666, 30000, 66), sender=66)
            yield node, left, right
    finally:
        for robot in (left, right):
            robot.close()
        attacker.shutdown()


def test_a_jump_is_neither_stored_nor_relayed_and_honest_writes_still_cross(channels: tuple[str, str]) -> None:
    a, b = channels
    with jump_attack(a, b, Guard(max_jump=50)) as (node, left, right):
        run_until(node, lambda: node.stats()[a]["drop_jump"] >= 1, [left, right])
        right.engine.put(3, 2)  # honest, on the other bus: timestamp 2
        run_until(node, lambda: node.engine is not None and node.engine.entry(3) == (2, 2, 9), [left, right])
        for _ in range(20):  # the robots on the attacker's bus hold the forgery and repeat it: still refused
            run_until(node, lambda: True, [left, right])
            time.sleep(0.01)
        assert right.engine.entry(3) == (2, 2, 9)
        assert node.engine is not None and node.engine.entry(3) == (2, 2, 9)


def test_without_a_guard_the_same_jump_takes_the_key_over(channels: tuple[str, str]) -> None:
    a, b = channels
    with jump_attack(a, b, None) as (node, left, right):
        run_until(node, lambda: right.engine.entry(3) == (666, 30000, 66), [left, right])


def test_a_read_only_link_is_heard_but_its_entries_never_leave_it(channels: tuple[str, str]) -> None:
    a, b = channels
    classroom, lab = BusRobot(5, a), BusRobot(9, b)
    guard = Guard(links={a: LinkPolicy(read_only=True)})
    with Node([bus_link(a), bus_link(b)], robot_id=100, guard=guard) as node:
        classroom.engine.put(3, 11)
        lab.engine.put(4, 22)
        run_until(node, lambda: node.engine is not None and node.engine.has(3) and classroom.engine.has(4),
                  [classroom, lab])
        for _ in range(20):  # time for a wrong relay to show
            lab.step()
            classroom.step()
            time.sleep(0.01)
        assert not lab.engine.has(3)  # stored in our table, never relayed to the lab's bus
        assert classroom.engine.entry(4) == (22, 1, 9)  # the lab's data still reaches the classroom
    for robot in (classroom, lab):
        robot.close()


def test_raw_mode_does_not_relay_a_read_only_link(channels: tuple[str, str]) -> None:
    a, b = channels
    bus_a, bus_b = can.Bus(interface="virtual", channel=a), can.Bus(interface="virtual", channel=b)
    guard = Guard(links={a: LinkPolicy(read_only=True)})
    with Node([bus_link(a), bus_link(b)], mode=Mode.RAW, guard=guard) as node:
        inject(bus_a, Message(Op.PUT, 1, 1, 1, 5), sender=5)
        inject(bus_b, Message(Op.PUT, 2, 2, 1, 6), sender=6)
        run_until(node, lambda: node.stats()[a]["in"] == 1 and node.stats()[b]["in"] == 1)
        time.sleep(0.1)
        heard_on_a = [bus_a.recv(0.5)]
        assert heard_on_a[0] is not None and bytes(heard_on_a[0].data) == encode(Message(Op.PUT, 2, 2, 1, 6))
        assert bus_b.recv(0.2) is None
    bus_a.shutdown()
    bus_b.shutdown()


def test_listeners_see_only_what_passes_and_each_refusal_is_counted_on_its_link(channels: tuple[str, str]) -> None:
    a, _ = channels
    bus = can.Bus(interface="virtual", channel=a)
    guard = Guard(rate=2, links={a: LinkPolicy(deny=IdSet.parse("7", 255), keys=IdSet.parse("0-9", 0x7FFF))})
    heard: list[Heard] = []
    with Node([bus_link(a)], mode=Mode.LISTEN, guard=guard) as node:
        node.listen(heard=heard.append)
        inject(bus, Message(Op.PUT, 1, 1, 1, 5), sender=5)
        inject(bus, Message(Op.PUT, 1, 1, 2, 7), sender=7)  # denied
        inject(bus, Message(Op.PUT, 50, 1, 1, 6), sender=6)  # forbidden key
        for ts in range(1, 6):
            inject(bus, Message(Op.PUT, 2, 1, ts, 8), sender=8)  # 2 pass, 3 beyond the rate
        run_until(node, lambda: node.stats()[a]["in"] == 8)
        stats = node.stats()[a]
    assert [(h.message.key, h.sender) for h in heard] == [(1, 5), (2, 8), (2, 8)]
    assert (stats["drop_untrusted"], stats["drop_key"], stats["drop_rate"]) == (1, 1, 3)
    assert stats["in"] == len(heard) + stats["drop_untrusted"] + stats["drop_key"] + stats["drop_rate"]
    bus.shutdown()


def cycling_ids_through(channel: str, guard: Guard) -> int:
    """How many of 1,000 PUTs pass `guard` when their node claims a new CAN id (1..127) for each frame."""
    attacker = can.Bus(interface="virtual", channel=channel)
    heard: list[Heard] = []
    node = Node([bus_link(channel)], mode=Mode.LISTEN, guard=guard)
    node.listen(heard=heard.append)
    try:
        with node:
            for i in range(1000):
                inject(attacker, Message(Op.PUT, 1, i, i + 1, 1), sender=1 + i % 127)
            run_until(node, lambda: node.stats()[channel]["in"] >= 1000)
    finally:
        attacker.shutdown()
    counters = node.stats()[channel]
    assert len(heard) + sum(n for name, n in counters.items() if name.startswith("drop_")) == 1000
    return len(heard)


def test_a_can_node_cycling_its_id_is_held_to_the_bus_source_rate_while_rate_alone_lets_it_all_in(
        channels: tuple[str, str]) -> None:
    a, b = channels
    assert cycling_ids_through(a, Guard(rate=10)) == 1000  # ids are claims: 10 a second per id lets all in
    assert 100 <= cycling_ids_through(b, Guard(rate=10, source_rate=100)) <= 150  # one bus, one source
