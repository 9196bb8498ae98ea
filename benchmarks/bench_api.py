"""The Python API: put -> neighbour latency against the same through a Node directly; watch throughput.

The neighbour is a python-can handle on the same virtual bus as the swarm's link:
the time measured is from calling put to the neighbour holding the frame. Through
the API the put crosses to the gateway thread (`Node.call_soon`) and back; through
the Node it is a plain call on the thread that owns it.

Watch throughput is changes per second a consumer thread takes out of a watch:
once fed straight from the gateway's change listener (the API's own cost), and
once end to end, PUTs flooded onto the bus and watched, against the same flood
into a bare Node that nobody watches.
"""

from __future__ import annotations

import statistics
import threading
import time
from collections.abc import Callable, Iterator

import can

import vstig_hw
from vstig_hw import Entry, Message, Op
from vstig_hw.api.changes import ChangeHub, Watch
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Node
from vstig_hw.links.can import can_link

from .registry import Result, benchmark

_PUTS = 4000
_ROUNDS = 20
_CHANGES = 50_000
_GOAL = 50_000.0  # changes/s to one consumer, on one core


def _latencies(put: Callable[[int, int], object], neighbour: can.BusABC, n: int) -> list[float]:
    """Seconds from put(key, value) to the neighbour receiving the frame, n times."""
    samples = []
    for i in range(n):
        start = time.perf_counter()
        put(i % 1000, i)
        frame = neighbour.recv(1.0)
        samples.append(time.perf_counter() - start)
        assert frame is not None, "the neighbour heard nothing"
    return samples


@benchmark("api")
def put_latency() -> Iterator[Result]:
    """Rounds of puts through each in turn, so a busy machine slows both alike; the median of each."""
    stamp = time.monotonic_ns()
    node_bus, api_bus = f"bench-api-node-{stamp}", f"bench-api-swarm-{stamp}"
    node_neighbour = can.Bus(interface="virtual", channel=node_bus)
    api_neighbour = can.Bus(interface="virtual", channel=api_bus)
    direct: list[float] = []
    api: list[float] = []
    try:
        with Node([can_link("virtual", node_bus, robot_id=1)], 1, budget=None) as node, \
                vstig_hw.join(f"can:virtual:{api_bus}", robot_id=2, budget=None, refresh=False) as swarm:
            _latencies(node.put, node_neighbour, 200)  # warm up
            _latencies(swarm.put, api_neighbour, 200)
            for _ in range(_ROUNDS):
                direct += _latencies(node.put, node_neighbour, _PUTS // _ROUNDS)
                api += _latencies(swarm.put, api_neighbour, _PUTS // _ROUNDS)
    finally:
        node_neighbour.shutdown()
        api_neighbour.shutdown()
    yield Result("api.put -> neighbour (median)", statistics.median(api) * 1e6, "us",
                 "Node.put -> neighbour (median)", statistics.median(direct) * 1e6)


@benchmark("api")
def watch_throughput() -> Iterator[Result]:
    # The API's own cost: the gateway's listener publishing, a consumer thread taking.
    hub = ChangeHub(lambda attach: None)
    watch = Watch(buffer=_CHANGES)
    hub.add(watch)
    new = Entry(1, 1, 9)
    got = [0]

    def consume() -> None:
        for _ in watch:
            got[0] += 1
            if got[0] == _CHANGES:
                return

    consumer = threading.Thread(target=consume)
    start = time.perf_counter()
    consumer.start()
    publish = hub.publish
    for key in range(_CHANGES):
        publish(key & 0x7FFF, None, new, "can0", 9)
    consumer.join(30)
    hub_rate = _CHANGES / (time.perf_counter() - start)
    yield Result("api.watch publish -> consumer", hub_rate, "change/s", "goal 50k change/s", _GOAL)

    # End to end: PUTs flooded onto a virtual bus, stored by the gateway, taken from a watch.
    frames = _flood(_CHANGES)
    bare = _flooded_node(frames)
    watched, overflow = _flooded_swarm(frames)
    yield Result("api.watch end to end (bus -> gateway -> consumer)", watched, "change/s",
                 "the same flood into a bare Node (stored/s)", bare)
    yield Result("api.watch end to end vs goal", watched, "change/s", "goal 50k change/s", _GOAL)
    yield Result("api.watch end to end overflow", float(overflow), "changes", "changes flooded", float(_CHANGES))


def _flood(n: int) -> list[can.Message]:
    """n PUTs, each a change: keys 0..29999 at timestamp 1, then again at timestamp 2..."""
    codec = can_framing_for(9)
    return [codec.encode(Message(Op.PUT, i % 30_000, i & 0xFFFF, 1 + i // 30_000, 9))[0] for i in range(n)]


def _send_all(bus: can.BusABC, frames: list[can.Message]) -> None:
    for frame in frames:
        bus.send(frame)


def _flooded_node(frames: list[can.Message]) -> float:
    channel = f"bench-api-flood-{time.monotonic_ns()}"
    sender = can.Bus(interface="virtual", channel=channel)
    node = Node([can_link("virtual", channel, robot_id=1)], 1, budget=None)
    try:
        with node:
            assert node.engine is not None
            engine = node.engine
            flooder = threading.Thread(target=_send_all, args=(sender, frames))
            start = time.perf_counter()
            flooder.start()  # from a thread, as for the swarm: the same three threads share the GIL
            node.run(until=lambda: sum(engine.counts.values()) >= len(frames), duration=60)
            elapsed = time.perf_counter() - start
            flooder.join()
            return len(frames) / elapsed
    finally:
        sender.shutdown()


def _flooded_swarm(frames: list[can.Message]) -> tuple[float, int]:
    channel = f"bench-api-flood-{time.monotonic_ns()}"
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        with vstig_hw.join(f"can:virtual:{channel}", robot_id=1, budget=None, refresh=False, max_jump=None) as swarm:
            watch = swarm.watch()
            taken = 0
            flooder = threading.Thread(target=_send_all, args=(sender, frames))
            start = time.perf_counter()
            flooder.start()
            while taken + watch.overflow < len(frames):
                if watch.get(2.0) is None:
                    break
                taken += 1
            elapsed = time.perf_counter() - start
            flooder.join()
            return taken / elapsed, watch.overflow
    finally:
        sender.shutdown()
