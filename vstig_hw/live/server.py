"""The live view's server: what a gateway hears, served to Foxglove over its WebSocket protocol (`foxglove-sdk`).

It runs in a process of its own (`python -m vstig_hw.live.server`), fed by the gateway's
`view.LiveView` through a pipe, so its work (encoding, the table, the writes, the SDK's threads)
never competes with the gateway's loop for Python's GIL.

Channels (docs/how-to/live-view.md lists their fields):

* `/vstig/<link>`: every message each link hears, as `vstig_msgs/msg/Message` in CDR, the schema and
  encoding of our MCAP captures (`capture.rosbag`), stamped with the time it was heard;
* `/vstig/table`: per key what `sniff`'s table shows (JSON);
* `/vstig/writes`: each write's spread as `analyze` measures it, live (JSON, `spread.LiveSpread`);
* `/vstig/stats`: the link and engine counters, and the live view's own (JSON);
* `/vstig/robots`: the gateway's roster, every robot's row, once a second (JSON; only while it keeps one).

Table and stats are sent at most `rate` times a second, and only while a viewer subscribes. JSON is strict: a
number that is not finite (a float16 key holding NaN) is sent as null, which every JSON parser reads.

At most `viewers` viewers at once (the SDK has no limit of its own: `sdklog`); one more is told why and closed.
What the SDK logs reaches stderr escaped and rate-limited (`sdklog`): a viewer's bytes never do.

A thread of ours encodes what the gateway sent and hands it to the SDK, which queues up to `backlog`
messages per viewer and drops a slow viewer's oldest (a viewer that stops reading its control messages
is disconnected), in threads of its own. Viewers coming and going touch no link.
"""

from __future__ import annotations

import collections
import contextlib
import heapq
import json
import math
import signal
import struct
import sys
import threading
import time
from typing import Any

from ..capture.rosbag import MSGDEF, TYPE_NAME, cdr_message, topic_for
from ..counters import Counters
from ..gateway.swarmview import SwarmView
from ..links.link import Heard
from ..values import ValueType, from_raw
from ..wire import Message
from .sdklog import SdkLog
from .spread import LiveSpread

__all__ = ["LIVE_STATS", "VIEWERS", "LiveServer", "main", "strict_json"]

LIVE_STATS = "live"  # the live view's counters, beside the links' in /vstig/stats and on the gateway's exit

BACKLOG = 4096  # messages the SDK queues per viewer before it drops that viewer's oldest
INBOX = 65_536  # units read from the gateway and not yet handed to the SDK
PUMP = 0.05  # seconds between two hand-overs: a message reaches Foxglove within ~50 ms
TABLE_ROWS = 500  # keys per /vstig/table message: the most recently heard, in key order
WRITE_ROWS = 50  # writes per /vstig/writes tick
LINK_RATE = 2000.0  # messages a second per link channel: what a Foxglove panel can show, not all a bus can carry
VIEWERS = 16  # viewers at once: a lab's screens, far below what costs the server its memory (~0.4 MB each)

_INT = {"type": "integer"}
_NUM = {"type": "number"}
_STR = {"type": "string"}
_INTS = {"type": "array", "items": _INT}


def _object(**properties: Any) -> dict[str, Any]:
    return {"type": "object", "properties": properties}


TABLE_SCHEMA = _object(
    messages=_INT, keys_total=_INT,
    rows={"type": "array", "items": _object(
        key=_INT, value={"type": ["number", "null"]}, timestamp=_INT, robot={"type": ["integer", "null"]},
        last_seen=_NUM, last_seen_ago=_NUM, puts=_INT, gets=_INT, conflicts=_INT, stale_senders=_INTS, refused=_INT,
        last_refused=_STR)})
WRITE_SCHEMA = _object(
    key=_INT, value=_INT, timestamp=_INT, robot=_INT, first_heard=_NUM, link=_STR, senders_total=_INT,
    senders_caught_up=_INT, behind=_INTS, time_so_far=_NUM, converged_after={"type": ["number", "null"]},
    superseded={"type": "boolean"})
STATS_SCHEMA = _object(links={"type": "object", "additionalProperties": {"type": "object"}},
                       engine={"type": "object"}, live={"type": "object"})
ROBOTS_SCHEMA = _object(  # the rows are RobotView.as_json, as sniff --robots --jsonl prints them
    t=_NUM, robots_total=_INT, alive=_INT, quiet=_INT, gone=_INT, untracked=_INT,
    rows={"type": "array", "items": _object(
        robot=_INT, sender={"type": ["integer", "null"]}, named_by=_STR, links={"type": "array", "items": _STR},
        state={"type": "string", "enum": ["alive", "quiet", "gone"]}, last_heard_s=_NUM, rate=_NUM, messages=_INT,
        writes=_INT, gets=_INT, behind=_INTS, refused=_INT, quality={"type": ["integer", "null"]})})


