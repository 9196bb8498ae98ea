"""`vstig_hw.join(...)`: a Python program as a swarm member, through the gateway's Node.

`Swarm` is a thin public face: the Node owns its threads (its loop runs on a thread of
its own from `Node.open`), its lock and its listeners. A call from another thread
(`put`, `get`, `items`...) runs on the caller's thread through the Node's own
thread-safe calls, which take its lock only while they work: no thread hand-off,
so a put reaches the links as fast as through the Node itself. What must wait
without blocking (asyncio) is handed to the loop (`Node.submit`) and awaited as a
Future. `entry`, `has` and `size` read the table directly: one dict lookup, atomic
in CPython. A confirmed put is `vstig put`'s own driver (`gateway.oneshot.confirm_write`):
its verdict completes a Future the moment a link's reader hears it.
"""

from __future__ import annotations

import concurrent.futures
import logging
import os
import threading
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

from ..auth import SwarmKeys, read_swarm_key
from ..counters import Counters
from ..engine import ConflictLost, ConflictResolver, Entry, higher_robot_wins
from ..gateway.guard import DEFAULT_MAX_JUMP, Guard
from ..gateway.kept_roster import keep_roster
from ..gateway.node import DEFAULT_BUDGET, DEFAULT_PERIOD, Listening, Node, SwarmClosed
from ..gateway.oneshot import HearsItself, PutResult, confirm_write, not_taken, unreached
from ..gateway.refresh import RoundRobinGet
from ..gateway.ros2 import serve_ros2
from ..gateway.roster import RobotView, Roster, StateChange
from ..gateway.signing import unkeyed_policy
from ..links.assemble import LinkBuildError, assemble_links, check_link_count
from ..links.link import Link, LinkSpec
from ..links.registry import parse
from ..transports.base import TransportError
from ..values import VALUE_TYPES, ValueType, from_raw, to_raw
from ..wire import KEY_MAX, check_field
from .changes import DEFAULT_BUFFER, Change, ChangeHub, Hub, OnChange, Subscription, Watch
from .recording import Recording
from .tables import MAX_TABLE, specs_for_table, table_of

__all__ = ["DEFAULT_WAIT", "HearsItself", "NotTaken", "Swarm", "SwarmClosed", "join"]

DEFAULT_WAIT = 2.0  # seconds a confirmed write waits for a neighbour, as `vstig put --wait`
CLOSE_DRAIN = 5.0  # seconds close() lets what is held back (a budget) go out at most

log = logging.getLogger("vstig_hw.api")
T = TypeVar("T")
LinkLike = str | LinkSpec | Link[Any]


