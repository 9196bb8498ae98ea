"""What a Node does with the messages its links heard: one part per job, chosen by the Node's `Mode`.

C twin: vstig_hw/_cext/parts.c (Seat, Relay); held equal by tests/native (index: vstig_hw/_vstig.pyi).

The Node (node.py) reads the links, frames, guards and tells the listeners; then
it hands each batch of messages to its part (python-can's `Notifier` hands
messages to a `Listener` the same way):

* `Seat`: the PC as a robot. Its engine judges what links heard; what the engine
  queues goes out on every link (ENGINE mode). With no outlets it only judges
  and never transmits: a sniffer's outcome counts (LISTEN with count_outcomes).
* `RawRelay`: a transparent bridge. Every message heard on one link is queued on
  every other link as is: no engine, no merging (RAW mode).
* A listening Node has no part at all: nothing is judged or sent.

Every batch comes with its source: the index of the link that heard it and, where
the link tells its peers apart (a Zenoh session), which of them (`sub`). What a
part queues on the outlets carries that source, so each outlet shares itself
fairly among them (`fairshare`); the Seat's own messages are `LOCAL`.

A part runs under the Node's lock, on whichever thread handed it the batch.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import Any

from ..engine import Entry, Outcome, Stigmergy
from ..links.link import Link
from ..timestamps import TS_NONE
from ..wire import GET_BIT, KEY_MAX, Message, Op
from .fairshare import LOCAL
from .guard import Guard
from .outlet import Outlet

__all__ = ["INTAKE_BURST_TICKS", "INTAKE_TICKS", "ChangeListener", "RawRelay", "Seat"]

INTAKE_TICKS = 16  # a source's messages the engine takes per tick: this many ticks of a link's budget
INTAKE_BURST_TICKS = 10  # a source that was quiet may give this many ticks of intake at once (a backlog)

# key, entry before (None: new key), entry after, link it came from (None: our own put), sender (None: unnamed)
ChangeListener = Callable[[int, Entry | None, Entry, str | None, int | None], None]


class RawRelay:
    """Queues what one link heard on every other link's outlet (outlets[i] belongs to links[i])."""

    def __init__(self, outlets: list[Outlet], guard: Guard | None) -> None:
        self.guard = guard
        # per link: the other links' outlets (what it heard goes there)
        self._others = [[other for other in outlets if other is not outlet] for outlet in outlets]
        self._names = [outlet.link.name for outlet in outlets]

    def take(self, index: int, messages: list[Message], sender: int | None, sub: Hashable = None) -> None:
        guard = self.guard
        if guard is not None and guard.read_only(self._names[index]):  # heard, never passed on
            return
        for outlet in self._others[index]:
            outlet.push(messages, index, sub)

    def queue_out(self) -> None:
        """Nothing of its own to send: `take` queued every message already."""

    def tick(self) -> None:
        """Nothing counted per tick."""