class LiveServer:
    """Serve the links' traffic (`feed`) and counters (`set_stats`) on host:port until `close()`; `open()`
    first (binding may fail: RuntimeError)."""

    def __init__(self, links: list[str], host: str = "127.0.0.1", port: int = 8765, *,
                 value_type: ValueType = "uint16", larger_value_wins: bool = False, rate: float = 10.0,
                 backlog: int = BACKLOG, link_rate: float = LINK_RATE, viewers: int = VIEWERS,
                 robots: bool = False) -> None:
        self.link_names = links
        self.has_roster = robots  # the gateway keeps a roster: /vstig/robots is advertised
        self.host, self.port = host, port
        self.value_type = value_type
        self.interval = 1.0 / rate
        self.backlog = backlog
        self.link_rate = link_rate
        self._allowance: dict[str, float] = {}  # per link channel: messages it may still send (a token bucket)
        self._pumped = time.monotonic()
        # Each counter has one writer thread, and every name exists from the start: copying them is safe.
        self.counters = Counters(drop_behind=0, sent=0, throttled=0, subscribed=0, subscriptions=0,
                                 viewers_refused=0, log_dropped=0)
        self.sdk_log = SdkLog(self.counters, viewers)  # installed as the server opens, before the SDK logs
        # (link, time heard, sender, messages, why refused or None), one per unit the gateway handled
        self._inbox: collections.deque[tuple[str, float, int | None, list[Message], str | None]] = \
            collections.deque()
        self._view = SwarmView()
        if larger_value_wins:
            from ..engine import larger_value_wins as rule

            self._view = SwarmView(rule)
        self._spread = LiveSpread(larger_value_wins=larger_value_wins)
        self._stats: dict[str, Any] | None = None
        self._robots: bytes | None = None  # the latest /vstig/robots message, as JSON, not yet sent
        self._next_table = 0.0
        self._table_at = -1  # view.messages when the table was last sent
        self._table_again = 0.0
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

        self.sdk_log.install()
        context = self._context = foxglove.Context()  # our channels go to our server only (kept: it holds them)
        self._server = foxglove.start_server(name="vstig-hw", host=self.host, port=self.port, context=context,
                                             server_listener=Viewers(), message_backlog_size=self.backlog)
        self.port = self._server.port
        schema = foxglove.Schema(name=TYPE_NAME, encoding="ros2msg", data=MSGDEF.encode())
        for name in self.link_names:
            self._links[name] = foxglove.Channel(topic_for(name), schema=schema, message_encoding="cdr",
                                                 context=context, metadata={"link": name}).base

        def json_channel(topic: str, name: str, schema: dict[str, Any]) -> Any:
            named = foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())
            return foxglove.Channel(topic, schema=named, message_encoding="json", context=context).base

        self._table = json_channel("/vstig/table", "vstig_hw.Table", TABLE_SCHEMA)
        self._writes = json_channel("/vstig/writes", "vstig_hw.WriteSpread", WRITE_SCHEMA)
        self._stats_channel = json_channel("/vstig/stats", "vstig_hw.Stats", STATS_SCHEMA)
        self._robots_channel = json_channel("/vstig/robots", "vstig_hw.Robots", ROBOTS_SCHEMA) \
            if self.has_roster else None
        self._thread = threading.Thread(target=self._run, name="vstig-live-view", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._server is not None:
            self._server.stop()
            self._server = None
        self.sdk_log.uninstall()

    def __enter__(self) -> LiveServer:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what the gateway sends (any thread) -------------------------------------------
    def feed(self, link: str, t: float, sender: int | None, messages: list[Message], reason: str | None = None) -> None:
        if len(self._inbox) < INBOX:
            self._inbox.append((link, t, sender, messages, reason))
        else:  # our thread is behind the gateway: counted with the gateway's own (the two are added up)
            self.counters["drop_behind"] += len(messages)

    def set_stats(self, stats: dict[str, Any]) -> None:
        """The gateway's counters (`Node.stats()` as plain dicts) and its side of the live view's."""
        self._stats = stats

    def set_robots(self, message: bytes) -> None:
        """The gateway's roster as one /vstig/robots message (JSON, `view.robots_message`)."""
        self._robots = message

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
        if stats is not None and self._stats_channel.has_sinks():
            live = dict(self.counters)
            live["drop_behind"] += stats.get(LIVE_STATS, {}).get("drop_behind", 0)
            links = {k: v for k, v in stats.items() if k not in ("engine", LIVE_STATS)}
            self._stats_channel.log(strict_json({"links": links, "engine": stats.get("engine", {}), "live": live}))
        robots, self._robots = self._robots, None
        if robots is not None and self._robots_channel is not None and self._robots_channel.has_sinks():
            self._robots_channel.log(robots)
        now = time.monotonic()
        if now >= self._next_table:
            self._next_table = now + self.interval
            self._send_table_and_writes()

    def _send_table_and_writes(self) -> None:
        wall = time.time()
        if self._writes.has_sinks():
            for row in self._spread.updates(wall, WRITE_ROWS):
                self._writes.log(strict_json(row))
            self._spread.forget_before(wall)
        now = time.monotonic()  # unchanged, it is sent again each second: for a viewer who just came
        if self._table.has_sinks() and (self._view.messages != self._table_at or now >= self._table_again):
            self._table_at, self._table_again = self._view.messages, now + 1.0
            self._table.log(strict_json(self.table()))

    def table(self) -> dict[str, Any]:
        """What sniff's table shows, for the TABLE_ROWS keys heard most recently, in key order."""
        keys = self._view.keys
        shown = sorted(heapq.nlargest(TABLE_ROWS, keys, key=lambda k: keys[k].last_seen))
        now = time.time()
        rows = []
        for key in shown:
            k = keys[key]
            held = k.has_entry  # a key only ever asked for: no value, no robot (timestamp 0, as on the wire)
            rows.append({"key": key, "value": from_raw(k.value, self.value_type) if held else None,
                         "timestamp": k.timestamp, "robot": k.robot if held else None,
                         "last_seen": k.last_seen, "last_seen_ago": round(now - k.last_seen, 3),
                         "puts": k.puts, "gets": k.gets, "conflicts": k.conflicts,
                         "stale_senders": k.stale_senders(), "refused": k.refused, "last_refused": k.last_refused})
        return {"messages": self._view.messages, "keys_total": len(keys), "rows": rows}


def strict_json(row: dict[str, Any]) -> bytes:
    """`row` as strict JSON: NaN and infinities (a float key's value) as null, not the `NaN` JSON.parse refuses."""
    try:
        return json.dumps(row, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:
        return json.dumps(_finite(row), separators=(",", ":"), allow_nan=False).encode()


def _finite(value: Any) -> Any:
    """`value` with every float that is not finite, at any depth, replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _descriptors_to_the_hard_limit() -> None:
    """Raise this process's open-file limit to its hard limit: the SDK stops accepting viewers for good at the
    first accept() that fails, and a desktop's usual soft limit (1,024) is reached by that many connections."""
    try:
        import resource
    except ImportError:  # not POSIX
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != hard:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))