class NotTaken(RuntimeError):
    """A confirmed put no neighbour showed it took; the message names what the swarm holds instead.

    `result` has the details: `verdict` (superseded or unanswered), `written` (our
    last write), `holds` (our table's entry then), `heard` (the last entry a
    neighbour's message carried), `tries`.
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
                 options: dict[str, Any] | None = None, roster: Roster | None = None,
                 swarm_keys: SwarmKeys | None = None) -> None:
        if value_type not in VALUE_TYPES:
            raise ValueError(f"value_type must be one of {', '.join(VALUE_TYPES)}, got {value_type!r}")
        self.value_type: ValueType = value_type
        self._node = Node(links, robot_id, period=period, budget=budget, guard=guard, swarm_keys=swarm_keys)
        self._node.label = f"robot {robot_id}'s swarm on {', '.join(link.name for link in links)}"
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
            self._node.listen(tick=RoundRobinGet())
        serve_ros2(self._node)  # ros2: links publish what the Node hears and answer put, get and table
        self._roster = keep_roster(self._node, roster)  # who is heard: `robots`, `watch_robots`
        self._robot_hub: Hub[StateChange] = Hub(lambda _attach: None)  # the roster is fed whether watched or not
        self._roster.on_change(self._robot_hub.offer)
        self._hub = ChangeHub(self._attach_hub)
        self._hub_listening: Listening | None = None
        self._callbacks: list[OnChange] = []
        self._lock = threading.Lock()
        self._opened = False
        self._specs = None if specs is None else list(specs)  # what `stigmergy(n)` derives its links from
        self._options = options or {}
        self._root = self  # the swarm whose tables this one is; it keeps them, one handle per table
        self._tables: dict[int, Swarm] = {}

    # -- lifetime --------------------------------------------------------------
    def open(self) -> Swarm:
        """Open every link and start the gateway thread (`join` does it)."""
        if self._opened:
            raise SwarmClosed("this swarm was opened once already; join again for a new one")
        self._opened = True
        self._node.listen(closed=self._node_closed)
        self._node.open()
        return self

    def close(self) -> None:
        """Leave the swarm: what was put but held back by the budget goes out (5 s at most), every watch ends,
        the links close. Safe to call twice, and from a hook (the gateway thread then closes once it returns)."""
        if self._opened:
            self._node.close(drain=CLOSE_DRAIN)
        else:
            self._node.close(drain=0.0)
        for callback in self._callbacks:
            callback.cancel()
        for table in list(self._tables.values()):
            table.close()

    @property
    def closed(self) -> bool:
        """Whether the swarm can no longer be used."""
        return not self._opened or self._node.closed

    def __repr__(self) -> str:
        state = "open" if not self.closed else "closed"
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
        re-broadcasts it, a GET or an answer carries it, or it writes on top of it),
        up to `timeout` seconds per write and `tries` writes when the swarm answers
        with a newer or conflicting entry; `learn` seconds of asking first make the
        write newer than what the swarm holds. Raises NotTaken naming what the swarm
        holds instead, HearsItself when a link brings our own messages back.
        """
        raw = self._raw(key, value)
        if not confirm:
            self._check_open()
            return self._node.put(key, raw)
        if self._node.on_node_thread():
            raise RuntimeError("put(confirm=True) waits for the gateway thread, so it cannot run on it (inside "
                               "onconflict or onconflictlost): use confirm=False there, or on_change")
        result = self._confirm(key, raw, timeout=timeout, tries=tries, learn=learn).result()
        return self.taken(key, result, timeout)

    def get(self, key: int) -> float | None:
        """The paper's read: our value for `key` (None if unknown), and a GET carrying it broadcast."""
        check_key(key)
        self._check_open()
        raw = self._node.get(key)
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
        """Every (key, entry) of our table (a snapshot)."""
        self._check_open()
        return self._node.entries()

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
        closed with the first swarm; asking again, from any of them, gives the same
        one. A link that cannot carry it raises ValueError naming the link.
        """
        check_field("stigmergy", MAX_TABLE, table)
        self._check_open()
        root = self._root
        if root is not self:
            return root.stigmergy(table)
        if self._specs is None:
            raise ValueError("stigmergy: this swarm was joined with Link objects or a Guard object, which belong to "
                             "one table; join with link specs (and max_jump=) to derive another table's")
        if table == table_of(self._specs):
            return self
        with self._lock:
            joined = self._tables.get(table)
            if joined is None or joined.closed:
                listening = [link.listening for link in self._node.links]
                joined = self._tables[table] = join(*specs_for_table(self._specs, table, listening),
                                                    robot_id=self.robot_id, **self._options)
                joined._root = self
        return joined

    # -- conflicts, under Buzz's names ---------------------------------------------
    def onconflict(self, rule: ConflictResolver) -> ConflictResolver:
        """Set the conflict rule: `rule(key, local, remote)` returns the winning Entry (Buzz's onconflict).

        It runs inside the gateway (a link's reader thread, holding the gateway's lock): keep it
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
    def watch(self, keys: Iterable[int] | None = None, *, buffer: int = DEFAULT_BUFFER) -> Watch[Change]:
        """An iterator of every Change to the table from now on (only `keys`, if given), until the swarm closes.

        It holds at most `buffer` changes a reader has not taken: past that the
        oldest are dropped and counted in `overflow`; the gateway never waits.
        """
        watch: Watch[Change] = Watch(checked_keys(keys), buffer)
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
        watch: Watch[Change] = Watch(checked_keys(keys), buffer)
        self._subscribe(watch)
        handle = OnChange(callback, watch, self._hook_failed)
        self._callbacks.append(handle)
        return handle

    # -- who is in the swarm ---------------------------------------------------------
    def robots(self) -> list[RobotView]:
        """Every robot the swarm's links heard, sorted by state (alive, quiet, gone) then id: who (a sender
        the medium names, else a writer id), links, last heard, rate, writes, GETs, keys it is behind on
        (docs/how-to/robots.md)."""
        self._check_open()
        return self._roster.snapshot()

    def watch_robots(self, robots: Iterable[int] | None = None, *,
                     buffer: int = DEFAULT_BUFFER) -> Watch[StateChange]:
        """An iterator of every robot's state change from now on (alive, quiet, gone; only `robots`, if given),
        until the swarm closes; bounded as `watch` is."""
        watch: Watch[StateChange] = Watch(None if robots is None else list(robots), buffer)
        self._subscribe_robots(watch)
        return watch

    # -- captures ------------------------------------------------------------------
    def record(self, path: str | os.PathLike[str], *, overwrite: bool = False,
               max_bytes: int | None = None) -> Recording:
        """Start recording what the links hear into `path`, as `vstig record` would; `stop()` the Recording.

        The extension picks the format (CAN: .log .asc .blf .csv .pcap .trc; serial
        and zenoh: any name; .mcap for links of several media, with the mcap extra).
        An existing file is never replaced unless `overwrite` (FileExistsError);
        `max_bytes` rotates to numbered files. Recordings stop when the swarm closes,
        once every unit its links read is written.
        """
        if not isinstance(path, str | os.PathLike):
            raise TypeError(f"record needs a file name, got {path!r}")
        self._check_open()
        return Recording(self._node, path, overwrite=overwrite, max_bytes=max_bytes)

    # -- what happened -------------------------------------------------------------
    def stats(self) -> dict[str, Counters]:
        """The gateway's counters per link and the engine's outcomes, then the API's own under "api"."""
        self._check_open()
        stats = self._node.stats()
        api = Counters(self.counters)
        api["watch_overflow"] = self._hub.overflow()
        stats["api"] = api
        return stats

    @property
    def links(self) -> list[str]:
        """The names of the swarm's links, as counters and changes name them."""
        return [link.name for link in self._node.links]

    @property
    def reachable(self) -> dict[str, tuple[str, ...]]:
        """The endpoints others reach this swarm's links by, per link name: those a link listens on
        (a zenoh link's, e.g. ("tcp/127.0.0.1:7447",)); links that listen on none are left out."""
        return {link.name: link.listening for link in self._node.links if link.listening}

    # -- for vstig_hw.aio and tools: the same calls as Futures ------------------------
    def submit(self, call: Callable[[], T]) -> concurrent.futures.Future[T]:
        """Run `call()` on the gateway thread (with the gateway to itself); its result as a Future."""
        self._check_open()
        return self._node.submit(call)

    def put_future(self, key: int, value: float | str, *, timeout: float = DEFAULT_WAIT, tries: int = 3,
                   learn: float = 0.0) -> concurrent.futures.Future[PutResult]:
        """A confirmed put as a Future of its PutResult (`taken` turns one into the entry or NotTaken)."""
        return self._confirm(key, self._raw(key, value), timeout=timeout, tries=tries, learn=learn)

    def taken(self, key: int, result: PutResult, timeout: float = DEFAULT_WAIT) -> Entry:
        """The entry a neighbour showed it took; NotTaken naming what the swarm holds if none did."""
        problem = not_taken(result, key, ", ".join(self.links), timeout, self._shown)
        if problem is not None:
            raise NotTaken(problem + unreached(self._node.links), key, result)
        return result.written

    # -- inside ------------------------------------------------------------------------
    def _confirm(self, key: int, raw: int, *, timeout: float, tries: int,
                 learn: float) -> concurrent.futures.Future[PutResult]:
        if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        check_field("tries", 100, tries)
        if tries < 1:
            raise ValueError(f"tries must be at least 1, got {tries}")
        if isinstance(learn, bool) or not isinstance(learn, int | float) or learn < 0:
            raise ValueError(f"learn must be a number of seconds >= 0, got {learn!r}")
        self._check_open()
        return confirm_write(self._node, key, raw, learn=learn, wait=timeout, tries=tries)

    def _node_closed(self) -> None:
        """The gateway closed (close(), or its loop failed: logged with what broke it): every watch ends."""
        if self._node.failure is not None:
            log.error("%s stopped", self._node.label, exc_info=self._node.failure)
        self._hub.close()
        self._robot_hub.close()

    def _raw(self, key: int, value: float | str) -> int:
        check_key(key)
        if type(value) is int and 0 <= value <= 0xFFFF and self.value_type == "uint16":  # the common case, at once
            return value
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise TypeError(f"value must be a number (or a string of one), got {value!r}")
        try:
            return to_raw(value, self.value_type)
        except (ValueError, TypeError) as error:
            raise ValueError(f"value: {error}") from None

    def _shown(self, entry: Entry) -> str:
        return f"value={from_raw(entry.value, self.value_type)} timestamp={entry.timestamp} robot={entry.robot}"

    def _check_open(self) -> None:
        if not self._opened:
            raise SwarmClosed(f"{self._node.label} is closed: it is not open yet")
        self._node.check_open()

    def _subscribe(self, watch: Subscription[Change]) -> None:
        self._check_open()
        self._hub.add(watch)

    def _subscribe_robots(self, watch: Subscription[StateChange]) -> None:
        self._check_open()
        self._robot_hub.add(watch)

    def _attach_hub(self, attach: bool) -> None:
        """The gateway tells changes only while someone watches: without, it keeps its fast path."""
        if attach and self._hub_listening is None:
            self._hub_listening = self._node.listen(change=self._hub.publish)
        elif not attach and self._hub_listening is not None:
            self._hub_listening.cancel()
            self._hub_listening = None

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
         refresh: bool = True, value_type: ValueType = "uint16", roster: Roster | None = None,
         swarm_key: str | os.PathLike[str] | None = None) -> Swarm:
    """Join the swarm on every link as robot `robot_id`; the open Swarm (a context manager).

    `links` are spec strings in the CLI's grammar ("can:socketcan:can0",
    "serial:/dev/ttyUSB0?framing=epuck4", "zenoh:lab"; `vstig links` lists them),
    parsed specs or Link objects. The rest are `vstig bridge`'s options with its
    defaults: the control `period` (s), the `budget` (messages per link per
    period), the jump guard's `max_jump` (None: off) or a whole `guard`, the
    conflict rule (`onconflict`; default: higher robot id wins), a GET of one key
    per period (`refresh`), and how values read (`value_type`). `roster`: who is in
    the swarm (`robots`), a `vstig_hw.gateway.roster.Roster` with thresholds of your own. `swarm_key`: the
    swarm key file (bridge's --swarm-key FILE: mode 600), to check tags on links with auth=require or auth=prefer
    and tag this robot's writes (docs/how-to/auth.md).

    A link told to connect somewhere (a zenoh link's `connect=`) that reaches nobody there within its wait
    (3 s) raises TransportError naming the endpoints, as a missing serial port does.
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
        check_link_count(len(links))  # before a single spec is parsed: 40,000 of them are refused at once
        specs = [parse(link) if isinstance(link, str) else link for link in links]
    except ValueError as error:
        raise ValueError(f"links: {error}") from None
    try:
        built = assemble_links(specs, robot_id)
    except LinkBuildError as error:
        raise ValueError(f"{error.argument}: {error}") from None
    keys = None if swarm_key is None else SwarmKeys(read_swarm_key(swarm_key))
    complaint = unkeyed_policy(built) if keys is None else None
    if complaint is not None:
        raise ValueError(f"swarm_key: {complaint}")
    options: dict[str, Any] = {"period": period, "budget": budget, "max_jump": max_jump, "onconflict": onconflict,
                               "onconflictlost": onconflictlost, "refresh": refresh, "value_type": value_type,
                               "swarm_key": swarm_key}
    swarm = Swarm(built, robot_id, period=period, budget=budget,
                  guard=Guard(max_jump=max_jump) if guard is None and max_jump is not None else guard,
                  onconflict=onconflict, onconflictlost=onconflictlost, refresh=refresh, value_type=value_type,
                  specs=None if any(isinstance(spec, Link) for spec in specs) or guard is not None
                  else [spec for spec in specs if not isinstance(spec, Link)],
                  options=options, roster=roster, swarm_keys=keys)
    swarm.open()
    why = unreached(built)
    if why:  # a program would otherwise write into the void, with one log line at most to tell it
        swarm.close()
        raise TransportError(why.removeprefix("; "))
    return swarm


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
