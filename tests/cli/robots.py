"""Robots in the test process, each on its own real radio to a `vstig bridge`: a pty (cobs8) or slcan-on-pty CAN.

A robot is a full engine running the paper's program: it puts its own id under
a key once, then does a get of every key it watches at each control step, and
handles what its radio hears in between.
"""

from __future__ import annotations

from collections.abc import Iterable

from peers import PtyPeer, SlcanAdapter

from vstig_hw import Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.wire import Message


class Robot:
    def __init__(self, robot_id: int, watch: Iterable[int] = (1,)) -> None:
        self.id = robot_id
        self.engine = Stigmergy(robot_id, onconflict=larger_value_wins)
        self.watch = set(watch)

    def value(self, key: int) -> int | None:
        entry = self.engine.entry(key)
        return None if entry is None else entry.value

    def step(self) -> None:
        """One control step: take in what the radio heard, get every watched key, send the outbox."""
        for msg in self._heard():
            self.engine.receive(msg)
        for key in self.watch:
            self.engine.get(key)
        self._send(self.engine.drain())

    def put(self, key: int, value: int) -> None:
        self.watch.add(key)
        self.engine.put(key, value)
        self._send(self.engine.drain())

    def _heard(self) -> list[Message]:
        raise NotImplementedError

    def _send(self, messages: list[Message]) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class PtyRobot(Robot):
    """A robot whose radio is a pty speaking cobs8; the bridge opens `spec`."""

    def __init__(self, robot_id: int, watch: Iterable[int] = (1,)) -> None:
        super().__init__(robot_id, watch)
        self.radio = PtyPeer()
        self.framing = make_serial_framing("cobs8")
        self.spec = f"serial:{self.radio.path}?framing=cobs8"

    def _heard(self) -> list[Message]:
        return self.framing.feed(self.radio.read(0))

    def _send(self, messages: list[Message]) -> None:
        data = b"".join(unit for msg in messages for unit in self.framing.encode(msg))
        if data:
            self.radio.write(data)

    def close(self) -> None:
        self.radio.close()


class CanRobot(Robot):
    """A robot on a CAN bus behind an slcan adapter (python-can's real slcan driver runs in the bridge)."""

    def __init__(self, robot_id: int, watch: Iterable[int] = (1,)) -> None:
        super().__init__(robot_id, watch)
        self.adapter = SlcanAdapter()
        self.framing = CanFraming(CanIdScheme(), sender=robot_id)
        self.spec = f"can:slcan:{self.adapter.path}"
        self._seen = 0

    def _heard(self) -> list[Message]:
        frames = self.adapter.sent[self._seen:]
        self._seen += len(frames)
        return [msg for frame in frames for msg in self.framing.feed(frame)]

    def _send(self, messages: list[Message]) -> None:
        for msg in messages:
            for frame in self.framing.encode(msg):
                self.adapter.inject(frame)

    def close(self) -> None:
        self.adapter.close()

