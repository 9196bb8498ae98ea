"""A fair share of one link's way out for every source of what it carries. Pure: no clock, no I/O.

An outlet (outlet.py) sends at most its budget; whoever fills it fastest used to
own it: a radio flooding distinct keys within its baud, or a local Zenoh flood,
put thousands of messages ahead of every other robot's, and a write from robot A
reached robot B seconds late. So every outlet keeps one line per source and
serves the lines in turn.

**A source** is what caused a message to be sent, named by something the
gateway itself knows:

* a link (its index in the Node): what the engine stores from it, the answers to
  its GETs, the conflicts it causes; in a raw bridge, what it heard;
* `LOCAL`: this gateway's own messages (the program's put/get/ask, the refresh GETs);
* within a link, a sub-source where the link tells its peers apart (a Zenoh
  session: see `Link.source_of`); the link's messages whose sender it cannot tell
  apart share its line `None`. At most `LINES_PER_LINK` sub-sources have a line of
  their own at a time; the others share `None`.

**The share** is two-level round robin, one message per turn (every message is
8 bytes, so this is deficit round robin with a quantum of one message): the links
(and LOCAL) take turns, and within a link its sub-sources take turns. A source
with nothing waiting has no turn. So a message waits for at most one message of
every other active link (and of every other active sub-source of its own link),
however much any of them has queued.

**Sparse links go first** (RFC 8290's new flows, section 4.1, with a quantum of
one message): a link whose lines were all empty, and which was not served within
the last round, is *sparse*: its first message leaves before any backlogged
link's, then the link takes its turns among them. A link served whose lines then
emptied keeps its place in the round, empty, until its turn comes again: only then
may it be sparse again. So a source that sends one message each time its line
empties gets one message per round, as in the plain round robin, never more; and
what the outlet lets sparse messages use at once (a reserve of its window,
outlet.py) is bounded by the number of links. Only links are sparse, not
sub-sources: those cost a peer little to make (a Zenoh session), so a flood of
fresh sessions, each sending one message, stays within its link's share.

**Each line keeps the out-queue's rules** (vstig_hw/outqueue.py, SPEC section 5)
in `FairQueue`: PUTs before GETs, oldest first, a replaced message keeps its
place. One pending message per key across all lines, judged as the out-queue
judges it:

* a message that replaces the pending one (newer, or a conflict's winner) takes
  it out of every line and waits in its own source's line (in place, if that
  line held the key);
* a message carrying the same entry as the pending one is not queued again, but
  its source's line gets a place for the pending message too: it leaves from the
  first line that reaches it, and leaves every line then. An answer to robot B's
  GET therefore never waits behind the flood of a source that asked first, and a
  flooder asking for robot A's entries cannot pull them into its own line.

So the share changes only the order in which keys leave, never what is sent for
a key. `FairFifo` is the raw bridge's form: each line a FIFO of every message.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Hashable, Iterator
from itertools import chain
from typing import Generic, TypeVar

from ..outqueue import OutQueue, replaces, same_entry
from ..wire import GET_BIT, KEY_MAX, Message

__all__ = ["LINES_PER_LINK", "LOCAL", "FairFifo", "FairQueue"]

LOCAL = -1  # the source of this gateway's own messages (a link's index otherwise)
LINES_PER_LINK = 64  # sub-sources of one link with a line of their own at a time; beyond, they share None


class _Line(OutQueue):
    """One source's line of newest-per-key messages."""

    def __init__(self, link: int, sub: Hashable) -> None:
        super().__init__()
        self.link = link
        self.sub = sub
        self.waiting = False  # in the turns (it has messages)

    def place(self, key: int, msg: Message) -> None:
        """Queue `msg` for `key`, which no line holds: last in its op's line (no judging needed)."""
        (self._gets if msg[0] & GET_BIT else self._puts)[key] = msg


class _Fifo(deque[Message]):
    """One source's line of every message, oldest first."""

    def __init__(self, link: int, sub: Hashable) -> None:
        super().__init__()
        self.link = link
        self.sub = sub
        self.waiting = False


Line = TypeVar("Line", _Line, _Fifo)