class Seat:
    """An engine with a seat in the swarm: judges what links heard, puts its outbox on every outlet.

    A PUT it stores is not echoed onto the link it came from when that link is one
    broadcast domain (`Link.one_domain`): every robot there heard the original.
    `on_change` (the Node's listeners, set by the Node) hears of every entry that changed.

    What the engine queues goes out under the source that caused it: what it stored
    from a link, its answers to that link's GETs and the conflicts that link caused
    carry the link (and its `sub`); the program's put/get/ask, `LOCAL`. The engine's
    outbox is queued out whenever the source changes, so it never mixes two.

    The engine takes at most `intake` messages a `period` from one source, measured
    by the time each batch was read (a token bucket holding `INTAKE_BURST_TICKS`
    periods' worth: a backlog after a stall, or a loop delayed by a loaded machine,
    still gets in whole); the rest are dropped before it and counted as `drop_intake`
    on the link: a flood costs the engine and the outlets no more than that, whatever
    the medium carries. None: no bound (a seat that only judges, or a node without a
    budget).
    """

    def __init__(self, engine: Stigmergy, links: list[Link[Any]], outlets: list[Outlet], guard: Guard | None,
                 on_change: Sequence[ChangeListener] = (), intake: int | None = None, period: float = 0.1) -> None:
        if intake is not None and intake < 1:
            raise ValueError(f"the engine's intake per source and tick must be at least 1 message, got {intake}")
        self.engine = engine
        self.links = links
        self.outlets = outlets  # outlets[i] belongs to links[i]; none: the seat only judges
        self.guard = guard
        self.on_change = on_change  # the Node's, replaced as listeners come and go
        self.intake = intake
        self._rate = 0.0 if intake is None else intake / period  # messages a second a source may give
        self._burst = 0.0 if intake is None else float(intake * INTAKE_BURST_TICKS)
        # source (a link's index, or (index, sub) for a link's peer) -> (messages it may still give, as of when)
        self._allowed: dict[Hashable, tuple[float, float]] = {}
        self._latest = 0.0  # the newest batch time seen: sources idle for a full refill are forgotten at `tick`
        self._link: int = LOCAL  # the source (link, sub) that caused the messages in the engine's outbox
        self._sub: Hashable = None
        # key -> (the PUT just stored, index of the one-domain link it came from), until the next queue_out
        self._heard_from: dict[int, tuple[Message, int]] = {}

    # -- the robot's program ---------------------------------------------------------
    def put(self, key: int, value: int) -> None:
        engine = self.engine
        self._caused_by(LOCAL, None)
        old = engine.entry(key) if self.on_change else None
        engine.put(key, value)
        if self.on_change:
            self._tell(key, old, None, engine.robot_id)

    def get(self, key: int) -> int | None:
        self._caused_by(LOCAL, None)
        value = self.engine.get(key)
        self._heard_from.pop(key, None)  # the GET may have merged into the key's pending PUT: send it everywhere
        return value

    def ask(self, key: int) -> None:
        """Queue an empty GET for `key` (timestamp 0) on every link: every neighbour holding it answers."""
        ask = [Message(Op.GET, key, 0, TS_NONE, self.engine.robot_id)]
        for outlet in self.outlets:
            outlet.push(ask)  # (LOCAL) a PUT already queued for the key says more and stays (SPEC section 5)

    # -- what links heard ------------------------------------------------------------
    def take(self, index: int, messages: list[Message], sender: int | None, sub: Hashable = None) -> None:
        engine = self.engine
        if index != self._link or sub != self._sub:
            self._caused_by(index, sub)
        if self.on_change:
            self._receive_telling(index, messages, sender)
        elif self.outlets and self.links[index].one_domain:
            self._receive_from_domain(index, messages)
        else:
            for msg in messages:
                engine.receive(msg)

    def _caused_by(self, link: int, sub: Hashable) -> None:
        """What the engine queues next is caused by source (link, sub): queue out what another caused first."""
        if link != self._link or sub != self._sub:
            if self.engine.pending():
                self.queue_out()
            self._link, self._sub = link, sub

    def admit(self, index: int, sub: Hashable, messages: list[Message], t: float) -> list[Message]:
        """Of what link `index` (peer `sub`) handed over in the batch read at `t`, what the engine takes within
        the source's intake; the rest are counted `drop_intake`. The Node asks before the guard, so a flood past
        its intake costs no more than its decoding."""
        source: Hashable = index if sub is None else (index, sub)
        allowed = self._allowed.get(source)
        if allowed is None:
            left = self._burst
        else:
            left, since = allowed
            if t > since:
                left = min(self._burst, left + (t - since) * self._rate)
        if len(messages) > left:
            room = int(left)
            self.links[index].counters["drop_intake"] += len(messages) - room
            messages = messages[:room]
        self._allowed[source] = (left - len(messages), t)
        if t > self._latest:
            self._latest = t
        return messages

    def tick(self) -> None:
        """Forget the sources whose allowance has refilled whole since they last gave (as good as new)."""
        allowed = self._allowed
        if len(allowed) > len(self.links):
            full_after = self._burst / self._rate if self._rate else 0.0
            old = self._latest - full_after
            for source in [source for source, (_, since) in allowed.items() if since < old]:
                del allowed[source]

    def _receive_from_domain(self, index: int, messages: list[Message]) -> None:
        """Receive what link `index` (one broadcast domain) heard, noting each PUT stored from it.

        Every robot on that link heard the PUT when we did, so `queue_out` keeps its
        re-broadcast off that link. An answer for the key to that link undoes the note:
        the answer may be that very entry, merged into the pending re-broadcast.
        """
        engine, heard_from = self.engine, self._heard_from
        for msg in messages:
            outcome = engine.receive(msg)
            if outcome is Outcome.STORED and not msg[0] & GET_BIT:  # stored as is: the outbox holds `msg`
                heard_from[msg[0]] = (msg, index)
            elif outcome is Outcome.ANSWERED:
                noted = heard_from.get(msg[0] & KEY_MAX)
                if noted is not None and noted[1] == index:
                    del heard_from[msg[0] & KEY_MAX]

    def _receive_telling(self, index: int, messages: list[Message], sender: int | None) -> None:
        """Receive as `take` does, one message at a time, telling `on_change` of every entry that changed."""
        engine = self.engine
        link = self.links[index]
        domain = link.one_domain and self.outlets
        for msg in messages:
            key = msg[0] & KEY_MAX
            old = engine.entry(key)
            if domain:
                self._receive_from_domain(index, [msg])
            else:
                engine.receive(msg)
            self._tell(key, old, link.name, sender)

    def _tell(self, key: int, old: Entry | None, link: str | None, sender: int | None) -> None:
        new = self.engine.entry(key)
        if new is not None and new != old:
            for listener in self.on_change:
                listener(key, old, new, link, sender)

    # -- what goes out -----------------------------------------------------------------
    def queue_out(self) -> None:
        """Copy the engine's outbox into every link's outlet, under the source that caused it (none: the outbox
        is dropped unsent)."""
        engine = self.engine
        if not engine.pending():
            return
        outgoing = engine.drain()
        link, sub = self._link, self._sub
        guard = self.guard
        confined_to = guard.confined_to if guard is not None and guard.confines else None
        if confined_to is None and not self._heard_from:  # the common case: every message to every link
            for outlet in self.outlets:
                outlet.push(outgoing, link, sub)
        else:
            self._push_where_due(outgoing, confined_to, link, sub)

    def _push_where_due(self, outgoing: list[Message], confined_to: Callable[[Message], str | None] | None,
                        link: int, sub: Hashable) -> None:
        """Queue each message on every link but the one-domain link it came from and those a guard keeps it off."""
        origins = self._origins(outgoing)
        for i, outlet in enumerate(self.outlets):
            name = outlet.link.name
            due = []
            for msg, origin in zip(outgoing, origins, strict=True):
                if origin == i:  # every robot on that link heard it already
                    outlet.link.counters["not_echoed"] += 1
                elif confined_to is None or confined_to(msg) in (None, name):  # a read-only link's entries stay
                    due.append(msg)
            outlet.push(due, link, sub)

    def _origins(self, outgoing: list[Message]) -> list[int]:
        """Per message, the one-domain link it was heard on (-1: none), and forget the notes."""
        heard_from = self._heard_from
        if not heard_from:
            return [-1] * len(outgoing)
        origins = []
        for msg in outgoing:
            noted = heard_from.get(msg[0])  # a PUT's head is its key
            origins.append(noted[1] if noted is not None and noted[0] is msg else -1)
        heard_from.clear()
        return origins
