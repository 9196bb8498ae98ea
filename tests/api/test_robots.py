"""`swarm.robots()` and `swarm.watch_robots()` against robots on a python-can virtual bus (senders named), from a
thread and from asyncio."""

from __future__ import annotations

import asyncio
import threading
import time

import can
import pytest

import vstig_hw
import vstig_hw.aio
from vstig_hw import Message, Op
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway.roster import RobotState, Roster, StateChange

ME = 250
PERIOD = 0.05
SILENCED = {3, 4}


class Heartbeats:
    """Robots 1..6 on a python-can virtual bus, each writing a key of its own every period (its CAN ID names it),
    until `silence()` stops robots 3 and 4."""

    def __init__(self) -> None:
        self.channel = f"robots-api-{time.monotonic_ns()}"
        self.links = [f"can:virtual:{self.channel}"]
        self.silenced = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        with can.Bus(interface="virtual", channel=self.channel) as bus:
            step = 0
            while not self._stop.wait(PERIOD):
                step += 1
                for robot in range(1, 7):
                    if not (self.silenced.is_set() and robot in SILENCED):
                        for frame in can_framing_for(robot).encode(Message(Op.PUT, 100 + robot, step, step, robot)):
                            bus.send(frame)

    def silence(self) -> None:
        self.silenced.set()

    def __enter__(self) -> Heartbeats:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


@pytest.fixture
def robots() -> Heartbeats:
    return Heartbeats()


def test_robots_and_their_state_changes_from_a_thread(robots: Heartbeats) -> None:
    with robots, vstig_hw.join(*robots.links, robot_id=ME, period=PERIOD,
                               roster=Roster(PERIOD, gone_after=1.0)) as swarm:
        watch = swarm.watch_robots(robots=[3, 4, 5])
        end = time.monotonic() + 20
        while {view.robot for view in swarm.robots()} != set(range(1, 7)):
            assert time.monotonic() < end, swarm.robots()
            time.sleep(0.05)
        assert all(v.state is RobotState.ALIVE and v.named_by == "sender" and v.writes >= 1 for v in swarm.robots())
        robots.silence()
        changes: list[StateChange] = []
        while len(changes) < 4:
            change = watch.get(timeout=10)
            assert change is not None, changes
            changes.append(change)
        views = {view.robot: view for view in swarm.robots()}
    assert sorted((c.robot, c.old.value, c.new.value) for c in changes) == [
        (3, "alive", "quiet"), (3, "quiet", "gone"), (4, "alive", "quiet"), (4, "quiet", "gone")]
    assert views[3].state is RobotState.GONE and views[5].state is RobotState.ALIVE
    assert [v.robot for v in views.values()] == [1, 2, 5, 6, 3, 4]  # alive first, then gone, each by id
    assert watch.get(timeout=1) is None  # ended with the swarm


def test_watch_robots_from_asyncio(robots: Heartbeats) -> None:
    async def main() -> list[StateChange]:
        async with vstig_hw.aio.join(*robots.links, robot_id=ME, period=PERIOD) as swarm:
            watch = swarm.watch_robots()
            while {view.robot for view in swarm.robots()} != set(range(1, 7)):
                await asyncio.sleep(0.05)
            robots.silence()
            return [await asyncio.wait_for(watch.__anext__(), 10) for _ in range(2)]

    with robots:
        changes = asyncio.run(main())
    assert sorted((c.robot, c.new.value) for c in changes) == [(3, "quiet"), (4, "quiet")]


def test_robots_on_a_closed_swarm_say_so() -> None:
    swarm = vstig_hw.join(f"can:virtual:robots-closed-{time.monotonic_ns()}", robot_id=ME)
    swarm.close()
    with pytest.raises(vstig_hw.SwarmClosed):
        swarm.robots()
    with pytest.raises(vstig_hw.SwarmClosed):
        swarm.watch_robots()
