"""Robots in the test process, each on its own real radio to a `vstig bridge`: a pty (cobs8) or slcan-on-pty CAN.

A robot is a full engine running the paper's program: it puts its own id under
a key once, then does a get of every key it watches at each control step, and
handles what its radio hears in between.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

from peers import PtyPeer, SlcanAdapter

from vstig_hw import Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.wire import Message, Op


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


class LaggingSwarm:
    """The roster's scenario (issue 47): pty robots 1..count, each writing a key of its own (100 + id) every step;
    robot 1 also writes KEY; robot LAGGING keeps sending its own old write of KEY (timestamp 1) instead of a
    heartbeat; robots SILENT stop sending once `silence()` is called (`silent_since` then says when)."""

    SILENT = (9, 10, 11)
    LAGGING = 12
    KEY = 50

    def __init__(self, count: int = 12, period: float = 0.1) -> None:
        self.robots = [PtyRobot(n) for n in range(1, count + 1)]
        self.period = period
        self.steps = 0
        self.silent_since: float | None = None

    @property
    def specs(self) -> list[str]:
        return [robot.spec for robot in self.robots]

    def step(self) -> None:
        """One control step for every robot still talking, then a period's sleep."""
        self.steps += 1
        for robot in self.robots:
            if robot.id in self.SILENT and self.silent_since is not None:
                continue
            if robot.id == self.LAGGING:
                robot.radio.write(robot.framing.encode(Message(Op.PUT, self.KEY, 7, 1, self.LAGGING))[0])
            else:
                robot.put(100 + robot.id, self.steps)  # its heartbeat: a write of its own each step
            if robot.id == 1:
                robot.put(self.KEY, self.steps)
        time.sleep(self.period)

    def silence(self) -> None:
        self.silent_since = time.monotonic()

    def close(self) -> None:
        for robot in self.robots:
            robot.close()
