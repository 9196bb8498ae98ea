"""A confirmed write as a state machine: pure (no I/O, no thread, no clock), like the engine.

Fed what links heard, what our table holds and the time, it says what to send
and, once, its verdict, which never changes after (h11's named states and
transitions are the model). `oneshot.confirm_write` drives it on a Node for
`vstig put` and the Python API alike.

    LEARNING --(learn s)--> WAITING --(a neighbour shows it)--> DONE: TAKEN
        |                     | \\--(superseded, tries left)--> WAITING (written again)
        |                     |  \\-(superseded, no try left)--> DONE: SUPERSEDED
        |                     \\---(wait s)--------------------> DONE: UNANSWERED
        \\-------(our own probe comes back)-------------------> DONE: HEARS_ITSELF

The rules:

* **Taken**: a neighbour's message carries our exact entry (it re-broadcast our
  PUT when it stored it, answered a GET with it, or its own GET carries it), or
  a write one timestamp past ours from another robot: whoever wrote it held ours
  (a write takes the next timestamp after the entry its writer holds), unless
  another entry with our timestamp was heard (a conflict), which it may have been
  built on instead. The verdict is fixed the moment it is reached: a newer write
  that comes later (robots keep writing) does not undo it.
* **Superseded**: our table's entry changed to one that is not ours (a newer
  write, or a conflict our write lost) before any neighbour showed ours: written
  again at the next timestamp while `tries` allow, else not taken, naming what
  the swarm holds. A copy of a superseded write heard later does not count.
* **Unanswered**: no neighbour showed the write within `wait` seconds of it.
* **Our echo is never a neighbour.** A radio that echoes what it is sent (or a
  loop) brings our own frames back, indistinguishable from a neighbour's copy.
  So before anything of ours goes out, a *probe* (an empty GET under our id,
  sent ahead of every queue) goes out on every link: a device that echoes brings
  it back before anything sent after it, so once a link's probe came back every
  copy of our entry on it may be our own, and the write ends HEARS_ITSELF; a copy
  heard on a link before its probe came back cannot be our echo. A neighbour
  never sends an empty GET under our id: where the medium names senders, a
  relayed one (Buzz relays empty GETs for keys it lacks) names its relay, and our
  own frames (sender = us) are skipped. Without `learn` the probe goes right
  before the write; a second one right after it makes every neighbour holding
  the key answer at once (a gateway that stored our write does not echo it back
  onto a broadcast medium, so its answer is the news).
* Each control step (`tick`) it asks: alternately a probe and a GET carrying our
  view (a holder of anything older takes ours and re-broadcasts it, a holder of
  something newer answers with it).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ..engine import Entry
from ..timestamps import TS_NONE, next_timestamp
from ..wire import Message, Op

__all__ = ["ConfirmedWrite", "PutResult", "Send", "State", "Verdict"]


class State(enum.Enum):
    LEARNING = "learning"  # asking what the swarm holds, before the first write
    WAITING = "waiting"  # our write is out: waiting for a neighbour to show it
    DONE = "done"  # the verdict is fixed


class Verdict(enum.Enum):
    TAKEN = "taken"  # a neighbour showed our entry, or wrote on top of it
    SUPERSEDED = "superseded"  # the swarm holds another entry, after every try
    UNANSWERED = "unanswered"  # no neighbour showed the write within the wait
    HEARS_ITSELF = "hears itself"  # a link brings our own frames back: no neighbour can be told from our echo
    UNCONFIRMED = "unconfirmed"  # written without asking for a confirmation


class Send(enum.Enum):
    PROBE = "probe"  # an empty GET for the key under our id, sent at once ahead of every queue
    ASK = "ask"  # a GET carrying our view (the paper's read)
    WRITE = "write"  # put the value; the driver then tells `wrote` the entry it stored


@dataclass(frozen=True)
class PutResult:
    """What became of a confirmed write, fixed when its verdict was reached."""

    verdict: Verdict
    written: Entry  # our last write
    tries: int  # writes made
    holds: Entry | None  # our table's entry at the verdict: not `written` when superseded or built on
    heard: Entry | None  # the last entry a neighbour's message carried (None: nothing heard)
    shown: Entry | None = None  # what showed it was taken: our entry, or the write built on it

    @property
    def confirmed(self) -> bool:
        """A neighbour showed it took the write."""
        return self.verdict is Verdict.TAKEN

    @property
    def superseded(self) -> bool:
        """The swarm holds an entry other than our last write, not built on it."""
        return self.verdict is Verdict.SUPERSEDED


class ConfirmedWrite:
    """One confirmed write of `key` by robot `robot_id`; see the module docstring for its states and rules.

    `learn`: seconds of asking before the first write; `wait`: seconds each write
    waits for a neighbour (`first_wait` for the first: a caller that spent some
    of its budget opening links gives less); `tries`: writes at most. Without
    `confirm` it learns as asked, writes once and is done (UNCONFIRMED). Every input takes `now`
    (any monotonic clock) and returns what to send, in order.
    """

    def __init__(self, key: int, robot_id: int, *, learn: float = 0.0, wait: float = 2.0, tries: int = 3,
                 confirm: bool = True, first_wait: float | None = None) -> None:
        if tries < 1:
            raise ValueError(f"tries must be at least 1, got {tries}")
        self.key, self.robot_id = key, robot_id
        self.learn, self.wait, self.tries, self.confirm = learn, wait, tries, confirm
        self.first_wait = wait if first_wait is None else first_wait
        self.state = State.LEARNING
        self.verdict: Verdict | None = None
        self.written: Entry | None = None  # our last write (None: not written yet)
        self.made = 0  # writes made
        self.holds: Entry | None = None  # our table's entry, as told
        self.last_heard: Entry | None = None  # the last entry a neighbour's message carried
        self.shown: Entry | None = None  # what showed the write was taken
        self.echoed_on: str | None = None  # the link our own probe came back on
        self.deadline = 0.0  # when the current phase ends (learning, or the current write's wait)
        self._probed: set[str] = set()  # links our probe came back on (none: it cannot have)
        self._rival = False  # an entry with our write's timestamp from another robot was heard
        self._superseded = False  # our last write was superseded: it can no longer be taken (written again)
        self._asked = 0  # control steps asked in

    # -- inputs -----------------------------------------------------------------------
    def start(self, now: float) -> list[Send]:
        """Begin: probe (and write, unless learning first)."""
        if self.learn > 0:
            self.deadline = now + self.learn
            return [Send.PROBE]
        return [Send.PROBE, Send.WRITE] if self.confirm else [Send.WRITE]

    def wrote(self, entry: Entry, now: float) -> list[Send]:
        """The write asked for was made: `entry` is what our table stored."""
        self.written = self.holds = entry
        self.made += 1
        self._rival = self._superseded = False
        if not self.confirm:
            self._decide(Verdict.UNCONFIRMED)
            return []
        self.state = State.WAITING
        self.deadline = now + (self.first_wait if self.made == 1 else self.wait)
        return [Send.PROBE]  # every holder of the key answers now, a gateway that took it included

    def heard(self, message: Message, link: str, sender: int | None, now: float) -> list[Send]:
        """A message for our key, heard on `link` from `sender` (None: the medium names none)."""
        if self.state is State.DONE or message.key != self.key:
            return []
        if sender is not None and sender == self.robot_id:  # our own frame, named as ours (CAN IDs)
            return []
        if message.timestamp == TS_NONE:
            if message.op is Op.GET and message.robot == self.robot_id and sender is None:
                self._probed.add(link)  # our own probe, back: this link echoes what we send
                if self.confirm:
                    self.echoed_on = link
                    self._decide(Verdict.HEARS_ITSELF)
            return []
        entry = Entry(message.value, message.timestamp, message.robot)
        self.last_heard = entry
        written = self.written
        if self.state is not State.WAITING or written is None or self._superseded or link in self._probed:
            return []
        if entry == written:
            self._taken(entry)
        elif entry.timestamp == written.timestamp and entry.robot != written.robot:
            self._rival = True  # a conflict: a write one past our timestamp may be built on either entry
        elif (entry.timestamp == next_timestamp(written.timestamp) and entry.robot != self.robot_id
              and not self._rival):
            self._taken(entry)  # its writer held ours: it wrote on top of it
        return []

    def changed(self, holds: Entry | None, now: float) -> list[Send]:
        """What a message heard did to our table's entry for the key (not our own writes)."""
        if self.state is State.DONE:
            return []
        self.holds = holds
        if self.state is not State.WAITING or holds == self.written:
            return []
        if self.made < self.tries:
            if self._superseded:
                return []  # written again already asked for
            self._superseded = True
            return [Send.WRITE]  # newer than what superseded it: the engine writes one past what it holds
        self._decide(Verdict.SUPERSEDED)
        return []

    def tick(self, now: float) -> list[Send]:
        """A control step: the time limits, then one question."""
        if self.state is State.DONE:
            return []
        if now >= self.deadline:
            if self.state is State.LEARNING:
                return [Send.WRITE]
            self._decide(Verdict.UNANSWERED)
            return []
        self._asked += 1
        return [Send.ASK if self._asked % 2 == 0 else Send.PROBE]

    # -- outputs ------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.state is State.DONE

    def result(self) -> PutResult:
        """The verdict and what it was reached on (once done, and not HEARS_ITSELF before any write)."""
        if self.verdict is None or self.written is None:
            raise RuntimeError(f"key {self.key}: the confirmed write has no result yet ({self.state.value})")
        return PutResult(self.verdict, self.written, self.made, self.holds, self.last_heard, self.shown)

    # -- inside -------------------------------------------------------------------------
    def _taken(self, shown: Entry) -> None:
        self.shown = shown
        self._decide(Verdict.TAKEN)

    def _decide(self, verdict: Verdict) -> None:
        self.verdict = verdict
        self.state = State.DONE
