"""The Node's ways in for other threads and watchers: `submit` wakes a waiting loop, a `change` listener hears
every change of the table with the link and sender it came from; on a real python-can virtual bus."""

from __future__ import annotations

import time

import can
from waiting import wait_until

from vstig_hw import Entry, Message, Op
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Node
from vstig_hw.links import parse

Told = tuple[int, Entry | None, Entry, str | None, int | None]


def test_on_change_tells_heard_and_own_writes_once_each() -> None:
    channel = f"hooks-{time.monotonic_ns()}"
    robot = can.Bus(interface="virtual", channel=channel)
    node = Node([parse(f"can:virtual:{channel}").build("bus", robot_id=50)], 50)
    told: list[Told] = []
    node.listen(change=lambda *change: told.append(change))  # type: ignore[arg-type]
    codec = can_framing_for(7)
    with node:
        for msg in (Message(Op.PUT, 3, 30, 1, 7), Message(Op.PUT, 3, 30, 1, 7), Message(Op.PUT, 3, 31, 2, 7)):
            for frame in codec.encode(msg):
                robot.send(frame)
        wait_until(lambda: len(told) >= 2, 5)
        node.put(3, 99)
        time.sleep(0.05)
    robot.shutdown()
    assert told == [
        (3, None, Entry(30, 1, 7), "bus", 7),
        (3, Entry(30, 1, 7), Entry(31, 2, 7), "bus", 7),  # the repeat changed nothing: not told
        (3, Entry(31, 2, 7), Entry(99, 3, 50), None, 50),
    ]


def test_submit_wakes_a_waiting_loop_at_once() -> None:
    channel = f"hooks-{time.monotonic_ns()}"
    node = Node([parse(f"can:virtual:{channel}").build("bus", robot_id=50)], 50, period=10.0)  # no tick for 10 s
    ran: list[float] = []
    with node:
        time.sleep(0.1)  # the loop waits for the links now
        asked = time.monotonic()
        done = node.submit(lambda: ran.append(time.monotonic()) or 7)
        assert done.result(5) == 7
    assert ran and ran[0] - asked < 0.1  # not at the end of its 0.25 s wait, nor at the next tick
    assert node.wait_closed(0)
