"""The PC's seat in the swarm: one engine attached to any number of links, owning its threads.

C twin: vstig_hw/_cext/path.c (Path: `_deliver`, `_arrive`, `_spread`); held equal by tests/native (index:
vstig_hw/_vstig.pyi).

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
thread frames, guards, judges and sends everything one read returned, under the
Node's lock, before it reads again (`_deliver`); a frame is never queued for
another thread on its way from one device to another. The loop (`run`, `poll`
one step of it, or `start` on a thread of the Node's own) only ticks every
`period`, runs `submit`'s calls and sends what a budget window held back once the
window opens. Nothing waits on a device under the lock: each link writes through
its own bounded queue (`writer`), so a link that cannot take what we send delays
no other. An optional `guard` (see `guard`) sees what each link heard before the
engine, a raw relay or a listener does.

The Node owns its threads and its lock; everything else comes in through these
(what a new part, listener or program uses):

* `listen(unit=, heard=, refused=, messages=, change=, tick=, delivered=, closed=)` -> a
  `Listening` whose `cancel()` stops those calls. They run under the Node's lock on
  the thread that did the work (a reader's, the loop's, a caller's), so they must
  be quick and never wait for the loop.
* `put`, `get`, `ask`, `probe`, `entry`, `entries`, `stats`: from any thread.
* `submit(fn)` -> a Future: `fn` runs on the loop's thread with the Node to itself.
* `drain(timeout)`: what is held back goes out; `close(drain=)` stops, one rule
  for every command and the Python API:

A stop delivers or counts. `close` pauses the ticks (no refresh, no asks), stops
the readers and hands every batch they already read to the part and the
listeners; a transport that hands over anything later (a read that outlived the
stop, a device's callback in flight) has its messages counted as
`dropped_at_stop`, never handled half-way. Then what the budget held back goes
out (`drain`, at most `drain` seconds, at the budget's pace), the devices get the
rest of that time to take what the writers hold, what is left is counted
(`unsent_at_close`), and the links close.
"""

from __future__ import annotations

import collections
import concurrent.futures
import enum
import gc
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

from ..auth import SwarmKeys
from ..counters import ENGINE_STATS, Counters
from ..engine import ConflictResolver, Entry, Stigmergy
from ..links.link import Heard, Link
from ..timestamps import TS_NONE
from ..wire import Message, Op
from .compiled import compiled_for, jump_guard, receiver_for
from .delivery_state import DeliveryState
from .guard import Guard
from .outlet import Outlet
from .parts import INTAKE_TICKS, ChangeListener, RawRelay, Seat
from .readers import READ_TIMEOUT, LinkReaders
from .signing import Signing, unkeyed_policy

__all__ = ["CLOSE_DRAIN", "DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Listening", "Mode", "Node",
           "SwarmClosed", "favour_latency"]

DEFAULT_PERIOD = 0.1  # the paper's control step
DEFAULT_BUDGET = 64  # messages per link per tick: ~8 kB/s of cobs8, within a 115200-baud radio
CLOSE_DRAIN = 1.0  # seconds `close` gives what is held back and what the devices hold, by default

SWITCH_INTERVAL = 0.0005  # seconds: how soon a reader thread with a frame gets the GIL from another thread

log = logging.getLogger(__name__)
T = TypeVar("T")


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


class SwarmClosed(RuntimeError):
    """The swarm was closed (or its gateway stopped): no call reaches it any more."""


UnitListener = Callable[[Link[Any], float, Any], None]
HeardListener = Callable[[Heard], None]
RefusedListener = Callable[[Heard, str], None]  # a message the guard refused, and its drop counter name
TickListener = Callable[["Node"], None]
# What one unit carried, after the guard: link name, time heard, sender (None: the medium names none), messages.
# Cheaper than `heard` on a busy gateway: one call per unit and no `Heard` built (the live view uses it).
MessagesListener = Callable[[str, float, "int | None", list[Message]], None]
# A batch was handled and what it caused handed to the links (written, or queued to a slow link's writer):
# called with the wall-clock time the batch was read (the metrics' relay latency).
DeliveredListener = Callable[[float], None]
ClosedListener = Callable[[], None]


