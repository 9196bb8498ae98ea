"""The live view: what a gateway hears, served to Foxglove over its WebSocket protocol (`foxglove-sdk`).

Channels (docs/how-to/live-view.md lists their fields):

* `/vstig/<link>`: every message each link hears, as `vstig_msgs/msg/Message` in CDR, the schema and
  encoding of our MCAP captures (`capture.rosbag`), stamped with the time it was heard;
* `/vstig/table`: per key what `sniff`'s table shows (JSON);
* `/vstig/writes`: each write's spread as `analyze` measures it, live (JSON, `spread.LiveSpread`);
* `/vstig/stats`: the link and engine counters, and the live view's own (JSON).

Table and stats are sent at most `rate` times a second, and only while a viewer subscribes.

The gateway is never held up by a viewer. Its loop only appends what it heard to a bounded inbox
(full: the message is counted under `drop_behind` and the gateway goes on); a thread of ours encodes
and hands the messages to the SDK, which queues up to `backlog` messages per viewer and drops a slow
viewer's oldest (a viewer that stops reading its control messages is disconnected), in threads of its
own. Viewers coming and going touch no link.
"""

from __future__ import annotations

import collections
import heapq
import json
import threading
import time
from typing import Any

from ..capture.rosbag import MSGDEF, TYPE_NAME, cdr_message, topic_for
from ..counters import Counters
from ..links.link import Heard
from ..values import ValueType, from_raw
from ..wire import Message
from .node import Node
from .spread import LiveSpread
from .swarmview import SwarmView

__all__ = ["DEFAULT_PORT", "LIVE_STATS", "LiveView"]

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
LIVE_STATS = "live"  # the live view's counters, beside the links' in /vstig/stats and on exit
INBOX = 65_536  # messages heard and not yet handed to the SDK: ~1 s of a saturated gateway
BACKLOG = 4096  # messages the SDK queues per viewer before it drops that viewer's oldest
PUMP = 0.05  # seconds between two hand-overs: a message reaches Foxglove within ~50 ms
TABLE_ROWS = 500  # keys per /vstig/table message: the most recently heard, in key order
WRITE_ROWS = 50  # writes per /vstig/writes tick
LINK_RATE = 2000.0  # messages a second per link channel: what a Foxglove panel can show, not all a bus can carry

_INT = {"type": "integer"}
_NUM = {"type": "number"}
_STR = {"type": "string"}
_INTS = {"type": "array", "items": _INT}


def _object(**properties: Any) -> dict[str, Any]:
    return {"type": "object", "properties": properties}


TABLE_SCHEMA = _object(
    messages=_INT, keys_total=_INT,
    rows={"type": "array", "items": _object(
        key=_INT, value=_NUM, timestamp=_INT, robot=_INT, last_seen=_NUM, last_seen_ago=_NUM, puts=_INT,
        gets=_INT, conflicts=_INT, stale_senders=_INTS, refused=_INT, last_refused=_STR)})
WRITE_SCHEMA = _object(
    key=_INT, value=_INT, timestamp=_INT, robot=_INT, first_heard=_NUM, link=_STR, senders_total=_INT,
    senders_caught_up=_INT, behind=_INTS, time_so_far=_NUM, converged_after={"type": ["number", "null"]},
    superseded={"type": "boolean"})
STATS_SCHEMA = _object(links={"type": "object", "additionalProperties": {"type": "object"}},
                       engine={"type": "object"}, live={"type": "object"})


