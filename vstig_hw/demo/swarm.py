"""`vstig demo`'s swarm: robots on a virtual CAN bus and two pty radios, the gateway between.

With `gateways=2` the e-puck radio's arena has a gateway of its own, and the two
gateways meet over a zenoh link on loopback: the answer crosses the network too.

Everything real below the robots' engines: a python-can virtual bus, two ptys
opened through pyserial by the gateway's serial links, the real framings
(CAN, cobs8, epuck4). The radios are simulated on the ptys' master side: each
radio packet (one COBS frame) a robot or the gateway sends reaches every other
robot on that radio, and the gateway, independently with drop probability P.
The CAN bus is lossless, as CAN is; a CAN robot drops what it hears with the
same P, so every medium sees the configured loss.

Each medium counts `messages` (PUTs and GETs its robots sent), the `frames`
(CAN frames, radio packets) and `bytes` they took, and `copies`: one per
listener a frame reached (every other robot, and on a radio the gateway), of
which `lost` were dropped with P. So `lost` is about P times `copies`, and
many times `messages`: each frame has as many copies as listeners.

The task is the paper's: every robot puts its id under one key at start, does a
get every control step, and the larger value wins conflicts; the swarm has
converged when every robot holds the highest id.
"""

from __future__ import annotations

import os
import random
import select
import threading
import time
import tty
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from ..counters import Counters
from ..engine import Stigmergy, larger_value_wins
from ..framing import make_serial_framing
from ..gateway import Node
from ..links.can import CanSpec
from ..links.link import Link
from ..links.serial import SerialSpec
from ..links.zenoh import ZenohSpec

__all__ = ["DemoConfig", "DemoReport", "run_demo"]

KEY = 1
GATEWAY_ID = 250


@dataclass(frozen=True)
class DemoConfig:
    robots: int = 30
    drop: float = 0.75  # the paper's Figure 3 setting
    seed: int = 1
    step: float = 0.1  # seconds per control step, robots and gateway alike
    max_steps: int = 300
    channel: str = "vstig-demo"
    gateways: int = 1  # 2: the e-puck arena has a gateway of its own, joined to the first by a zenoh link


@dataclass
class Medium:
    name: str
    robots: list[Stigmergy] = field(default_factory=list)
    counters: Counters = field(default_factory=Counters)  # messages, frames, bytes, copies, lost, drop_<reason>

    def lost_copy(self, drop: float, rng: random.Random) -> bool:
        """One copy of a frame reaching one listener: True if the air loses it (probability `drop`)."""
        self.counters["copies"] += 1
        if rng.random() < drop:
            self.counters["lost"] += 1
            return True
        return False


@dataclass
class DemoReport:
    converged_at: int | None
    steps: int
    seconds: float
    media: list[Medium]
    gateway: dict[str, Counters]  # per link; "<gateway id>/<link>" when there are several gateways
    highest: int
    interrupted: bool = False  # the caller's stop ended the run (not convergence, not --max-steps)


class PtyRadio:
    """A radio simulated on a pty's master side; the gateway's serial link opens the slave."""

    def __init__(self, medium: Medium, framing: str, make_framing: Callable[[], Any], drop: float,
                 rng: random.Random) -> None:
        self.medium, self.framing, self.drop, self.rng = medium, framing, drop, rng
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no newline translation: the line carries binary frames
        self.path = os.ttyname(self._slave)
        self.codecs = [make_framing() for _ in medium.robots]
        self._buffer = b""

    def _packets_from_gateway(self) -> list[bytes]:
        while select.select([self.master], [], [], 0)[0]:
            try:
                self._buffer += os.read(self.master, 65536)
            except OSError:
                break
        *packets, self._buffer = self._buffer.split(b"\0")
        return [p + b"\0" for p in packets if p]

    def _hear(self, index: int, packet: bytes) -> None:
        if self.medium.lost_copy(self.drop, self.rng):
            return
        robot = self.medium.robots[index]
        for msg in self.codecs[index].feed(packet):
            robot.receive(msg)

    def step(self) -> None:
        for packet in self._packets_from_gateway():
            for index in range(len(self.medium.robots)):
                self._hear(index, packet)
        to_gateway = bytearray()
        for sender, robot in enumerate(self.medium.robots):
            for msg in robot.drain(1):
                self.medium.counters["messages"] += 1
                for unit in self.codecs[sender].encode(msg):
                    for packet in [p + b"\0" for p in unit.split(b"\0") if p]:
                        self.medium.counters["frames"] += 1
                        self.medium.counters["bytes"] += len(packet)
                        for index in range(len(self.medium.robots)):
                            if index != sender:
                                self._hear(index, packet)
                        if not self.medium.lost_copy(self.drop, self.rng):
                            to_gateway += packet
        if to_gateway:
            os.write(self.master, bytes(to_gateway))
        for codec in self.codecs:
            codec.tick()

    def drops(self) -> Counters:
        return _drops(self.codecs)

    def close(self) -> None:
        os.close(self.master)
        os.close(self._slave)


