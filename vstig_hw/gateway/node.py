"""The PC's seat in the swarm: one engine attached to any number of links.

Modes (each picks the part that handles what links heard, see `parts`):

* ENGINE: the Node is a robot (a `Seat`). What any link hears goes into its
  engine; what the engine queues goes out on every link (its own queue per link,
  see `outlet`). Data crosses media because the protocol re-broadcasts what is new
  and answers stale GETs, not because the gateway relays.
* RAW: a transparent bridge (a `RawRelay`). Every message heard on one link is
  re-encoded in each other link's framing and sent as is: no engine, no merging.
* LISTEN: a sniffer or recorder. Nothing is ever written to any link. With
  `count_outcomes` a `Seat` with no outlets still judges everything, so `stats()`
  tells what the traffic would do to a robot (sniff shows it).

`stats()` has the engine's receive outcomes (stored, answered, stale, same,
conflict, unknown, invalid: firmware_spec/SPEC.md section 4) beside the links'
counters, under ENGINE_STATS.

No hand-offs on the data path: each link reads in its own thread, and that
thread frames, guards, judges and sends everything one read returned, under
`lock`, before it reads again (`_deliver`); a frame is never queued for another
thread on its way from one device to another. The loop (`run`, or `poll`, one
step of it) only ticks every `period`, runs `call_soon`'s calls and sends what a
budget window held back once the window opens. Nothing waits on a device under
the lock: each link writes through its own bounded queue (`writer`), so a link
that cannot take what we send delays no other. An optional `guard` (see `guard`)
sees what each link heard before the engine, a raw relay or a listener does.
"""

from __future__ import annotations

import collections
import enum
import gc
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from ..counters import ENGINE_STATS, Counters
from ..engine import ConflictResolver, Stigmergy
from ..framing.kilobot_ohc import TransmitOnlyError
from ..links.link import Heard, Link
from ..wakeup import Wakeup
from ..wire import Message
from .compiled import compiled_for, jump_guard, receiver_for
from .guard import Guard
from .outlet import Outlet
from .parts import INTAKE_TICKS, ChangeListener, RawRelay, Seat
from .readers import READ_TIMEOUT, LinkReaders

__all__ = ["DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Mode", "Node", "favour_latency"]

DEFAULT_PERIOD = 0.1  # the paper's control step
DEFAULT_BUDGET = 64  # messages per link per tick: ~8 kB/s of cobs8, within a 115200-baud radio


SWITCH_INTERVAL = 0.0005  # seconds: how soon a reader thread with a frame gets the GIL from another thread