class LiveView:
    """Serve `node`'s traffic on host:port until `close()`; `open()` first (binding may fail: RuntimeError)."""

    def __init__(self, node: Node, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *,
                 value_type: ValueType = "uint16", larger_value_wins: bool = False, rate: float = 10.0,
                 inbox: int = INBOX, backlog: int = BACKLOG, link_rate: float = LINK_RATE) -> None:
        self.node = node
        self.host, self.port = host, port
        self.value_type = value_type
        self.interval = 1.0 / rate
        self.backlog = backlog
        self.link_rate = link_rate
        self._allowance: dict[str, float] = {}  # per link channel: messages it may still send (a token bucket)
        self._pumped = time.monotonic()
        # Each counter has one writer thread, and every name exists from the start: copying them is safe.
        self.counters = Counters(drop_behind=0, sent=0, throttled=0, subscribed=0, subscriptions=0)
        self._capacity = inbox
        # (link, time heard, sender, messages, why refused or None), one per unit the gateway handled
        self._inbox: collections.deque[tuple[str, float, int | None, list[Message], str | None]] = \
            collections.deque()
        self._view = SwarmView()
        if larger_value_wins:
            from ..engine import larger_value_wins as rule

            self._view = SwarmView(rule)
        self._spread = LiveSpread(larger_value_wins=larger_value_wins)
        self._stats: dict[str, Counters] | None = None
        self._next_stats = 0.0
        self._next_table = 0.0
        self._table_at = -1  # view.messages when the table was last sent
        self._stop = threading.Event()
        self._pumping = threading.Lock()  # our thread, and whoever calls pump() to hand everything over now
        self._thread: threading.Thread | None = None
        self._server: Any = None
        self._links: dict[str, Any] = {}
        self._context: Any = None

    # -- lifetime -------------------------------------------------------------
    def open(self) -> None:
        import foxglove
        from foxglove.websocket import ChannelView, Client, ServerListener

        counters = self.counters

        class Viewers(ServerListener):  # called in the SDK's threads
            def on_subscribe(self, client: Client, channel: ChannelView) -> None:
                counters["subscribed"] += 1
                counters["subscriptions"] += 1

            def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
                counters["subscriptions"] -= 1

        context = self._context = foxglove.Context()  # our channels go to our server only (kept: it holds them)
        self._server = foxglove.start_server(name="vstig-hw", host=self.host, port=self.port, context=context,
                                             server_listener=Viewers(), message_backlog_size=self.backlog)
        self.port = self._server.port
        schema = foxglove.Schema(name=TYPE_NAME, encoding="ros2msg", data=MSGDEF.encode())
        for link in self.node.links:
            self._links[link.name] = foxglove.Channel(topic_for(link.name), schema=schema, message_encoding="cdr",
                                                      context=context, metadata={"link": link.name}).base

        def json_channel(topic: str, name: str, schema: dict[str, Any]) -> Any:
            named = foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())
            return foxglove.Channel(topic, schema=named, message_encoding="json", context=context).base

        self._table = json_channel("/vstig/table", "vstig_hw.Table", TABLE_SCHEMA)
        self._writes = json_channel("/vstig/writes", "vstig_hw.WriteSpread", WRITE_SCHEMA)
        self._stats_channel = json_channel("/vstig/stats", "vstig_hw.Stats", STATS_SCHEMA)
        self.node.on_messages.append(self._heard)
        self.node.on_refused.append(self._refused)
        self.node.on_tick.append(self._tick)
        self._thread = threading.Thread(target=self._run, name="vstig-live-view", daemon=True)
        self._thread.start()

    def close(self) -> None:
        node = self.node
        if self._heard in node.on_messages:
            node.on_messages.remove(self._heard)
        if self._refused in node.on_refused:
            node.on_refused.remove(self._refused)
        if self._tick in node.on_tick:
            node.on_tick.remove(self._tick)
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._server is not None:
            self._server.stop()
            self._server = None

    def __enter__(self) -> LiveView:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    # -- the gateway's thread: as little as possible ---------------------------
    def _heard(self, link: str, t: float, sender: int | None, messages: list[Message]) -> None:
        if len(self._inbox) < self._capacity:
            self._inbox.append((link, t, sender, messages, None))
        else:
            self.counters["drop_behind"] += len(messages)

    def _refused(self, heard: Heard, reason: str) -> None:
        if len(self._inbox) < self._capacity:
            self._inbox.append((heard.link, heard.t, heard.sender, [heard.message], reason))
        else:
            self.counters["drop_behind"] += 1

    def _tick(self, node: Node) -> None:
        """Snapshot the counters here, where the loop changes them, at most `rate` times a second."""
        now = time.monotonic()
        if now >= self._next_stats and self._stats_channel.has_sinks():
            self._next_stats = now + self.interval
            stats = node.stats()
            stats[LIVE_STATS] = Counters(self.counters)
            self._stats = stats

    # -- our thread ------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.wait(PUMP):
            self.pump()
        self.pump()

    def pump(self) -> None:
        """Hand what the gateway heard to the SDK; send table, writes and stats when due."""
        with self._pumping:
            self._pump()

    def _pump(self) -> None:
        inbox, links, view, spread = self._inbox, self._links, self._view, self._spread
        now = time.monotonic()
        # Each link channel may send link_rate messages a second (bursts of a tenth of that); the rest are
        # counted `throttled`. Table, writes and stats still count every message. Unwatched: none sent.
        refill, self._pumped = (now - self._pumped) * self.link_rate, now
        watched = {name for name, channel in links.items() if channel.has_sinks()}
        allowance = {name: min(self.link_rate / 10, self._allowance.get(name, 0.0) + refill) if name in watched
                     else 0.0 for name in links}
        sent = throttled = 0
        add, spread_add = view.add_message, spread.add_message
        while inbox:
            link, t, sender, messages, reason = inbox.popleft()
            may = allowance[link]
            if may >= len(messages):
                log = links[link].log
                stamp = round(t * 1e9)
                for msg in messages:
                    log(cdr_message(msg, sender), stamp)
                allowance[link] = may - len(messages)
                sent += len(messages)
            elif link in watched:
                throttled += len(messages)
            for msg in messages:
                if reason is None:
                    add(msg, t, sender)
                    spread_add(msg, link, t, sender)
                else:
                    view.refuse(Heard(msg, link, t, sender), reason)
        self._allowance = allowance
        self.counters["sent"] += sent
        self.counters["throttled"] += throttled
        stats, self._stats = self._stats, None
        if stats is not None:
            self._stats_channel.log(_json({"links": {k: dict(v) for k, v in stats.items()
                                                     if k not in ("engine", LIVE_STATS)},
                                           "engine": dict(stats.get("engine", {})),
                                           "live": dict(stats[LIVE_STATS])}))
        now = time.monotonic()
        if now >= self._next_table:
            self._next_table = now + self.interval
            self._send_table_and_writes()

    def _send_table_and_writes(self) -> None:
        wall = time.time()
        if self._writes.has_sinks():
            for row in self._spread.updates(wall, WRITE_ROWS):
                self._writes.log(_json(row))
            self._spread.forget_before(wall)
        if self._table.has_sinks() and self._view.messages != self._table_at:
            self._table_at = self._view.messages
            self._table.log(_json(self.table()))

    def table(self) -> dict[str, Any]:
        """What sniff's table shows, for the TABLE_ROWS keys heard most recently, in key order."""
        keys = self._view.keys
        shown = sorted(heapq.nlargest(TABLE_ROWS, keys, key=lambda k: keys[k].last_seen))
        now = time.time()
        rows = []
        for key in shown:
            k = keys[key]
            rows.append({"key": key, "value": from_raw(k.value, self.value_type), "timestamp": k.timestamp,
                         "robot": k.robot, "last_seen": k.last_seen, "last_seen_ago": round(now - k.last_seen, 3),
                         "puts": k.puts, "gets": k.gets, "conflicts": k.conflicts,
                         "stale_senders": k.stale_senders(), "refused": k.refused, "last_refused": k.last_refused})
        return {"messages": self._view.messages, "keys_total": len(keys), "rows": rows}


def _json(row: dict[str, Any]) -> bytes:
    return json.dumps(row, separators=(",", ":")).encode()