class Listening:
    """Calls a Node makes to one listener (`Node.listen`); `cancel()` stops them: safe twice, from any thread,
    even from inside one of them (the batch being handled then may still reach the others)."""

    def __init__(self, node: Node, unit: UnitListener | None, heard: HeardListener | None,
                 refused: RefusedListener | None, messages: MessagesListener | None, change: ChangeListener | None,
                 tick: TickListener | None, delivered: DeliveredListener | None, closed: ClosedListener | None) -> None:
        self._node = node
        self.unit, self.heard, self.refused, self.messages = unit, heard, refused, messages
        self.change, self.tick, self.delivered, self.closed = change, tick, delivered, closed
        self.active = True

    def cancel(self) -> None:
        """Stop the calls; once it returns (from another thread than the Node's) none is running any more."""
        self._node._unlisten(self)

    def __enter__(self) -> Listening:
        return self

    def __exit__(self, *exc: object) -> None:
        self.cancel()


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
        pure: bool = False,
        swarm_keys: SwarmKeys | None = None,
    ) -> None:
        self.links = list(links)
        if not self.links:
            raise ValueError("a node needs at least one link")
        self.signing = _signing(self.links, mode, swarm_keys)
        names = [link.name for link in self.links]
        if len(set(names)) != len(names):
            raise ValueError(f"link names must differ, got {', '.join(names)}")
        if mode is Mode.RAW and len(self.links) < 2:
            raise ValueError("a raw bridge needs at least two links")
        self.mode = mode
        self.period = period
        self.robot_id = robot_id
        self.label = f"the gateway on {', '.join(names)}"  # what errors call this node ("... is closed: why")
        # A relaying Node's parts are compiled where this install has the compiled path (`compiled`): the same
        # interfaces, so everything below works on either; VSTIG_PURE=1 keeps them Python, and so does `pure` (a
        # recording bridge: the compiled outlets write to the device where no recorder sees what they send), and so
        # does the swarm key (`signing`: the compiled path carries no tags).
        compiled = None if pure or self.signing is not None else compiled_for(mode is not Mode.LISTEN, self.links)
        self.compiled = compiled is not None
        # what links hear passes it before the engine, a relay or a listener sees it
        self.guard = guard if compiled is None else jump_guard(guard)
        # what the deliveries (Python and compiled) and the loop tell each other; its `wake` is the loop's one
        # token (a call, a window or a slow device's room opening)
        self._state = DeliveryState()
        make_outlet = Outlet if compiled is None else compiled.outlet
        self.outlets = [] if mode is Mode.LISTEN else [
            make_outlet(link, budget, period, keep_all=mode is Mode.RAW, on_room=self._state.wake.set)
            for link in self.links
        ]
        # The listeners, one tuple per kind, replaced (never changed) by `listen` and `cancel`: the data path
        # reads them without a copy, and a listener may cancel itself while they are gone through.
        self._listenings: list[Listening] = []
        self._on_unit: tuple[UnitListener, ...] = ()
        self._on_heard: tuple[HeardListener, ...] = ()
        self._on_refused: tuple[RefusedListener, ...] = ()  # what the guard refused (a sniffer shows it too)
        self._on_tick: tuple[TickListener, ...] = ()
        self._on_messages: tuple[MessagesListener, ...] = ()
        self._on_change: tuple[ChangeListener, ...] = ()  # the table changed (Python API's watch); see `Seat`
        self._on_delivered: tuple[DeliveredListener, ...] = ()  # a batch handled and handed on (metrics' latency)
        self._on_closed: tuple[ClosedListener, ...] = ()
        self.engine: Stigmergy | None = None
        self.seat: Seat | None = None  # the engine's part: ENGINE, or LISTEN with count_outcomes
        self.part: Seat | RawRelay | None = None  # what handles the messages links heard (None: nothing)
        if mode is Mode.RAW:
            self.part = (RawRelay if compiled is None else compiled.relay)(self.outlets, self.guard)
        elif mode is Mode.ENGINE or count_outcomes:
            if self.signing is not None:
                self.engine = self.signing.engine_for(robot_id, onconflict)
            else:
                self.engine = Stigmergy(robot_id, onconflict=onconflict) if compiled is None else \
                    compiled.engine(robot_id, onconflict)
            intake = INTAKE_TICKS * budget if mode is Mode.ENGINE and budget is not None else None
            self.part = self.seat = (Seat if compiled is None else compiled.seat)(
                self.engine, self.links, self.outlets, self.guard, self._on_change, intake, period)
        self.ticks = 0
        # submit's calls, for the loop: (future, call), run under the lock on the loop's thread
        self._calls: collections.deque[tuple[concurrent.futures.Future[Any], Callable[[], Any]]] = \
            collections.deque()
        self._lock = threading.RLock()  # whoever works on the Node holds it: a reader thread, the loop, a caller
        # Each link's decoding: its framing's, or its compiled Receiver's (which then decodes for both deliveries).
        receivers = [None if compiled is None else receiver_for(link) for link in self.links]
        self._decode: list[Callable[[Any], list[Message]]] = [
            link.decode if receiver is None else receiver.feed
            for link, receiver in zip(self.links, receivers, strict=True)]
        if self.signing is not None:  # each unit's records kept for the check and the engine
            self._decode = [self.signing.decoder(link) for link in self.links]
            for link in self.links:
                link.record_of = self.signing.record_of(link)
        self._tickers: list[Callable[[], None]] = [
            link.tick if receiver is None else receiver.tick for link, receiver in zip(self.links, receivers,
                                                                                      strict=True)]
        # The compiled delivery (`compiled`) takes a batch whole while no listener wants each unit or every
        # `Heard`, and tells the `messages`, `refused`, `change` and `delivered` listeners itself: it looks at
        # these lists, which `_rebuild_listeners` keeps equal to the listeners' tuples.
        self._path_wants: list[Sequence[Any]] = []
        self._path_told: list[tuple[Callable[..., None], ...]] = [(), ()]  # messages, refused
        self._path_delivered: list[DeliveredListener] = []
        self._path = None if compiled is None else compiled.path(
            self._state, self._lock, self._deliver, self.links, receivers, self.part, self.guard, self.outlets,
            self._path_wants, self._path_told, self._path_delivered)
        self._readers = LinkReaders(self.links, self._deliver if self._path is None else self._deliver_compiled,
                                    self._path)
        self._loop_thread = 0  # ident of the thread in `run` (0: none)
        self._leftover: list[tuple[int, float, list[Any]]] = []  # batches read while closing, for `close`
        self._taking = True  # batches are handled; False once a stop handed over what was read (later: counted)
        self._paused = False  # no ticks: draining before a stop
        self._next_tick = 0.0
        self._opened: list[Link[Any]] = []
        self._flush_order: dict[int, list[Outlet]] = {}  # heard_on -> the outlets in `_spread`'s order
        self._closed_because: str | None = None  # why no call gets in any more (None: open for calls)
        self._shut = False  # the links were closed (or are being closed)
        self._shutting = threading.Lock()
        self._serving: threading.Thread | None = None  # the loop's own thread, after `start`
        self._stop_requested = threading.Event()  # `close` asked the running loop to return
        self._close_drain = CLOSE_DRAIN

    # -- lifetime --------------------------------------------------------------
    def open(self) -> None:
        """Open every link and start reading; on failure, close what was opened and re-raise."""
        try:
            for link in self.links:
                link.open()
                self._opened.append(link)
        except BaseException:
            self.close(drain=0.0)
            raise
        self._readers.start()
        self._next_tick = time.monotonic() + self.period

    def start(self) -> None:
        """Open the links (unless open) and run the loop on a thread of the Node's own until `close`.

        A listener that raises there ends it: the Node closes, naming why (`SwarmClosed`).
        """
        if self._serving is not None:
            raise RuntimeError(f"{self.label} was started once already")
        if not self._opened:
            self.open()
        self._serving = threading.Thread(target=self._serve, name=f"vstig-gateway-{self.robot_id}", daemon=True)
        self._serving.start()

    def close(self, drain: float = CLOSE_DRAIN) -> None:
        """Stop: ticks pause, every frame already read is handled (later ones counted), what is held back goes
        out within `drain` seconds, the links close. Safe twice and from any thread.

        From inside a listener, or on the thread running the loop, it asks the loop to stop and returns:
        the Node's own loop thread (`start`) then closes, and a caller's `run` returns to its caller, who
        closes (a `with` block does). From another thread it waits for a running loop to stop, then closes.
        """
        me = threading.get_ident()
        self._close_drain = drain
        serving = self._serving
        on_reader = me == self._state.reader_thread
        if serving is not None and serving.is_alive():
            self._request_stop()
            if serving.ident != me and not on_reader:
                serving.join()
            return
        if me == self._loop_thread or (on_reader and self._loop_thread):
            self._request_stop()
            return
        if self._loop_thread:  # a loop runs on another thread: it returns at its next look
            self._request_stop()
            while self._loop_thread:
                time.sleep(0.005)
        self._shutdown(0.0 if on_reader else drain)  # a listener with no loop running: nothing can drain

    def _request_stop(self) -> None:
        self._stop_requested.set()
        self._state.wake.set()

    @property
    def closed(self) -> bool:
        """Whether calls are refused: the Node closed, began closing, or its loop thread failed."""
        return self._closed_because is not None

    def check_open(self) -> None:
        """SwarmClosed naming why, once calls are refused (see `closed`)."""
        because = self._closed_because
        if because is not None:
            raise SwarmClosed(f"{self.label} is closed: {because}")

    def __enter__(self) -> Node:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _serve(self) -> None:
        """The loop's own thread (`start`): run until `close`; a failure closes the Node, naming it."""
        try:
            self.run()
        except BaseException as error:  # a link or a listener broke the loop: every caller hears why
            log.exception("%s stopped", self.label)
            with self._lock:
                if self._closed_because is None:
                    self._closed_because = f"its gateway stopped: {type(error).__name__}: {error}"
        finally:
            self._shutdown(self._close_drain)

    def _shutdown(self, drain: float) -> None:
        """The stop, once (see the module docstring): delivers or counts, drains, closes, tells `closed`."""
        with self._shutting:
            if self._shut:
                return
            self._shut = True
        deadline = time.monotonic() + drain
        with self._lock:
            if self._closed_because is None:
                self._closed_because = "it was closed"
            self._paused = True
        self._readers.stop()
        with self._lock:  # what the readers read is handled; whatever comes later is counted (`_deliver`)
            self._taking = False  # before the leftovers are taken: one appended later is `_deliver`'s to count
            leftover, self._leftover = self._leftover, []
            for item in leftover:
                try:
                    self._arrive(*item)
                except Exception:  # a listener that breaks now must not keep the links open
                    log.exception("a listener of %s failed while it stopped", self.label)
        self._fail_calls()
        self._stop_requested.clear()  # the stop asked of a running loop was honoured: the drain runs it again
        if self._opened and self.outlets:
            self._drain_until(deadline)
        for outlet in self.outlets:  # the devices get the rest of the time to take what the writers hold
            outlet.close(max(0.0, deadline - time.monotonic()))
        while self._opened:
            link = self._opened.pop()
            try:
                link.close()
            except Exception:  # closing must reach every link even if one device is already gone
                link.counters["close_error"] += 1
        for listener in self._on_closed:
            try:
                listener()
            except Exception:
                log.exception("a closed listener of %s failed", self.label)

    # -- the robot's program (ENGINE mode) --------------------------------------
    # Any thread may call these: they take the Node's lock themselves.
    def put(self, key: int, value: int) -> Entry:
        """Write `value` under `key` (timestamp one past ours) and send it; the entry written."""
        with self._lock:
            seat = self._seat()
            seat.put(key, value)
            self._spread_and_wake()
            entry = seat.engine.entry(key)
        assert entry is not None
        return entry

    def get(self, key: int) -> int | None:
        """Our value for `key` (None: unknown), and a GET carrying our view sent (the paper's read)."""
        with self._lock:
            value = self._seat().get(key)
            self._spread_and_wake()
            return value

    def ask(self, key: int) -> None:
        """Broadcast an empty GET for `key` (timestamp 0): every neighbour holding it answers with its entry.

        `get` carries our view of the key, which only holders of a newer entry
        answer; this asks everyone, whatever we hold (SPEC section 4, row 5).
        """
        with self._lock:
            self._seat().ask(key)
            self._spread_and_wake()

    def probe(self, key: int) -> None:
        """`ask` at once on every link, ahead of whatever is queued or held back by a budget window.

        What leaves after it leaves after it on every device, so a link that echoes
        brings it back before anything sent later (a confirmed write's test for an echo).
        """
        with self._lock:
            seat = self._seat()
            probe = Message(Op.GET, key, 0, TS_NONE, seat.engine.robot_id)
            now = time.monotonic()
            for outlet in self.outlets:
                outlet.send_now(probe, now)

    def entry(self, key: int) -> Entry | None:
        """Our entry for `key` (None: unknown); sends nothing."""
        self.check_open()
        return self._engine().entry(key)

    def entries(self) -> list[tuple[int, Entry]]:
        """Every (key, entry) of our table: a snapshot."""
        with self._lock:
            return list(self._engine().entries())

    def _seat(self) -> Seat:
        self.check_open()
        if self.seat is None or self.mode is not Mode.ENGINE:
            raise RuntimeError(f"a {self.mode.value} node cannot put, get or ask: only an engine node transmits")
        return self.seat

    def _engine(self) -> Stigmergy:
        if self.engine is None:
            raise RuntimeError(f"a {self.mode.value} node keeps no table")
        return self.engine

    # -- the loop ----------------------------------------------------------------
    def run(self, stop: threading.Event | None = None, until: Callable[[], bool] | None = None,
            duration: float | None = None) -> None:
        """Loop until `stop` is set, `until()` is true, `duration` seconds pass, or `close` asks it to stop.

        `until` runs on this thread under the lock, after every batch a link delivers
        (and at every tick): the loop is woken for it, which a plain relay is not.
        """
        deadline = None if duration is None else time.monotonic() + duration
        stopping = self._stop_requested
        self._state.wake_on_arrival = until is not None
        self._loop_thread = threading.get_ident()
        try:
            while not (stop is not None and stop.is_set()) and not stopping.is_set() \
                    and not (until is not None and self._holds(until)):
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return
                wait = self._next_tick - now
                if deadline is not None:
                    wait = min(wait, deadline - now)
                self.poll(max(0.0, min(wait, 0.25)))
        finally:
            self._state.wake_on_arrival = False
            self._loop_thread = 0

    def _holds(self, until: Callable[[], bool]) -> bool:
        with self._lock:
            return until()

    def poll(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for a wake-up (a call, a budget window opening), then tick if due.

        The links' frames are handled on their reader threads as they arrive
        (`_deliver`), not here; a listener's exception from there is raised here.
        """
        state = self._state
        wake = state.wake
        state.sleep_until = time.monotonic() + timeout  # set before reading retry_at: see `_deliver`
        retry = state.retry_at
        if retry is not None:
            timeout = min(timeout, retry - time.monotonic())
        wake.wait(timeout)  # wake-ups that came together are one
        state.sleep_until = 0.0
        with self._lock:  # held while working, never while waiting: other threads may call in between
            failure, state.failure = state.failure, None
            if failure is not None:
                raise failure
            calls = self._calls
            while calls:
                future, call = calls.popleft()
                _settle(future, call)
            now = time.monotonic()
            if now >= self._next_tick and not self._paused:
                self._tick(now)
            self._spread(now)

    def _deliver(self, index: int, t: float, units: list[Any]) -> None:
        """On link `index`'s reader thread: handle what one read returned, and send what it caused, at once.

        Everything the read returned is heard before anything is sent (one batch per
        write). The loop is woken only when it must look: a budget window holds
        messages back sooner than it would look by itself, or `run` has an `until`.
        Every batch is handled, or counted (`dropped_at_stop`) when it comes after a
        stop handed over what was read: the one place that rule lives.
        """
        lock = self._lock
        appended = False
        while not (lock.acquire(False) or lock.acquire(True, READ_TIMEOUT)):  # the first try parses no keywords
            if self._readers.stopping and not appended:  # the closer may hold the lock: it hands this batch on
                self._leftover.append((index, t, units))
                appended = True
                if self._taking:  # else the closer may be past its leftovers: count what it left, below
                    return
        if not self._taking:  # after the stop handed over what was read: counted, not handled half-way
            try:
                self._count_unhandled(None if appended else (index, units))
            finally:
                lock.release()
            return
        state = self._state
        state.reader_thread = threading.get_ident()
        try:
            self._arrive(index, t, units)
            self._spread(time.monotonic(), 1 << index)
            for delivered in self._on_delivered:
                delivered(t)
        except BaseException as failure:  # a listener broke: `run` raises it on the loop's thread, as before
            if state.failure is None:
                state.failure = failure
            state.wake.set()
            return
        finally:
            state.reader_thread = 0
            lock.release()
        retry = state.retry_at  # read after _spread set it; the loop sets sleep_until before reading it
        if state.wake_on_arrival or (retry is not None and retry < state.sleep_until):
            state.wake.set()

    def _count_unhandled(self, batch: tuple[int, list[Any]] | None) -> None:
        """Count as `dropped_at_stop` the messages of `batch` and of any leftovers nobody will hand over now:
        units a transport returned after the stop handed over what was read (under the lock)."""
        late = [(index, units) for index, _t, units in self._leftover]
        self._leftover = []
        if batch is not None:
            late.append(batch)
        for index, units in late:
            decode = self._decode[index]
            self.links[index].counters["dropped_at_stop"] += sum(len(decode(unit)) for unit in units)

    def _deliver_compiled(self, index: int, t: float, units: list[Any]) -> None:
        """`_deliver` for what a transport's own read returned, by the compiled delivery where it can."""
        path = self._path
        assert path is not None
        if not path.deliver(index, t, units):
            self._deliver(index, t, units)

    def _arrive(self, index: int, t: float, units: list[Any]) -> None:
        link = self.links[index]
        decode = self._decode[index]
        sender_of = link.sender_of
        part = self.part
        guard = self.guard
        on_unit, on_heard, on_messages = self._on_unit, self._on_heard, self._on_messages
        source_of = link.source_of if link.framing.names_sources else None  # one call less a unit where it says none
        admit = self.seat.admit if self.seat is not None and self.seat.intake is not None else None
        signing = self.signing
        heard_count = 0
        for unit in units:
            for listener in on_unit:
                listener(link, t, unit)
            messages = decode(unit)
            if not messages:
                continue
            heard_count += len(messages)
            if signing is not None:  # tags by the link's policy, before the guard and the intake
                messages = signing.check(link, messages, t, sender_of(unit), self._on_refused)
                if not messages:
                    continue
            source = source_of(unit) if source_of is not None else None  # which of the link's peers sent it
            if admit is not None:  # the engine's intake per source, before any other work
                messages = admit(index, source, messages, t)
                if not messages:
                    continue
            sender = sender_of(unit) if guard is not None or on_heard or self._on_change or on_messages else None
            told = False
            if guard is not None:
                if self._on_refused:
                    messages, told = self._judge_and_tell(guard, link, sender, source, messages, t), True
                else:
                    messages = guard.filter(link.name, sender, messages, t, link.counters, source)
            if on_heard and not told:
                for msg in messages:
                    heard = Heard(msg, link.name, t, sender)
                    for h_listener in on_heard:
                        h_listener(heard)
            if messages:
                for m_listener in on_messages:
                    m_listener(link.name, t, sender, messages)
            if part is not None and messages:
                part.take(index, messages, sender, source)
        link.counters["in"] += heard_count

    def _judge_and_tell(self, guard: Guard, link: Link[Any], sender: int | None, source: str | None,
                        messages: list[Message], t: float) -> list[Message]:
        """Tell the listeners every message, passed (heard) or refused (refused), in the order heard,
        as a sniffer shows them; the ones that passed."""
        kept = []
        for msg in messages:
            reason = guard.check(link.name, sender, msg, t, source)
            heard = Heard(msg, link.name, t, sender)
            if reason is None:
                kept.append(msg)
                for h_listener in self._on_heard:
                    h_listener(heard)
            else:
                link.counters[reason] += 1
                for r_listener in self._on_refused:
                    r_listener(heard, reason)
        return kept

    # -- other threads and listeners ------------------------------------------------
    # Whoever works on the Node holds its lock (an RLock nobody holds while waiting): a reader thread with a
    # batch, the loop, a caller of put/get/ask. Listeners run under it, on whichever thread did the work.
    def listen(self, *, unit: UnitListener | None = None, heard: HeardListener | None = None,
               refused: RefusedListener | None = None, messages: MessagesListener | None = None,
               change: ChangeListener | None = None, tick: TickListener | None = None,
               delivered: DeliveredListener | None = None, closed: ClosedListener | None = None) -> Listening:
        """Call these as the Node works, until the returned handle's `cancel()`; safe from any thread.

        * `unit(link, t, unit)`: every unit a link read, before it is decoded (a recorder);
        * `heard(Heard)`: every message that passed the guard, in the order heard;
        * `refused(Heard, reason)`: every message the guard refused, with its drop counter's name;
        * `messages(link_name, t, sender, messages)`: what one unit carried past the guard, one call
          per unit and no `Heard` built (cheaper than `heard` on a busy gateway);
        * `change(key, old, new, link_name, sender)`: our table's entry changed (`link_name` None:
          our own put); the engine tells changes only while someone listens;
        * `tick(node)`: every control period, on the loop's thread (not while a stop drains);
        * `delivered(t)`: a batch read at wall-clock time `t` was handled and what it caused handed to
          the links (written, or queued to a slow link's writer): the relay latency;
        * `closed()`: once, after the Node closed (every frame read handed over, the links closed).

        All but `closed` run under the Node's lock on the thread that did the work: quick, and
        never waiting for the loop (`on_node_thread` tells a listener it runs there).
        """
        listening = Listening(self, unit, heard, refused, messages, change, tick, delivered, closed)
        with self._lock:
            self._listenings.append(listening)
            self._rebuild_listeners()
        return listening

    def _unlisten(self, listening: Listening) -> None:
        with self._lock:
            if listening.active:
                listening.active = False
                self._listenings.remove(listening)
                self._rebuild_listeners()

    def _rebuild_listeners(self) -> None:
        every = self._listenings
        self._on_unit = tuple(x.unit for x in every if x.unit is not None)
        self._on_heard = tuple(x.heard for x in every if x.heard is not None)
        self._on_refused = tuple(x.refused for x in every if x.refused is not None)
        self._on_messages = tuple(x.messages for x in every if x.messages is not None)
        self._on_change = tuple(x.change for x in every if x.change is not None)
        self._on_tick = tuple(x.tick for x in every if x.tick is not None)
        self._on_delivered = tuple(x.delivered for x in every if x.delivered is not None)
        self._on_closed = tuple(x.closed for x in every if x.closed is not None)
        if self.seat is not None:
            self.seat.on_change = self._on_change
        self._path_wants[:] = [self._on_unit, self._on_heard]
        self._path_told[:] = [self._on_messages, self._on_refused]
        self._path_delivered[:] = self._on_delivered

    def on_node_thread(self) -> bool:
        """Whether the calling thread is working for the Node: its loop, or a reader thread handling a batch
        (a listener or a conflict rule it calls). Such a thread must not wait for the loop."""
        me = threading.get_ident()
        return me == self._loop_thread or me == self._state.reader_thread

    def submit(self, call: Callable[[], T]) -> concurrent.futures.Future[T]:
        """Run `call()` on the loop's thread with the Node to itself; its result (or exception) as a Future.

        On the Node's own threads it runs at once. Otherwise it runs at the loop's next
        poll, waking a loop that waits; a Node that closes first fails it with SwarmClosed.
        """
        future: concurrent.futures.Future[T] = concurrent.futures.Future()
        if self.on_node_thread():
            with self._lock:
                _settle(future, call)
            return future
        self._calls.append((future, call))  # deque.append is atomic: no lock shared with the loop
        self._state.wake.set()
        if self._shut:  # closed meanwhile: nobody will run it
            self._fail_calls()
        return future

    def _fail_calls(self) -> None:
        calls = self._calls
        while calls:
            try:
                future, _call = calls.popleft()
            except IndexError:  # another thread took the last one
                return
            if future.set_running_or_notify_cancel():
                future.set_exception(SwarmClosed(f"{self.label} is closed: {self._closed_because}"))

    def drain(self, timeout: float) -> bool:
        """Send what is held back now (budget windows, the devices' queues), pausing the ticks; True once it
        all left, False when `timeout` seconds passed first. On the loop's thread, or while no loop runs.

        What arrives meanwhile is still handled, and what it causes is sent, but not waited for: it ends
        when what was held back at the start has left, whatever the budget, so a swarm that keeps talking
        cannot hold it up (a stop stops the readers first: see `close`).
        """
        self._paused = True
        try:
            return self._drain_until(time.monotonic() + timeout)
        finally:
            self._paused = self._shut

    def _drain_until(self, deadline: float) -> bool:
        marks = [(outlet, outlet.handed + len(outlet)) for outlet in self.outlets]

        def drained() -> bool:
            return all((not len(outlet) or outlet.handed >= mark) and not len(outlet.writer) for outlet, mark in marks)

        self.run(until=drained, duration=max(0.0, deadline - time.monotonic()))
        with self._lock:
            return drained()

    def _tick(self, now: float) -> None:
        self.ticks += 1
        self._next_tick = max(self._next_tick + self.period, now)  # no catch-up burst after a stall
        for tick in self._tickers:  # each link's framing (its compiled Receiver's, where it has one)
            tick()
        if self.part is not None:
            self.part.tick()
        for listener in self._on_tick:
            listener(self)

    def _spread_and_wake(self) -> None:
        """`_spread` for a caller's put/get/ask: a waiting loop must look again if a budget held some back."""
        self._spread(time.monotonic())
        state = self._state
        retry = state.retry_at
        if retry is not None and retry < state.sleep_until:
            state.wake.set()

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
        self._state.retry_at = retry

    def _order_for(self, heard_on: int) -> list[Outlet]:
        """The outlets with those of links in `heard_on` last, the others in their order (a stable sort)."""
        outlets = self.outlets
        order = [outlets[i] for i in sorted(range(len(outlets)), key=lambda i: heard_on >> i & 1)]
        self._flush_order[heard_on] = order
        return order

    # -- what happened ------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """Per link: in/out, queued, and every drop by reason; then the engine's outcomes, if it has one.

        Taken under the lock: reader threads count as they work, and a counter dict must not grow while copied.
        """
        with self._lock:
            out = {link.name: link.stats() for link in self.links}
            for outlet in self.outlets:
                if len(outlet) or len(outlet.writer):
                    out[outlet.link.name]["queued"] = len(outlet) + len(outlet.writer)
            if self.engine is not None:
                out[ENGINE_STATS] = Counters({outcome.name.lower(): n for outcome, n in self.engine.counts.items()})
        return out

    def summary(self) -> str:
        return "  ".join(f"{name}: {counters.summary()}" for name, counters in self.stats().items())


def _signing(links: list[Link[Any]], mode: Mode, keys: SwarmKeys | None) -> Signing | None:
    """The swarm key's part of a Node (None: without the key, or no link with auth=require or prefer: every tag
    would be ignored, and the compiled path serves); ValueError naming what cannot work."""
    complaint = unkeyed_policy(links)
    if keys is None or complaint is None:
        if keys is None and complaint is not None:
            raise ValueError(complaint)
        return None
    if mode is Mode.RAW:
        raise ValueError("a raw bridge keeps no entries, so it cannot keep their proofs: run it with an engine "
                         "(without --raw) to check tags")
    return Signing(keys, links)


def _settle(future: concurrent.futures.Future[T], call: Callable[[], T]) -> None:
    """Run `call` for `future` unless it was cancelled; its result or exception goes to the future."""
    if not future.set_running_or_notify_cancel():
        return
    try:
        result = call()
    except BaseException as error:  # handed to whoever waits for the future, raised there
        future.set_exception(error)
    else:
        future.set_result(result)
