"""The swarm from Python: `vstig_hw.join(...)` makes this program a swarm member (`vstig_hw.aio` for asyncio).

- `swarm`: `join` and `Swarm` (put/get/entry/has/size/keys/foreach, confirmed puts, conflict hooks);
- `changes`: `Change`, `watch` iterators and `on_change` callbacks, bounded, never holding up the gateway;
- who is in the swarm: `swarm.robots()` (`RobotView`s), `swarm.watch_robots()` (`StateChange`s), a `Roster`'s
  thresholds for `join(roster=)`;
- `aio`: the same for asyncio, without blocking the event loop.

Every exception a program must catch is here and in `vstig_hw`: `TransportError` (a link
cannot open: `join`), `CaptureError` (a recording cannot be written), `NotTaken` and
`HearsItself` (a confirmed put), `SwarmClosed` (any call once the swarm closed).

User guide: docs/how-to/python.md.
"""

from __future__ import annotations

from ..capture.records import CaptureError
from ..engine import Entry
from ..gateway.confirm import PutResult, Verdict
from ..gateway.roster import RobotState, RobotView, Roster, StateChange
from ..transports.base import TransportError
from .changes import AsyncWatch, Change, OnChange, Watch
from .swarm import HearsItself, NotTaken, Swarm, SwarmClosed, join

__all__ = ["AsyncWatch", "CaptureError", "Change", "Entry", "HearsItself", "NotTaken", "OnChange", "PutResult",
           "RobotState", "RobotView", "Roster", "StateChange", "Swarm", "SwarmClosed", "TransportError", "Verdict",
           "Watch", "join"]
