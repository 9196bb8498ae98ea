"""Who is in the swarm: per robot, where and when it was heard, what it wrote and asked, and its state.

C twin: vstig_hw/_cext/roster.c (`RosterTally`: `take`, `refuse` and the sweep's rates and state judging in C).

Pure bookkeeping, sans-I/O: a gateway feeds it what passed its guard (`take`, the
signature of the Node's `messages` listener: one call per unit, no `Heard` built),
what its guard refused (`refuse`) and the time (`sweep`, every control period);
views read `snapshot()` and are told each state change (`on_change`).

Who a robot is: the sender where the medium names one (a CAN ID's sender field, an
XBee 64-bit source, a zenoh gateway id, a BuzzKH4 frame's robot); on a medium that
names none (a cobs8 radio) the writer id of the PUTs heard, and `named_by` says which.
There, a GET names nobody (its robot field is its entry's writer, not the asker): such
GETs are counted in `unattributed`, never guessed.

States: `alive`; `quiet` once not heard for longer than `quiet_after` (default three
control periods) and than three of its own usual gaps (a robot that talks once a second
is not quiet after 0.3 s); `gone` once not heard for `gone_after`. Each change is
logged once, counted in `changes` and told to `on_change`.

Behind: a robot whose messages show an entry for a key older than the newest this
gateway has heard for it (a GET's or PUT's timestamp; an empty GET holds nothing) is
flagged `behind` on that key once that lasts `behind_after`; one message showing the
newest (or newer) clears it. On a medium naming no sender only PUTs count, so it names
the writer whose old write is still being sent.

Bounded: at most `max_robots` robots (default 4,096); a new one past that takes a
`gone` robot's place, else is counted in `untracked` and never stored. Each robot
keeps at most MAX_BEHIND_KEYS keys it lags on (more: `behind_untracked`).

Compiled (`use_tally`): the per-message half, `take` and `refuse`, is a `RosterTally`'s,
which a compiled Path feeds with no Python per message; so are the rates and the judging of
states: a sweep runs Python only when a robot's state changes (the tally's `due`), and the
tally's `tick` is a Node's tick listener that calls `sweep` only then. The roster folds what it
tallied in (`fold`) at such a sweep and every read, then keeps states, changes and views as
here. A robot heard again after going quiet or gone is told alive at the fold, with the time
it was heard.
"""

from __future__ import annotations

import array
import enum
import logging
import math
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

from ..links.link import Heard
from ..timestamps import is_newer
from ..wire import GET_BIT, KEY_MAX, Message

__all__ = ["DEFAULT_MAX_ROBOTS", "RobotState", "RobotView", "Roster", "StateChange"]

log = logging.getLogger(__name__)

DEFAULT_MAX_ROBOTS = 4096
QUIET_PERIODS = 3  # control periods of silence (and usual gaps) before a robot is quiet
GONE_PERIODS = 100  # control periods of silence before it is gone: 10 s at the default 0.1 s
BEHIND_PERIODS = 3  # control periods a robot may show an old entry before it is flagged behind
MAX_BEHIND_KEYS = 64  # keys one robot may lag on that the roster remembers
RATE_WINDOW = 1.0  # seconds: the time constant of the recent message rate
_GAP_WEIGHT = 0.25  # how fast a robot's usual gap follows its latest one


class RobotState(enum.Enum):
    ALIVE = "alive"
    QUIET = "quiet"
    GONE = "gone"


STATE_ORDER = {RobotState.ALIVE: 0, RobotState.QUIET: 1, RobotState.GONE: 2}  # how views sort, a tally counts
_ALIVE = RobotState.ALIVE


@dataclass(frozen=True)
class RobotView:
    """One robot as the roster saw it at `snapshot` time (what every view shows)."""

    robot: int
    named_by: str  # "sender": the medium named it; "writer": the writer id of the PUTs heard
    links: tuple[str, ...]
    state: RobotState
    first_heard: float
    last_heard: float
    last_heard_s: float  # seconds since, at the snapshot
    rate: float  # messages per second, recent
    messages: int
    writes: int
    gets: int
    behind: tuple[int, ...]  # keys it has shown an older entry for, longer than behind_after
    refused: int  # messages of its the guard refused
    quality: int | None  # link quality where the medium reports it (none does today)

    def as_json(self) -> dict[str, object]:
        return {"robot": self.robot, "sender": self.robot if self.named_by == "sender" else None,
                "named_by": self.named_by, "links": list(self.links), "state": self.state.value,
                "last_heard_s": round(self.last_heard_s, 3), "rate": round(self.rate, 2),
                "messages": self.messages, "writes": self.writes, "gets": self.gets,
                "behind": list(self.behind), "refused": self.refused, "quality": self.quality}


