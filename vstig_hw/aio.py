"""The swarm from asyncio: `async with vstig_hw.aio.join(...) as swarm` (see `vstig_hw.api.aio`)."""

from __future__ import annotations

from .api.aio import AsyncSwarm, join

__all__ = ["AsyncSwarm", "join"]
