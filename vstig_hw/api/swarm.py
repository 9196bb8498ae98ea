"""`vstig_hw.join(...)`: a Python program as a swarm member, through the gateway's Node on a thread of its own.

The Node's loop runs on one background thread. A call from another thread
(`put`, `get`, `keys`...) runs on the caller's thread holding `Node.lock`, which
the loop holds only while it works, never while it waits for the links: no
thread hand-off, so a put reaches the links as fast as through the Node itself.
What must wait without blocking (asyncio, a confirmed put) is handed to the loop
with `Node.call_soon` and awaited as a Future. `entry`, `has` and `size` read the
table directly: one dict lookup, atomic in CPython.

A confirmed put is `vstig put`'s own logic (`gateway.oneshot.ConfirmedPut`),
stepped by the gateway thread after every poll instead of by a loop of its own.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

from ..counters import Counters
from ..engine import ConflictLost, ConflictResolver, Entry, higher_robot_wins
from ..gateway.guard import DEFAULT_MAX_JUMP, Guard
from ..gateway.node import DEFAULT_BUDGET, DEFAULT_PERIOD, Node
from ..gateway.oneshot import ConfirmedPut, HearsItself, PutResult, not_taken
from ..gateway.refresh import RoundRobinGet
from ..gateway.ros2 import serve_ros2
from ..links.assemble import LinkBuildError, assemble_links
from ..links.link import Link, LinkSpec
from ..links.registry import parse
from ..values import VALUE_TYPES, ValueType, from_raw, to_raw
from ..wire import KEY_MAX, check_field
from .changes import DEFAULT_BUFFER, Change, ChangeHub, OnChange, Subscription, Watch
from .recording import Recording
from .tables import MAX_TABLE, specs_for_table, table_of

__all__ = ["DEFAULT_WAIT", "HearsItself", "NotTaken", "Swarm", "SwarmClosed", "join"]

DEFAULT_WAIT = 2.0  # seconds a confirmed write waits for a neighbour, as `vstig put --wait`
CLOSE_DRAIN = 5.0  # seconds close() lets queued messages go out at most, as `vstig put` does before it exits

log = logging.getLogger("vstig_hw.api")
T = TypeVar("T")
LinkLike = str | LinkSpec | Link[Any]


class SwarmClosed(RuntimeError):
    """The swarm was closed (or its gateway stopped): no call reaches it any more."""


class NotTaken(RuntimeError):
    """A confirmed put no neighbour showed it took; the message names what the swarm holds instead.

    `result` has the details: `written` (our last write), `holds` (our table's entry
    now), `heard` (the last entry a neighbour's message carried), `tries`.
    """

    def __init__(self, message: str, key: int, result: PutResult) -> None:
        super().__init__(message)
        self.key = key
        self.result = result


class Swarm:
    """This program's seat in the swarm: a robot with its own id, reachable from any thread.

    Made by `vstig_hw.join`, already open; use it as a context manager or call
    `close`. Keys are 0..32767; values are the 16-bit field seen as `value_type`
    (uint16, int16 or float16); the entries (`entry`, `watch`) carry the raw field.
    """

    def __init__(self, links: Sequence[Link[Any]], robot_id: int, *, period: float, budget: int | None,
                 guard: Guard | None, onconflict: ConflictResolver | None, onconflictlost: ConflictLost | None,
                 refresh: bool, value_type: ValueType, specs: Sequence[LinkSpec] | None = None,
                 options: dict[str, Any] | None = None) -> None:
        if value_type not in VALUE_TYPES:
            raise ValueError(f"value_type must be one of {', '.join(VALUE_TYPES)}, got {value_type!r}")
        self.value_type: ValueType = value_type
        self._node = Node(links, robot_id, period=period, budget=budget, guard=guard)
        engine = self._node.engine
        assert engine is not None
        self._engine = engine
        self.robot_id = robot_id
        self.counters = Counters()  # the API's own: hook_error...
        self._rule: ConflictResolver = higher_robot_wins
        self._lost: ConflictLost | None = None
        engine.onconflict = self._resolve
        self.onconflict(onconflict or higher_robot_wins)
        self.onconflictlost(onconflictlost)
        if refresh:
            self._node.on_tick.append(RoundRobinGet())
        serve_ros2(self._node)  # ros2: links publish what the Node hears and answer put, get and table
        self._hub = ChangeHub(self._attach_hub)
        self._callbacks: list[OnChange] = []
        self._puts: list[tuple[ConfirmedPut, concurrent.futures.Future[PutResult]]] = []  # gateway thread only
        self._waiting: set[concurrent.futures.Future[Any]] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed_because: str | None = "it is not open yet"
        self._specs = None if specs is None else list(specs)  # what `stigmergy(n)` derives its links from
        self._options = options or {}
        self._tables: dict[int, Swarm] = {}
        self._recordings: list[Recording] = []

    # -- lifetime --------------------------------------------------------------
    def open(self) -> Swarm:
        """Open every link and start the gateway thread (`join` does it)."""
        if self._thread is not None:
            raise SwarmClosed("this swarm was opened once already; join again for a new one")
        self._node.open()
        self._closed_because = None
        self._thread = threading.Thread(target=self._run, name=f"vstig-gateway-{self.robot_id}", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Leave the swarm: stop the gateway thread, end every watch, close the links. Safe to call twice."""
        with self._lock:
            if self._closed_because is None:
                self._closed_because = "it was closed"
        self._stop.set()
        thread = self._thread
        if thread is not None and thread.is_alive():
            self._node.call_soon(_nothing)  # wake the loop now rather than at its next tick
            if not self._on_gateway_thread():  # on it (a hook closing the swarm), it ends by itself
                thread.join(CLOSE_DRAIN + 2.0)  # it sends what is queued, then closes the links
        self._hub.close()
        for callback in self._callbacks:
            callback.cancel()
        for table in self._tables.values():
            table.close()
        self._fail_waiting()

    @property
    def closed(self) -> bool:
        """Whether the swarm can no longer be used."""
        return self._closed_because is not None

    def __repr__(self) -> str:
        state = "open" if self._closed_because is None else f"closed: {self._closed_because}"
        return f"<Swarm robot {self.robot_id} on {', '.join(self.links)} ({state})>"

    def __enter__(self) -> Swarm:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the robot's program -------------------------------------------------------
    def put(self, key: int, value: float | str, *, confirm: bool = False, timeout: float = DEFAULT_WAIT,
            tries: int = 3, learn: float = 0.0) -> Entry:
        """Write `value` under `key`; the entry written (raw value, timestamp, our id).

        With `confirm`, wait until a neighbour shows it took the write (it
        re-broadcasts it, or a GET carries it), up to `timeout` seconds per write
        and `tries` writes when the swarm answers with a newer or conflicting
        entry; `learn` seconds of asking first make the write newer than what the
        swarm holds. Raises NotTaken naming what the swarm holds instead,
        HearsItself when a link brings our own GETs back.
        """
        raw = self._raw(key, value)
        if not confirm:
            return self._call(lambda: self._put_now(key, raw))
        result = self._put_future(key, raw, timeout=timeout, tries=tries, learn=learn).result()
        return self.taken(key, result, timeout)

    def get(self, key: int) -> float | None:
        """The paper's read: our value for `key` (None if unknown), and a GET carrying it broadcast."""
        check_key(key)
        raw = self._call(lambda: self._node.get(key))
        return None if raw is None else from_raw(raw, self.value_type)

    def entry(self, key: int) -> Entry | None:
        """Our entry for `key` (raw value, timestamp, robot), or None; sends nothing."""
        check_key(key)
        self._check_open()
        return self._engine.entry(key)

    def has(self, key: int) -> bool:
        """Whether our table holds `key`."""
        check_key(key)
        self._check_open()
        return self._engine.has(key)

    def size(self) -> int:
        """How many keys our table holds."""
        self._check_open()
        return self._engine.size()

    def keys(self) -> list[int]:
        """Every key our table holds (a snapshot)."""
        return [key for key, _ in self.items()]

    def items(self) -> list[tuple[int, Entry]]:
        """Every (key, entry) of our table (a snapshot, taken on the gateway thread)."""
        return self._call(lambda: list(self._engine.entries()))

    def foreach(self, function: Callable[[int, Entry], object]) -> None:
        """Call `function(key, entry)` for every entry, as Buzz's foreach (on a snapshot: it may put)."""
        for key, entry in self.items():
            function(key, entry)

    def value(self, entry: Entry) -> float:
        """An entry's raw value seen as this swarm's `value_type`."""
        return from_raw(entry.value, self.value_type)

    def stigmergy(self, table: int) -> Swarm:
        """Table `table` (0..255) on the same media, as Buzz's `stigmergy.create(id)`: an independent Swarm.

        It is carried apart where the medium can (29-bit CAN IDs: `extended=1`;
        zenoh: its key space), joined with the same robot id and options, and
        closed with this swarm; asking again gives the same one. A link that cannot
        carry it raises ValueError naming the link.
        """
        check_field("stigmergy", MAX_TABLE, table)
        self._check_open()
        if self._specs is None:
            raise ValueError("stigmergy: this swarm was joined with Link objects or a Guard object, which belong to "
                             "one table; join with link specs (and max_jump=) to derive another table's")
        if table == table_of(self._specs):
            return self
        with self._lock:
            joined = self._tables.get(table)
            if joined is None or joined.closed:
                listening = [getattr(link.transport, "listening", ()) for link in self._node.links]
                joined = self._tables[table] = join(*specs_for_table(self._specs, table, listening),
                                                    robot_id=self.robot_id, **self._options)
        return joined

    # -- conflicts, under Buzz's names ---------------------------------------------
    def onconflict(self, rule: ConflictResolver) -> ConflictResolver:
        """Set the conflict rule: `rule(key, local, remote)` returns the winning Entry (Buzz's onconflict).

        It runs inside the gateway (a link's reader thread, holding `Node.lock`): keep it
        quick; it may call `put` (not confirmed). One that raises is logged and counted
        (hook_error), and the higher robot id wins. Usable as a decorator.
        """
        if not callable(rule):
            raise TypeError(f"onconflict needs a function (key, local, remote) -> Entry, got {rule!r}")
        self._rule = rule
        return rule

    def onconflictlost(self, hook: ConflictLost | None) -> ConflictLost | None:
        """Set `hook(key, our_lost_entry)`, called once when a conflict took one of our writes (Buzz's name).

        Runs inside the gateway, as `onconflict`. Usable as a decorator; None removes it.
        """
        if hook is not None and not callable(hook):
            raise TypeError(f"onconflictlost needs a function (key, entry) or None, got {hook!r}")
        self._lost = hook
        self._engine.onconflictlost = None if hook is None else self._conflict_lost
        return hook

    # -- changes -------------------------------------------------------------------
    def watch(self, keys: Iterable[int] | None = None, *, buffer: int = DEFAULT_BUFFER) -> Watch:
        """An iterator of every Change to the table from now on (only `keys`, if given), until the swarm closes.

        It holds at most `buffer` changes a reader has not taken: past that the
        oldest are dropped and counted in `overflow`; the gateway never waits.
        """
        watch = Watch(checked_keys(keys), buffer)
        self._subscribe(watch)
        return watch

    def on_change(self, callback: Callable[[Change], object], keys: Iterable[int] | None = None, *,
                  buffer: int = DEFAULT_BUFFER) -> OnChange:
        """Call `callback(change)` for every change (only `keys`, if given), on a thread of its own.

        The callback may call back into the swarm, even `put(confirm=True)`. A slow
        one gets a bounded buffer (see `watch`); one that raises is logged and counted
        (hook_error). Returns a handle whose `cancel()` stops it.
        """
        if not callable(callback):
            raise TypeError(f"on_change needs a function (change), got {callback!r}")
        watch = Watch(checked_keys(keys), buffer)
        self._subscribe(watch)
        handle = OnChange(callback, watch, self._hook_failed)
        self._callbacks.append(handle)
        return handle

    # -- captures ------------------------------------------------------------------
    def record(self, path: str | os.PathLike[str], *, overwrite: bool = False,
               max_bytes: int | None = None) -> Recording:
        """Start recording what the links hear into `path`, as `vstig record` would; `stop()` the Recording.

        The extension picks the format (CAN: .log .asc .blf .csv .pcap .trc; serial
        and zenoh: any name; .mcap for links of several media, with the mcap extra).
        An existing file is never replaced unless `overwrite` (FileExistsError);
        `max_bytes` rotates to numbered files. Recordings stop when the swarm closes.
        """
        self._check_open()
        recording = Recording(self._node, path, overwrite=overwrite, max_bytes=max_bytes)
        self._recordings.append(recording)
        return recording

    # -- what happened -------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """The gateway's counters per link and the engine's outcomes, then the API's own under "api"."""
        stats = self._call(self._node.stats)
        api = Counters(self.counters)
        api["watch_overflow"] = self._hub.overflow()
        stats["api"] = api
        return stats

    @property
    def links(self) -> list[str]:
        """The names of the swarm's links, as counters and changes name them."""
        return [link.name for link in self._node.links]

    @property
    def reachable(self) -> dict[str, str]:
        """Where links are reachable by others, by link name (a zenoh link: the endpoints it listens on)."""
        return {link.name: about for link in self._node.links if (about := getattr(link.transport, "about", ""))}

    # -- for vstig_hw.aio and tools: the same calls as Futures ------------------------
    def submit(self, call: Callable[[], T]) -> concurrent.futures.Future[T]:
        """Run `call()` on the gateway thread (with the Node to itself); its result as a Future."""
        self._check_open()
        future: concurrent.futures.Future[T] = concurrent.futures.Future()
        if self._on_gateway_thread():
            _settle(future, call)
            return future
        with self._lock:
            self._waiting.add(future)
        future.add_done_callback(self._forget)
        self._node.call_soon(lambda: _settle(future, call))
        if self._closed_because is not None:  # closed while we handed it over: nobody will run it
            self._fail_waiting()
        return future

    def put_future(self, key: int, value: float | str, *, timeout: float = DEFAULT_WAIT, tries: int = 3,
                   learn: float = 0.0) -> concurrent.futures.Future[PutResult]:
        """A confirmed put as a Future of its PutResult (`taken` turns one into the entry or NotTaken)."""
        return self._put_future(key, self._raw(key, value), timeout=timeout, tries=tries, learn=learn)

    def taken(self, key: int, result: PutResult, timeout: float = DEFAULT_WAIT) -> Entry:
        """The entry a neighbour showed it took; NotTaken naming what the swarm holds if none did."""
        problem = not_taken(result, key, ", ".join(self.links), timeout, self._shown)
        if problem is not None:
            raise NotTaken(problem, key, result)
        return result.written

    # -- inside ------------------------------------------------------------------------
    def _run(self) -> None:
        node = self._node
        try:
            node.run(stop=self._stop, until=self._step_puts)
            # Closing: what was put but held back by a budget still goes out, for a little while.
            node.run(until=lambda: not any(len(outlet) for outlet in node.outlets), duration=CLOSE_DRAIN)
        except BaseException as error:  # a link or a hook broke the loop: every caller hears why
            log.exception("the gateway thread stopped")
            self._closed_because = f"its gateway stopped: {type(error).__name__}: {error}"
        finally:
            self._stop.set()
            with self._node.lock:  # no caller is inside the Node while it closes, and none gets in after
                if self._closed_because is None:
                    self._closed_because = "its gateway stopped"
                self._node.close()  # hands every unit already read to the recordings
                for recording in self._recordings:
                    recording.stop()
            self._hub.close()
            self._fail_waiting()

    def _step_puts(self) -> bool:
        """Between polls, on the gateway thread: step every confirmed put; never stops the loop."""
        if self._puts:
            with self._node.lock:
                self._step_puts_now()
        return False

    def _step_puts_now(self) -> None:
        if self._puts:
            now = time.monotonic()
            going = []
            for put, future in self._puts:
                try:
                    done = put.step(now)
                except HearsItself as error:
                    put.detach()
                    _complete(future, error=error)
                    continue
                if done:
                    put.detach()
                    _complete(future, put.result())
                else:
                    going.append((put, future))
            self._puts = going

    def _put_future(self, key: int, raw: int, *, timeout: float, tries: int,
                    learn: float) -> concurrent.futures.Future[PutResult]:
        if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        check_field("tries", 100, tries)
        if tries < 1:
            raise ValueError(f"tries must be at least 1, got {tries}")
        if isinstance(learn, bool) or not isinstance(learn, int | float) or learn < 0:
            raise ValueError(f"learn must be a number of seconds >= 0, got {learn!r}")
        if self._on_gateway_thread():
            raise RuntimeError("put(confirm=True) waits for the gateway thread, so it cannot run on it (inside "
                               "onconflict or onconflictlost): use confirm=False there, or on_change")
        result: concurrent.futures.Future[PutResult] = concurrent.futures.Future()

        def start() -> None:
            put = ConfirmedPut(self._node, key, raw, learn=learn, wait=timeout, tries=tries)
            if put.start(time.monotonic()):
                put.detach()
                _complete(result, put.result())
            else:
                self._puts.append((put, result))

        started = self.submit(start)
        started.add_done_callback(lambda done: _pass_failure(done, result))
        with self._lock:
            self._waiting.add(result)
        result.add_done_callback(self._forget)
        if self._closed_because is not None:
            self._fail_waiting()
        return result

    def _put_now(self, key: int, raw: int) -> Entry:
        node = self._node
        node.put(key, raw)
        for outlet in node.outlets:
            if len(outlet):  # a budget held some back: the loop, waiting, must see when to send it
                node.call_soon(_nothing)
                break
        entry = self._engine.entry(key)
        assert entry is not None
        return entry

    def _call(self, call: Callable[[], T]) -> T:
        """Run `call` on this thread with the Node to ourselves: its lock is free whenever the loop waits."""
        with self._node.lock:
            self._check_open()
            return call()

    def _raw(self, key: int, value: float | str) -> int:
        check_key(key)
        if type(value) is int and 0 <= value <= 0xFFFF and self.value_type == "uint16":  # the common case, at once
            return value
        try:
            return to_raw(value, self.value_type)
        except (ValueError, TypeError) as error:
            raise ValueError(f"value: {error}") from None

    def _shown(self, entry: Entry) -> str:
        return f"value={from_raw(entry.value, self.value_type)} timestamp={entry.timestamp} robot={entry.robot}"

    def _check_open(self) -> None:
        if self._closed_because is not None:
            raise SwarmClosed(f"robot {self.robot_id}'s swarm on {', '.join(self.links)} is closed: "
                              f"{self._closed_because}")

    def _on_gateway_thread(self) -> bool:
        """On the gateway thread, or on a link's reader thread in a hook (the Node works on both)."""
        return threading.current_thread() is self._thread or self._node.on_node_thread()

    def _forget(self, future: concurrent.futures.Future[Any]) -> None:
        with self._lock:
            self._waiting.discard(future)

    def _fail_waiting(self) -> None:
        """Fail every Future nobody will complete now, naming why."""
        if self._thread is not None and self._thread.is_alive() and self._closed_because is None:
            return
        with self._lock:
            waiting, self._waiting = self._waiting, set()
        for future in waiting:
            if not future.done():
                future.set_exception(SwarmClosed(f"robot {self.robot_id}'s swarm on {', '.join(self.links)} "
                                                 f"is closed: {self._closed_because}"))

    def _subscribe(self, watch: Subscription) -> None:
        self._check_open()
        self._hub.add(watch)

    def _attach_hub(self, attach: bool) -> None:
        """The Node tells changes only while someone watches: without, it keeps its fast path."""
        with self._node.lock:  # not while the gateway goes through them
            listeners = self._node.on_change
            if attach and self._hub.publish not in listeners:
                listeners.append(self._hub.publish)
            elif not attach and self._hub.publish in listeners:
                listeners.remove(self._hub.publish)

    def _resolve(self, key: int, local: Entry, remote: Entry) -> Entry:
        """The user's rule, checked here: a rule that raises or returns what the engine cannot store is
        logged and counted, and the higher robot id wins, so the gateway thread never stops on it."""
        try:
            chosen = self._rule(key, local, remote)
            _check_winner(chosen, local, remote, self.robot_id)
            return chosen
        except Exception:
            log.exception("onconflict %r failed on key %d", self._rule, key)
            self._hook_failed()
            return higher_robot_wins(key, local, remote)

    def _conflict_lost(self, key: int, entry: Entry) -> None:
        hook = self._lost
        if hook is None:
            return
        try:
            hook(key, entry)
        except Exception:
            log.exception("onconflictlost %r failed on key %d", hook, key)
            self._hook_failed()

    def _hook_failed(self) -> None:
        self.counters["hook_error"] += 1


def join(*links: LinkLike, robot_id: int, period: float = DEFAULT_PERIOD, budget: int | None = DEFAULT_BUDGET,
         max_jump: int | None = DEFAULT_MAX_JUMP, guard: Guard | None = None,
         onconflict: ConflictResolver | None = None, onconflictlost: ConflictLost | None = None,
         refresh: bool = True, value_type: ValueType = "uint16") -> Swarm:
    """Join the swarm on every link as robot `robot_id`; the open Swarm (a context manager).

    `links` are spec strings in the CLI's grammar ("can:socketcan:can0",
    "serial:/dev/ttyUSB0?framing=epuck4", "zenoh:lab"; `vstig links` lists them),
    parsed specs or Link objects. The rest are `vstig bridge`'s options with its
    defaults: the control `period` (s), the `budget` (messages per link per
    period), the jump guard's `max_jump` (None: off) or a whole `guard`, the
    conflict rule (`onconflict`; default: higher robot id wins), a GET of one key
    per period (`refresh`), and how values read (`value_type`).
    """
    if not links:
        raise ValueError("links: join needs at least one link, e.g. join('can:socketcan:can0', robot_id=200)")
    if isinstance(robot_id, bool) or not isinstance(robot_id, int) or not 0 <= robot_id <= 0xFFFF:
        raise ValueError(f"robot_id must be an integer in 0..65535, got {robot_id!r}")
    if isinstance(period, bool) or not isinstance(period, int | float) or not 0.001 <= period <= 60:
        raise ValueError(f"period must be 0.001..60 seconds, got {period!r}")
    if budget is not None:
        check_field("budget", 1_000_000, budget)
        if budget < 1:
            raise ValueError(f"budget must be at least 1 message per period (or None: no limit), got {budget}")
    try:
        specs = [parse(link) if isinstance(link, str) else link for link in links]
    except ValueError as error:
        raise ValueError(f"links: {error}") from None
    try:
        built = assemble_links(specs, robot_id)
    except LinkBuildError as error:
        raise ValueError(f"{error.argument}: {error}") from None
    options: dict[str, Any] = {"period": period, "budget": budget, "max_jump": max_jump, "onconflict": onconflict,
                               "onconflictlost": onconflictlost, "refresh": refresh, "value_type": value_type}
    swarm = Swarm(built, robot_id, period=period, budget=budget,
                  guard=Guard(max_jump=max_jump) if guard is None and max_jump is not None else guard,
                  onconflict=onconflict, onconflictlost=onconflictlost, refresh=refresh, value_type=value_type,
                  specs=None if any(isinstance(spec, Link) for spec in specs) or guard is not None
                  else [spec for spec in specs if not isinstance(spec, Link)],
                  options=options)
    return swarm.open()


def check_key(key: int) -> None:
    """ValueError naming `key` unless it is a key (0..32767)."""
    if type(key) is int and 0 <= key <= KEY_MAX:
        return
    check_field("key", KEY_MAX, key)


def checked_keys(keys: Iterable[int] | None) -> list[int] | None:
    """The keys a watch asked for, each checked (None: every key)."""
    if keys is None:
        return None
    if isinstance(keys, int):
        raise TypeError(f"keys must be a collection of keys (e.g. [{keys}]), got the int {keys}")
    checked = list(keys)
    for key in checked:
        check_key(key)
    return checked


def _check_winner(chosen: object, local: Entry, remote: Entry, robot_id: int) -> None:
    """ValueError unless `chosen` is an entry the engine can store as a conflict's winner (see engine.py)."""
    if not isinstance(chosen, tuple) or len(chosen) != 3:
        raise ValueError(f"onconflict must return an Entry(value, timestamp, robot), got {chosen!r}")
    value, _, robot = chosen
    check_field("the winner's value", 0xFFFF, value)
    check_field("the winner's robot", 0xFFFF, robot)
    if (value, robot) not in ((local.value, local.robot), (remote.value, remote.robot)) \
            and robot not in (robot_id, local.robot, remote.robot):
        raise ValueError(f"onconflict returned {chosen!r}: a new value must name this robot ({robot_id}) or "
                         f"the writer of one of the two entries ({local.robot} or {remote.robot})")


def _settle(future: concurrent.futures.Future[T], call: Callable[[], T]) -> None:
    if future.done():  # failed by close() meanwhile: nobody waits for it
        return
    try:
        _complete(future, result=call())
    except BaseException as error:  # handed to the caller's thread, raised there
        _complete(future, error=error)


def _complete(future: concurrent.futures.Future[Any], result: Any = None, error: BaseException | None = None) -> None:
    """Set a Future's outcome unless close() already failed it (which must not break the gateway thread)."""
    with contextlib.suppress(concurrent.futures.InvalidStateError):
        if error is None:
            future.set_result(result)
        else:
            future.set_exception(error)


def _pass_failure(started: concurrent.futures.Future[None], result: concurrent.futures.Future[PutResult]) -> None:
    error = started.exception()
    if error is not None:
        _complete(result, error=error)


def _nothing() -> None:
    pass