class StateChange(NamedTuple):
    """Robot `robot` went from `old` to `new` at `t` (the gateway's wall clock); `links`: where it was heard."""

    robot: int
    old: RobotState
    new: RobotState
    t: float
    links: tuple[str, ...]


class _Robot:
    __slots__ = ("behind_since", "counted", "first", "gap", "gets", "last", "links", "messages", "named",
                 "quality", "rate", "refused", "state", "who", "writes")

    def __init__(self, who: int, named: bool, t: float) -> None:
        self.who, self.named = who, named
        self.links: set[str] = set()
        self.first = self.last = t
        self.gap = 0.0  # its usual gap between units heard (0: heard once)
        self.messages = self.writes = self.gets = self.refused = 0
        self.counted = 0  # `messages` at the last sweep (the rate's count)
        self.rate = 0.0
        self.behind_since: dict[int, float] = {}  # key -> when it first showed an older entry for it
        self.quality: int | None = None
        self.state = RobotState.ALIVE


StateListener = Callable[[StateChange], None]
MessagesListener = Callable[[str, float, "int | None", list[Message]], None]
RefusedListener = Callable[[Heard, str], None]


class Tally(Protocol):
    """The roster's per-message half in C (vstig_hw._vstig.RosterTally): fed as a Node's listeners, folded in."""

    def take(self, link: str, t: float, sender: int | None, messages: list[Message], /) -> None: ...
    def __call__(self, heard: Heard, reason: str) -> None: ...
    def mark(self, robot: int, state: int, /) -> None: ...
    def due(self, now: float, /) -> bool: ...
    def tick(self, node: object, /) -> None: ...
    def fold(self) -> tuple[list[tuple[Any, ...]], list[int], int, int, int] | None: ...


# A tally's type: made with (max_robots, quiet_after, gone_after, on_due: the roster's sweep).
TallyKind = Callable[[int, float, float, Callable[[float], None]], Tally]
TickListener = Callable[[Any], None]


