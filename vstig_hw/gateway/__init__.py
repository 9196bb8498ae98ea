"""The gateway: the PC's seat in the swarm (`Node`), its event loop and its ways out."""

from .node import DEFAULT_BUDGET, DEFAULT_PERIOD, ENGINE_STATS, Mode, Node, favour_latency
from .outlet import Outlet, SendWindow
from .shutdown import stop_on_signals

__all__ = [
    "DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Mode", "Node", "Outlet", "SendWindow", "favour_latency",
    "stop_on_signals",
]