class CanRobots:
    """Robots on a python-can virtual bus, each with its own bus handle and CAN framing."""

    def __init__(self, medium: Medium, channel: str, drop: float, rng: random.Random) -> None:
        import can

        from ..framing.can import can_framing_for

        self.medium, self.drop, self.rng = medium, drop, rng
        self.buses = [can.Bus(interface="virtual", channel=channel) for _ in medium.robots]
        self.codecs = [can_framing_for(robot.robot_id) for robot in medium.robots]

    def step(self) -> None:
        for bus, codec, robot in zip(self.buses, self.codecs, self.medium.robots, strict=True):
            while (frame := bus.recv(0)) is not None:
                if self.medium.lost_copy(self.drop, self.rng):
                    continue
                for msg in codec.feed(frame):
                    robot.receive(msg)
        for bus, codec, robot in zip(self.buses, self.codecs, self.medium.robots, strict=True):
            for msg in robot.drain(1):
                self.medium.counters["messages"] += 1
                for frame in codec.encode(msg):
                    self.medium.counters["frames"] += 1
                    self.medium.counters["bytes"] += len(frame.data)
                    bus.send(frame)

    def drops(self) -> Counters:
        return _drops(self.codecs)

    def close(self) -> None:
        for bus in self.buses:
            bus.shutdown()


def _drops(codecs: list[Any]) -> Counters:
    """Every robot framing's drops, by reason, summed over a medium."""
    total = Counters()
    for codec in codecs:
        total.update({f"drop_{reason}": n for reason, n in codec.drops.items()})
    return total


def _split(config: DemoConfig) -> tuple[list[int], list[int], list[int]]:
    """Robot ids 1..N over CAN, cobs8 and epuck4; the highest id sits on the e-puck radio, so the
    answer has to cross two media to reach the CAN robots."""
    ids = list(range(1, config.robots + 1))
    third = len(ids) // 3
    return ids[:third], ids[third:2 * third], ids[2 * third:]


def run_demo(config: DemoConfig, show: Callable[[int, list[Medium], int], None] | None = None,
             stop: threading.Event | None = None) -> DemoReport:
    rng = random.Random(config.seed)
    can_ids, cobs_ids, epuck_ids = _split(config)
    media = [Medium(name, [Stigmergy(i, onconflict=larger_value_wins) for i in ids])
             for name, ids in (("can", can_ids), ("cobs8", cobs_ids), ("epuck4", epuck_ids))]
    channel = f"{config.channel}-{os.getpid()}-{rng.getrandbits(24)}"
    can_side = CanRobots(media[0], channel, config.drop, rng)
    radios = [PtyRadio(media[1], "cobs8", lambda: make_serial_framing("cobs8"), config.drop, rng),
              PtyRadio(media[2], "epuck4", lambda: make_serial_framing("epuck4"), config.drop, rng)]
    links: list[Link[Any]] = [CanSpec("virtual", channel).build("can", robot_id=GATEWAY_ID)]
    links += [SerialSpec(radio.path, framing=radio.framing).build(radio.framing) for radio in radios]
    nodes: list[Node] = []
    highest = config.robots
    everyone = [robot for medium in media for robot in medium.robots]
    for robot in everyone:
        robot.put(KEY, robot.robot_id)
    stopped = stop or threading.Event()
    converged_at = None
    start = time.monotonic()
    step = 0
    interrupted = False
    try:
        for n, arena in enumerate(_arenas(links, config.gateways, f"demo-{channel}")):
            nodes.append(Node(arena, GATEWAY_ID + n, period=config.step, onconflict=larger_value_wins))
            nodes[-1].open()  # before the next arena is built: it connects to the port this one bound
        for step in range(1, config.max_steps + 1):
            deadline = start + step * config.step
            can_side.step()
            for radio in radios:
                radio.step()
            agreed = sum(robot.get(KEY) == highest for robot in everyone)
            if show:
                show(step, media, agreed)
            if agreed == len(everyone):
                converged_at = step
                break
            if stopped.wait(max(0.0, deadline - time.monotonic())):
                interrupted = True
                break
    finally:
        stopped.set()
        for node in nodes:
            node.close()
        can_side.close()
        for radio in radios:
            radio.close()
    media[0].counters.update(can_side.drops())
    for medium, radio in zip(media[1:], radios, strict=True):
        medium.counters.update(radio.drops())
    if len(nodes) == 1:
        traffic = nodes[0].stats()
    else:
        traffic = {f"{node_id(node)}/{name}": c for node in nodes for name, c in node.stats().items()}
    return DemoReport(converged_at, step, time.monotonic() - start, media, traffic, highest, interrupted)


def node_id(node: Node) -> int:
    return node.engine.robot_id if node.engine else 0


def _arenas(links: list[Link[Any]], gateways: int, swarm: str) -> Iterator[list[Link[Any]]]:
    """One gateway with every link, or two: CAN and cobs8 on the first, the e-puck radio on the second,
    each with a zenoh link (the first listens on a free loopback port, the second connects to it).
    The second arena is built when asked for, once the first gateway is open and its port bound."""
    if gateways == 1:
        yield links
        return
    first = ZenohSpec(swarm).build("zenoh", robot_id=GATEWAY_ID)
    yield [*links[:2], first]
    endpoints = first.transport.listening
    yield [links[2], ZenohSpec(swarm, connect=endpoints).build("zenoh", robot_id=GATEWAY_ID + 1)]
