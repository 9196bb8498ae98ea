"""Stand-in robots to try a program on, without hardware: `vstig demo`'s robots, running your robot program.

They live in this process, on real links a swarm joins like any other: a
python-can virtual bus (`can:virtual:<channel>`) and a pty radio speaking cobs8
(`serial:<pty>?framing=cobs8`), opened through pyserial by the gateway. Every
`step` seconds each robot runs `program(robot, step_number)` (a robot is a
`Stigmergy`: put, get, entry...), hears what its medium carried and sends one
message, as `vstig demo`'s robots do.

    with VirtualRobots(can_ids=range(1, 11), radio_ids=range(11, 21), program=figure1) as robots:
        with vstig_hw.join(*robots.links, robot_id=250) as swarm:
            ...

From a shell, `python -m vstig_hw.api.virtual robots.pty` runs robots 1..20 on
a pty radio playing the paper's Figure 1 (agree on the highest id), reachable
from any other process as `serial:robots.pty?framing=cobs8` (a symlink it makes,
and removes on exit) until Ctrl-C.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from ..demo.swarm import CanRobots, Medium, PtyRadio
from ..engine import ConflictResolver, Stigmergy, larger_value_wins
from ..framing import make_serial_framing

__all__ = ["FIGURE1_KEY", "Program", "VirtualRobots", "figure1", "main"]

Program = Callable[[Stigmergy, int], None]  # (robot, step number) -> None, once per step
FIGURE1_KEY = 1


def figure1(robot: Stigmergy, step: int) -> None:
    """The paper's Figure 1 program: read the key; while it holds less than our id, write our id."""
    highest = robot.get(FIGURE1_KEY)
    if highest is None or highest < robot.robot_id:
        robot.put(FIGURE1_KEY, robot.robot_id)


class VirtualRobots:
    """Robots on a python-can virtual bus (`can_ids`) and on a pty radio (`radio_ids`); `links` names both.

    `drop` is each radio packet's (and CAN frame's) chance to be lost, per robot.
    """

    def __init__(self, can_ids: Iterable[int] = (), radio_ids: Iterable[int] = (), *,
                 program: Program | None = None, onconflict: ConflictResolver | None = None,
                 step: float = 0.01, drop: float = 0.0, seed: int = 1) -> None:
        rng = random.Random(seed)
        self.program = program
        self.step = step
        self.steps = 0
        self.errors: list[BaseException] = []  # what a program raised (the robots stop at the first)
        self._can = Medium("can", [Stigmergy(i, onconflict=onconflict) for i in can_ids])
        self._radio = Medium("radio", [Stigmergy(i, onconflict=onconflict) for i in radio_ids])
        self.robots = self._can.robots + self._radio.robots
        if not self.robots:
            raise ValueError("can_ids, radio_ids: give at least one robot")
        self.links: list[str] = []
        self.radio_path: str | None = None  # the pty the radio robots are on, if any
        self._media: list[CanRobots | PtyRadio] = []
        if self._can.robots:
            channel = f"virtual-robots-{os.getpid()}-{rng.getrandbits(32):08x}"
            self._media.append(CanRobots(self._can, channel, drop, rng))
            self.links.append(f"can:virtual:{channel}")
        if self._radio.robots:
            radio = PtyRadio(self._radio, "cobs8", lambda: make_serial_framing("cobs8"), drop, rng)
            self._media.append(radio)
            self.radio_path = radio.path
            self.links.append(f"serial:{radio.path}?framing=cobs8")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="virtual-robots", daemon=True)

    def robot(self, robot_id: int) -> Stigmergy:
        """The robot with this id."""
        for robot in self.robots:
            if robot.robot_id == robot_id:
                return robot
        raise KeyError(f"robot_id: no virtual robot {robot_id}")

    def start(self) -> VirtualRobots:
        """Start stepping (the context manager does it)."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop stepping and close the bus and the pty."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        for medium in self._media:
            medium.close()

    def __enter__(self) -> VirtualRobots:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.wait(self.step):
            self.steps += 1
            try:
                if self.program is not None:
                    for robot in self.robots:
                        self.program(robot, self.steps)
                for medium in self._media:
                    medium.step()
            except Exception as error:  # shown by whoever checks `errors`; the robots stop
                self.errors.append(error)
                return


def main(argv: list[str] | None = None) -> int:
    """`python -m vstig_hw.api.virtual PATH`: Figure 1 robots on a pty radio, reachable at PATH, until Ctrl-C."""
    from ..gateway.shutdown import stop_on_signals

    parser = argparse.ArgumentParser(prog="python -m vstig_hw.api.virtual",
                                     description="Stand-in robots playing the paper's Figure 1 (agree on the highest "
                                                 "id) on a pty radio, for trying a program without hardware.")
    parser.add_argument("path", type=Path, help="a new path: made a symlink to the radio's pty (removed on exit)")
    parser.add_argument("--robots", type=int, default=20, choices=range(1, 201), metavar="N",
                        help="how many robots (ids 1..N; default 20)")
    args = parser.parse_args(argv)
    path: Path = args.path
    if path.exists() or path.is_symlink():
        parser.error(f"{path} exists: name a path that does not (it is never replaced)")
    # Signals first: one that comes after "Ctrl-C stops" is said (or while the robots start) is a clean stop
    with stop_on_signals() as stop, VirtualRobots(radio_ids=range(1, args.robots + 1), program=figure1,
                                                  onconflict=larger_value_wins) as robots:
        assert robots.radio_path is not None
        path.symlink_to(robots.radio_path)
        try:
            print(f"{args.robots} robots play Figure 1 on serial:{path}?framing=cobs8; Ctrl-C stops", flush=True)
            while not stop.wait(0.5) and not robots.errors:
                pass
        finally:
            path.unlink()
    held: dict[int | None, int] = {}
    for robot in robots.robots:
        entry = robot.entry(FIGURE1_KEY)
        held[None if entry is None else entry.value] = held.get(None if entry is None else entry.value, 0) + 1
    print("robots hold " + ", ".join(f"{value}: {count}" for value, count in sorted(held.items(), key=str)), flush=True)
    for error in robots.errors:
        print(f"a robot's program failed: {error}", file=sys.stderr)
    return 1 if robots.errors else 0


if __name__ == "__main__":
    sys.exit(main())
