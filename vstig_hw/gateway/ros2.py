"""The gateway's side of a ros2: link: what the Node hears and changes, published; put, get and table, served.

The ros2 transport (transports/ros2.py) owns rclpy and the ROS 2 types; this part
owns what they carry, in the Node's terms:

* every message a link heard, after the guard, goes to that link's `heard/<link>`
  topic (`messages` listener: one call per unit, no `Heard` built);
* every change of the table goes to `changes` (`change` listener);
* the counters go to /diagnostics, once a second (`tick` listener);
* the roster kept for the Node (`KeptRoster.of`) goes to `robots` (latched) when it changes (who is there,
  their states, links and the keys they are behind on), at most once a ROBOTS_EVERY: made on the
  transport's request thread, never the loop's;
* `put` is a confirmed write (`oneshot.confirm_write`, as `vstig put` makes it): the
  service answers the entry a neighbour took, or why not and what the swarm holds;
  `get` reads the table (sending nothing), `table` all of it, from a snapshot that every call asked
  before it was taken shares, taken at most once a TABLE_SPACING (`TableSnapshots`): no number of
  calls holds the Node's lock more often, and the node process is sent each snapshot once;
* a PUT a ROS 2 node writes with timestamp 0 gets the timestamp after our entry.

The services run on the transport's request threads and reach the Node as any
other thread does; a confirmed write is driven by the Node's own threads, and the
service waits for its Future. Whoever builds a Node with ros2: links composes this part in with
`serve_ros2(node)` before opening it (`vstig bridge`, `vstig sniff`, `vstig_hw.join`), as the
live view and recordings are composed; everything the part does to the Node is in this module.
"""

from __future__ import annotations

import concurrent.futures
import json
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..engine import Entry
from ..framing.ros2 import Ros2Framing
from ..links.link import Link
from ..tagged import AuthPolicy
from ..timestamps import next_timestamp
from ..transports.ros2 import (  # no rclpy at import: it loads when the node opens
    TABLE_RECORD,
    PutAnswer,
    Ros2Transport,
    TableSnapshot,
)
from ..wire import KEY_MAX, Message
from .kept_roster import KeptRoster
from .node import SwarmClosed
from .oneshot import HearsItself, confirm_write, not_taken
from .roster_message import robots_message, standing

if TYPE_CHECKING:
    from .node import Node

__all__ = ["PUT_TRIES", "PUT_WAIT", "ROBOTS_EVERY", "TABLE_SPACING", "Ros2Part", "TableSnapshots", "serve_ros2"]

PUT_WAIT = 2.0  # seconds a confirmed write waits for a neighbour, as `vstig put --wait`
PUT_TRIES = 3
_GRACE = 5.0  # seconds beyond its writes' waits a put may take before the service gives up on the loop
TABLE_SPACING = 0.2  # seconds at least between two snapshots of a changing table (each holds the Node's lock)
ROBOTS_EVERY = 1.0  # seconds at least between two roster messages on `robots`


def serve_ros2(node: Node) -> list[Ros2Part]:
    """A part for every link whose transport serves ROS 2, attached to `node`."""
    return [Ros2Part(node, link, link.transport) for link in node.links if isinstance(link.transport, Ros2Transport)]


class TableSnapshots:
    """The table as the `table` service answers it: a call gets the newest snapshot if the table has not changed
    since, or if it was taken after the call was asked; else a new one, taken no sooner than TABLE_SPACING after
    the last. So 50 calls at once cost the Node's lock one or two snapshots, and calls in a loop five a second."""

    def __init__(self, take: Callable[[], list[tuple[int, Entry]]]) -> None:
        self._take = take
        self._taking = threading.Lock()  # one snapshot at a time; the calls behind it share it
        self.changes = 0  # changes of the table seen (`changed`, on the data path under the Node's lock)
        self._last = TableSnapshot(0, b"")
        self._last_changes = -1
        self._taken_at = -TABLE_SPACING

    def changed(self) -> None:
        self.changes += 1

    def snapshot(self) -> TableSnapshot:
        asked = time.monotonic()
        with self._taking:
            if self._last_changes == self.changes or self._taken_at >= asked:
                return self._last
            time.sleep(max(0.0, self._taken_at + TABLE_SPACING - time.monotonic()))
            changes, self._taken_at = self.changes, time.monotonic()
            pack = TABLE_RECORD.pack
            records = b"".join([pack(key, *entry) for key, entry in sorted(self._take())])
            self._last, self._last_changes = TableSnapshot(self._last.serial + 1, records), changes
            return self._last


