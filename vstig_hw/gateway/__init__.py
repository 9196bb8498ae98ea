"""The gateway: the PC's seat in the swarm (`Node`), its event loop and its ways out."""

from .node import DEFAULT_BUDGET, DEFAULT_PERIOD, Mode, Node
from .outlet import Outlet, SendWindow
from .shutdown import stop_on_signals

__all__ = ["DEFAULT_BUDGET", "DEFAULT_PERIOD", "Mode", "Node", "Outlet", "SendWindow", "stop_on_signals"]
