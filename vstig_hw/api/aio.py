"""The swarm from asyncio: `async with vstig_hw.aio.join(...) as swarm`.

The same Swarm underneath, its gateway on its own thread; what waits for that
thread (a put, a get, a confirmed put) is awaited as a Future it completes, so
no call blocks the event loop and no executor thread is spent per call. Opening
and closing (links may take a moment to open) run in a worker thread.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from ..counters import Counters
from ..engine import ConflictLost, ConflictResolver, Entry
from ..gateway.guard import DEFAULT_MAX_JUMP, Guard
from ..gateway.node import DEFAULT_BUDGET, DEFAULT_PERIOD
from ..gateway.roster import RobotView, Roster, StateChange
from ..values import ValueType
from .changes import DEFAULT_BUFFER, AsyncWatch, Change
from .recording import Recording
from .swarm import DEFAULT_WAIT, LinkLike, Swarm, SwarmClosed, check_key, checked_keys
from .swarm import join as join_sync

__all__ = ["AsyncSwarm", "join"]

T = TypeVar("T")


class AsyncSwarm:
    """A Swarm for asyncio code: `async with` joins and leaves; calls that wait are coroutines.

    `entry`, `has` and `size` read the table at once and stay plain methods.
    `sync` is the underlying Swarm, for code that runs in threads.
    """

    def __init__(self, opener: Callable[[], Swarm]) -> None:
        self._opener = opener
        self._swarm: Swarm | None = None

    async def open(self) -> AsyncSwarm:
        """Join: open every link and start the gateway thread (`async with` does it)."""
        if self._swarm is not None:
            raise SwarmClosed("this swarm was opened once already; join again for a new one")
        self._swarm = await asyncio.to_thread(self._opener)
        return self

    async def close(self) -> None:
        """Leave the swarm; every watch ends."""
        if self._swarm is not None:
            await asyncio.to_thread(self._swarm.close)

    async def __aenter__(self) -> AsyncSwarm:
        return await self.open()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def sync(self) -> Swarm:
        """The underlying thread-safe Swarm."""
        if self._swarm is None:
            raise SwarmClosed("the swarm is not open yet: use `async with vstig_hw.aio.join(...) as swarm`")
        return self._swarm

    async def put(self, key: int, value: float | str, *, confirm: bool = False, timeout: float = DEFAULT_WAIT,
                  tries: int = 3, learn: float = 0.0) -> Entry:
        """As `Swarm.put`: the entry written; with `confirm`, the one a neighbour took, else NotTaken."""
        swarm = self.sync
        if not confirm:
            swarm._raw(key, value)  # bad input raises here, not in the gateway
            return await self._wait(lambda: swarm.put(key, value))
        result = await asyncio.wrap_future(swarm.put_future(key, value, timeout=timeout, tries=tries, learn=learn))
        return swarm.taken(key, result, timeout)

    async def get(self, key: int) -> float | None:
        """As `Swarm.get`: our value (None if unknown), and a GET broadcast."""
        swarm = self.sync
        check_key(key)
        return await self._wait(lambda: swarm.get(key))

    def entry(self, key: int) -> Entry | None:
        """As `Swarm.entry` (no waiting)."""
        return self.sync.entry(key)

    def has(self, key: int) -> bool:
        """As `Swarm.has` (no waiting)."""
        return self.sync.has(key)

    def size(self) -> int:
        """As `Swarm.size` (no waiting)."""
        return self.sync.size()

    async def items(self) -> list[tuple[int, Entry]]:
        """As `Swarm.items`: a snapshot of every (key, entry)."""
        swarm = self.sync
        return await self._wait(swarm.items)

    async def keys(self) -> list[int]:
        """As `Swarm.keys`."""
        return [key for key, _ in await self.items()]

    async def stats(self) -> dict[str, Counters]:
        """As `Swarm.stats`."""
        return await asyncio.to_thread(self.sync.stats)

    def watch(self, keys: Iterable[int] | None = None, *, buffer: int = DEFAULT_BUFFER) -> AsyncWatch[Change]:
        """As `Swarm.watch`, as an async iterator on the running loop: `async for change in swarm.watch()`."""
        swarm = self.sync
        watch: AsyncWatch[Change] = AsyncWatch(checked_keys(keys), buffer)
        swarm._subscribe(watch)
        return watch

    def robots(self) -> list[RobotView]:
        """As `Swarm.robots` (a snapshot taken at once: a plain method)."""
        return self.sync.robots()

    def watch_robots(self, robots: Iterable[int] | None = None, *,
                     buffer: int = DEFAULT_BUFFER) -> AsyncWatch[StateChange]:
        """As `Swarm.watch_robots`, as an async iterator: `async for change in swarm.watch_robots()`."""
        swarm = self.sync
        watch: AsyncWatch[StateChange] = AsyncWatch(None if robots is None else list(robots), buffer)
        swarm._subscribe_robots(watch)
        return watch

    def onconflict(self, rule: ConflictResolver) -> ConflictResolver:
        """As `Swarm.onconflict` (the rule runs on the gateway thread: a plain function)."""
        return self.sync.onconflict(rule)

    def onconflictlost(self, hook: ConflictLost | None) -> ConflictLost | None:
        """As `Swarm.onconflictlost` (runs on the gateway thread: a plain function)."""
        return self.sync.onconflictlost(hook)

    async def stigmergy(self, table: int) -> AsyncSwarm:
        """As `Swarm.stigmergy`: table `table` on the same media (its links open in a worker thread)."""
        swarm = self.sync
        tables = AsyncSwarm(lambda: swarm.stigmergy(table))
        return await tables.open()

    def record(self, path: str | os.PathLike[str], *, overwrite: bool = False,
               max_bytes: int | None = None) -> Recording:
        """As `Swarm.record`: start recording what the links hear into `path`."""
        return self.sync.record(path, overwrite=overwrite, max_bytes=max_bytes)

    async def _wait(self, call: Callable[[], T]) -> T:
        return await asyncio.wrap_future(self.sync.submit(call))


def join(*links: LinkLike, robot_id: int, period: float = DEFAULT_PERIOD, budget: int | None = DEFAULT_BUDGET,
         max_jump: int | None = DEFAULT_MAX_JUMP, guard: Guard | None = None,
         onconflict: ConflictResolver | None = None, onconflictlost: ConflictLost | None = None,
         refresh: bool = True, value_type: ValueType = "uint16", roster: Roster | None = None,
         swarm_key: str | os.PathLike[str] | None = None) -> AsyncSwarm:
    """`vstig_hw.join`'s arguments; an AsyncSwarm that joins on `async with` (or `await swarm.open()`)."""
    options: dict[str, Any] = {"robot_id": robot_id, "period": period, "budget": budget, "max_jump": max_jump,
                               "guard": guard, "onconflict": onconflict, "onconflictlost": onconflictlost,
                               "refresh": refresh, "value_type": value_type, "roster": roster,
                               "swarm_key": swarm_key}
    return AsyncSwarm(lambda: join_sync(*links, **options))