class _Turns(Generic[Line]):
    """The lines of the sources with messages waiting, in the order of their turns (links, then sub-sources).

    A link's own line (sub None) is kept once made, empty or not (there is one per link, and the hot path then
    makes nothing); a sub-source's line lives while it has messages waiting.
    """

    _kind: type[Line]
    # declared: the compiled outlets (vstig_hw/_cext/outlet.c) read these too
    sparse: OrderedDict[int, OrderedDict[Hashable, Line]]
    active: int

    def __init__(self) -> None:
        # link -> its ring of lines with messages waiting (sub -> line), the first of each next in turn. A link with
        # messages is in `sparse` (its lines were empty and it was not served within the last round: it goes
        # first, one message) or in `turns` (the round); a link served whose ring emptied stays in `turns`, its
        # ring empty, until its turn comes round. The rings are kept once made.
        self.sparse: OrderedDict[int, OrderedDict[Hashable, Line]] = OrderedDict()
        self.turns: OrderedDict[int, OrderedDict[Hashable, Line]] = OrderedDict()
        self.active = 0  # links with messages waiting (0: nothing waits)
        self._rings: dict[int, OrderedDict[Hashable, Line]] = {}
        self._lines: dict[tuple[int, Hashable], Line] = {}  # (link, sub) -> its line, made or kept
        self._subs: dict[int, int] = {}  # link -> how many sub-source lines (sub not None) it has

    @property
    def sources(self) -> int:
        """How many sources (link, sub) have messages waiting."""
        return sum(len(subs) for subs in self._waiting_rings())

    def _waiting_rings(self) -> Iterator[OrderedDict[Hashable, Line]]:
        return chain(self.sparse.values(), self.turns.values())

    def _line(self, link: int, sub: Hashable) -> Line:
        """The line of source (link, sub): made if it has none (`_settle` it once queued to)."""
        line = self._lines.get((link, sub))
        if line is None:
            if sub is not None:
                made = self._subs.get(link, 0)
                if made >= LINES_PER_LINK:
                    return self._line(link, None)
                self._subs[link] = made + 1
            line = self._lines[link, sub] = self._kind(link, sub)
        return line

    def _settle(self, line: Line) -> None:
        """After messages were queued to or taken from `line`: it joins the turns or leaves them."""
        if line:
            if not line.waiting:
                line.waiting = True
                link = line.link
                ring = self._rings.get(link)
                if ring is None:
                    ring = self._rings[link] = OrderedDict()
                ring[line.sub] = line
                if len(ring) == 1:
                    self.active += 1
                    if link not in self.turns:  # not served within the last round: sparse
                        self.sparse[link] = ring
        elif line.waiting:
            self._leave(line)
        elif line.sub is not None:  # made for nothing: a sub-source's line lives only while it has messages
            self._drop(line)

    def _leave(self, line: Line) -> None:
        """Take an emptied line out of its ring (its link keeps its place in the round, if it has one)."""
        line.waiting = False
        link = line.link
        ring = self._rings[link]
        del ring[line.sub]
        if not ring:
            self.sparse.pop(link, None)
            self.active -= 1
            if not self.active:  # nothing waits: every link's turn has passed
                self.turns.clear()
        if line.sub is not None:
            self._drop(line)

    def _drop(self, line: Line) -> None:
        del self._lines[line.link, line.sub]
        self._subs[line.link] -= 1

    def _served(self, line: Line) -> None:
        """After `line` sent one message: it goes last among its link's lines, its link last in the round (empty
        or not: a link served is not sparse again before its turn comes round)."""
        link = line.link
        ring = self._rings[link]
        if line:
            ring.move_to_end(line.sub)
        else:
            self._leave(line)
            if not self.active:
                return
        self.sparse.pop(link, None)
        turns = self.turns
        turns[link] = ring
        turns.move_to_end(link)

    def _served_alone(self, line: Line) -> None:
        """After `line`, the only one with messages waiting, sent some: every other link's turn has passed."""
        if not line:
            self._leave(line)  # nothing waits now
            return
        link = line.link
        self.sparse.pop(link, None)
        self.turns.clear()
        self.turns[link] = self._rings[link]

    def _next_ring(self) -> OrderedDict[Hashable, Line]:
        """The ring of the link whose turn it is (there is one: the caller checked that `active`)."""
        if self.sparse:
            return next(iter(self.sparse.values()))
        turns = self.turns
        while True:
            ring = next(iter(turns.values()))
            if ring:
                return ring
            turns.popitem(last=False)  # served within the last round, emptied since: its turn passes

    def _next(self) -> Line:
        """The line whose turn it is (there is one: the caller checked)."""
        return next(iter(self._next_ring().values()))

    def _only(self) -> Line | None:
        """The one line with messages waiting, if there is exactly one (the common case: no contention)."""
        if self.active == 1:
            ring = self._next_ring()
            if len(ring) == 1:
                return next(iter(ring.values()))
        return None


