"""The PC's seat in the swarm: one engine attached to any number of links.

Modes:

* ENGINE: the Node is a robot. What any link hears goes into its engine; what
  the engine queues goes out on every link (its own queue per link, see
  `outlet`). Data crosses media because the protocol re-broadcasts what is new
  and answers stale GETs, not because the gateway relays. A PUT it stores is not
  echoed onto the link it came from when that link is one broadcast domain
  (`Link.one_domain`): every robot there heard the original.
* RAW: a transparent bridge. Every message heard on one link is re-encoded in
  each other link's framing and sent as is: no engine, no merging.
* LISTEN: a sniffer or recorder. Nothing is ever written to any link. With
  `count_outcomes` an engine that never transmits still hears everything, so
  `stats()` tells what the traffic would do to a robot (sniff shows it).

`stats()` has the engine's receive outcomes (stored, answered, stale, same,
conflict, unknown, invalid: firmware_spec/SPEC.md section 4) beside the links'
counters, under ENGINE_STATS.

One event loop: `run` (or `poll`, one step of it) drains the reader threads'
queue, ticks every `period`, and flushes the outlets whenever their budget
window allows. It never waits on a device: each link reads in its own thread,
a few batches ahead at most (a flooding link waits its turn), and writes through
its own bounded queue (`writer`), so a link that cannot take what we send delays
no other. An optional `guard` (see `guard`) sees what each link heard
before the engine, a raw relay or a listener does.
"""

from __future__ import annotations

import collections
import enum
import gc
import queue
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from ..counters import ENGINE_STATS, Counters
from ..engine import ConflictResolver, Entry, Outcome, Stigmergy
from ..framing.kilobot_ohc import TransmitOnlyError
from ..links.link import Heard, Link
from ..timestamps import TS_NONE
from ..wire import GET_BIT, KEY_MAX, Message, Op
from .guard import Guard
from .outlet import Outlet
from .readers import LinkReaders

__all__ = ["DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Mode", "Node", "favour_latency"]

DEFAULT_PERIOD = 0.1  # the paper's control step
DEFAULT_BUDGET = 64  # messages per link per tick: ~8 kB/s of cobs8, within a 115200-baud radio


SWITCH_INTERVAL = 0.0005  # seconds: how soon a reader thread with a frame gets the GIL from the loop


def favour_latency() -> None:
    """Tune this process for relaying frames promptly; call it once everything is imported and built.

    * Hand the GIL between threads every 0.5 ms instead of CPython's 5 ms, so a
      frame a reader thread has just read does not wait up to 5 ms while the
      loop runs Python.
    * Freeze what exists now (modules, links) out of the garbage collector's
      sight (`gc.freeze`). A full collection stops every thread while it walks
      the heap: with the CLI's imports that took 23-32 ms, every few seconds at
      5,000 frames/s, and each one delayed ~150 frames. Afterwards it walks only
      what the gateway allocated since, which is small.

    `vstig bridge` calls this; it is process-wide, so the library never does it by itself.
    """
    sys.setswitchinterval(SWITCH_INTERVAL)
    gc.collect()  # garbage frozen now would never be freed
    gc.freeze()


class Mode(enum.Enum):
    ENGINE = "engine"
    RAW = "raw"
    LISTEN = "listen"


UnitListener = Callable[[Link[Any], float, Any], None]
HeardListener = Callable[[Heard], None]
RefusedListener = Callable[[Heard, str], None]  # a message the guard refused, and its drop counter name
TickListener = Callable[["Node"], None]
# What one unit carried, after the guard: link name, time heard, sender (None: the medium names none), messages.
# Cheaper than on_heard on a busy gateway: one call per unit and no `Heard` built (the live view uses it).
MessagesListener = Callable[[str, float, "int | None", list[Message]], None]
# key, entry before (None: new key), entry after, link it came from (None: our own put), sender (None: unnamed)
ChangeListener = Callable[[int, Entry | None, Entry, str | None, int | None], None]


