"""vstig_hw.aio against robots on a python-can virtual bus and a pty radio: awaited calls never block the loop."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

import vstig_hw.aio
from vstig_hw import Entry, Stigmergy
from vstig_hw.api import AsyncWatch, Change, NotTaken, SwarmClosed
from vstig_hw.api.virtual import VirtualRobots

ME = 60


def reading(robot: Stigmergy, step: int) -> None:
    robot.get(1)


async def ticking(ticks: list[float], until: asyncio.Event) -> None:
    """Count how often the loop gets to run this: a blocked loop makes gaps."""
    while not until.is_set():
        ticks.append(time.monotonic())
        await asyncio.sleep(0.005)


def test_await_put_confirm_get_and_async_for_change() -> None:
    async def main(robots: VirtualRobots) -> None:
        async with vstig_hw.aio.join(*robots.links, robot_id=ME, period=0.02) as swarm:
            done = asyncio.Event()
            ticks: list[float] = []
            ticker = asyncio.create_task(ticking(ticks, done))
            watch = swarm.watch(keys=[7])
            started = time.monotonic()
            taken = await swarm.put(1, 1500, confirm=True, timeout=2.0)
            assert taken == Entry(1500, 1, ME)
            assert await swarm.get(1) == 1500 and swarm.entry(1) == taken and swarm.has(1)
            robots.robot(3).put(7, 70)
            change = await asyncio.wait_for(watch.__anext__(), 5.0)
            assert (change.key, change.new, change.sender) == (7, Entry(70, 1, 3), None)  # a pty names no sender
            assert sorted(await swarm.keys()) == [1, 7, 9] and swarm.size() == 3  # the robots' key 9 too
            with pytest.raises(NotTaken):  # the robots keep writing key 9: awaited, not blocking
                await swarm.put(9, 1, confirm=True, timeout=0.6, tries=1)
            done.set()
            await ticker
            elapsed = time.monotonic() - started
            gaps = [b - a for a, b in itertools.pairwise(ticks)]
            assert max(gaps) < 0.4, max(gaps)  # the loop ran all along (a blocking put would stop it >= 0.6 s)
            assert len(ticks) > elapsed / 0.05
        async for _ in watch:  # it ends with the swarm
            pytest.fail("a watch of a closed swarm yields nothing")
        with pytest.raises(SwarmClosed):
            await swarm.put(1, 1)

    def stubborn(robot: Stigmergy, step: int) -> None:
        robot.get(1)
        for _ in range(5):  # every robot writes key 9 over and over: ours is always older when it arrives
            robot.put(9, 777)

    with VirtualRobots(can_ids=[1, 2], radio_ids=[3], program=stubborn) as robots:
        asyncio.run(main(robots))


def test_a_slow_async_reader_loses_the_oldest_counted() -> None:
    async def main(robots: VirtualRobots) -> None:
        async with vstig_hw.aio.join(*robots.links, robot_id=ME) as swarm:
            watch = swarm.watch(buffer=4)
            for key in range(10):
                await swarm.put(key, key)
            assert watch.overflow == 6
            assert [change.key async for change in _take(watch, 4)] == [6, 7, 8, 9]

    with VirtualRobots(can_ids=[1]) as robots:
        asyncio.run(main(robots))


async def _take(watch: AsyncWatch, n: int) -> AsyncIterator[Change]:
    for _ in range(n):
        yield await watch.__anext__()


def test_an_async_swarm_opens_another_table_and_records(tmp_path: Path) -> None:
    async def main() -> None:
        channel = f"aio-tables-{time.monotonic_ns()}"
        async with vstig_hw.aio.join(f"can:virtual:{channel}?extended=1", robot_id=ME) as swarm:
            table = await swarm.stigmergy(2)
            recording = swarm.record(tmp_path / "t.log")
            await swarm.put(1, 10)
            await table.put(1, 20)
            assert swarm.entry(1) == Entry(10, 1, ME) and table.entry(1) == Entry(20, 1, ME)
            recording.stop()
        assert table.sync.closed

    asyncio.run(main())
