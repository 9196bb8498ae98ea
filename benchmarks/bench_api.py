"""The Python API: put -> neighbour latency against the same through a Node directly; watch throughput.

The neighbour is a python-can handle on the same virtual bus as the swarm's link:
the time measured is from calling put to the neighbour holding the frame. Through
the API the put crosses to the gateway thread (`Node.submit`) and back; through
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
            end = time.monotonic() + 60
            while sum(engine.counts.values()) < len(frames) and time.monotonic() < end:
                time.sleep(0.001)  # the node's own threads take them
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


_CONFIRMS = 60


class _EchoRobot:
    """A robot on a virtual bus that re-broadcasts what it stores at once (its own thread, no control step)."""

    def __init__(self, channel: str, robot_id: int = 7) -> None:
        from vstig_hw import Stigmergy

        self.bus = can.Bus(interface="virtual", channel=channel)
        self.engine, self.codec = Stigmergy(robot_id), can_framing_for(robot_id)
        self._running = True
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while self._running:
            frame = self.bus.recv(0.05)
            if frame is None:
                continue
            for msg in self.codec.feed(frame):
                self.engine.receive(msg)
            for msg in self.engine.drain():
                self.bus.send(self.codec.encode(msg)[0])

    def close(self) -> None:
        self._running = False
        self._thread.join(2)
        self.bus.shutdown()


def _confirm_times(swarm: vstig_hw.Swarm, first_key: int) -> list[float]:
    samples = []
    for i in range(_CONFIRMS):
        start = time.perf_counter()
        swarm.put(first_key + i, i, confirm=True, timeout=5.0)
        samples.append(time.perf_counter() - start)
    return samples


@benchmark("api")
def confirm_latency() -> Iterator[Result]:
    """A confirmed put -> its verdict: beside a robot on a bus (anchor: the same robot's round trip for a bare
    PUT), and through a `vstig bridge` over zenoh that holds the write (anchor: the bus robot's confirm)."""
    import subprocess
    import sys
    from pathlib import Path

    from .zenoh_peer import free_port

    stamp = time.monotonic_ns()
    channel = f"bench-confirm-{stamp}"
    robot = _EchoRobot(channel)
    tap = can.Bus(interface="virtual", channel=channel)
    codec = can_framing_for(9)
    try:
        bare = []
        for i in range(_CONFIRMS):  # a bare PUT to the robot and back: the floor of any confirmation here
            msg = Message(Op.PUT, 20000 + i, i, 1, 9)
            start = time.perf_counter()
            tap.send(codec.encode(msg)[0])
            while True:
                frame = tap.recv(1.0)
                assert frame is not None, "the robot did not re-broadcast"
                if msg in codec.feed(frame):
                    break
            bare.append(time.perf_counter() - start)
        with vstig_hw.join(f"can:virtual:{channel}", robot_id=2) as swarm:
            _confirm_times(swarm, 1000)  # warm up
            on_bus = _confirm_times(swarm, 2000)
    finally:
        tap.shutdown()
        robot.close()
    port = free_port()
    lab = f"bench-confirm-{stamp % 100000}"
    vstig = str(Path(sys.executable).with_name("vstig"))
    bridge = subprocess.Popen([vstig, "bridge", f"zenoh:{lab}?listen=tcp/127.0.0.1:{port}",
                               f"can:virtual:{lab}", "--robot-id", "200"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(2.0)  # its session listens
        with vstig_hw.join(f"zenoh:{lab}?connect=tcp/127.0.0.1:{port}", robot_id=9) as program:
            _confirm_times(program, 3000)
            through_gateway = _confirm_times(program, 4000)
    finally:
        bridge.terminate()
        bridge.wait(20)
    yield Result("api.confirm on a bus robot (median)", statistics.median(on_bus) * 1e3, "ms",
                 "bare PUT -> the robot's re-broadcast (median)", statistics.median(bare) * 1e3)
    yield Result("api.confirm through a zenoh gateway (median)", statistics.median(through_gateway) * 1e3, "ms",
                 "api.confirm on a bus robot (median)", statistics.median(on_bus) * 1e3)
    yield Result("api.confirm through a zenoh gateway (p90)", sorted(through_gateway)[int(0.9 * _CONFIRMS)] * 1e3,
                 "ms", "one control period", 100.0)
