"""RoundRobinGet: the gateway GETs one key of its table per tick, cycling, on a real virtual CAN bus."""

from __future__ import annotations

import os
import time

import can

from vstig_hw import Op
from vstig_hw.framing.can import can_framing
from vstig_hw.gateway import Node, RoundRobinGet
from vstig_hw.links import parse


def test_each_tick_gets_the_next_key_carrying_the_nodes_view() -> None:
    channel = f"refresh-{os.getpid()}"
    robot = can.Bus(interface="virtual", channel=channel)
    node = Node([parse(f"can:virtual:{channel}").build("bus", robot_id=100)], 100, period=0.02)
    node.listen(tick=RoundRobinGet())
    engine = node.engine
    assert engine is not None
    for key in (3, 1, 2):
        engine.put(key, 10 * key)
    engine.drain()  # the PUTs are not what this test watches
    with node:
        time.sleep(0.5)
    robot_framing = can_framing()
    gets = [msg for frame in iter(lambda: robot.recv(0), None) for msg in robot_framing.feed(frame)
            if msg.op is Op.GET]
    robot.shutdown()
    keys = [msg.key for msg in gets]
    assert len(keys) >= 9 and keys[:6] == [1, 2, 3, 1, 2, 3]  # every key in turn, again and again
    assert all(msg.value == 10 * msg.key and msg.timestamp == 1 for msg in gets)  # each carries the node's view
