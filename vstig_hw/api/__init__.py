"""The swarm from Python: `vstig_hw.join(...)` makes this program a swarm member (`vstig_hw.aio` for asyncio).

- `swarm`: `join` and `Swarm` (put/get/entry/has/size/keys/foreach, confirmed puts, conflict hooks);
- `changes`: `Change`, `watch` iterators and `on_change` callbacks, bounded, never holding up the gateway;
- `aio`: the same for asyncio, without blocking the event loop.

User guide: docs/how-to/python.md.
"""

from __future__ import annotations

from ..engine import Entry
from .changes import AsyncWatch, Change, OnChange, Watch
from .swarm import HearsItself, NotTaken, Swarm, SwarmClosed, join

__all__ = ["AsyncWatch", "Change", "Entry", "HearsItself", "NotTaken", "OnChange", "Swarm", "SwarmClosed", "Watch",
           "join"]
