"""A gateway's own program: each control step, GET one key it holds, round-robin.

A robot running the paper's program GETs every step, and that is what repairs
a stale neighbour: a GET carries the asker's view, and whoever holds a newer
entry answers with a PUT (or takes the asker's if it is newer, or resolves a
tie by the conflict rule). A gateway runs no program of its own, so without
this two gateways that were apart (a network partition, a restarted process)
would stay apart until someone writes again: a stale PUT gets no answer. One
GET per step, cycling over the table, makes every entry cross every link again
within `size` steps: a few bytes per step, on every link.
"""

from __future__ import annotations

from .node import Node

__all__ = ["RoundRobinGet"]


class RoundRobinGet:
    """An `on_tick` listener: GET the next key of the node's table each tick."""

    def __init__(self) -> None:
        self._cycle: list[int] = []

    def __call__(self, node: Node) -> None:
        engine = node.engine
        if engine is None or not engine.size():
            return
        if not self._cycle:
            self._cycle = sorted((key for key, _ in engine.entries()), reverse=True)
        node.get(self._cycle.pop())
