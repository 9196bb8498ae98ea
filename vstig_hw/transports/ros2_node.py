"""A ros2: link's ROS 2 node, in a process of its own: `python -m vstig_hw.transports.ros2_node CONFIG`.

rclpy, Fast DDS and the executor live here, so none of their threads, Python work or
GIL turns is the gateway's. The gateway (transports/ros2.py) writes frames to our
stdin and reads frames from our stdout (the protocol: `ros2.py`):

    in   H  messages a link heard      -> <ns>/heard/<link>       (vstig_msgs/Message, raw CDR)
         C  changes of the table       -> <ns>/changes            (vstig_msgs/Change, keyed)
         B  what the gateway broadcasts -> <ns>/broadcast          (CDR, as the framing encoded it; a
                                               TaggedMessage, by its size, -> <ns>/broadcast_tagged)
         A  the answer to a request we asked;  S  the gateway's counters -> /diagnostics
         T  a page of a table snapshot (before the answer that names it; we keep the last one)
         O  a part of the roster (JSON, its last part flagged) -> <ns>/robots (vstig_msgs/Robots, transient local)
    out  W  what ROS 2 nodes wrote on <ns>/write and <ns>/write_tagged (at most write_rate a second, both)
         Q  a service request (put, get, table) for the gateway to answer
         K  what we counted since the last K (once a second and when we end), with the writes refused here
            (`drop_bad_cdr`: not a vstig_msgs/Message or TaggedMessage, a key or an op out of range)

It ends when its stdin closes (the gateway closed the link, or died), and ignores
SIGINT: Ctrl-C is the gateway's to handle, which then closes us.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import sys
import threading
import time
from importlib.resources import files
from typing import IO, Any

from ..counters import Counters
from ..framing.ros2 import CDR_SIZE, TAGGED_CDR_SIZE, cdr_message, message_of_cdr, ros_name, tagged_of_cdr
from ..wire import Message
from .ros2 import CHANGE, FRAME, HEARD, PUTS_AT_ONCE, ROBOTS_PART, TABLE_PAGE, TABLE_RECORD, Ros2Options

WRITE_POLL = 0.05  # seconds between two takes from the write topic: what a ROS 2 write may wait
DIAGNOSTICS_PERIOD = 1.0
NICENESS = 10  # the node's CPU comes after the data path's: a flood it receives costs the gateway's threads little
SERVICE_DEPTH = 1000  # requests a service holds while it answers others
ANSWER_WAIT = 30.0  # seconds a service waits for the gateway's answer (a confirmed put takes up to ~11)
# The executor's threads: the puts in flight, one answering further puts busy, and one each for get, table and
# the two timers, so that none of them waits for a thread.
EXECUTOR_THREADS = PUTS_AT_ONCE + 5
_PROFILE = "fastdds_loopback.xml"
_DROPS = ("drop_", "rx_lost", "rx_overflow", "tx_dropped", "tx_overflow", "put_busy", "behind")


def _configure(options: Ros2Options) -> None:
    """Point Fast DDS at its profile and rcl at its discovery range (both read once, as the node starts)."""
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    if options.profile:
        os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = options.profile
    elif options.discovery == "localhost":
        os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(files(__package__) / _PROFILE)
    else:
        os.environ.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
    # The profile confines the transports; within them, discover by multicast (at once), not by polling peers.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"


def _node(name: str, namespace: str, context: Any) -> Any:
    """A node that takes no global ROS arguments and offers no parameter or log services (a gateway has none)."""
    import rclpy

    return rclpy.create_node(name, namespace=namespace, context=context, use_global_arguments=False,
                             enable_rosout=False, start_parameter_services=False)


class Ros2Node:
    """The node, its topics and services, and the two pipes to the gateway."""

    def __init__(self, config: dict[str, Any], out: IO[bytes]) -> None:
        import rclpy
        from rclpy.executors import MultiThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from ..ros2msgs import load

        self.options = Ros2Options(**config["options"])
        self.links: list[str] = config["links"]
        self.robot_id: int = config["robot_id"]
        self.counters = Counters()  # since the last K frame (the gateway adds them up)
        self._counting = threading.Lock()  # the main thread and the executor's count
        self._out, self._out_lock = out, threading.Lock()
        self._types = load()
        _configure(self.options)
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.options.domain,
                   signal_handler_options=SignalHandlerOptions.NO)  # the gateway owns the signals
        self.node = _node(config["node_name"], self.options.namespace, self.context)
        self._asked: dict[int, tuple[threading.Event, list[Any]]] = {}
        self._ids = itertools.count(1)
        self._puts = threading.BoundedSemaphore(PUTS_AT_ONCE)
        self._tokens, self._refilled = float(self.options.write_rate), time.monotonic()
        self._sequences: dict[str, int] = {}  # a writer's GID -> the last sequence number taken from it
        self._dropped: dict[str, int] = {}  # per part, the drops the last /diagnostics sample counted
        self._stats: dict[str, dict[str, int]] = {}
        self._pages: tuple[int, list[bytes]] = (0, [])  # the table snapshot coming in: serial, its pages so far
        self._table_entries: tuple[int, list[Any]] = (0, [])  # the last snapshot answered, as Entry messages
        self._roster_parts: list[bytes] = []  # the roster message coming in
        self._declare(config["served"])
        self.executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS, context=self.context)
        self.executor.add_node(self.node)

    def _declare(self, served: bool) -> None:
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        msg, srv, node, options = self._types.msg, self._types.srv, self.node, self.options
        reliability = ReliabilityPolicy.RELIABLE if options.reliable else ReliabilityPolicy.BEST_EFFORT
        stream = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=options.depth, reliability=reliability)
        table = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.broadcast = node.create_publisher(msg.Message, "broadcast", stream)
        self.broadcast_tagged = node.create_publisher(msg.TaggedMessage, "broadcast_tagged", stream)
        self.heard = [node.create_publisher(msg.Message, f"heard/{ros_name(link)}", stream) for link in self.links]
        # What ROS 2 nodes write is taken at a bounded pace, not as it comes: its subscription sits on a node no
        # executor spins; a timer takes what `write_rate` allows, and Fast DDS drops the rest (rx_lost).
        self.intake = _node(f"{node.get_name()}_write", options.namespace, self.context)
        self.writes = [self.intake.create_subscription(kind, topic, _never, stream, raw=True)
                       for kind, topic in ((msg.Message, "write"), (msg.TaggedMessage, "write_tagged"))]
        # Each callback in a group of its own, so none waits for another (a default group runs one callback at a
        # time): puts are reentrant, `_put` bounds those in flight and answers the rest busy at once.
        node.create_timer(WRITE_POLL, self._take_writes, MutuallyExclusiveCallbackGroup())
        self.robots = node.create_publisher(msg.Robots, "robots", table)  # latched: a late subscriber gets it
        self.changes = None
        if served:
            self.changes = node.create_publisher(msg.Change, "changes", table)
            # Requests wait in the service's history while its group is busy: ROS 2's default (10) drops the oldest
            # of a burst unanswered, and its caller waits for ever.
            asked = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SERVICE_DEPTH,
                               reliability=ReliabilityPolicy.RELIABLE)
            for kind, name, answer, group in ((srv.Put, "put", self._put, ReentrantCallbackGroup()),
                                              (srv.Get, "get", self._get, MutuallyExclusiveCallbackGroup()),
                                              (srv.Table, "table", self._table, MutuallyExclusiveCallbackGroup())):
                node.create_service(kind, name, answer, qos_profile=asked, callback_group=group)
        from diagnostic_msgs.msg import DiagnosticArray

        diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        node.create_timer(DIAGNOSTICS_PERIOD, lambda: self._diagnose(diagnostics), MutuallyExclusiveCallbackGroup())

    # -- to the gateway -------------------------------------------------------------
    def _count(self, name: str, n: int = 1) -> None:
        with self._counting:
            self.counters[name] += n

    def _ship_counters(self) -> None:
        """What we counted since the last time (K frame), for the link's counters."""
        with self._counting:
            counted, self.counters = self.counters, Counters()
        if counted:
            self._send(b"K", json.dumps(counted).encode())

    def _send(self, kind: bytes, payload: bytes) -> None:
        with self._out_lock:
            self._out.write(FRAME.pack(kind, len(payload)) + payload)
            self._out.flush()

    def _ask(self, request: dict[str, Any]) -> Any:
        """Send a request and wait for the gateway's answer (None: it did not answer in time)."""
        ident = next(self._ids)
        answered, answer = threading.Event(), list[Any]()
        self._asked[ident] = (answered, answer)
        try:
            self._send(b"Q", json.dumps({"id": ident, **request}).encode())
            answered.wait(ANSWER_WAIT)
        finally:
            self._asked.pop(ident, None)
        return answer[0] if answer else None

    # -- from the gateway (our stdin, on the main thread) ------------------------------------
    def serve(self, stdin: IO[bytes]) -> None:
        """Publish what the gateway sends until it closes our stdin."""
        self._spinning = threading.Thread(target=self._spin, name="ros2-executor", daemon=True)
        self._spinning.start()
        read = stdin.read
        msg = self._types.msg
        while True:
            head = read(FRAME.size)
            if len(head) < FRAME.size:
                return
            kind, size = FRAME.unpack(head)
            payload = read(size)
            if len(payload) < size:
                return
            try:
                self._take(kind, payload, msg)
            except Exception:  # the node closed under us, or rclpy broke: counted, the next frame may go
                self._count("tx_dropped", 1)

    def _take(self, kind: bytes, payload: bytes, msg: Any) -> None:
        if kind == b"H":
            heard, published = self.heard, 0
            for index, sender, *words in HEARD.iter_unpack(payload):
                heard[index].publish(cdr_message(tuple.__new__(Message, words), sender))
                published += 1
            self._count("published", published)
        elif kind == b"B":  # CDR already: the framing encoded them with the gateway's robot id as sender
            if len(payload) == TAGGED_CDR_SIZE:  # one record (a link that checks tags sends each so)
                self.broadcast_tagged.publish(payload)
                return
            for start in range(0, len(payload), CDR_SIZE):
                self.broadcast.publish(payload[start:start + CDR_SIZE])
        elif kind == b"C" and self.changes is not None:
            for key, has_old, *fields in CHANGE.iter_unpack(payload):
                old, new, link, sender = fields[0:3], fields[3:6], fields[6], fields[7]
                self.changes.publish(msg.Change(
                    key=key, has_old=bool(has_old), old_entry=self._entry(key, old if has_old else None),
                    new_entry=self._entry(key, new), link="" if link == 0xFFFF else self.links[link],
                    sender=sender))
                self._count("published", 1)
        elif kind == b"A":
            answer = json.loads(payload)
            waiting = self._asked.get(answer.pop("id"))
            if waiting is not None:
                waiting[1].append(answer)
                waiting[0].set()
        elif kind == b"T":
            serial, first = TABLE_PAGE.unpack_from(payload)
            pages = [] if first == 0 or serial != self._pages[0] else self._pages[1]
            pages.append(payload[TABLE_PAGE.size:])
            self._pages = (serial, pages)
        elif kind == b"S":
            self._stats = json.loads(payload)
        elif kind == b"O":
            self._roster_parts.append(payload[ROBOTS_PART.size:])
            if ROBOTS_PART.unpack_from(payload)[0]:
                roster, self._roster_parts = json.loads(b"".join(self._roster_parts)), []
                self.robots.publish(self._robots(roster, msg))
                self._count("published", 1)

    @staticmethod
    def _robots(roster: dict[str, Any], msg: Any) -> Any:
        """The roster message (gateway.roster_message) as a vstig_msgs/Robots."""
        robots = [msg.Robot(robot=row["robot"], named_by=row["named_by"], links=row["links"], state=row["state"],
                            last_heard_s=float(row["last_heard_s"]), rate=float(row["rate"]),
                            messages=row["messages"], writes=row["writes"], gets=row["gets"], behind=row["behind"],
                            refused=row["refused"], quality=-1 if row["quality"] is None else row["quality"])
                  for row in roster["rows"]]
        return msg.Robots(t=float(roster["t"]), robots_total=roster["robots_total"], alive=roster["alive"],
                          quiet=roster["quiet"], gone=roster["gone"], untracked=roster["untracked"], robots=robots)

    def _spin(self) -> None:
        with contextlib.suppress(Exception):  # the context shuts down as we end
            self.executor.spin()

    # -- on the executor's threads ------------------------------------------------------
    def _take_writes(self) -> None:
        """Take what ROS 2 nodes wrote, as many as `write_rate` allows since the last time; ship them."""
        now = time.monotonic()
        rate = self.options.write_rate
        self._tokens = min(float(rate), self._tokens + (now - self._refilled) * rate)
        self._refilled = now
        taken: list[list[Any]] = []
        garbage = 0
        # One sample from each write topic in turn while tokens last: a flood on one leaves the other its half.
        waiting = list(zip(self.writes, (message_of_cdr, tagged_of_cdr), strict=True))
        while waiting and self._tokens >= 1.0:
            subscription, valid = waiting.pop(0)
            with subscription.handle:  # rclpy's executor takes a sample this way (Subscription.handle)
                sample = subscription.handle.take_message(subscription.msg_type, True)
            if sample is None:
                continue  # empty: not asked again this time
            waiting.append((subscription, valid))
            self._tokens -= 1.0  # garbage costs its taking too: a garbage flood is bounded as any other
            payload, info = sample
            source = self._writer_of(info)
            if valid(payload) is None:  # refused here, not shipped to the gateway's data path
                garbage += 1
            else:
                taken.append([payload.hex(), source])
        if garbage:
            self._count("drop_bad_cdr", garbage)
        if taken:
            self._count("rx", len(taken))
            self._send(b"W", json.dumps(taken).encode())

    def _writer_of(self, info: Any) -> str | None:
        """The writer's GID (hex), counting the samples of it Fast DDS dropped before we took them (rx_lost)."""
        gid = info.get("publisher_gid") if isinstance(info, dict) else None
        if not isinstance(gid, dict) or "data" not in gid:
            return None
        source = bytes(gid["data"]).hex()
        sequence = info.get("publication_sequence_number")
        if isinstance(sequence, int):
            last = self._sequences.get(source)
            if last is not None and sequence > last + 1:
                self._count("rx_lost", sequence - last - 1)
            self._sequences[source] = sequence
        return source

    def _entry(self, key: int, fields: Any) -> Any:
        entry = self._types.msg.Entry()
        if fields is not None:
            entry.key, (entry.value, entry.timestamp, entry.robot) = key, fields
        return entry

    def _put(self, request: Any, response: Any) -> Any:
        self._count("put", 1)
        if not self._puts.acquire(blocking=False):
            self._count("put_busy", 1)
            response.taken = False
            response.reason = f"busy: {PUTS_AT_ONCE} confirmed puts are in progress; ask again"
            return response
        try:
            answer = self._ask({"put": [request.key, request.value]})
        finally:
            self._puts.release()
        if answer is None:
            response.taken, response.reason = False, "the gateway did not answer in time"
            return response
        response.taken, response.reason = answer["taken"], answer["reason"]
        response.entry = self._entry(request.key, answer["entry"])
        return response

    def _get(self, request: Any, response: Any) -> Any:
        self._count("get", 1)
        answer = self._ask({"get": request.key})
        entry = answer.get("entry") if answer else None
        response.found, response.entry = entry is not None, self._entry(request.key, entry)
        return response

    def _table(self, request: Any, response: Any) -> Any:
        self._count("table", 1)
        answer = self._ask({"table": True})
        serial = (answer or {}).get("table", 0)
        if serial and serial != self._table_entries[0]:  # a snapshot we have not answered yet: its pages are in
            pages = self._pages
            records = b"".join(pages[1]) if pages[0] == serial else b""
            if len(records) != answer["count"] * TABLE_RECORD.size:  # pages lost: the gateway restarted us?
                self._count("drop_table", 1)
                return response
            self._table_entries = (serial, [self._entry(key, fields) for key, *fields
                                            in TABLE_RECORD.iter_unpack(records)])
        response.entries = self._table_entries[1] if serial else []
        return response

    def _diagnose(self, publisher: Any) -> None:
        """The gateway's counters as one DiagnosticStatus per link (and the engine): WARN while drops grow."""
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        self._ship_counters()
        array = DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        for part, counts in self._stats.items():
            counters = Counters(counts)
            dropped = sum(n for name, n in counters.items() if name.startswith(_DROPS))
            growing, self._dropped[part] = dropped > self._dropped.get(part, 0), dropped
            array.status.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN if growing else DiagnosticStatus.OK,
                name=f"vstig {self.options.namespace}: {part}", hardware_id=self.node.get_name(),
                message=counters.summary(),
                values=[KeyValue(key=name, value=str(count)) for name, count in sorted(counters.items())]))
        if array.status:
            publisher.publish(array)

    def close(self) -> None:
        """Stop the executor and wait for its thread (a thread still in rclpy as Python exits aborts it), then
        the node, the context and our last counters."""
        self.executor.shutdown(timeout_sec=2.0)
        spinning = getattr(self, "_spinning", None)
        if spinning is not None:
            spinning.join(timeout=5.0)
        self.intake.destroy_node()
        self.node.destroy_node()
        self.context.try_shutdown()
        self._ship_counters()


def _never(_: object) -> None:
    """The write subscription's callback: never called, no executor spins its node."""


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the gateway, which closes our stdin
    os.nice(NICENESS)  # before any thread starts: every thread of ours yields the CPU to the gateway's
    out = sys.stdout.buffer
    try:
        node = Ros2Node(json.loads(argv[0]), out)
    except Exception as error:  # one line for the gateway to show: no rclpy, no compiler, a bad profile...
        message = " ".join(str(error).split()) or type(error).__name__
        out.write(FRAME.pack(b"E", len(message.encode())) + message.encode())
        out.flush()
        return 1
    out.write(FRAME.pack(b"R", 0))  # ready: the node and its entities exist
    out.flush()
    try:
        node.serve(sys.stdin.buffer)
    finally:
        node.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
