"""The paper's Figure 1 with this PC as a member: the swarm agrees on the highest robot id.

Every member runs the same program each control step: read the key; while it holds
less than our own id, write our id. Conflicts (two writes at one timestamp) go to
the larger value. The PC joins with an id above every robot's, so the answer is
its own and has to reach every robot on every link.

    python examples/figure1.py can:socketcan:can0 serial:/dev/ttyUSB0 --robot-id 200
    python examples/figure1.py        # 30 stand-in robots on a CAN bus and a lossy pty radio, checked
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from _args import example_arguments

import vstig_hw
from vstig_hw.api import Swarm
from vstig_hw.api.virtual import FIGURE1_KEY, VirtualRobots, figure1
from vstig_hw.engine import larger_value_wins

KEY = FIGURE1_KEY


def play(swarm: Swarm, seconds: float, settled: Callable[[], bool] = lambda: False) -> float | None:
    """Run Figure 1 for up to `seconds` (or until `settled()`); the value the PC holds at the end."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and not settled():
        highest = swarm.get(KEY)
        if highest is None or highest < swarm.robot_id:
            swarm.put(KEY, swarm.robot_id)
        time.sleep(0.05)
    return swarm.get(KEY)


def holding(robots: VirtualRobots, value: int) -> int:
    """How many stand-in robots hold `value` under the key."""
    return sum(1 for robot in robots.robots if (entry := robot.entry(KEY)) is not None and entry.value == value)


def main() -> int:
    args = example_arguments(__doc__, 20.0)
    if args.links:
        with vstig_hw.join(*args.links, robot_id=args.robot_id, onconflict=larger_value_wins) as swarm:
            print(f"the swarm agrees on {play(swarm, args.seconds)}")
        return 0
    with VirtualRobots(can_ids=range(1, 16), radio_ids=range(16, 31), program=figure1,
                       onconflict=larger_value_wins, drop=0.3) as robots, \
            vstig_hw.join(*robots.links, robot_id=args.robot_id, onconflict=larger_value_wins) as swarm:
        started = time.monotonic()
        target = max(args.robot_id, 30)

        held = play(swarm, args.seconds, lambda: holding(robots, target) == len(robots.robots))
        agreed = holding(robots, target)
        print(f"after {time.monotonic() - started:.1f} s the PC holds {held}; {agreed} of {len(robots.robots)} "
              f"robots hold {target}")
        return 0 if held == target and agreed == len(robots.robots) and not robots.errors else 1


if __name__ == "__main__":
    sys.exit(main())