class Node:
    def __init__(
        self,
        links: Iterable[Link[Any]],
        robot_id: int = 0,
        *,
        mode: Mode = Mode.ENGINE,
        period: float = DEFAULT_PERIOD,
        budget: int | None = DEFAULT_BUDGET,
        onconflict: ConflictResolver | None = None,
        count_outcomes: bool = False,
        guard: Guard | None = None,
    ) -> None:
        self.links = list(links)
        if not self.links:
            raise ValueError("a node needs at least one link")
        names = [link.name for link in self.links]
        if len(set(names)) != len(names):
            raise ValueError(f"link names must differ, got {', '.join(names)}")
        if mode is Mode.RAW and len(self.links) < 2:
            raise ValueError("a raw bridge needs at least two links")
        self.mode = mode
        self.period = period
        self.guard = guard  # what links hear passes it before the engine, a relay or a listener sees it
        judge = mode is Mode.ENGINE or (count_outcomes and mode is Mode.LISTEN)
        self.engine = Stigmergy(robot_id, onconflict=onconflict) if judge else None
        self.outlets = [] if mode is Mode.LISTEN else [
            Outlet(link, budget, period, keep_all=mode is Mode.RAW) for link in self.links
        ]
        self.on_unit: list[UnitListener] = []
        self.on_heard: list[HeardListener] = []
        self.on_refused: list[RefusedListener] = []  # what the guard refused (a sniffer shows it too)
        self.on_tick: list[TickListener] = []
        self.on_messages: list[MessagesListener] = []
        self.on_change: list[ChangeListener] = []  # the table changed (Python API's watch); see `_receive_telling`
        self.ticks = 0
        self._calls: collections.deque[Callable[[], None]] = collections.deque()  # `call_soon`'s, for the loop
        self.lock = threading.RLock()  # `poll` works under it; another thread holding it may call put/get
        self._readers = LinkReaders(self.links)
        self._next_tick = 0.0
        self._retry_at: float | None = None
        self._opened: list[Link[Any]] = []
        # key -> (the PUT just stored, index of the one-domain link it came from), until the next drain
        self._heard_from: dict[int, tuple[Message, int]] = {}

    # -- lifetime --------------------------------------------------------------
    def open(self) -> None:
        """Open every link and start reading; on failure, close what was opened and re-raise."""
        try:
            for link in self.links:
                link.open()
                self._opened.append(link)
        except BaseException:
            self.close()
            raise
        self._readers.start()
        self._next_tick = time.monotonic() + self.period

    def close(self) -> None:
        """Stop reading, hand every unit already read to the listeners (no frame lost), close the links."""
        self._readers.stop()
        arrivals = self._readers.arrivals
        while not arrivals.empty():
            item = arrivals.get_nowait()
            if item is not None:
                self._arrive(*item)
        for outlet in self.outlets:  # what the devices take within a moment still goes out
            outlet.close()
        while self._opened:
            link = self._opened.pop()
            try:
                link.close()
            except Exception:  # closing must reach every link even if one device is already gone
                link.counters["close_error"] += 1

    def __enter__(self) -> Node:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the robot's program (ENGINE mode) --------------------------------------
    def put(self, key: int, value: int) -> None:
        engine = self._engine()
        old = engine.entry(key) if self.on_change else None
        engine.put(key, value)
        if self.on_change:
            self._tell(key, old, None, engine.robot_id)
        self._spread(time.monotonic())

    def get(self, key: int) -> int | None:
        value = self._engine().get(key)
        self._heard_from.pop(key, None)  # the GET may have merged into the key's pending PUT: send that everywhere
        self._spread(time.monotonic())
        return value

    def ask(self, key: int) -> None:
        """Broadcast an empty GET for `key` (timestamp 0): every neighbour holding it answers with its entry.

        `get` carries our view of the key, which only holders of a newer entry
        answer; this asks everyone, whatever we hold (SPEC section 4, row 5).
        """
        ask = Message(Op.GET, key, 0, TS_NONE, self._engine().robot_id)
        for outlet in self.outlets:
            outlet.push(ask)  # a PUT already queued for the key says more and stays (SPEC section 5)
        self._spread(time.monotonic())

    def _engine(self) -> Stigmergy:
        if self.engine is None or self.mode is not Mode.ENGINE:
            raise RuntimeError(f"a {self.mode.value} node cannot put, get or ask: only an engine node transmits")
        return self.engine

    # -- the loop ----------------------------------------------------------------
    def run(self, stop: threading.Event | None = None, until: Callable[[], bool] | None = None,
            duration: float | None = None) -> None:
        """Loop until `stop` is set, `until()` is true, or `duration` seconds pass."""
        deadline = None if duration is None else time.monotonic() + duration
        while not (stop is not None and stop.is_set()) and not (until is not None and until()):
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                return
            wait = self._next_tick - now
            if self._retry_at is not None:
                wait = min(wait, self._retry_at - now)
            if deadline is not None:
                wait = min(wait, deadline - now)
            self.poll(max(0.0, min(wait, 0.25)))

    def poll(self, timeout: float) -> None:
        """Handle what arrives within `timeout` seconds, then tick if a tick is due."""
        arrivals = self._readers.arrivals
        try:
            item = arrivals.get(timeout=timeout) if timeout > 0 else arrivals.get_nowait()
        except queue.Empty:
            item = None
        with self.lock:  # held while working, never while waiting: other threads may call in between
            heard_on = 0  # bit i: link i delivered in this poll
            handled = 0
            done = self._readers.done
            while item is not None:
                self._arrive(*item)
                done(item[0])
                heard_on |= 1 << item[0]
                handled += 1
                if handled >= self._readers.per_poll:  # a flooding link cannot keep the loop from sending
                    break
                try:
                    item = arrivals.get_nowait()
                except queue.Empty:
                    item = None
            calls = self._calls
            while calls:
                calls.popleft()()
            now = time.monotonic()
            if now >= self._next_tick:
                self._tick(now)
            self._spread(now, heard_on)

    def _arrive(self, index: int, t: float, units: list[Any]) -> None:
        link = self.links[index]
        feed = link.framing.feed
        sender_of = link.sender_of
        source_of = getattr(link.framing, "source_of", None)  # who really sent it, where more than the link
        engine = self.engine
        outlets = self.outlets
        guard = self.guard
        relays = guard is None or not guard.read_only(link.name)
        heard_count = 0
        for unit in units:
            for listener in self.on_unit:
                listener(link, t, unit)
            try:
                messages = feed(unit)
            except TransmitOnlyError:  # bytes from a stock overhead controller: counted, not decoded
                link.counters["drop_undecodable"] += 1
                continue
            if not messages:
                continue
            heard_count += len(messages)
            sender = sender_of(unit) if guard is not None or self.on_heard or self.on_change or self.on_messages \
                else None
            told = False
            if guard is not None:
                source = source_of(unit) if source_of is not None else None
                if self.on_refused:
                    messages, told = self._judge_and_tell(guard, link, sender, source, messages, t), True
                else:
                    messages = guard.filter(link.name, sender, messages, t, link.counters, source)
            if self.on_heard and not told:
                for msg in messages:
                    heard = Heard(msg, link.name, t, sender)
                    for h_listener in self.on_heard:
                        h_listener(heard)
            if messages:
                for m_listener in self.on_messages:
                    m_listener(link.name, t, sender, messages)
            if engine is not None:
                if self.on_change:
                    self._receive_telling(engine, index, messages, sender)
                elif link.one_domain and outlets:
                    self._receive_from_domain(engine, index, messages)
                else:
                    for msg in messages:
                        engine.receive(msg)
            elif self.mode is Mode.RAW and relays:
                for outlet in outlets:
                    if outlet.link is not link:
                        for msg in messages:
                            outlet.push(msg)
        link.counters["in"] += heard_count

    def _judge_and_tell(self, guard: Guard, link: Link[Any], sender: int | None, source: str | None,
                        messages: list[Message], t: float) -> list[Message]:
        """Tell the listeners every message, passed (on_heard) or refused (on_refused), in the order heard,
        as a sniffer shows them; the ones that passed."""
        kept = []
        for msg in messages:
            reason = guard.check(link.name, sender, msg, t, source)
            heard = Heard(msg, link.name, t, sender)
            if reason is None:
                kept.append(msg)
                for h_listener in self.on_heard:
                    h_listener(heard)
            else:
                link.counters[reason] += 1
                for r_listener in self.on_refused:
                    r_listener(heard, reason)
        return kept

    def _receive_from_domain(self, engine: Stigmergy, index: int, messages: list[Message]) -> None:
        """Receive what link `index` (one broadcast domain) heard, noting each PUT stored from it.

        Every robot on that link heard the PUT when we did, so `_spread` keeps its
        re-broadcast off that link. An answer for the key to that link undoes the note:
        the answer may be that very entry, merged into the pending re-broadcast.
        """
        heard_from = self._heard_from
        for msg in messages:
            outcome = engine.receive(msg)
            if outcome is Outcome.STORED and not msg[0] & GET_BIT:  # stored as is: the outbox holds `msg`
                heard_from[msg[0]] = (msg, index)
            elif outcome is Outcome.ANSWERED:
                noted = heard_from.get(msg[0] & KEY_MAX)
                if noted is not None and noted[1] == index:
                    del heard_from[msg[0] & KEY_MAX]

    # -- other threads and watchers (the Python API, vstig_hw.api) ----------------
    # A Node is single-threaded, with two ways in for another thread: hold `lock` (an RLock `poll`
    # holds only while it works, never while it waits) around put/get/ask, or hand a call to the loop.
    def call_soon(self, call: Callable[[], None]) -> None:
        """Run `call` on the loop's thread at its next poll, waking a loop that waits; safe from any thread.

        The loop runs it between draining what links heard and ticking; an exception
        it raises ends `run`, so a caller wraps what may fail.
        """
        self._calls.append(call)  # deque.append is atomic: no lock shared with the loop
        self._readers.arrivals.put(None)  # the wake-up: poll's drain stops at None, harmlessly

    def _receive_telling(self, engine: Stigmergy, index: int, messages: list[Message], sender: int | None) -> None:
        """Receive as `_arrive` does, one message at a time, telling `on_change` of every entry that changed."""
        link = self.links[index]
        domain = link.one_domain and self.outlets
        for msg in messages:
            key = msg[0] & KEY_MAX
            old = engine.entry(key)
            if domain:
                self._receive_from_domain(engine, index, [msg])
            else:
                engine.receive(msg)
            self._tell(key, old, link.name, sender)

    def _tell(self, key: int, old: Entry | None, link: str | None, sender: int | None) -> None:
        new = self.engine.entry(key) if self.engine is not None else None
        if new is not None and new != old:
            for listener in self.on_change:
                listener(key, old, new, link, sender)

    def _tick(self, now: float) -> None:
        self.ticks += 1
        self._next_tick = max(self._next_tick + self.period, now)  # no catch-up burst after a stall
        for link in self.links:
            link.tick()
        for listener in self.on_tick:
            listener(self)

    def _spread(self, now: float, heard_on: int = 0) -> None:
        """Copy the engine's outbox into every link's queue, then send what budgets allow.

        Links that just delivered (bits of `heard_on`) are flushed last: on a broadcast
        medium every robot there heard those frames when we did, so what they caused is
        news on the other links first, and a slow echo must not hold up the crossing.
        """
        if self.engine is not None and self.engine.pending():
            outgoing = self.engine.drain()
            confined_to = self.guard.confined_to if self.guard is not None and self.guard.confines else None
            origins = self._origins(outgoing)
            for i, outlet in enumerate(self.outlets):
                name = outlet.link.name
                for msg, origin in zip(outgoing, origins, strict=True):
                    if origin == i:  # every robot on that link heard it already
                        outlet.link.counters["not_echoed"] += 1
                    elif confined_to is None or confined_to(msg) in (None, name):  # a read-only link's entries stay
                        outlet.push(msg)
        outlets = self.outlets  # outlets[i] belongs to links[i]
        if heard_on:  # a stable sort: those links move to the end, the others keep their order
            outlets = [outlets[i] for i in sorted(range(len(outlets)), key=lambda i: heard_on >> i & 1)]
        retry = None
        for outlet in outlets:
            again = outlet.flush(now)
            if again is not None and (retry is None or again < retry):
                retry = again
        self._retry_at = retry

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

    # -- what happened ------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """Per link: in/out, queued, and every drop by reason; then the engine's outcomes, if it has one."""
        out = {link.name: link.stats() for link in self.links}
        for outlet in self.outlets:
            if len(outlet) or len(outlet.writer):
                out[outlet.link.name]["queued"] = len(outlet) + len(outlet.writer)
        if self.engine is not None:
            out[ENGINE_STATS] = Counters({outcome.name.lower(): n for outcome, n in self.engine.counts.items()})
        return out

    def summary(self) -> str:
        return "  ".join(f"{name}: {counters.summary()}" for name, counters in self.stats().items())
