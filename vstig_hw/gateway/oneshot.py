"""One write or one read through a Node, checked against what the swarm says (`vstig put`, `vstig get`).

A write is taken only when a neighbour shows it: it re-broadcasts our PUT when it
stores it, or sends a GET carrying it. Nothing else counts (a robot that finds our
PUT stale stays silent), so `put_confirmed`:

1. asks every control step while learning, so its write is newer than anything heard;
2. writes, and keeps asking and listening;
3. when it hears a newer entry, or loses a conflict, writes again (next timestamp),
   at most `tries` writes in all;
4. reports whether a neighbour showed the write, and what the swarm said otherwise.

A link that brings our own empty GET back (a radio that echoes what it is sent, or
another robot with our id) cannot confirm anything, since a neighbour's copy of our
PUT looks like our own echo: that raises `HearsItself`, before writing if learning
found it.

Asking alternates two GETs: one carrying our view (a holder of anything older
stores ours and re-broadcasts it, a holder of something newer answers with it)
and an empty one (every holder answers with its entry, which shows our write even
when the re-broadcast that stored it was lost).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..engine import Entry, Stigmergy
from ..links.link import Heard
from ..timestamps import TS_NONE
from ..wire import Op
from .node import Node

__all__ = ["ConfirmedPut", "HearsItself", "KeyWatch", "PutResult", "get_newest", "not_taken", "put_confirmed"]


class HearsItself(RuntimeError):
    """The link brings our own GETs back, so no answer can be told from our echo."""


@dataclass
class KeyWatch:
    """What neighbours said about one key: every entry their messages carried, and the last one."""

    key: int
    robot_id: int
    seen: set[Entry] = field(default_factory=set)
    last: Entry | None = None
    hears_itself: bool = False  # our own empty GET came back: an echoing radio, or our id taken

    def __call__(self, heard: Heard) -> None:
        msg = heard.message
        if msg.key != self.key or heard.sender == self.robot_id:  # CAN names senders: skip our own frames
            return
        if msg.timestamp == TS_NONE:  # an empty GET carries no entry; with our id it is our own
            self.hears_itself |= msg.op is Op.GET and msg.robot == self.robot_id
            return
        self.last = Entry(msg.value, msg.timestamp, msg.robot)
        self.seen.add(self.last)


class _Asker:
    """An on_tick listener: each control step one GET for the key, a view GET and an empty GET in turn."""

    def __init__(self, key: int) -> None:
        self.key = key
        self.steps = 0

    def __call__(self, node: Node) -> None:
        self.steps += 1
        if self.steps % 2:
            node.ask(self.key)
        else:
            node.get(self.key)


@dataclass(frozen=True)
class PutResult:
    written: Entry  # our last write
    confirmed: bool  # a neighbour's message carried it
    tries: int  # writes made
    holds: Entry | None  # our engine's entry at the end: not `written` when the swarm superseded it
    heard: Entry | None  # the last entry a neighbour's message carried (None: nothing heard)

    @property
    def superseded(self) -> bool:
        """The swarm holds an entry other than our last write."""
        return self.holds != self.written


class ConfirmedPut:
    """One confirmed write as steps, driven by whoever runs the node's loop (`put_confirmed`, the Python API).

    Call `start` once, then `step` after every poll until it returns True, then
    `result`; `detach` (also on failure) removes its listeners. Everything runs on
    the loop's thread. Without `confirm` (a radio that cannot answer) it writes
    once and is done, unconfirmed.
    """

    def __init__(self, node: Node, key: int, value: int, *, learn: float, wait: float, tries: int = 3,
                 confirm: bool = True, spent: float = 0.0) -> None:
        engine = node.engine
        if engine is None:
            raise RuntimeError(f"a {node.mode.value} node cannot write")
        self.node, self.engine, self.key, self.value = node, engine, key, value
        # `spent`: seconds already used opening the node, taken from `learn`, then from the first write's wait
        self.learn, self.wait, self.tries, self.confirm = max(0.0, learn - spent), wait, tries, confirm
        self._first_wait = max(0.0, wait - max(0.0, spent - learn))
        self.watch = KeyWatch(key, engine.robot_id)
        self.asker = _Asker(key)
        self.written: Entry | None = None  # None while learning
        self.made = 0
        self.deadline = 0.0
        self.done = False

    def start(self, now: float) -> bool:
        """Attach the listeners and ask (learning) or write; True when already done (no confirm)."""
        self.node.on_heard.append(self.watch)
        self.node.on_tick.append(self.asker)
        if self.learn:
            self.asker(self.node)
            self.deadline = now + self.learn
            return False
        self._write(now)
        return self.done

    def step(self, now: float) -> bool:
        """After a poll: True once done; HearsItself when the link brings our own GETs back."""
        if self.done:
            return True
        watch = self.watch
        if self.written is None:
            if not (self.confirm and watch.hears_itself) and now < self.deadline:
                return False
            self._check_not_echoed()
            self._write(now)
            return self.done
        if not _settled(watch, self.written, self.engine) and now < self.deadline:
            return False
        self._check_not_echoed()
        if self.engine.entry(self.key) == self.written or self.made >= self.tries:
            self.done = True
        else:
            watch.seen.clear()
            self._write(now)
        return self.done

    def detach(self) -> None:
        """Remove the listeners (safe to call twice)."""
        for listeners, listener in ((self.node.on_heard, self.watch), (self.node.on_tick, self.asker)):
            if listener in listeners:
                listeners.remove(listener)  # type: ignore[arg-type]

    def result(self) -> PutResult:
        """What became of the write (after `step` returned True)."""
        assert self.written is not None
        holds = self.engine.entry(self.key)
        confirmed = self.confirm and self.written in self.watch.seen and holds == self.written
        return PutResult(self.written, confirmed, self.made, holds, self.watch.last)

    def _write(self, now: float) -> None:
        self.written, self.made = _write(self.node, self.key, self.value), self.made + 1
        self.deadline = now + (self._first_wait if self.made == 1 else self.wait)
        self.done = not self.confirm

    def _check_not_echoed(self) -> None:
        _check_not_echoed(self.node, self.watch, self.confirm)


def put_confirmed(node: Node, key: int, value: int, *, learn: float, wait: float, tries: int = 3,
                  confirm: bool = True, spent: float = 0.0) -> PutResult:
    """Write `value` under `key` through an open ENGINE node whose loop nobody else runs, as described above.

    Each write waits up to `wait` seconds for a neighbour to show it. Without
    `confirm` (a radio that cannot answer) it writes once and returns unconfirmed.
    `spent`: seconds already used opening the node, taken from `learn`, then from the first write's wait.
    """
    put = ConfirmedPut(node, key, value, learn=learn, wait=wait, tries=tries, confirm=confirm, spent=spent)
    try:
        if not put.start(time.monotonic()):
            node.run(until=lambda: put.step(time.monotonic()))
        _drain(node)
    finally:
        put.detach()
    return put.result()


def not_taken(result: PutResult, key: int, where: str, wait: float, show: Callable[[Entry], str] = str, *,
              confirm: bool = True) -> str | None:
    """Why the write was not taken, in one line naming what the swarm holds; None when it was.

    Superseded is always a failure; unconfirmed only when a confirmation was asked for.
    """
    ours = show(result.written)
    if result.superseded:
        assert result.holds is not None
        return (f"key {key}: the swarm holds {show(result.holds)} on {where}, not our write ({ours}), "
                f"after {result.tries} writes")
    if confirm and not result.confirmed:
        said = f"the last entry heard was {show(result.heard)}" if result.heard else "nothing was heard for the key"
        return f"key {key}: no neighbour on {where} took our write ({ours}) within {wait:g} s; {said}"
    return None


def get_newest(node: Node, key: int, wait: float) -> Entry | None:
    """Ask every control step for `wait` seconds; the newest entry heard (conflicts resolved), or None."""
    engine = node.engine
    if engine is None:
        raise RuntimeError(f"a {node.mode.value} node cannot ask")
    asker = _Asker(key)
    node.on_tick.append(asker)
    try:
        asker(node)
        node.run(duration=wait)
    finally:
        node.on_tick.remove(asker)
    return engine.entry(key)


def _check_not_echoed(node: Node, watch: KeyWatch, confirm: bool) -> None:
    if confirm and watch.hears_itself:
        names = ", ".join(link.name for link in node.links)
        raise HearsItself(f"{names} brings our own GETs back (robot id {watch.robot_id}): the radio echoes what "
                          "we send, or another robot uses that id; no answer can be told from our echo "
                          "(--no-confirm writes anyway)")


def _settled(watch: KeyWatch, written: Entry, engine: Stigmergy) -> bool:
    """A neighbour showed our write, the swarm superseded it, or the link brings our own GETs back."""
    return written in watch.seen or engine.entry(watch.key) != written or watch.hears_itself


def _write(node: Node, key: int, value: int) -> Entry:
    node.put(key, value)  # timestamp: one past the newest we hold, so newer than anything heard
    assert node.engine is not None
    entry = node.engine.entry(key)
    assert entry is not None
    return entry


def _drain(node: Node) -> None:
    """Send what is queued before the links close."""
    node.run(until=lambda: all(not len(outlet) for outlet in node.outlets), duration=5.0)
    time.sleep(0.05)  # let the device's own buffer drain before the port closes