def _shown(entry: Entry) -> str:
    return f"value={entry.value} timestamp={entry.timestamp} robot={entry.robot}"


class Ros2Part:
    """One ros2: link's services and topics, fed by `node` (see the module's docstring)."""

    def __init__(self, node: Node, link: Link[Any], transport: Ros2Transport) -> None:
        self.node = node
        self.transport = transport
        self._auth = link.auth
        self._where = ", ".join(other.name for other in node.links)
        self.snapshots = TableSnapshots(node.entries)
        self._next_robots = 0.0
        self._standing: list[tuple[Any, ...]] | None = None  # what the last roster message published showed
        transport.serve(self if node.engine is not None else None, [other.name for other in node.links])
        if node.engine is not None and isinstance(link.framing, Ros2Framing):
            link.framing.stamp = self._stamp
        self.listening = node.listen(messages=self._heard, tick=self._tick,
                                     change=self._changed if node.engine is not None else None)

    # -- what the Node tells (under its lock, on whichever thread did the work) ----------
    def _heard(self, link: str, t: float, sender: int | None, messages: list[Message]) -> None:
        self.transport.publish_heard(link, messages, sender)

    def _changed(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        self.snapshots.changed()
        self.transport.publish_change(key, old, new, link, sender)

    def _tick(self, node: Node) -> None:
        self.transport.publish_stats(node.stats())  # for /diagnostics (the transport sends one a second)
        now = time.monotonic()
        if now >= self._next_robots:
            self._next_robots = now + ROBOTS_EVERY
            kept = KeptRoster.of(node)
            if kept is not None:
                self.transport.publish_robots(lambda: self._roster_if_changed(kept))

    def _roster_if_changed(self, kept: KeptRoster) -> bytes | None:
        """On the transport's request thread: the roster message, or None if it shows what the last one did."""
        message = robots_message(kept)
        now_standing = standing(message)
        if now_standing == self._standing:
            return None
        self._standing = now_standing
        return json.dumps(message).encode()

    def _stamp(self, key: int) -> int:
        engine = self.node.engine
        entry = engine.entry(key) if engine is not None else None
        return next_timestamp(entry.timestamp) if entry is not None else 1

    # -- served, on the transport's request threads ----------------------------------
    def put(self, key: int, value: int) -> PutAnswer:
        node = self.node
        if key > KEY_MAX:
            return PutAnswer(False, None, key, f"key must be 0..{KEY_MAX}, got {key}")
        if node.engine is None or node.mode.value != "engine":
            return PutAnswer(False, None, key, f"a {node.mode.value} gateway does not write: give it --robot-id")
        if self._auth is not AuthPolicy.OFF:  # the service writes as the gateway, under its key: no caller's proof
            return PutAnswer(False, None, key, f"this link checks tags (auth={self._auth.value}): a put would write "
                             "under the gateway's key for anyone; publish your robot's signed write on write_tagged")
        try:
            result = confirm_write(node, key, value, learn=0.0, wait=PUT_WAIT, tries=PUT_TRIES).result(
                timeout=PUT_WAIT * PUT_TRIES + _GRACE)
        except HearsItself as error:  # the service confirms every put: no way to write anyway to name
            return PutAnswer(False, None, key, error.reason)
        except SwarmClosed as error:
            return PutAnswer(False, None, key, str(error))
        except concurrent.futures.TimeoutError:
            return PutAnswer(False, None, key, "the gateway's loop did not take the write in time")
        problem = not_taken(result, key, self._where, PUT_WAIT, _shown)
        if problem is None:
            return PutAnswer(True, result.written, key, "")
        return PutAnswer(False, result.holds if result.superseded else result.heard, key, problem)

    def get(self, key: int) -> Entry | None:
        engine = self.node.engine
        return engine.entry(key) if engine is not None and key <= KEY_MAX else None  # one dict lookup: atomic

    def table(self) -> TableSnapshot:
        return self.snapshots.snapshot()  # served only where the Node has a table (`serve`)