class Roster:
    def __init__(self, period: float = 0.1, *, quiet_after: float | None = None, gone_after: float | None = None,
                 behind_after: float | None = None, max_robots: int = DEFAULT_MAX_ROBOTS) -> None:
        self.quiet_after = QUIET_PERIODS * period if quiet_after is None else quiet_after
        self.gone_after = GONE_PERIODS * period if gone_after is None else gone_after
        self.behind_after = BEHIND_PERIODS * period if behind_after is None else behind_after
        for name, value in (("quiet_after", self.quiet_after), ("gone_after", self.gone_after),
                            ("behind_after", self.behind_after)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
        if self.gone_after <= self.quiet_after:
            raise ValueError(f"gone_after ({self.gone_after:g} s) must be longer than quiet_after "
                             f"({self.quiet_after:g} s)")
        if max_robots < 1:
            raise ValueError(f"max_robots must be at least 1, got {max_robots!r}")
        self.max_robots = max_robots
        self._robots: dict[int, _Robot] = {}
        self._newest = array.array("H", bytes(2 * (KEY_MAX + 1)))  # key -> newest timestamp heard (0: none)
        self.untracked = 0  # robots heard while the roster was full of robots not gone
        self.behind_untracked = 0  # keys a robot lagged on past MAX_BEHIND_KEYS
        self.unattributed = 0  # messages naming nobody: GETs on a medium that names no sender
        self.changes: Counter[str] = Counter()  # "alive->quiet": how often
        self.on_change: list[StateListener] = []
        self._swept = math.nan  # when `sweep` last ran
        self._gone = 0  # robots tracked whose state is gone
        self._tally: Tally | None = None  # the per-message half in C, if the data path is compiled
        self._folding = threading.RLock()  # one fold or sweep at a time (the Node's thread, a view's)

    # -- how it is fed ---------------------------------------------------------------------
    def use_tally(self, kind: TallyKind) -> None:
        """Take messages and refusals, and keep rates and judge states, through a tally of `kind` (RosterTally)
        made for this roster, before it is fed."""
        if self._robots or self._tally is not None:
            raise ValueError("a roster takes a tally before it is fed, once")
        self._tally = kind(self.max_robots, self.quiet_after, self.gone_after, self.sweep)

    @property
    def tallied(self) -> bool:
        """Whether a tally in C takes what it is fed."""
        return self._tally is not None

    def listeners(self) -> tuple[MessagesListener, RefusedListener]:
        """What feeds it, as a Node's `messages` and `refused` listeners: its tally's (C), or its own `take`
        and `refuse`."""
        if self._tally is None:
            return self.take, self.refuse
        return self._tally.take, self._tally

    def tally_tick(self) -> TickListener | None:
        """Its tally's tick (a Node's `tick` listener in C: the wall clock, the rates, and `sweep` only when a state
        changes); None without a tally."""
        return None if self._tally is None else self._tally.tick

    def fold(self) -> None:
        """What the tally took since the last fold, into the robots (no-op without a tally)."""
        tally = self._tally
        if tally is None:
            return
        with self._folding:
            folded = tally.fold()
            if folded is None:  # nothing heard since
                return
            records, evicted, self.untracked, self.behind_untracked, self.unattributed = folded
            robots = self._robots
            for who in evicted:
                forgotten = robots.pop(who, None)
                if forgotten is not None and forgotten.state is RobotState.GONE:
                    self._gone -= 1
            for (who, named, fresh, first, last, gap, rate, messages, writes, gets, refused, links, revived,
                 behind) in records:
                robot = robots.get(who)
                if robot is None or fresh:
                    robot = robots[who] = _Robot(who, named, first)
                robot.last, robot.gap, robot.rate, robot.messages, robot.writes = last, gap, rate, messages, writes
                robot.gets, robot.refused, robot.links, robot.behind_since = gets, refused, set(links), dict(behind)
                if revived is not None and robot.state is not _ALIVE:
                    self._change(robot, _ALIVE, *revived)  # when it was heard again, and where it had been heard

    # -- what the gateway heard: the hot path ---------------------------------------------
    # Per unit: one dict lookup and a few attributes; per message: its op and one timestamp compared with the
    # newest of its key (RFC 1982 order, `is_newer`, written out: a call per message would cost a third more).
    def take(self, link: str, t: float, sender: int | None, messages: list[Message]) -> None:
        """What one unit carried past the guard (the Node's `messages` listener)."""
        if sender is None:
            self._take_writers(link, t, messages)
            return
        robot = self._robots.get(sender)
        if robot is None:
            robot = self._new(sender, True, t)
            if robot is None:
                return
        if t != robot.last:
            self._heard_at(robot, t)
        count = len(messages)
        robot.messages += count
        if link not in robot.links:
            robot.links.add(link)
        if robot.state is not _ALIVE:
            self._change(robot, _ALIVE, t)
        newest = self._newest
        behind = robot.behind_since
        gets = 0
        for word, _value, ts, _writer in messages:
            gets += word >> 15
            key = word & KEY_MAX
            held = newest[key]
            if ts == held:
                if behind:
                    behind.pop(key, None)
                continue
            distance = (ts - held) & 0xFFFF
            if ts and (not held or 0 < distance < 0x8000 or (distance == 0x8000 and ts > held)):  # is_newer
                newest[key] = ts
                if behind:
                    behind.pop(key, None)
            elif key not in behind:  # older, or an empty GET while the key holds an entry
                self._lags(robot, key, t)
        robot.gets += gets
        robot.writes += count - gets

    def _take_writers(self, link: str, t: float, messages: list[Message]) -> None:
        """A unit from a medium that names no sender: each PUT is its writer's; GETs name nobody."""
        robots = self._robots
        newest = self._newest
        for msg in messages:
            word, _value, ts, writer = msg
            if word & GET_BIT:
                self.unattributed += 1
                continue
            robot = robots.get(writer)
            if robot is None:
                robot = self._new(writer, False, t)
                if robot is None:
                    continue
            if t != robot.last:
                self._heard_at(robot, t)
            robot.messages += 1
            robot.writes += 1
            if link not in robot.links:
                robot.links.add(link)
            if robot.state is not _ALIVE:
                self._change(robot, _ALIVE, t)
            key = word & KEY_MAX
            held = newest[key]
            behind = robot.behind_since
            if ts == held or is_newer(ts, held):
                newest[key] = ts
                if behind:
                    behind.pop(key, None)
            elif key not in behind:
                self._lags(robot, key, t)

    @staticmethod
    def _heard_at(robot: _Robot, t: float) -> None:
        gap = t - robot.last
        if gap > 0:
            robot.gap += (gap - robot.gap) * _GAP_WEIGHT if robot.gap else gap
        robot.last = t

    def _lags(self, robot: _Robot, key: int, t: float) -> None:
        """`robot` showed an entry for `key` older than the newest heard, from `t` on (bounded per robot)."""
        if len(robot.behind_since) < MAX_BEHIND_KEYS:
            robot.behind_since[key] = t
        else:
            self.behind_untracked += 1

    def refuse(self, heard: Heard, reason: str) -> None:
        """A message the guard refused (the Node's `refused` listener): counted to whoever it names."""
        msg = heard.message
        who, named = (heard.sender, True) if heard.sender is not None else (msg.robot, False)
        if heard.sender is None and msg[0] & GET_BIT:
            self.unattributed += 1
            return
        robot = self._robots.get(who) or self._new(who, named, heard.t)
        if robot is not None:
            robot.refused += 1

    def _new(self, who: int, named: bool, t: float) -> _Robot | None:
        robots = self._robots
        if len(robots) >= self.max_robots and not self._evict_gone():
            self.untracked += 1
            return None
        robot = robots[who] = _Robot(who, named, t)
        return robot

    def _evict_gone(self) -> bool:
        """Forget the gone robot heard longest ago, to make room; False if none is gone."""
        if not self._gone:  # a flood of new ids into a full roster of live robots costs no scan
            return False
        oldest = min((r for r in self._robots.values() if r.state is RobotState.GONE), key=lambda r: r.last)
        del self._robots[oldest.who]
        self._gone -= 1
        return True

    # -- time ------------------------------------------------------------------------
    def sweep(self, now: float) -> None:
        """The time is `now` (the gateway's clock, as `take`'s): rates, states, and who is behind."""
        with self._folding:  # a view's fold tells no return between this sweep's reading and its changes
            tally = self._tally
            if tally is not None and not tally.due(now):  # it moved the rates on; no state changes
                return
            self.fold()
            self._judge(now)

    def _judge(self, now: float) -> None:
        dt = now - self._swept
        rates = self._tally is None  # else the tally's `due` keeps them
        smoothing = 1.0 - math.exp(-dt / RATE_WINDOW) if rates and dt > 0 else 0.0  # nan on the first sweep: no rate
        for robot in list(self._robots.values()):
            if smoothing:
                heard = robot.messages - robot.counted
                robot.rate += (heard / dt - robot.rate) * smoothing
                robot.counted = robot.messages
            silent = now - robot.last
            if silent > self.gone_after:
                state = RobotState.GONE
            elif silent > self.quiet_after and silent > QUIET_PERIODS * robot.gap:
                state = RobotState.QUIET
            else:
                state = RobotState.ALIVE
            if state is not robot.state:
                self._change(robot, state, now)
        if not dt <= 0:  # (nan on the first sweep)
            self._swept = now

    def _change(self, robot: _Robot, state: RobotState, t: float, heard_on: list[str] | None = None) -> None:
        old, robot.state = robot.state, state
        self._gone += (state is RobotState.GONE) - (old is RobotState.GONE)
        if self._tally is not None:
            self._tally.mark(robot.who, STATE_ORDER[state])  # what its `due` judges against; only gone ones make room
        self.changes[f"{old.value}->{state.value}"] += 1
        links = tuple(sorted(robot.links if heard_on is None else heard_on))
        log.info("robot %d (%s on %s): %s -> %s", robot.who, "sender" if robot.named else "writer",
                 ", ".join(links), old.value, state.value)
        change = StateChange(robot.who, old, state, t, links)
        for listener in self.on_change:
            listener(change)

    # -- what views read --------------------------------------------------------------
    def __len__(self) -> int:
        self.fold()
        return len(self._robots)

    def snapshot(self, now: float) -> list[RobotView]:
        """Every robot tracked, sorted by state (alive, quiet, gone) then id."""
        # Copies taken in one step each (a C-level list of a dict or a set), so that a view may be made on
        # another thread than the one feeding the roster: what it shows may be a message old, never torn.
        self.fold()
        views = [self._view(robot, now) for robot in list(self._robots.values())]
        views.sort(key=lambda v: (STATE_ORDER[v.state], v.robot))
        return views

    def _view(self, robot: _Robot, now: float) -> RobotView:
        lag = self.behind_after
        behind = tuple(sorted(key for key, since in list(robot.behind_since.items()) if now - since >= lag))
        return RobotView(robot.who, "sender" if robot.named else "writer", tuple(sorted(robot.links)), robot.state,
                         robot.first, robot.last, max(0.0, now - robot.last), robot.rate, robot.messages,
                         robot.writes, robot.gets, behind, robot.refused, robot.quality)

    def last_heard(self, robot: int) -> float | None:
        """When `robot` was last heard (`take`'s clock); None if it is not tracked."""
        self.fold()
        tracked = self._robots.get(robot)
        return None if tracked is None else tracked.last

    def counts(self) -> dict[tuple[str, RobotState], int]:
        """(link, state) -> robots in that state heard on that link (the metrics' series: not one per robot)."""
        self.fold()
        out: Counter[tuple[str, RobotState]] = Counter()
        for robot in list(self._robots.values()):
            for link in sorted(robot.links):
                out[link, robot.state] += 1
        return dict(out)
