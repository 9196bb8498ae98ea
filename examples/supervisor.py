"""A supervisor that reacts to `on_change`: robots publish their battery level, the PC sends the low ones home.

Each robot writes its battery level (0..100) under key BATTERY + its id whenever it
changes, and obeys key HOME + its id: when that key's value grows, it goes home
and recharges to 100. The PC's callback runs for every battery change; a level
under LOW gets a confirmed put of the robot's HOME key, from inside the callback
(which never deadlocks the gateway). It stops once every robot was sent home and
came back charged.

    python examples/supervisor.py can:socketcan:can0 --robot-id 200 --robots 1-12
    python examples/supervisor.py      # 8 stand-in robots on a CAN bus and a pty radio, checked
"""

from __future__ import annotations

import sys
import threading
import time

from _args import example_arguments

import vstig_hw
from vstig_hw import Stigmergy
from vstig_hw.api import Change, NotTaken, Swarm
from vstig_hw.api.virtual import VirtualRobots

BATTERY, HOME = 200, 300
LOW = 20
CHARGED = 90  # a level the robot reports only after recharging (it may drain a little before it says so)


class Supervisor:
    """Sends a robot home once its battery is under LOW; done when every robot came back charged."""

    def __init__(self, swarm: Swarm, robots: list[int]) -> None:
        self.swarm = swarm
        self.sent: dict[int, int] = {}  # robot -> times sent home
        self.recharged: set[int] = set()
        self.robots = robots
        self.finished = threading.Event()

    def __call__(self, change: Change) -> None:
        robot, level = change.key - BATTERY, change.new.value
        if level < LOW and robot not in self.sent:
            self.sent[robot] = 1
            try:
                self.swarm.put(HOME + robot, self.sent[robot], confirm=True, timeout=1.0)
                print(f"robot {robot} at {level}%: sent home", flush=True)
            except NotTaken as error:
                print(f"robot {robot} at {level}%: not reached ({error}); trying again", flush=True)
                del self.sent[robot]
        elif level >= CHARGED and robot in self.sent and robot not in self.recharged:
            self.recharged.add(robot)
            print(f"robot {robot} is back, charged", flush=True)
            if self.recharged >= set(self.robots):
                self.finished.set()


class BatteryProgram:
    """The robots' program: drain a percent every few steps, publish the level, obey the HOME key."""

    def __init__(self) -> None:
        self.level: dict[int, int] = {}
        self.obeyed: dict[int, int] = {}

    def __call__(self, robot: Stigmergy, step: int) -> None:
        me = robot.robot_id
        level = self.level.setdefault(me, 100)
        orders = robot.get(HOME + me) or 0
        if orders > self.obeyed.get(me, 0):
            self.obeyed[me], level = orders, 100  # home, recharged
        elif step % (2 + me % 4) == 0:
            level = max(0, level - 1)
        if level != self.level[me] or step == 1:
            robot.put(BATTERY + me, level)
        self.level[me] = level


def supervise(swarm: Swarm, robots: list[int], seconds: float) -> Supervisor:
    supervisor = Supervisor(swarm, robots)
    handle = swarm.on_change(supervisor, keys=[BATTERY + robot for robot in robots])
    supervisor.finished.wait(seconds)
    handle.cancel()
    print(f"{len(supervisor.sent)} robots sent home, {len(supervisor.recharged)} back; "
          f"{handle.overflow} changes dropped", flush=True)
    return supervisor


def id_range(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def main() -> int:
    args = example_arguments(__doc__, 30.0, lambda parser: parser.add_argument(
        "--robots", type=id_range, default=None, help="the robots' ids, e.g. 1-12"))
    if args.links:
        if args.robots is None:
            args.error("--robots: name the robots to supervise, e.g. 1-12")
        with vstig_hw.join(*args.links, robot_id=args.robot_id) as swarm:
            done = supervise(swarm, args.robots, args.seconds).finished.is_set()
        return 0 if done else 1
    ids = list(range(1, 9))
    program = BatteryProgram()
    started = time.monotonic()
    with VirtualRobots(can_ids=ids[:4], radio_ids=ids[4:], program=program) as robots, \
            vstig_hw.join(*robots.links, robot_id=args.robot_id) as swarm:
        supervisor = supervise(swarm, ids, args.seconds)
    print(f"{time.monotonic() - started:.1f} s; robots obeyed: {dict(sorted(program.obeyed.items()))}")
    ok = supervisor.finished.is_set() and program.obeyed == dict.fromkeys(ids, 1) and not robots.errors
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
