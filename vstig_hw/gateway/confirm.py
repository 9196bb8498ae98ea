"""A confirmed write as a state machine: pure (no I/O, no thread, no clock), like the engine.

Fed what links heard, what our table holds and the time, it says what to send
and, once, its verdict, which never changes after. h11's `_state.py` is the
model: each input is read as one `Event`, and one table (`TRANSITIONS`) maps
(state, event) to the next state, what to send and the verdict it reaches; an
event the table lacks for a state is a bug (`UnexpectedEvent`), never ignored.
The machine also decides which messages concern the write (our key, not our
own frames), so its driver feeds it everything links heard. `oneshot.confirm_write`
drives it on a Node for `vstig put` and the Python API alike.

The table, as `diagram()` renders it (a test holds this text equal to it;
`python -m vstig_hw.gateway.confirm` prints it):

    IDLE
        --start, learning first-----> LEARNING / probe
        --start---------------------> WRITING / probe, write
        --start, unconfirmed--------> WRITING / write
    LEARNING
        --step (odd)----------------> itself / probe
        --step (even)---------------> itself / ask
        --time limit----------------> WRITING / write
        --our probe came back-------> DONE: HEARS_ITSELF
        stays on: heard; table holds ours
    WRITING
        --stored--------------------> WAITING / probe
        --stored, unconfirmed-------> DONE: UNCONFIRMED
    WAITING
        --step (odd)----------------> itself / probe
        --step (even)---------------> itself / ask
        --time limit----------------> DONE: UNANSWERED
        --our probe came back-------> DONE: HEARS_ITSELF
        --our entry shown-----------> DONE: TAKEN
        --a rival at our timestamp--> CONTESTED
        --a write one past ours-----> DONE: TAKEN
        --superseded, tries left----> WRITING / write
        --superseded, no try left---> DONE: SUPERSEDED
        stays on: heard; table holds ours
    CONTESTED
        --step (odd)----------------> itself / probe
        --step (even)---------------> itself / ask
        --time limit----------------> DONE: UNANSWERED
        --our probe came back-------> DONE: HEARS_ITSELF
        --our entry shown-----------> DONE: TAKEN
        --superseded, tries left----> WRITING / write
        --superseded, no try left---> DONE: SUPERSEDED
        stays on: heard; a rival at our timestamp; a write one past ours; table holds ours
    DONE
        takes every event and stays: the verdict never changes

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
from ..wire import KEY_MAX, Message, Op

__all__ = ["TRANSITIONS", "ConfirmedWrite", "Event", "PutResult", "Send", "State", "Transition", "UnexpectedEvent",
           "Verdict", "diagram"]


class State(enum.Enum):
    IDLE = "idle"  # not started
    LEARNING = "learning"  # asking what the swarm holds, before the first write
    WRITING = "writing"  # a write asked for: the driver tells `wrote` what it stored before anything else
    WAITING = "waiting"  # our write is out: waiting for a neighbour to show it
    CONTESTED = "contested"  # waiting, but an entry with our timestamp from another robot was heard
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


class Event(enum.Enum):
    """One input, as the machine reads it (the value labels it in the diagram)."""

    LEARN_FIRST = "start, learning first"
    START = "start"
    START_UNCONFIRMED = "start, unconfirmed"
    STEP_PROBE = "step (odd)"  # a control step within the time limit: they alternate a probe and an ask
    STEP_ASK = "step (even)"
    DEADLINE = "time limit"  # a control step past the learning or the write's wait
    STORED = "stored"  # `wrote`: our table stored the write
    STORED_UNCONFIRMED = "stored, unconfirmed"
    ECHOED = "our probe came back"  # an empty GET under our id that names no sender (confirming only)
    HEARD = "heard"  # a neighbour's entry that shows nothing about our write
    SHOWN = "our entry shown"  # a neighbour's message carries our exact entry
    RIVAL = "a rival at our timestamp"  # another robot's entry with our write's timestamp (a conflict)
    BUILT_ON = "a write one past ours"  # another robot's entry one timestamp past our write
    HELD = "table holds ours"  # our table's entry changed, to our write or before any write
    SUPERSEDED = "superseded, tries left"  # our table's entry is no longer our write
    LAST_SUPERSEDED = "superseded, no try left"


@dataclass(frozen=True)
class Transition:
    """Where an event leads from a state: the next state, what to send, and the verdict it reaches (if any)."""

    to: State
    sends: tuple[Send, ...] = ()
    verdict: Verdict | None = None


def _steps(state: State) -> dict[Event, Transition]:
    """A control step within the time limit: `state` asks again, a probe and a view in turn."""
    return {Event.STEP_PROBE: Transition(state, (Send.PROBE,)), Event.STEP_ASK: Transition(state, (Send.ASK,))}


def _waiting(state: State, built_on: Transition) -> dict[Event, Transition]:
    """Our write is out (WAITING, or CONTESTED: they differ only in what a write one past ours shows)."""
    return {
        **_steps(state),
        Event.DEADLINE: Transition(State.DONE, verdict=Verdict.UNANSWERED),
        Event.ECHOED: Transition(State.DONE, verdict=Verdict.HEARS_ITSELF),
        Event.HEARD: Transition(state),
        Event.SHOWN: Transition(State.DONE, verdict=Verdict.TAKEN),
        Event.RIVAL: Transition(State.CONTESTED),
        Event.BUILT_ON: built_on,
        Event.HELD: Transition(state),
        Event.SUPERSEDED: Transition(State.WRITING, (Send.WRITE,)),  # newer: the engine writes one past what it holds
        Event.LAST_SUPERSEDED: Transition(State.DONE, verdict=Verdict.SUPERSEDED),
    }


# The whole machine. A state takes only the events listed for it; DONE takes every event and changes nothing.
TRANSITIONS: dict[State, dict[Event, Transition]] = {
    State.IDLE: {
        Event.LEARN_FIRST: Transition(State.LEARNING, (Send.PROBE,)),
        Event.START: Transition(State.WRITING, (Send.PROBE, Send.WRITE)),  # the probe goes right before the write
        Event.START_UNCONFIRMED: Transition(State.WRITING, (Send.WRITE,)),
    },
    State.LEARNING: {
        **_steps(State.LEARNING),
        Event.DEADLINE: Transition(State.WRITING, (Send.WRITE,)),
        Event.ECHOED: Transition(State.DONE, verdict=Verdict.HEARS_ITSELF),
        Event.HEARD: Transition(State.LEARNING),
        Event.HELD: Transition(State.LEARNING),
    },
    State.WRITING: {  # the driver makes the write and tells `wrote` before anything else (under the Node's lock)
        # a second probe right after the write: every holder of the key answers now, a gateway that took it included
        Event.STORED: Transition(State.WAITING, (Send.PROBE,)),
        Event.STORED_UNCONFIRMED: Transition(State.DONE, verdict=Verdict.UNCONFIRMED),
    },
    State.WAITING: _waiting(State.WAITING, Transition(State.DONE, verdict=Verdict.TAKEN)),  # its writer held ours
    # a write one past our timestamp may be built on the rival instead: it shows nothing
    State.CONTESTED: _waiting(State.CONTESTED, Transition(State.CONTESTED)),
    State.DONE: {event: Transition(State.DONE) for event in Event},
}


def diagram() -> str:
    """The transition table as text, for the module docstring: each state, where each event takes it and what it
    sends; the events a state takes without moving or sending on one line."""
    width = max(len(event.value) for event in Event) + 4
    lines: list[str] = []
    for state, events in TRANSITIONS.items():
        lines.append(state.name)
        quiet = [event.value for event, step in events.items() if step == Transition(state)]
        if len(quiet) == len(Event):
            lines.append("    takes every event and stays: the verdict never changes")
            continue
        for event, step in events.items():
            if step != Transition(state):
                to = "itself" if step.to is state else step.to.name
                verdict = f": {step.verdict.name}" if step.verdict else ""
                sends = f" / {', '.join(send.value for send in step.sends)}" if step.sends else ""
                lines.append(f"    --{event.value}".ljust(width + 4, "-") + f"> {to}{verdict}{sends}")
        if quiet:
            lines += _packed("    stays on: ", quiet, "        ")
    return "\n".join(lines)


def _packed(first: str, items: list[str], then: str, width: int = 100) -> list[str]:
    """`items` joined by "; " on lines of at most `width` (never one split), the first after `first`."""
    lines = [first]
    for item in items:
        start = lines[-1] in (first, then)
        if not start and len(lines[-1]) + 2 + len(item) > width:
            lines[-1] += ";"
            lines.append(then)
            start = True
        lines[-1] += item if start else "; " + item
    return lines


class UnexpectedEvent(RuntimeError):
    """An input the table has no transition for in the current state: a bug in the machine or its driver."""


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
    (any monotonic clock) and returns what to send, in order. Each input is read as an `Event` and
    moves by `TRANSITIONS`; once DONE, nothing it is told changes anything.
    """

    def __init__(self, key: int, robot_id: int, *, learn: float = 0.0, wait: float = 2.0, tries: int = 3,
                 confirm: bool = True, first_wait: float | None = None) -> None:
        if tries < 1:
            raise ValueError(f"tries must be at least 1, got {tries}")
        self.key, self.robot_id = key, robot_id
        self.learn, self.wait, self.tries, self.confirm = learn, wait, tries, confirm
        self.first_wait = wait if first_wait is None else first_wait
        self.state = State.IDLE
        self.verdict: Verdict | None = None
        self.written: Entry | None = None  # our last write (None: not written yet)
        self.made = 0  # writes made
        self.holds: Entry | None = None  # our table's entry, as told
        self.last_heard: Entry | None = None  # the last entry a neighbour's message carried
        self.shown: Entry | None = None  # what showed the write was taken
        self.echoed_on: str | None = None  # the link our own probe came back on
        self.deadline = 0.0  # when the current phase ends (learning, or the current write's wait)
        self._steps = 0  # control steps asked in

    # -- inputs -----------------------------------------------------------------------
    def start(self, now: float) -> list[Send]:
        """Begin: probe (and write, unless learning first)."""
        if self.learn > 0:
            self.deadline = now + self.learn
            return _sends(self._move(Event.LEARN_FIRST))
        return _sends(self._move(Event.START if self.confirm else Event.START_UNCONFIRMED))

    def wrote(self, entry: Entry, now: float) -> list[Send]:
        """The write asked for was made: `entry` is what our table stored."""
        step = self._move(Event.STORED if self.confirm else Event.STORED_UNCONFIRMED)
        if step is not None:
            self.written = self.holds = entry
            self.made += 1
            self.deadline = now + (self.first_wait if self.made == 1 else self.wait)
        return _sends(step)

    def heard(self, message: Message, link: str, sender: int | None, now: float) -> list[Send]:
        """A message heard on `link` from `sender` (None: the medium names none). One for another key, one of
        our own frames, or an empty GET that is not our probe back, does not concern this write."""
        if message.key != self.key or sender == self.robot_id:  # another key, or our own frame named as ours
            return []
        if message.timestamp == TS_NONE:
            if not (self.confirm and message.op is Op.GET and message.robot == self.robot_id and sender is None):
                return []  # a neighbour's question (a relayed empty GET names its relay), or nothing to judge
            step = self._move(Event.ECHOED)
            if step is not None:
                self.echoed_on = link  # our own probe, back: this link echoes what we send
            return _sends(step)
        entry = Entry(message.value, message.timestamp, message.robot)
        step = self._move(self._shows(entry))
        if step is not None:
            self.last_heard = entry
            if step.verdict is Verdict.TAKEN:
                self.shown = entry
        return _sends(step)

    def heard_on(self, link: str, sender: int | None, messages: list[Message], now: float) -> list[Send]:
        """What a link heard, as the Node tells it: `heard` for each message for our key, in turn."""
        key = self.key
        ours = [message for message in messages if message[0] & KEY_MAX == key]  # the head: op bit and key
        return [send for message in ours for send in self.heard(message, link, sender, now)] if ours else []

    def changed(self, holds: Entry | None, now: float) -> list[Send]:
        """What a message heard did to our table's entry for the key (not our own writes)."""
        written = self.written
        if written is None or holds == written:
            event = Event.HELD
        else:
            event = Event.SUPERSEDED if self.made < self.tries else Event.LAST_SUPERSEDED
        step = self._move(event)
        if step is not None:
            self.holds = holds
        return _sends(step)

    def table_changed(self, key: int, holds: Entry | None, link: str | None, now: float) -> list[Send]:
        """The Node's change notice: `changed` when a message heard on `link` moved our key's entry; another
        key, or our own write (`link` None: `wrote` told it), does not concern this write."""
        if key != self.key or link is None:
            return []
        return self.changed(holds, now)

    def tick(self, now: float) -> list[Send]:
        """A control step: the time limit, else one question."""
        if now >= self.deadline:
            return _sends(self._move(Event.DEADLINE))
        self._steps += 1
        return _sends(self._move(Event.STEP_ASK if self._steps % 2 == 0 else Event.STEP_PROBE))

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
    def _shows(self, entry: Entry) -> Event:
        """What a neighbour's `entry` shows about our last write (whether it counts is the table's)."""
        written = self.written
        if written is None:
            return Event.HEARD
        if entry == written:
            return Event.SHOWN
        if entry.timestamp == written.timestamp and entry.robot != written.robot:
            return Event.RIVAL
        if entry.timestamp == next_timestamp(written.timestamp) and entry.robot != self.robot_id:
            return Event.BUILT_ON
        return Event.HEARD

    def _move(self, event: Event) -> Transition | None:
        """Take `event` by the table: the next state and the verdict it reaches. None once DONE, which takes
        every event and changes nothing (the caller then records nothing either)."""
        step = TRANSITIONS[self.state].get(event)
        if step is None:
            raise UnexpectedEvent(f"key {self.key}: the confirmed write cannot take '{event.value}' while "
                                  f"{self.state.value} (a bug in its driver or its table)")
        if self.state is State.DONE:
            return None
        self.state = step.to
        if step.verdict is not None:
            self.verdict = step.verdict
        return step


def _sends(step: Transition | None) -> list[Send]:
    return list(step.sends) if step is not None else []


if __name__ == "__main__":
    print(diagram())
