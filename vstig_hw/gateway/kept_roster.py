"""A Node's roster, fed by the Node's own listeners: what bridge, sniff, record and the API keep.

`keep_roster(node)` listens to what passed the guard (`messages`: one call per unit,
no `Heard` built), what the guard refused (`refused`) and the ticks (`tick`: the
roster's clock, every control period). Views read `snapshot()` from any thread, and
`on_change` tells each state change on the thread that saw it (quick, never waiting).
`cancel()` stops the feeding.

Where the data path is compiled (not `VSTIG_PURE=1`), the roster takes messages and refusals
through a `RosterTally` (vstig_hw/_cext/roster.c): a compiled Path feeds it with no Python
per message, and the tally's own tick listener keeps the rates and runs the roster's sweep
only when a robot's state changes (a quiet tick runs no Python); the roster folds it in then
and on every read, and a robot heard again is told alive on the thread that folded (the
tick's, or a view's).
"""

from __future__ import annotations

import time
import weakref
from typing import TYPE_CHECKING

from ..native import native
from .roster import RobotView, Roster, StateListener

if TYPE_CHECKING:
    from .node import Node

__all__ = ["KeptRoster", "keep_roster"]


_KEPT: weakref.WeakKeyDictionary[Node, KeptRoster] = weakref.WeakKeyDictionary()


class KeptRoster:
    def __init__(self, node: Node, roster: Roster) -> None:
        self.roster = roster
        if native is not None and not roster.tallied and len(roster) == 0:
            roster.use_tally(native.RosterTally)
        messages, refused = roster.listeners()
        self.listening = node.listen(messages=messages, refused=refused, tick=roster.tally_tick() or self._sweep)
        _KEPT[node] = self

    @staticmethod
    def of(node: Node) -> KeptRoster | None:
        """The roster kept for `node` (the latest `keep_roster`), for the views built on the node alone:
        metrics, the live view, a ROS 2 topic; None if it keeps none (`--no-roster`)."""
        return _KEPT.get(node)

    def _sweep(self, _node: Node) -> None:
        self.roster.sweep(time.time())  # the clock the readers stamp what they read with

    def snapshot(self) -> list[RobotView]:
        """Every robot now, sorted by state then id (safe from any thread)."""
        return self.roster.snapshot(time.time())

    def on_change(self, listener: StateListener) -> None:
        self.roster.on_change.append(listener)

    def cancel(self) -> None:
        self.listening.cancel()
        for node, kept in list(_KEPT.items()):
            if kept is self:
                del _KEPT[node]


def keep_roster(node: Node, roster: Roster | None = None) -> KeptRoster:
    """Keep `roster` (default: one with the default thresholds for the Node's period) fed by `node`."""
    return KeptRoster(node, Roster(node.period) if roster is None else roster)
