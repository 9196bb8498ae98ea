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
from dataclasses import dataclass, field
from functools import partial

from ..engine import Entry, Stigmergy
from ..links.link import Heard
from ..timestamps import TS_NONE
from ..wire import Op
from .node import Node

__all__ = ["HearsItself", "KeyWatch", "PutResult", "get_newest", "put_confirmed"]


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
        return self.holds != self.written


def put_confirmed(node: Node, key: int, value: int, *, learn: float, wait: float, tries: int = 3,
                  confirm: bool = True, spent: float = 0.0) -> PutResult:
    """Write `value` under `key` through an open ENGINE node, as described above.

    Each write waits up to `wait` seconds for a neighbour to show it. Without
    `confirm` (a radio that cannot answer) it writes once and returns unconfirmed.
    `spent`: seconds already used opening the node, taken from `learn`, then from the first write's wait.
    """
    learn, over = max(0.0, learn - spent), max(0.0, spent - learn)
    first_wait = max(0.0, wait - over)
    engine = node.engine
    if engine is None:
        raise RuntimeError(f"a {node.mode.value} node cannot write")
    watch = KeyWatch(key, engine.robot_id)
    asker = _Asker(key)
    node.on_heard.append(watch)
    node.on_tick.append(asker)
    try:
        if learn:
            asker(node)
            node.run(until=lambda: confirm and watch.hears_itself, duration=learn)
            _check_not_echoed(node, watch, confirm)
        written, made = _write(node, key, value), 1
        if confirm:
            while True:
                node.run(until=partial(_settled, watch, written, engine), duration=first_wait if made == 1 else wait)
                _check_not_echoed(node, watch, confirm)
                if engine.entry(key) == written or made >= tries:
                    break
                watch.seen.clear()
                written, made = _write(node, key, value), made + 1
        _drain(node)
    finally:
        node.on_heard.remove(watch)
        node.on_tick.remove(asker)
    confirmed = confirm and written in watch.seen and engine.entry(key) == written
    return PutResult(written, confirmed, made, engine.entry(key), watch.last)


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
