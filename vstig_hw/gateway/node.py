"""The PC's seat in the swarm: one engine attached to any number of links, owning its threads.

Its `Mode` (ENGINE a robot, RAW a transparent bridge, LISTEN a sniffer or recorder: see `assembly.Mode`) picks
the part that handles what links heard. The Node is a façade over its collaborators, one job each:

* `assembly.build_parts`: what it is made of (compiled or Python parts, outlets, engine, part), chosen once;
* `lifecycle.LinkLifecycle`: the links from open to close, a reader thread per link, the loop's thread, the stop;
* `delivery.Delivery`: what a read returned, handled and sent on, on the reader's thread (the compiled one or
  the Python one, chosen once when the Node is built);
* `outbound.Outbound`: the engine's outbox onto each link's outlet, in the order they flush;
* `loop.Loop`: its own thread, ticking every `period`, running `submit`'s calls, sending what a window held back;
* `delivery_state.DeliveryState`: the wake-ups the deliveries and the loop give each other (declared: the C
  reads it too);
* `listeners.Listeners`: who is told what (`listen`).

One way to own it, for every command and the Python API: `open()` (or `with node:`) opens the links and starts
the loop on the Node's own thread; callers then use `put`/`get`/`ask`/`probe`/`entry`/`entries`/`stats` from
any thread, `submit(fn)` (a Future: `fn` runs on the loop's thread with the Node to itself), `listen(...)`,
`drain(timeout)`, `wait_closed(timeout)` and `close(drain=)`. Nobody else drives the loop. A listener or rule
that raises on the Node's threads closes it, naming why (`SwarmClosed`, and `failure`). A stop delivers or
counts (`lifecycle`).
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from ..auth import SwarmKeys
from ..counters import ENGINE_STATS, Counters
from ..engine import ConflictResolver, Entry, Stigmergy
from ..links.link import Link
from ..timestamps import TS_NONE
from ..wire import Message, Op
from . import listeners as on
from .assembly import Mode, build_parts
from .delivery import Delivery
from .delivery_state import DeliveryState
from .guard import Guard
from .latency import favour_latency
from .lifecycle import CLOSE_DRAIN, LinkLifecycle, SwarmClosed
from .listeners import Listeners, Listening
from .loop import Loop, settle
from .outbound import Outbound
from .parts import Seat

__all__ = ["CLOSE_DRAIN", "DEFAULT_BUDGET", "DEFAULT_PERIOD", "ENGINE_STATS", "Listening", "Mode", "Node",
           "SwarmClosed", "favour_latency"]

DEFAULT_PERIOD = 0.1  # the paper's control step
DEFAULT_BUDGET = 64  # messages per link per tick: ~8 kB/s of cobs8, within a 115200-baud radio

T = TypeVar("T")


class Node:
    def __init__(self, links: Iterable[Link[Any]], robot_id: int = 0, *, mode: Mode = Mode.ENGINE,
                 period: float = DEFAULT_PERIOD, budget: int | None = DEFAULT_BUDGET,
                 onconflict: ConflictResolver | None = None, count_outcomes: bool = False, guard: Guard | None = None,
                 pure: bool = False, swarm_keys: SwarmKeys | None = None) -> None:
        self.links = list(links)
        if not self.links:
            raise ValueError("a node needs at least one link")
        self.mode, self.period, self.robot_id = mode, period, robot_id
        self._lock = threading.RLock()  # whoever works on the Node holds it: a reader thread, the loop, a caller
        self._state = DeliveryState()  # its `wake` is the loop's one token (a call, a window or a device's room)
        self._listeners = Listeners(self._lock)
        parts = build_parts(self.links, robot_id, mode, period, budget, onconflict, count_outcomes, guard, pure,
                            swarm_keys, self._state.wake.set, self._listeners.change)
        self.compiled = parts.compiled is not None  # its parts are C (`compiled`); else Python
        self.signing, self.guard, self.outlets = parts.signing, parts.guard, parts.outlets
        self.engine, self.seat, self.part = parts.engine, parts.seat, parts.part
        self._listeners.seat = self.seat
        self._outbound = Outbound(self.outlets, self.seat, self._state)
        self._delivery = Delivery(self.links, self.part, self.guard, self.signing, self._listeners, self._outbound,
                                  self._state, self._lock, parts.compiled)
        self._loop = Loop(self._lock, self._state, period, self._tick, self._outbound.spread)
        self._lifecycle = LinkLifecycle(f"the gateway on {', '.join(link.name for link in self.links)}", self.links,
                                        self._delivery, self._outbound, self._loop, self._listeners, self._lock,
                                        self._drain_until)

    # -- lifetime (`lifecycle`) -------------------------------------------------
    def open(self) -> None:
        """Open every link, start reading and start the loop on a thread of the Node's own until `close`; on
        failure, close what was opened and re-raise. Once per Node."""
        self._lifecycle.open(f"vstig-gateway-{self.robot_id}")

    def close(self, drain: float = CLOSE_DRAIN) -> None:
        """Stop: ticks pause, every frame already read is handled (later ones counted), what is held back goes
        out within `drain` seconds, the links close. Safe twice and from any thread: from the Node's own threads
        (a listener, a submitted call) it asks the loop to stop and returns, from another it waits for the end."""
        self._lifecycle.close(drain, self.on_node_thread())

    def wait_closed(self, timeout: float | None = None) -> bool:
        """Wait until the Node closed (by `close`, or by a failure on its threads: see `failure`) or `timeout`
        seconds passed; whether it closed."""
        return self._lifecycle.wait_closed(timeout)

    @property
    def failure(self) -> BaseException | None:
        """What broke the Node's loop, which closed it (None: nothing)."""
        return self._lifecycle.failure

    @property
    def closed(self) -> bool:
        """Whether calls are refused: the Node closed, began closing, or its loop thread failed."""
        return self._lifecycle.closed_because is not None

    def check_open(self) -> None:
        """SwarmClosed naming why, once calls are refused (see `closed`)."""
        if self._lifecycle.closed_because is not None:
            raise self._lifecycle.closed_error()

    @property
    def label(self) -> str:
        """What errors call this node ("... is closed: why")."""
        return self._lifecycle.label

    @label.setter
    def label(self, label: str) -> None:
        self._lifecycle.label = label

    def __enter__(self) -> Node:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the robot's program (ENGINE mode) --------------------------------------
    # Any thread may call these: they take the Node's lock themselves.
    def put(self, key: int, value: int) -> Entry:
        """Write `value` under `key` (timestamp one past ours) and send it; the entry written."""
        with self._lock:
            seat = self._seat()
            seat.put(key, value)
            self._outbound.spread_and_wake()
            entry = seat.engine.entry(key)
        assert entry is not None
        return entry

    def get(self, key: int) -> int | None:
        """Our value for `key` (None: unknown), and a GET carrying our view sent (the paper's read)."""
        with self._lock:
            value = self._seat().get(key)
            self._outbound.spread_and_wake()
            return value

    def ask(self, key: int) -> None:
        """Broadcast an empty GET for `key` (timestamp 0): every neighbour holding it answers with its entry.

        `get` carries our view of the key, which only holders of a newer entry
        answer; this asks everyone, whatever we hold (SPEC section 4, row 5).
        """
        with self._lock:
            self._seat().ask(key)
            self._outbound.spread_and_wake()

    def probe(self, key: int) -> None:
        """`ask` at once on every link, ahead of whatever is queued or held back by a budget window.

        What leaves after it leaves after it on every device, so a link that echoes
        brings it back before anything sent later (a confirmed write's test for an echo).
        """
        with self._lock:
            self._outbound.send_now(Message(Op.GET, key, 0, TS_NONE, self._seat().engine.robot_id))

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

    # -- other threads and listeners ------------------------------------------------
    # Whoever works on the Node holds its lock (an RLock nobody holds while waiting): a reader thread with a
    # batch, the loop, a caller of put/get/ask. Listeners run under it, on whichever thread did the work.
    def listen(self, *, unit: on.UnitListener | None = None, heard: on.HeardListener | None = None,
               refused: on.RefusedListener | None = None, messages: on.MessagesListener | None = None,
               change: on.ChangeListener | None = None, tick: Callable[[Node], None] | None = None,
               delivered: on.DeliveredListener | None = None, closed: on.ClosedListener | None = None) -> Listening:
        """Call these as the Node works, until the returned handle's `cancel()`; safe from any thread. What each
        is told, and when: the `listeners` module. All but `closed` run under the Node's lock on the thread that did
        the work: quick, and never waiting for the loop (`on_node_thread` tells a listener it runs there)."""
        listening = Listening(self._listeners, unit, heard, refused, messages, change, tick, delivered, closed)
        self._listeners.add(listening)
        return listening

    def on_node_thread(self) -> bool:
        """Whether the calling thread is working for the Node: its loop, or a reader thread handling a batch
        (a listener or a conflict rule it calls). Such a thread must not wait for the loop."""
        return self._loop.on_thread() or threading.get_ident() == self._state.reader_thread

    def submit(self, call: Callable[[], T]) -> concurrent.futures.Future[T]:
        """Run `call()` on the loop's thread with the Node to itself; its result (or exception) as a Future.

        On the Node's own threads it runs at once, and so it does, on the caller's thread, while no loop runs
        yet (the links still opening). Otherwise it runs at the loop's next step, waking a loop that waits; a
        Node that closes first fails it with SwarmClosed.
        """
        future: concurrent.futures.Future[T] = concurrent.futures.Future()
        if self.on_node_thread() or not (self._loop.running or self._lifecycle.shut):
            with self._lock:
                settle(future, call)
            return future
        self._loop.call_soon(future, call)
        if self._lifecycle.shut:  # closed meanwhile: nobody will run it
            self._loop.fail_calls(self._lifecycle.closed_error)
        return future

    def drain(self, timeout: float) -> bool:
        """Send what is held back now (budget windows, the devices' queues), pausing the ticks; True once it
        all left, False when `timeout` seconds passed first (or the Node closed first).

        What arrives meanwhile is still handled, and what it causes is sent, but not waited for: it ends
        when what was held back at the start has left, whatever the budget, so a swarm that keeps talking
        cannot hold it up (a stop stops the readers first: see `close`).
        """
        if self._loop.on_thread():
            return self._drain_until(time.monotonic() + timeout)
        with self._lock:
            marks = self._outbound.marks()
        if not self._loop.running or self.on_node_thread():  # no loop to send it (a reader thread must not wait)
            return self._outbound.drained(marks)
        self._loop.paused = True
        try:
            return self._loop.wait_until(lambda: self._outbound.drained(marks), timeout)
        finally:
            self._loop.paused = self._lifecycle.shut

    def _drain_until(self, deadline: float, stoppable: bool = True) -> bool:
        """On the loop's thread: run the loop, ticks paused, until what the outlets hold now has left."""
        marks = self._outbound.marks()
        return self._loop.run_paused(lambda: self._outbound.drained(marks), deadline, stoppable=stoppable)

    def _tick(self) -> None:
        """Every period, on the loop's thread under the lock: the links' framings, the part, the tick listeners."""
        for tick in self._delivery.tickers:  # each link's framing (its compiled Receiver's, where it has one)
            tick()
        if self.part is not None:
            self.part.tick()
        for listener in self._listeners.tick:
            listener(self)

    @property
    def ticks(self) -> int:
        """Control periods ticked so far."""
        return self._loop.ticks

    # -- what happened ------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """Per link: in/out, queued, and every drop by reason; then the engine's outcomes, if it has one.

        Taken under the lock: reader threads count as they work, and a counter dict must not grow while copied.
        """
        with self._lock:
            out = {link.name: link.stats() for link in self.links}
            for name, queued in self._outbound.queued().items():
                out[name]["queued"] = queued
            if self.engine is not None:
                out[ENGINE_STATS] = Counters({outcome.name.lower(): n for outcome, n in self.engine.counts.items()})
        return out

    def summary(self) -> str:
        return "  ".join(f"{name}: {counters.summary()}" for name, counters in self.stats().items())