def favour_latency() -> None:
    """Tune this process for relaying frames promptly; call it once everything is imported and built.

    * Hand the GIL between threads every 0.5 ms instead of CPython's 5 ms, so a
      frame a reader thread has just read does not wait up to 5 ms while
      another thread runs Python.
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
        # A relaying Node's parts are compiled where this install has the compiled path (`compiled`): the same
        # interfaces, so everything below works on either; VSTIG_PURE=1 keeps them Python.
        compiled = compiled_for(mode is not Mode.LISTEN, self.links)
        self.guard = guard if compiled is None else jump_guard(guard)  # what links hear passes it first
        self._wake = Wakeup()  # one token wakes the waiting loop (a call, a window or a slow device's room opening)
        make_outlet = Outlet if compiled is None else compiled.outlet
        self.outlets = [] if mode is Mode.LISTEN else [
            make_outlet(link, budget, period, keep_all=mode is Mode.RAW, on_room=self._wake.set)
            for link in self.links
        ]
        self.on_unit: list[UnitListener] = []
        self.on_heard: list[HeardListener] = []
        self.on_refused: list[RefusedListener] = []  # what the guard refused (a sniffer shows it too)
        self.on_tick: list[TickListener] = []
        self.on_messages: list[MessagesListener] = []
        self.on_change: list[ChangeListener] = []  # the table changed (Python API's watch); see `Seat`
        # A batch was handled and what it caused handed to the links (written, or queued to a slow link's writer):
        # called with the wall-clock time the batch was read, under `lock` (the metrics' relay latency).
        self.on_delivered: list[Callable[[float], None]] = []
        self.engine: Stigmergy | None = None
        self.seat: Seat | None = None  # the engine's part: ENGINE, or LISTEN with count_outcomes
        self.part: Seat | RawRelay | None = None  # what handles the messages links heard (None: nothing)
        if mode is Mode.RAW:
            self.part = (RawRelay if compiled is None else compiled.relay)(self.outlets, self.guard)
        elif mode is Mode.ENGINE or count_outcomes:
            self.engine = Stigmergy(robot_id, onconflict) if compiled is None else \
                compiled.engine(robot_id, onconflict)
            intake = INTAKE_TICKS * budget if mode is Mode.ENGINE and budget is not None else None
            self.part = self.seat = (Seat if compiled is None else compiled.seat)(
                self.engine, self.links, self.outlets, self.guard, self.on_change, intake, period)
        self.ticks = 0
        self._calls: collections.deque[Callable[[], None]] = collections.deque()  # `call_soon`'s, for the loop
        self.lock = threading.RLock()  # whoever works on the Node holds it: a reader thread, the loop, a caller
        # Each link's decoding: its framing's, or its compiled Receiver's (which then decodes for both deliveries).
        receivers = [None if compiled is None else receiver_for(link) for link in self.links]
        self._decode: list[Callable[[Any], list[Message]]] = [
            link.framing.feed if receiver is None else receiver.feed
            for link, receiver in zip(self.links, receivers, strict=True)]
        self._tickers: list[Callable[[], None]] = [
            link.tick if receiver is None else receiver.tick for link, receiver in zip(self.links, receivers,
                                                                                      strict=True)]
        # The compiled delivery (`compiled`): it takes a batch whole while no listener wants each unit or message
        # (it looks at these lists), and hands it to `_deliver` otherwise.
        self._path = None if compiled is None else compiled.path(
            self, self.lock, self._deliver, self.links, receivers, self.part, self.guard, self.outlets,
            [self.on_unit, self.on_heard, self.on_refused, self.on_messages, self.on_change], self.on_delivered)
        self._readers = LinkReaders(self.links, self._deliver if self._path is None else self._deliver_compiled,
                                    self._path)
        self._sleep_until = 0.0  # when the waiting loop looks again by itself (0: it is not waiting)
        self._wake_on_arrival = False  # the loop has an `until` to check after every batch
        self._loop_thread = 0  # ident of the thread in `run`, of the reader handling a batch (0: none)
        self._reader_thread = 0
        self._failure: BaseException | None = None  # what a listener raised on a reader thread, for `run`
        self._leftover: list[tuple[int, float, list[Any]]] = []  # batches read while closing, for `close`
        self._next_tick = 0.0
        self._retry_at: float | None = None
        self._opened: list[Link[Any]] = []
        self._flush_order: dict[int, list[Outlet]] = {}  # heard_on -> the outlets in `_spread`'s order

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
        with self.lock:
            leftover, self._leftover = self._leftover, []
            for item in leftover:
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
    # put, get and ask take `lock` themselves: any thread may call them.
    def put(self, key: int, value: int) -> None:
        with self.lock:
            self._seat().put(key, value)
            self._spread_and_wake()

    def get(self, key: int) -> int | None:
        with self.lock:
            value = self._seat().get(key)
            self._spread_and_wake()
            return value

    def ask(self, key: int) -> None:
        """Broadcast an empty GET for `key` (timestamp 0): every neighbour holding it answers with its entry.

        `get` carries our view of the key, which only holders of a newer entry
        answer; this asks everyone, whatever we hold (SPEC section 4, row 5).
        """
        with self.lock:
            self._seat().ask(key)
            self._spread_and_wake()

    def _seat(self) -> Seat:
        if self.seat is None or self.mode is not Mode.ENGINE:
            raise RuntimeError(f"a {self.mode.value} node cannot put, get or ask: only an engine node transmits")
        return self.seat

    # -- the loop ----------------------------------------------------------------
    def run(self, stop: threading.Event | None = None, until: Callable[[], bool] | None = None,
            duration: float | None = None) -> None:
        """Loop until `stop` is set, `until()` is true, or `duration` seconds pass.

        `until` runs on this thread under `lock`, after every batch a link delivers
        (and at every tick): the loop is woken for it, which a plain relay is not.
        """
        deadline = None if duration is None else time.monotonic() + duration
        self._wake_on_arrival = until is not None
        self._loop_thread = threading.get_ident()
        try:
            while not (stop is not None and stop.is_set()) and not (until is not None and self._holds(until)):
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return
                wait = self._next_tick - now
                if deadline is not None:
                    wait = min(wait, deadline - now)
                self.poll(max(0.0, min(wait, 0.25)))
        finally:
            self._wake_on_arrival = False
            self._loop_thread = 0

    def _holds(self, until: Callable[[], bool]) -> bool:
        with self.lock:
            return until()

    def poll(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for a wake-up (a call, a budget window opening), then tick if due.

        The links' frames are handled on their reader threads as they arrive
        (`_deliver`), not here; a listener's exception from there is raised here.
        """
        wake = self._wake
        self._sleep_until = time.monotonic() + timeout  # set before reading _retry_at: see `_deliver`
        retry = self._retry_at
        if retry is not None:
            timeout = min(timeout, retry - time.monotonic())
        wake.wait(timeout)  # wake-ups that came together are one
        self._sleep_until = 0.0
        with self.lock:  # held while working, never while waiting: other threads may call in between
            failure, self._failure = self._failure, None
            if failure is not None:
                raise failure
            calls = self._calls
            while calls:
                calls.popleft()()
            now = time.monotonic()
            if now >= self._next_tick:
                self._tick(now)
            self._spread(now)

    def _deliver(self, index: int, t: float, units: list[Any]) -> None:
        """On link `index`'s reader thread: handle what one read returned, and send what it caused, at once.

        Everything the read returned is heard before anything is sent (one batch per
        write). The loop is woken only when it must look: a budget window holds
        messages back sooner than it would look by itself, or `run` has an `until`.
        """
        lock = self.lock
        while not (lock.acquire(False) or lock.acquire(True, READ_TIMEOUT)):  # the first try parses no keywords
            if self._readers.stopping:  # the closer may hold the lock: it hands this batch on
                self._leftover.append((index, t, units))
                return
        if self._readers.stopping:  # a transport's callback, late: the closer may be past its leftovers
            lock.release()
            return
        self._reader_thread = threading.get_ident()
        try:
            self._arrive(index, t, units)
            self._spread(time.monotonic(), 1 << index)
            for delivered in self.on_delivered:
                delivered(t)
        except BaseException as failure:  # a listener broke: `run` raises it on the loop's thread, as before
            if self._failure is None:
                self._failure = failure
            self._wake.set()
            return
        finally:
            self._reader_thread = 0
            lock.release()
        retry = self._retry_at  # read after _spread set it; the loop sets _sleep_until before reading it
        if self._wake_on_arrival or (retry is not None and retry < self._sleep_until):
            self._wake.set()

    def _deliver_compiled(self, index: int, t: float, units: list[Any]) -> None:
        """`_deliver` for what a transport's own read returned, by the compiled delivery where it can."""
        path = self._path
        assert path is not None
        if not path.deliver(index, t, units):
            self._deliver(index, t, units)

    def _arrive(self, index: int, t: float, units: list[Any]) -> None:
        link = self.links[index]
        feed = self._decode[index]
        sender_of = link.sender_of
        source_of = link.source_of
        part = self.part
        guard = self.guard
        admit = self.seat.admit if self.seat is not None and self.seat.intake is not None else None
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
            source = source_of(unit) if source_of is not None else None  # which of the link's peers sent it
            if admit is not None:  # the engine's intake per source, before any other work
                messages = admit(index, source, messages, t)
                if not messages:
                    continue
            sender = sender_of(unit) if guard is not None or self.on_heard or self.on_change or self.on_messages \
                else None
            told = False
            if guard is not None:
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
            if part is not None and messages:
                part.take(index, messages, sender, source)
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

    # -- other threads and watchers (the Python API, vstig_hw.api) ----------------
    # Whoever works on the Node holds `lock` (an RLock nobody holds while waiting): a reader thread with a
    # batch, the loop, a caller of put/get/ask. Another thread holds it around several calls, or hands a call
    # to the loop. Listeners (on_unit, on_heard, on_change...) run under it, on whichever thread did the work.
    def on_node_thread(self) -> bool:
        """Whether the calling thread is working for the Node: its loop in `run`, or a reader thread handling
        a batch (a listener or a conflict rule it calls). Such a thread must not wait for the loop."""
        me = threading.get_ident()
        return me == self._loop_thread or me == self._reader_thread

    def call_soon(self, call: Callable[[], None]) -> None:
        """Run `call` on the loop's thread at its next poll, waking a loop that waits; safe from any thread.

        The loop runs it between draining what links heard and ticking; an exception
        it raises ends `run`, so a caller wraps what may fail.
        """
        self._calls.append(call)  # deque.append is atomic: no lock shared with the loop
        self._wake.set()

    def _tick(self, now: float) -> None:
        self.ticks += 1
        self._next_tick = max(self._next_tick + self.period, now)  # no catch-up burst after a stall
        for tick in self._tickers:  # each link's framing (its compiled Receiver's, where it has one)
            tick()
        if self.part is not None:
            self.part.tick()
        for listener in self.on_tick:
            listener(self)

    def _spread_and_wake(self) -> None:
        """`_spread` for a caller's put/get/ask: a waiting loop must look again if a budget held some back."""
        self._spread(time.monotonic())
        retry = self._retry_at
        if retry is not None and retry < self._sleep_until:
            self._wake.set()

    def _spread(self, now: float, heard_on: int = 0) -> None:
        """Queue the engine's outbox on the links (`Seat.queue_out`), then send what budgets allow.

        Links that just delivered (bits of `heard_on`) are flushed last: on a broadcast
        medium every robot there heard those frames when we did, so what they caused is
        news on the other links first, and a slow echo must not hold up the crossing.
        """
        if self.seat is not None:
            self.seat.queue_out()
        outlets = self.outlets  # outlets[i] belongs to links[i]
        if heard_on:
            outlets = self._flush_order.get(heard_on) or self._order_for(heard_on)
        retry = None
        for outlet in outlets:
            again = outlet.flush(now)
            if again is not None and (retry is None or again < retry):
                retry = again
        self._retry_at = retry

    def _order_for(self, heard_on: int) -> list[Outlet]:
        """The outlets with those of links in `heard_on` last, the others in their order (a stable sort)."""
        outlets = self.outlets
        order = [outlets[i] for i in sorted(range(len(outlets)), key=lambda i: heard_on >> i & 1)]
        self._flush_order[heard_on] = order
        return order

    # -- what happened ------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """Per link: in/out, queued, and every drop by reason; then the engine's outcomes, if it has one.

        Taken under `lock`: reader threads count as they work, and a counter dict must not grow while copied.
        """
        with self.lock:
            out = {link.name: link.stats() for link in self.links}
            for outlet in self.outlets:
                if len(outlet) or len(outlet.writer):
                    out[outlet.link.name]["queued"] = len(outlet) + len(outlet.writer)
            if self.engine is not None:
                out[ENGINE_STATS] = Counters({outcome.name.lower(): n for outcome, n in self.engine.counts.items()})
        return out

    def summary(self) -> str:
        return "  ".join(f"{name}: {counters.summary()}" for name, counters in self.stats().items())
