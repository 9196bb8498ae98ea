"""Several stigmergies (Buzz's stigmergy.create): two tables on one python-can virtual bus, no crosstalk."""

from __future__ import annotations

import os
import time
import tty
from collections.abc import Iterator

import can
import pytest

import vstig_hw
from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.framing.can import can_framing_for

ME = 70


class TableRobot:
    """A robot on the bus speaking one table (29-bit IDs, stigmergy field `table`)."""

    def __init__(self, channel: str, robot_id: int, table: int) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.codec = can_framing_for(robot_id, extended=True, stigmergy=table)
        self.engine = Stigmergy(robot_id)

    def step(self) -> None:
        while (frame := self.bus.recv(0)) is not None:
            for msg in self.codec.feed(frame):
                self.engine.receive(msg)
        for msg in self.engine.drain():
            for frame in self.codec.encode(msg):
                self.bus.send(frame)

    def put(self, key: int, value: int) -> None:
        self.engine.put(key, value)
        self.step()


@pytest.fixture
def channel() -> Iterator[str]:
    yield f"tables-{os.getpid()}-{time.monotonic_ns()}"


def settle(robots: list[TableRobot], until: object, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for robot in robots:
            robot.step()
        if until():  # type: ignore[operator]
            return True
        time.sleep(0.005)
    return False


def test_two_tables_on_one_can_bus_keep_apart(channel: str) -> None:
    zero, two = TableRobot(channel, 1, 0), TableRobot(channel, 2, 2)
    with vstig_hw.join(f"can:virtual:{channel}?extended=1", robot_id=ME) as swarm:
        table2 = swarm.stigmergy(2)
        assert swarm.stigmergy(2) is table2 and swarm.stigmergy(0) is swarm
        swarm.put(1, 10)
        table2.put(1, 20)
        assert settle([zero, two], lambda: zero.engine.entry(1) == Entry(10, 1, ME)
                      and two.engine.entry(1) == Entry(20, 1, ME))
        zero.put(5, 50)
        two.put(5, 52)
        assert settle([zero, two], lambda: swarm.entry(5) == Entry(50, 1, 1) and table2.entry(5) == Entry(52, 1, 2))
        time.sleep(0.1)
        for robot in (zero, two):
            robot.step()
        assert swarm.entry(1) == Entry(10, 1, ME) and table2.entry(1) == Entry(20, 1, ME)  # no crosstalk
        assert zero.engine.entry(1) == Entry(10, 1, ME) and two.engine.entry(1) == Entry(20, 1, ME)
        assert sorted(swarm.keys()) == [1, 5] and sorted(table2.keys()) == [1, 5]
    assert table2.closed  # closed with the swarm
    zero.bus.shutdown()
    two.bus.shutdown()


def test_a_link_that_carries_one_table_is_refused_naming_it(channel: str) -> None:
    with vstig_hw.join(f"can:virtual:{channel}", robot_id=ME) as swarm, \
            pytest.raises(ValueError, match=r"stigmergy: can:virtual:.* has 11-bit IDs, .* add extended=1"):
        swarm.stigmergy(2)
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        with vstig_hw.join(f"serial:{os.ttyname(slave)}", robot_id=ME) as swarm:
            with pytest.raises(ValueError, match=r"stigmergy: serial:.* carries one table"):
                swarm.stigmergy(1)
            with pytest.raises(ValueError, match=r"stigmergy must be an integer in 0\.\.255, got 256"):
                swarm.stigmergy(256)
    finally:
        os.close(master)
        os.close(slave)


def test_messages_of_another_table_never_reach_ours(channel: str) -> None:
    with vstig_hw.join(f"can:virtual:{channel}?extended=1&stigmergy=3", robot_id=ME) as swarm:
        other = can.Bus(interface="virtual", channel=channel)
        for frame in can_framing_for(9, extended=True, stigmergy=4).encode(Message(Op.PUT, 7, 1, 1, 9)):
            other.send(frame)
        mine = can_framing_for(9, extended=True, stigmergy=3).encode(Message(Op.PUT, 8, 1, 1, 9))
        for frame in mine:
            other.send(frame)
        deadline = time.monotonic() + 5
        while not swarm.has(8) and time.monotonic() < deadline:
            time.sleep(0.005)
        assert swarm.has(8) and not swarm.has(7)
        assert swarm.stigmergy(3) is swarm
        other.shutdown()
