"""The roster tests' swarm of pty robots, stepped by the test: each writes a key of its own every step (its
heartbeat), robot 1 also writes KEY, one robot keeps sending its old write of KEY (timestamp 1: behind), and the
robots in `silent` send nothing."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

from robots import PtyRobot

from vstig_hw.wire import Message, Op

KEY = 50


class RosterSteps:
    def __init__(self, robots: Sequence[PtyRobot], lagging: int, step: float = 0.1,
                 also: Callable[[], None] | None = None) -> None:
        self.robots, self.lagging, self.step, self.also = robots, lagging, step, also
        self.silent: set[int] = set()
        self.steps = 0

    def __call__(self) -> None:
        self.steps += 1
        for robot in self.robots:
            if robot.id in self.silent:
                continue
            if robot.id == self.lagging:
                robot.radio.write(robot.framing.encode(Message(Op.PUT, KEY, 7, 1, self.lagging))[0])
            else:
                robot.put(100 + robot.id, self.steps)
            if robot.id == 1:
                robot.put(KEY, self.steps)
        if self.also is not None:
            self.also()
        time.sleep(self.step)
