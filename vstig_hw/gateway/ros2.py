"""The gateway's side of a ros2: link: what the Node hears and changes, published; put, get and table, served.

The ros2 transport (transports/ros2.py) owns rclpy and the ROS 2 types; this part
owns what they carry, in the Node's terms:

* every message a link heard, after the guard, goes to that link's `heard/<link>`
  topic (`messages` listener: one call per unit, no `Heard` built);
* every change of the table goes to `changes` (`change` listener);
* the counters go to /diagnostics, once a second (`tick` listener);
* `put` is a confirmed write (`oneshot.confirm_write`, as `vstig put` makes it): the
  service answers the entry a neighbour took, or why not and what the swarm holds;
  `get` reads the table (sending nothing), `table` all of it;
* a PUT a ROS 2 node writes with timestamp 0 gets the timestamp after our entry.

The services run on the transport's request threads and reach the Node as any
other thread does; a confirmed write is driven by the Node's own threads, and the
service waits for its Future. Whoever builds a Node with ros2: links composes this part in with
`serve_ros2(node)` before opening it (`vstig bridge`, `vstig sniff`, `vstig_hw.join`), as the
live view and recordings are composed; everything the part does to the Node is in this module.
"""

from __future__ import annotations

import concurrent.futures
from typing import TYPE_CHECKING, Any

from ..engine import Entry
from ..framing.ros2 import Ros2Framing
from ..links.link import Link
from ..timestamps import next_timestamp
from ..transports.ros2 import PutAnswer, Ros2Transport  # no rclpy at import: it loads when the node opens
from ..wire import KEY_MAX, Message
from .node import SwarmClosed
from .oneshot import HearsItself, confirm_write, not_taken

if TYPE_CHECKING:
    from .node import Node

__all__ = ["PUT_TRIES", "PUT_WAIT", "Ros2Part", "serve_ros2"]

PUT_WAIT = 2.0  # seconds a confirmed write waits for a neighbour, as `vstig put --wait`
PUT_TRIES = 3
_GRACE = 5.0  # seconds beyond its writes' waits a put may take before the service gives up on the loop


def serve_ros2(node: Node) -> list[Ros2Part]:
    """A part for every link whose transport serves ROS 2, attached to `node`."""
    return [Ros2Part(node, link, link.transport) for link in node.links if isinstance(link.transport, Ros2Transport)]


def _shown(entry: Entry) -> str:
    return f"value={entry.value} timestamp={entry.timestamp} robot={entry.robot}"


class Ros2Part:
    """One ros2: link's services and topics, fed by `node` (see the module's docstring)."""

    def __init__(self, node: Node, link: Link[Any], transport: Ros2Transport) -> None:
        self.node = node
        self.transport = transport
        self._where = ", ".join(other.name for other in node.links)
        transport.serve(self if node.engine is not None else None, [other.name for other in node.links])
        if node.engine is not None and isinstance(link.framing, Ros2Framing):
            link.framing.stamp = self._stamp
        self.listening = node.listen(messages=self._heard, tick=self._tick,
                                     change=self._changed if node.engine is not None else None)

    # -- what the Node tells (under its lock, on whichever thread did the work) ----------
    def _heard(self, link: str, t: float, sender: int | None, messages: list[Message]) -> None:
        self.transport.publish_heard(link, messages, sender)

    def _changed(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        self.transport.publish_change(key, old, new, link, sender)

    def _tick(self, node: Node) -> None:
        self.transport.publish_stats(node.stats())  # for /diagnostics (the transport sends one a second)

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
        try:
            result = confirm_write(node, key, value, learn=0.0, wait=PUT_WAIT, tries=PUT_TRIES).result(
                timeout=PUT_WAIT * PUT_TRIES + _GRACE)
        except (HearsItself, SwarmClosed) as error:
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

    def table(self) -> list[tuple[int, Entry]]:
        return self.node.entries() if self.node.engine is not None else []  # a snapshot, taken under the lock
