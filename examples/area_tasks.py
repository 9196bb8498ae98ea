"""Area task allocation through the stigmergy: the PC opens areas, robots claim, visit and complete them.

One key per area; its value packs a state and a robot id (state << 12 | robot):
OPEN (0) by the PC, CLAIMED by a robot that will visit it, DONE by the robot
that visited it. A robot claims only an area it sees OPEN; two robots that claim
one area at the same timestamp conflict, and the conflict rule (higher robot id
wins, everywhere) keeps one claim: the other robot sees it lost and looks for
another area. A robot starts visiting only once its claim has stood for a while,
so no area is visited twice. The PC watches every area key and reports.

    python examples/area_tasks.py can:socketcan:can0 --robot-id 200
    python examples/area_tasks.py      # 12 stand-in robots on a CAN bus and a lossy pty radio, checked
"""

from __future__ import annotations

import random
import sys
import time
from dataclasses import dataclass, field

from _args import example_arguments

import vstig_hw
from vstig_hw import Entry, Stigmergy
from vstig_hw.api import Swarm
from vstig_hw.api.virtual import VirtualRobots

FIRST_AREA = 100
OPEN, CLAIMED, DONE = 0, 1, 2
STATES = ("open", "claimed", "done")


def pack(state: int, robot: int) -> int:
    return state << 12 | robot


def unpack(entry: Entry | None) -> tuple[int, int] | None:
    """(state, robot) of an area's entry, None for an area not opened yet."""
    return None if entry is None else (entry.value >> 12, entry.value & 0xFFF)


def supervise(swarm: Swarm, areas: list[int], seconds: float) -> dict[int, int]:
    """Open every area, then watch until all are done (or `seconds` pass); area -> the robot that did it."""
    conflicts = 0

    @swarm.onconflict
    def higher_robot(key: int, local: Entry, remote: Entry) -> Entry:  # the default rule, counted
        nonlocal conflicts
        conflicts += 1
        return remote if remote.robot > local.robot else local

    watch = swarm.watch(keys=areas)
    for area in areas:
        swarm.put(area, pack(OPEN, swarm.robot_id))
    done: dict[int, int] = {}
    end = time.monotonic() + seconds
    while len(done) < len(areas) and time.monotonic() < end:
        change = watch.get(timeout=0.5)
        if change is None or change.link is None:
            continue
        state = unpack(change.new)
        assert state is not None
        print(f"area {change.key}: {STATES[state[0]]} by robot {state[1]}", flush=True)
        if state[0] == DONE:
            done[change.key] = state[1]
    print(f"{len(done)} of {len(areas)} areas done; {conflicts} conflicting claims resolved here; "
          f"{watch.overflow} changes dropped", flush=True)
    return done


@dataclass
class Worker:
    """A robot's memory between control steps."""

    rng: random.Random
    area: int | None = None
    since: int = 0
    visited: list[int] = field(default_factory=list)


class AreaProgram:
    """The robots' program: claim an OPEN area, keep the claim SETTLE steps, visit VISIT steps, mark it DONE."""

    SETTLE = 30
    VISIT = 20

    def __init__(self, areas: list[int]) -> None:
        self.areas = areas
        self.workers: dict[int, Worker] = {}
        self.visits: dict[int, list[int]] = {area: [] for area in areas}  # who visited each area

    def __call__(self, robot: Stigmergy, step: int) -> None:
        me = self.workers.setdefault(robot.robot_id, Worker(random.Random(robot.robot_id)))
        robot.get(self.areas[step % len(self.areas)])  # ask around: repairs what the radio lost
        if me.area is None:
            free = [area for area in self.areas if (state := unpack(robot.entry(area))) and state[0] == OPEN]
            if free:
                me.area, me.since = me.rng.choice(free), step
                robot.put(me.area, pack(CLAIMED, robot.robot_id))
            return
        robot.get(me.area)
        if unpack(robot.entry(me.area)) != (CLAIMED, robot.robot_id):  # another robot's claim won
            me.area = None
        elif step - me.since == self.SETTLE:
            self.visits[me.area].append(robot.robot_id)
        elif step - me.since >= self.SETTLE + self.VISIT:
            robot.put(me.area, pack(DONE, robot.robot_id))
            me.area = None


def main() -> int:
    args = example_arguments(__doc__, 30.0, lambda parser: parser.add_argument("--areas", type=int, default=16))
    areas = list(range(FIRST_AREA, FIRST_AREA + args.areas))
    if args.links:
        with vstig_hw.join(*args.links, robot_id=args.robot_id) as swarm:
            done = supervise(swarm, areas, args.seconds)
        return 0 if len(done) == len(areas) else 1
    program = AreaProgram(areas)
    with VirtualRobots(can_ids=range(1, 7), radio_ids=range(7, 13), program=program, drop=0.1) as robots, \
            vstig_hw.join(*robots.links, robot_id=args.robot_id) as swarm:
        done = supervise(swarm, areas, args.seconds)
    twice = {area: who for area, who in program.visits.items() if len(who) > 1}
    unvisited = [area for area, who in program.visits.items() if not who]
    wrong = {area: robot for area, robot in done.items() if program.visits[area] != [robot]}
    print(f"visited twice: {twice or 'none'}; never visited: {unvisited or 'none'}; "
          f"done by a robot that did not visit: {wrong or 'none'}")
    return 0 if len(done) == len(areas) and not twice and not unvisited and not wrong and not robots.errors else 1


if __name__ == "__main__":
    sys.exit(main())
