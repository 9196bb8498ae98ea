"""The virtual-stigmergy protocol engine: sans-I/O, deterministic.

C twin: vstig_hw/_cext/engine.c (Engine); held equal by tests/native (index: vstig_hw/_vstig.pyi).

Feed it what the radios heard (`receive`), call `put`/`get` as the robot's
program does, and broadcast whatever `drain` hands back. It owns no socket,
thread or clock, so the simulator, the gateway and the tests drive the same code.

Where the paper is silent we decide, and say so here:

* A GET carrying timestamp 0 means "I have nothing". If we hold the key we answer
  with a PUT; if we don't, we drop it (`Outcome.UNKNOWN`). Buzz relays it, but two
  robots that both lack a key would then bounce the query between them for ever;
  the asker's next `get` asks again anyway.
* A PUT with timestamp 0 is malformed (0 is reserved) and dropped (`INVALID`).
* Same timestamp and same robot is the same write: nothing happens, even when
  the value differs (only a robot that restarted and reused its counter can do
  that, and neither copy is more right than the other).
* A conflict winner that is neither entry (a merge) is a new write of the robot
  it names, at the next timestamp; the other robots keep that robot's entry.
  Keeping the local timestamp, as Buzz does, lets two robots hold one
  (timestamp, robot) with different values, and then never agree.
* `onconflictlost` fires when the entry we held was our write and the winner is
  not ours: once per lost write, not again when its echo comes back.

Every difference from Buzz, with the test that pins it, is tabled in
firmware_spec/DECISIONS.md.

The table stores each entry as the PUT message that carries it, so re-broadcasts
and answers cost no allocation; `receive` reads messages by their wire words.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterator
from typing import NamedTuple

from .outqueue import OutQueue
from .timestamps import TS_NONE, is_newer, next_timestamp
from .wire import GET_BIT, KEY_MAX, U16_MAX, Message, Op, check_field

__all__ = ["Entry", "Outcome", "Stigmergy", "higher_robot_wins", "larger_value_wins", "sum_merge"]


class Entry(NamedTuple):
    value: int
    timestamp: int
    robot: int


ConflictResolver = Callable[[int, Entry, Entry], Entry]
ConflictLost = Callable[[int, Entry], None]


class Outcome(enum.IntEnum):
    """What `receive` did with a message (also the engine's counter names)."""

    STORED = 0  # remote was newer: stored and queued for re-broadcast
    ANSWERED = 1  # a GET older than ours: queued a PUT of our entry
    STALE = 2  # a PUT older than ours: ignored
    SAME = 3  # same timestamp, same robot: nothing to do
    CONFLICT = 4  # same timestamp, other robot: resolved, winner queued
    UNKNOWN = 5  # an empty GET for a key we don't hold
    INVALID = 6  # a PUT with the reserved timestamp 0


def higher_robot_wins(key: int, local: Entry, remote: Entry) -> Entry:
    """Buzz's default conflict rule."""
    return remote if remote.robot > local.robot else local


def larger_value_wins(key: int, local: Entry, remote: Entry) -> Entry:
    """The paper's Figure 1 rule: larger value, then larger robot id."""
    return remote if (remote.value, remote.robot) > (local.value, local.robot) else local


def sum_merge(key: int, local: Entry, remote: Entry) -> Entry:
    """A merging rule: the sum of the values (mod 2**16), named for the higher robot.

    The shape every merging rule needs: the robot it names is one of the two
    writers, picked by an order on robot ids whichever entry is local.
    """
    return Entry((local.value + remote.value) & U16_MAX, local.timestamp, max(local.robot, remote.robot))


_new = tuple.__new__
_STORED, _ANSWERED, _STALE, _SAME, _CONFLICT, _UNKNOWN, _INVALID = Outcome


def _as_put(key: int, value: int, timestamp: int, robot: int) -> Message:
    return _new(Message, (key, value, timestamp, robot))


class Stigmergy:
    """One robot's view of one virtual stigmergy."""

    def __init__(
        self,
        robot_id: int,
        onconflict: ConflictResolver | None = None,
        onconflictlost: ConflictLost | None = None,
    ) -> None:
        check_field("robot_id", U16_MAX, robot_id)
        self.robot_id = robot_id
        self.onconflict: ConflictResolver = onconflict or higher_robot_wins
        self.onconflictlost = onconflictlost
        self._counts = [0] * len(Outcome)
        self._table: dict[int, Message] = {}
        self._outbox = OutQueue()

    # -- the robot's program -------------------------------------------------
    def put(self, key: int, value: int) -> None:
        """Write locally (timestamp old + 1, or 1) and queue a PUT."""
        _check(key, value)
        local = self._table.get(key)
        timestamp = next_timestamp(local[2]) if local else 1
        self._table[key] = stored = _as_put(key, value, timestamp, self.robot_id)
        self._outbox.push(stored)

    def get(self, key: int) -> int | None:
        """The local value (None if unknown); queues a GET carrying our view."""
        if type(key) is not int or not 0 <= key <= KEY_MAX:  # the hot path: every robot, every step
            _check(key, 0)
        local = self._table.get(key)
        if local is None:
            self._outbox.push(Message(Op.GET, key, 0, TS_NONE, self.robot_id))
            return None
        self._outbox.push(_new(Message, (local[0] | GET_BIT, local[1], local[2], local[3])))
        return local[1]

    def has(self, key: int) -> bool:
        return key in self._table

    def size(self) -> int:
        return len(self._table)

    def entry(self, key: int) -> Entry | None:
        local = self._table.get(key)
        return Entry(local[1], local[2], local[3]) if local else None

    def entries(self) -> Iterator[tuple[int, Entry]]:
        """Every (key, entry), as Buzz's foreach (a snapshot: safe to put while iterating)."""
        return iter([(key, Entry(m[1], m[2], m[3])) for key, m in self._table.items()])

    @property
    def counts(self) -> dict[Outcome, int]:
        """How many received messages had each outcome."""
        return dict(zip(Outcome, self._counts, strict=True))

    # -- the radio -----------------------------------------------------------
    def receive(self, msg: Message) -> Outcome:
        """Apply one message heard from a neighbour."""
        outcome = self._receive(msg)
        self._counts[outcome] += 1
        return outcome

    def _receive(self, msg: Message) -> Outcome:
        head, value, ts, robot = msg
        key = head & KEY_MAX
        is_get = head & GET_BIT
        local = self._table.get(key)
        if ts == TS_NONE:
            if not is_get:
                return _INVALID
            if local is None:
                return _UNKNOWN
        if local is None or is_newer(ts, local[2]):
            stored = _as_put(key, value, ts, robot) if is_get else msg
            self._table[key] = stored
            self._outbox.push(stored)
            return _STORED
        if ts != local[2]:
            if is_get:
                self._outbox.push(local)
                return _ANSWERED
            return _STALE
        if robot == local[3]:
            return _SAME
        self._resolve(key, Entry(local[1], ts, local[3]), Entry(value, ts, robot))
        return _CONFLICT

    def _resolve(self, key: int, local: Entry, remote: Entry) -> None:
        chosen = self.onconflict(key, local, remote)
        if chosen is local or chosen is remote:  # fields already valid: skip the checked constructor
            winner = _as_put(key, chosen[0], local[1], chosen[2])
        elif not isinstance(chosen, tuple) or len(chosen) != 3:
            raise TypeError(f"onconflict must return an Entry(value, timestamp, robot), got {chosen!r}")
        else:
            winner = self._merged_winner(key, local, remote, chosen[0], chosen[2])
        self._table[key] = winner
        self._outbox.push(winner)
        # Only the entry we held can be our lost write: the echo of a write that
        # already lost comes back as the remote, and must not be reported again.
        if self.onconflictlost and local[2] == self.robot_id and winner[3] != self.robot_id:
            self.onconflictlost(key, local)

    def _merged_winner(self, key: int, local: Entry, remote: Entry, value: int, robot: int) -> Message:
        """The entry to store for a winner that may be neither of the two entries.

        A new value (a merge) is a new write of the robot it names: that robot
        stores it at the next timestamp, so it supersedes both inputs everywhere
        and no two robots hold one (timestamp, robot) with different values.
        Every other robot keeps the named robot's own entry until that write comes.
        """
        for entry in (local, remote):
            if (value, robot) == (entry[0], entry[2]):
                return _as_put(key, value, local[1], robot)
        if robot == self.robot_id:
            return Message(Op.PUT, key, value, next_timestamp(local[1]), robot)
        for entry in (local, remote):
            if robot == entry[2]:
                return _as_put(key, entry[0], local[1], robot)
        raise ValueError(f"onconflict returned {Entry(value, local[1], robot)} for key {key}: a new value must "
                         f"name this robot ({self.robot_id}) or the writer of one of the two entries "
                         f"({local[2]} or {remote[2]})")

    # -- what to broadcast ---------------------------------------------------
    def drain(self, budget: int | None = None) -> list[Message]:
        """Messages to broadcast now: at most `budget` (one control step's bandwidth)."""
        return self._outbox.drain(budget)

    def pending(self) -> int:
        """How many messages wait in the outgoing queue."""
        return len(self._outbox)


def _check(key: int, value: int) -> None:
    check_field("key", KEY_MAX, key)
    check_field("value", U16_MAX, value)
