"""Stand-ins for the CAN link, for gateway tests that need a real python-can bus but no ID scheme.

A real `can.Bus(interface="virtual")` underneath; the framing is the simplest
that names the sender (`0x600 | op << 8 | robot & 0xFF`).
"""

from __future__ import annotations

import can

from vstig_hw import Message, Stigmergy, decode, encode
from vstig_hw.counters import Counters
from vstig_hw.link import Link


class BusTransport:
    def __init__(self, channel: str) -> None:
        self.name = channel
        self.counters = Counters()
        self.bus: can.BusABC | None = None

    def open(self) -> None:
        self.bus = can.Bus(interface="virtual", channel=self.name)

    def close(self) -> None:
        if self.bus is not None:
            self.bus.shutdown()

    def read(self, timeout: float) -> list[can.Message]:
        assert self.bus is not None
        first = self.bus.recv(timeout)
        if first is None:
            return []
        units = [first]
        while (more := self.bus.recv(0)) is not None:
            units.append(more)
        return units

    def write(self, unit: can.Message) -> None:
        assert self.bus is not None
        self.bus.send(unit)

    @property
    def connected(self) -> bool:
        return self.bus is not None


class PlainCanFraming:
    name = "plain-can"

    def __init__(self) -> None:
        self.drops = Counters()

    def encode(self, msg: Message) -> list[can.Message]:
        can_id = 0x600 | int(msg.op) << 8 | msg.robot & 0xFF
        return [can.Message(arbitration_id=can_id, data=encode(msg), is_extended_id=False)]

    def feed(self, unit: can.Message) -> list[Message]:
        if unit.dlc != 8:
            self.drops["bad_dlc"] += 1
            return []
        return [decode(bytes(unit.data))]

    def sender_of(self, unit: can.Message) -> int:
        return int(unit.arbitration_id) & 0xFF

    def tick(self) -> None:
        pass


def bus_link(channel: str, name: str | None = None) -> Link[can.Message]:
    return Link(name or channel, BusTransport(channel), PlainCanFraming())


class BusRobot:
    """A robot on a virtual bus: an engine, a bus handle, and one control step at a time."""

    def __init__(self, robot_id: int, channel: str) -> None:
        self.engine = Stigmergy(robot_id)
        self.framing = PlainCanFraming()
        self.bus = can.Bus(interface="virtual", channel=channel)

    def step(self) -> None:
        while (frame := self.bus.recv(0)) is not None:
            for msg in self.framing.feed(frame):
                self.engine.receive(msg)
        for msg in self.engine.drain():
            for frame in self.framing.encode(msg):
                self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()
