"""One filter for every command that reads or writes captures: record, decode, replay, analyze.

A `Filter` keeps a message when every criterion given holds: its key, the robot
of its entry, the node that sent it (where the medium names one: a CAN frame's
ID), its op, its link, and its time in seconds after the first record
(`since <= t < until`). `accepts` is the definition; `mask` is the same test
over numpy columns, for analyze's batches (tests hold the two equal).

Captures hold link units, not messages: `decoded.RecordFilter` applies a
`Filter` along a capture, with the decoder that turns its units into messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..wire import KEY_MAX, Message, Op

if TYPE_CHECKING:  # numpy comes with the analyze extra; record, replay and decode filter without it
    import numpy as np
    import numpy.typing as npt

__all__ = ["Filter"]

Set = frozenset[int] | None


@dataclass(frozen=True)
class Filter:
    keys: Set = None
    robots: Set = None  # the robot field of the entry (who wrote it)
    senders: Set = None  # the node that sent the message: a CAN frame's sender field
    ops: frozenset[Op] | None = None
    links: frozenset[str] | None = None
    since: float | None = None  # seconds after the first record
    until: float | None = None

    @property
    def by_message(self) -> bool:
        """Whether a unit must be decoded to decide (anything beyond link and time)."""
        return any(c is not None for c in (self.keys, self.robots, self.senders, self.ops))

    def __bool__(self) -> bool:
        return self.by_message or any(c is not None for c in (self.links, self.since, self.until))

    def accepts_unit(self, t: float, link: str) -> bool:
        """The link and time criteria alone; `t` in seconds after the first record."""
        return ((self.links is None or link in self.links) and (self.since is None or t >= self.since)
                and (self.until is None or t < self.until))

    def accepts(self, t: float, link: str, sender: int | None, message: Message) -> bool:
        head, _, _, robot = message
        return (self.accepts_unit(t, link)
                and (self.keys is None or head & KEY_MAX in self.keys)
                and (self.robots is None or robot in self.robots)
                and (self.senders is None or sender in self.senders)
                and (self.ops is None or Op(head >> 15) in self.ops))

    def mask(self, t: npt.NDArray[np.float64], link: npt.NDArray[np.int64], link_names: Sequence[str],
             sender: npt.NDArray[np.int64], op: npt.NDArray[np.int64], key: npt.NDArray[np.int64],
             robot: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        """`accepts` over columns (t after the first record; link as indices into `link_names`; sender -1: none)."""
        import numpy as np

        keep = np.ones(len(t), dtype=bool)
        if self.links is not None:
            wanted = [i for i, name in enumerate(link_names) if name in self.links]
            keep &= np.isin(link, wanted)
        if self.since is not None:
            keep &= t >= self.since
        if self.until is not None:
            keep &= t < self.until
        for column, wanted_values in ((key, self.keys), (robot, self.robots), (sender, self.senders)):
            if wanted_values is not None:
                keep &= np.isin(column, list(wanted_values))
        if self.ops is not None:
            keep &= np.isin(op, [int(o) for o in self.ops])
        return keep
