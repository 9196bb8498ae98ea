"""The roster over a capture's time: who was heard when, and their silences (`vstig analyze --robots`).

The gateways' roster (gateway.roster), fed with each captured message at its capture
time and swept every control period of capture time, so its states and thresholds
are the live ones: a robot is quiet after `quiet_after` (and three of its usual gaps)
without a message, gone after `gone_after`. Each silence that made a robot quiet or
gone is a gap: from when it was last heard until it was heard again (or the capture
ended: open). Pure: no files, no clock.

Bounded as the roster is (`max_robots`), and at most MAX_GAPS gaps and MAX_CHANGES
state changes are kept; more are counted (`gaps_untold`, `changes_untold`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from .analysis import DEFAULT_WINDOW, NO_SENDER, Analyzer, Batch, Conflict
from .gateway.roster import DEFAULT_MAX_ROBOTS, RobotState, RobotView, Roster, StateChange
from .wire import Message

__all__ = ["MAX_CHANGES", "MAX_GAPS", "Gap", "RosterAnalyzer", "RosterHistory", "RosterReport"]

MAX_GAPS = 100_000
MAX_CHANGES = 100_000
PERIOD = 0.1  # seconds of capture time between two sweeps: the gateways' default control period


class Gap(NamedTuple):
    """`robot` was not heard from `start` (when last heard) until `end` (heard again; None: the capture ended)."""

    robot: int
    start: float
    end: float | None
    seconds: float  # until `end`, or until the capture's last message


@dataclass(frozen=True)
class RosterReport:
    robots: list[RobotView]  # as the roster stood at the capture's end (sorted by state, then id)
    gaps: list[Gap]  # by start
    changes: list[StateChange]  # in time order
    quiet_after: float
    gone_after: float
    untracked: int  # robots heard past max_robots
    gaps_untold: int
    changes_untold: int


class RosterHistory:
    def __init__(self, *, quiet_after: float | None = None, gone_after: float | None = None,
                 max_robots: int = DEFAULT_MAX_ROBOTS, period: float = PERIOD) -> None:
        self.roster = Roster(period, quiet_after=quiet_after, gone_after=gone_after, max_robots=max_robots)
        self.roster.on_change.append(self._changed)
        self.period = period
        self._next_sweep = math.nan  # capture time of the next sweep (nan: nothing heard yet)
        self._last = math.nan  # the latest capture time heard
        self._open: dict[int, float] = {}  # robot -> when its current silence began
        self._gaps: list[Gap] = []
        self._changes: list[StateChange] = []
        self.gaps_untold = self.changes_untold = 0

    def take(self, link: str, t: float, sender: int | None, message: Message) -> None:
        """One captured message, heard on `link` at capture time `t` (roughly in time order)."""
        self._advance(t)
        self.roster.take(link, t, sender, [message])

    def _advance(self, t: float) -> None:
        """Sweep every period of capture time up to `t`; over a stretch in which nothing was heard, only until
        every robot is gone (nothing changes after that until the next message)."""
        if math.isnan(self._next_sweep):
            self._next_sweep = t + self.period
        elif t > self._last:
            idle_until = self._last + self.roster.gone_after + 2 * self.period
            while self._next_sweep <= t:
                self.roster.sweep(self._next_sweep)
                self._next_sweep += self.period
                if idle_until < self._next_sweep < t:
                    self._next_sweep = t  # every robot is gone by now
        if not t <= self._last:
            self._last = t

    def _changed(self, change: StateChange) -> None:
        if len(self._changes) < MAX_CHANGES:
            self._changes.append(change)
        else:
            self.changes_untold += 1
        if change.new is RobotState.ALIVE:
            start = self._open.pop(change.robot, None)
            if start is not None:
                self._gap(Gap(change.robot, start, change.t, change.t - start))
        elif change.old is RobotState.ALIVE:
            last = self.roster.last_heard(change.robot)
            self._open[change.robot] = change.t if last is None else last

    def _gap(self, gap: Gap) -> None:
        if len(self._gaps) < MAX_GAPS:
            self._gaps.append(gap)
        else:
            self.gaps_untold += 1

    def report(self) -> RosterReport:
        """The roster at the capture's last message, the gaps (those still open until then) and the changes."""
        end = self._last
        if not math.isnan(end):
            self._advance(end)
            self.roster.sweep(end)
        for robot, start in sorted(self._open.items(), key=lambda item: item[1]):
            self._gap(Gap(robot, start, None, end - start))
        self._open.clear()
        roster = self.roster
        return RosterReport(roster.snapshot(end) if not math.isnan(end) else [],
                            sorted(self._gaps, key=lambda gap: (gap.start, gap.robot)), list(self._changes),
                            roster.quiet_after, roster.gone_after, roster.untracked, self.gaps_untold,
                            self.changes_untold)


class RosterAnalyzer(Analyzer):
    """An Analyzer that also hands every message it is given to a RosterHistory (`vstig analyze --robots`)."""

    def __init__(self, history: RosterHistory, window: float = DEFAULT_WINDOW, conflict: Conflict = "robot") -> None:
        super().__init__(window, conflict)
        self.history = history

    def add(self, batch: Batch) -> None:
        take, links, new = self.history.take, self.links, tuple.__new__
        columns = (batch.t, batch.link, batch.sender, batch.op, batch.key, batch.value, batch.timestamp, batch.robot)
        for t, link, sender, op, key, value, timestamp, robot in zip(*(c.tolist() for c in columns), strict=True):
            take(links[link], t, None if sender == NO_SENDER else sender,
                 new(Message, (op << 15 | key, value, timestamp, robot)))
        super().add(batch)