class FairQueue(_Turns[_Line]):
    """Newest-per-key lines, one per source, served in turn (see the module's docstring)."""

    _kind = _Line

    def __init__(self) -> None:
        super().__init__()
        self._holders: dict[int, _Line | tuple[_Line, ...]] = {}  # key -> the line(s) its pending message is in

    def __len__(self) -> int:
        return len(self._holders)

    def push(self, messages: list[Message], link: int, sub: Hashable = None) -> int:
        """Queue `messages` from source (link, sub); returns how many were not queued (a message at least
        as new was pending for their key: the out-queue's rules)."""
        line = self._line(link, sub)
        holders = self._holders
        merged = 0
        for msg in messages:
            key = msg[0] & KEY_MAX
            holder = holders.get(key)
            if holder is None:
                line.place(key, msg)
                holders[key] = line
            elif holder is line:
                if not line.push(msg):
                    merged += 1
            elif not self._contest(msg, key, holder, line):
                merged += 1
        if not line.waiting:
            self._settle(line)
        return merged

    def _contest(self, msg: Message, key: int, holder: _Line | tuple[_Line, ...], line: _Line) -> bool:
        """Queue `msg` for `key`, pending in other lines (`holder`), in `line`; True if it replaced the pending."""
        held = holder if isinstance(holder, tuple) else (holder,)
        pending = held[0].pending(key)
        assert pending is not None
        if same_entry(msg, pending):
            if line not in held:  # a place in this source's line too: it leaves from whichever reaches it first
                line.place(key, pending)
                self._holders[key] = (*held, line)
            return False
        if not replaces(msg, pending):
            return False
        for other in held:
            if other is not line:
                other.remove(key)
                if not other:
                    self._leave(other)
        line.push(msg)  # in place if this line held the key
        self._holders[key] = line
        return True

    def drain(self, budget: int | None = None) -> list[Message]:
        """Up to `budget` messages (all if None): one from each source in turn."""
        only = self._only()
        if only is not None:  # one source waiting: its line, as the out-queue drains it
            out = only.drain(budget)
            if only:
                holders = self._holders
                for msg in out:
                    del holders[msg[0] & KEY_MAX]
            else:
                self._holders.clear()
            self._served_alone(only)
            return out
        out = []
        holders = self._holders
        limit = len(holders) if budget is None else min(budget, len(holders))
        while len(out) < limit:
            line = self._next()
            msg = line.pop()
            out.append(msg)
            self._served(line)
            key = msg[0] & KEY_MAX
            holder = holders.pop(key)
            if isinstance(holder, tuple):  # it had places in other lines too: it leaves them all
                for other in holder:
                    if other is not line:
                        other.remove(key)
                        if not other:
                            self._leave(other)
        return out


class FairFifo(_Turns[_Fifo]):
    """A raw bridge's lines: every message, oldest first, one line per source, served in turn.

    At most `limit` messages wait in all; past it, the oldest message of the longest
    line of the link with the most waiting is dropped (a flooder's own, never another
    source's while the flooder has more), and counted by the caller.
    """

    _kind = _Fifo

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f"a raw queue holds at least 1 message, got {limit}")
        super().__init__()
        self.limit = limit
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def push(self, messages: list[Message], link: int, sub: Hashable = None) -> int:
        """Queue every message of `messages` from source (link, sub); returns how many were dropped to make room."""
        if not messages:
            return 0
        line = self._line(link, sub)
        line.extend(messages)
        if not line.waiting:
            self._settle(line)
        self._count += len(messages)
        dropped = 0
        while self._count > self.limit:
            self._drop_one()
            dropped += 1
        return dropped

    def _drop_one(self) -> None:
        """Drop the oldest message of the longest line of the link with the most waiting (the first in turn of
        equals). Counting them costs a pass over the waiting lines, made only when the queue is full."""
        ring = max(self._waiting_rings(), key=lambda lines: sum(map(len, lines.values())))
        line = max(ring.values(), key=len)
        line.popleft()
        self._count -= 1
        if not line:
            self._leave(line)

    def drain(self, budget: int | None = None) -> list[Message]:
        """Up to `budget` messages (all if None): one from each source in turn."""
        only = self._only()
        if only is not None and (budget is None or budget >= len(only)):  # one source, all of it: the hot path
            out = list(only)
            only.clear()
            self._count = 0
            self._served_alone(only)
            return out
        out = []
        limit = self._count if budget is None else min(budget, self._count)
        while len(out) < limit:
            line = self._next()
            out.append(line.popleft())
            self._served(line)
        self._count -= len(out)
        return out
