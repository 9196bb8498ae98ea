"""The gateway: the PC's seat in the swarm (`Node`), its event loop and its ways out; what a new part or
listener builds on is `Node`'s own API (`listen` -> `Listening`, `submit`, `drain`, `close`: see `node`, which
names the collaborators it composes)."""

from .latency import favour_latency
from .node import (
    CLOSE_DRAIN,
    DEFAULT_BUDGET,
    DEFAULT_PERIOD,
    ENGINE_STATS,
    Listening,
    Mode,
    Node,
    SwarmClosed,
)
from .outlet import Outlet, SendWindow
from .refresh import RoundRobinGet
from .shutdown import stop_on_signals

__all__ = [
    "CLOSE_DRAIN", "DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Listening", "Mode", "Node", "Outlet",
    "RoundRobinGet", "SendWindow", "SwarmClosed", "favour_latency", "stop_on_signals",
]