# -- the process: `python -m vstig_hw.live.server CONFIG` (CONFIG: JSON, see view.LiveView.open) --
RECORD = struct.Struct("<Hdi4H")  # link index, time heard, sender (-1: none), the message's four wire words
FRAME = struct.Struct("<cI")  # kind (M: records, R: refused messages as JSON, S: counters as JSON,
# B: the roster as the /vstig/robots message), length


def main(argv: list[str] | None = None) -> int:
    """Serve until stdin ends: `ready PORT CPU_SECONDS` (or `error WHY`) first on stdout, `counters JSON` last."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the gateway's to handle; it closes our stdin
    config = json.loads((argv or sys.argv[1:])[0])
    names: list[str] = config["links"]
    server = LiveServer(names, config["host"], config["port"], value_type=config["value_type"],
                        larger_value_wins=config["larger_value_wins"], backlog=config["backlog"],
                        link_rate=config["link_rate"], viewers=config["viewers"], robots=config["robots"])
    server.sdk_log.install(everything=True)  # this process's every log line, safe and rate-limited
    _descriptors_to_the_hard_limit()
    out = sys.stdout
    try:
        server.open()
    except RuntimeError as error:  # the SDK's FoxgloveError: cannot bind, cannot resolve the host
        out.write(f"error {' '.join(str(error).split())}\n")
        return 1
    out.write(f"ready {server.port} {time.process_time()}\n")  # then what serving costs can be told apart
    out.flush()
    source = sys.stdin.buffer
    new = tuple.__new__  # a Message is the tuple of its four wire words, checked by the gateway already
    try:
        while len(head := source.read(FRAME.size)) == FRAME.size:
            kind, size = FRAME.unpack(head)
            payload = source.read(size)
            if kind == b"M":
                for index, t, sender, *words in RECORD.iter_unpack(payload):
                    server.feed(names[index], t, None if sender < 0 else sender, [new(Message, words)])
            elif kind == b"R":
                for index, t, sender, words, reason in json.loads(payload):
                    server.feed(names[index], t, sender, [new(Message, words)], reason)
            elif kind == b"S":
                server.set_stats(json.loads(payload))
            elif kind == b"B":
                server.set_robots(payload)
    finally:
        server.close()
        out.write(f"counters {json.dumps({**server.counters, 'cpu_seconds': time.process_time()})}\n")
        out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
