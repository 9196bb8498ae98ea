"""Ros2Transport: an rclpy node of the gateway's own, in a context of its own, under one namespace.

As a transport it moves `Ros2Sample`s: what ROS 2 nodes publish on `<ns>/write`
(vstig_msgs/Message) is handed straight to whoever asked (`deliver_to`: a gateway's
readers), from the executor's thread; what the gateway broadcasts is published on
`<ns>/broadcast`. Beside that it publishes what a gateway gives it, and serves
what a gateway answers (`serve`, called by `gateway.ros2`):

    <ns>/heard/<link>   vstig_msgs/Message   every message each link heard
    <ns>/changes        vstig_msgs/Change    keyed by `key`, reliable, transient-local, depth 1 a key:
                                             a late subscriber gets the newest change of every key
    <ns>/put, get, table                     services (vstig_msgs/srv/Put, Get, Table)
    /diagnostics        diagnostic_msgs/DiagnosticArray: the gateway's counters, once a second

Never on the data path's critical side: rclpy's executor (services, the write
topic's intake, the diagnostics timer) runs on threads of its own; topics are published
where the gateway's event happens, raw CDR on KEEP_LAST writers, which never wait
for a slow or absent subscriber (Fast DDS keeps the newest `depth` samples per
subscriber and drops the oldest). What ROS 2 nodes write is taken at a bounded
pace: at most `write_rate` writes a second, every WRITE_POLL seconds, the
subscription keeping `depth` samples in between; what a flooding writer sends
beyond is dropped inside Fast DDS, never seen by Python, and counted from the
writers' sequence numbers (`rx_lost`).

Discovery is set for the whole process when the first ros2: link opens (Fast DDS
reads its profile once): on this PC only by default (a Fast DDS profile that
listens on loopback and shared memory alone), or the LAN (`discovery=subnet`:
Fast DDS's defaults), or the user's profile file.

Counters: `rx`, `tx` (samples), `rx_lost`, `tx_dropped`, `published` (heard and changes samples),
`put`, `put_busy`, `get`, `table`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from typing import Any, Protocol

from ..counters import Counters
from ..engine import Entry
from ..framing.ros2 import NO_SENDER, Ros2Sample, cdr_message, ros_name
from ..wakeup import Wakeup
from ..wire import Message
from .base import DeviceTransport, TransportError, one_line

__all__ = ["DISCOVERY", "PutAnswer", "Ros2Options", "Ros2Transport", "Served"]

log = logging.getLogger(__name__)

DISCOVERY = ("localhost", "subnet")
INBOX_LIMIT = 4096  # samples queued for `read` when nobody takes them as they arrive (a transport used alone)
DIAGNOSTICS_PERIOD = 1.0  # seconds between two /diagnostics samples
WRITE_POLL = 0.02  # seconds between two takes from the write topic: what a ROS 2 write may wait
PUTS_AT_ONCE = 2  # confirmed puts in flight; one more is answered at once (put_busy)
_EXECUTOR_THREADS = PUTS_AT_ONCE + 1  # a put waits on its thread: one is always left for the rest
_PROFILE = "fastdds_loopback.xml"
_DROPS = ("drop_", "rx_lost", "rx_overflow", "tx_dropped", "tx_overflow", "put_busy")
_process_discovery: str | None = None  # what this process's Fast DDS was set up with (it reads that once)
_setup = threading.Lock()


@dataclass(frozen=True, slots=True)
class Ros2Options:
    namespace: str  # absolute: /vstig/<swarm>[/stigmergy<N>]
    domain: int | None = None  # None: $ROS_DOMAIN_ID, else 0
    discovery: str = "localhost"
    reliable: bool = True  # heard, broadcast and write topics (changes are always reliable)
    depth: int = 100
    write_rate: int = 500  # writes a second taken from ROS 2
    profile: str | None = None  # a Fast DDS XML profile file, passed through


@dataclass(frozen=True, slots=True)
class PutAnswer:
    taken: bool
    entry: Entry | None  # the write taken, else what the swarm holds (None: nothing)
    key: int
    reason: str  # why not ("" when taken)


class Served(Protocol):
    """What a gateway answers through the services, and counts through /diagnostics (gateway.ros2)."""

    def put(self, key: int, value: int) -> PutAnswer: ...
    def get(self, key: int) -> Entry | None: ...
    def table(self) -> list[tuple[int, Entry]]: ...
    def stats(self) -> dict[str, Counters]: ...


class _Session:
    """One rclpy context, its node, publishers and executor thread."""

    def __init__(self, context: Any, node: Any, executor: Any) -> None:
        self.context, self.node, self.executor = context, node, executor
        self.thread = threading.Thread(target=self._spin, name=f"ros2-{node.get_name()}", daemon=True)
        self.broadcast: Any = None
        self.changes: Any = None
        self.intake: Any = None  # the node that holds the write subscription, which no executor spins
        self.writes: Any = None
        self.heard: dict[str, Any] = {}
        self.failure: str | None = None

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception as exc:  # the context shut down under it, or rclpy broke: the transport reports it
            self.failure = one_line(exc)


def _ignored(_: object) -> None:
    """The write subscription's callback: never called, no executor spins its node."""


def rclpy_node(name: str, namespace: str, context: Any) -> Any:
    """A node that takes no global ROS arguments and offers no parameter or log services (a gateway has none)."""
    import rclpy

    return rclpy.create_node(name, namespace=namespace, context=context, use_global_arguments=False,
                             enable_rosout=False, start_parameter_services=False)


def _configure_process(options: Ros2Options) -> None:
    """Point Fast DDS at its profile and rcl at its discovery range, once per process (both read them once)."""
    global _process_discovery
    wanted = options.profile or options.discovery
    with _setup:
        if _process_discovery is not None:
            if _process_discovery != wanted:
                raise TransportError(f"ROS 2 in this process was set up for discovery {_process_discovery}; one "
                                     f"process cannot also use {wanted} (Fast DDS reads its profile once)")
            return
        os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
        if options.profile:
            os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = options.profile
        elif options.discovery == "localhost":
            os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(files(__package__) / _PROFILE)
        else:
            os.environ.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
        # The profile confines the transports; within them, discover by multicast (at once), not by polling peers.
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
        _process_discovery = wanted


class Ros2Transport(DeviceTransport[Ros2Sample, _Session]):
    """A ROS 2 node as a Transport[Ros2Sample]; see the module's docstring."""

    device_word = "ROS 2 node"
    reopen_on_write = False  # opening takes a while (discovery, entities): only `read` retries it

    def __init__(self, options: Ros2Options, *, name: str, node_name: str,
                 backoff: tuple[float, float] = (1.0, 10.0)) -> None:
        super().__init__(name, backoff)
        self.options = options
        self.node_name = node_name
        self._deliver: Callable[[list[Ros2Sample]], None] | None = None
        self._inbox: deque[Ros2Sample] = deque(maxlen=INBOX_LIMIT)
        self._arrived = Wakeup()
        self._served: Served | None = None
        self._links: tuple[str, ...] = ()
        self._puts = threading.BoundedSemaphore(PUTS_AT_ONCE)
        self._tokens = float(options.write_rate)
        self._refilled = time.monotonic()
        self._sequences: dict[str, int] = {}  # a writer's GID -> the last sequence number taken from it
        self._types: Any = None  # the vstig_msgs package, loaded when the node opens
        self._dropped: dict[str, int] = {}  # per part, the drops the last /diagnostics sample counted

    @property
    def about(self) -> str:
        """Where ROS 2 sees the gateway, for the start line."""
        domain = self.options.domain if self.options.domain is not None else os.environ.get("ROS_DOMAIN_ID", "0")
        reach = (f"Fast DDS profile {self.options.profile}" if self.options.profile
                 else "discovery on this PC only" if self.options.discovery == "localhost"
                 else "discovery on the LAN")
        return f"ROS 2 domain {domain}, namespace {self.options.namespace}, {reach}"

    # -- what a gateway adds ----------------------------------------------------
    def serve(self, served: Served, links: list[str]) -> None:
        """Answer the services and fill /diagnostics from `served`; publish `heard/<link>` for each of `links`.

        Called before `open` (the Node attaches its parts first); a reopened node serves again.
        """
        self._served = served
        self._links = tuple(links)

    def deliver_to(self, deliver: Callable[[list[Ros2Sample]], None] | None) -> None:
        """Hand what ROS 2 nodes write to `deliver`, on the executor's thread, instead of queueing it for `read`."""
        self._deliver = deliver

    def publish_heard(self, link: str, messages: list[Message], sender: int | None) -> None:
        """`messages` heard on `link`, on its `heard/<link>` topic; never waits (KEEP_LAST)."""
        session = self._device
        if session is None:
            return
        publisher = session.heard.get(link)
        if publisher is None:
            return
        try:
            for message in messages:
                publisher.publish(cdr_message(message, sender))
        except Exception:  # the node closed under us (InvalidHandle, RCLError): counted, the gateway goes on
            self.counters["tx_dropped"] += len(messages)
            return
        self.counters["published"] += len(messages)

    def publish_change(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        """One change of the table on `changes` (keyed: Fast DDS keeps the newest per key for late subscribers).

        Published as a message, not raw CDR: Fast DDS takes a sample's key from the message, and a serialized
        one would land every key in one instance (a late subscriber would get one change, not the table).
        """
        session = self._device
        if session is None or session.changes is None:
            return
        types = self._types.msg
        try:
            session.changes.publish(types.Change(
                key=key, has_old=old is not None, old_entry=self._entry(key, old), new_entry=self._entry(key, new),
                link=link or "", sender=NO_SENDER if sender is None else sender))
        except Exception:
            self.counters["tx_dropped"] += 1
            return
        self.counters["published"] += 1

    # -- the device calls ---------------------------------------------------------
    def _open_device(self) -> _Session:
        from ..ros2msgs import BuildError, load

        try:
            self._types = load()
        except BuildError as error:
            raise TransportError(f"{self.name}: {error}") from None
        _configure_process(self.options)
        import rclpy
        from rclpy.executors import MultiThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        context = rclpy.Context()
        try:
            rclpy.init(context=context, domain_id=self.options.domain,
                       signal_handler_options=SignalHandlerOptions.NO)  # our commands own their signals
            node = rclpy_node(self.node_name, self.options.namespace, context)
        except Exception as exc:
            if context.ok():
                context.try_shutdown()
            raise TransportError(f"{self.name}: cannot start a ROS 2 node: {one_line(exc)}") from None
        session = _Session(context, node, MultiThreadedExecutor(num_threads=_EXECUTOR_THREADS, context=context))
        try:
            self._declare(session)
        except Exception as exc:
            self._close_device(session)
            raise TransportError(f"{self.name}: cannot declare the ROS 2 topics and services: {one_line(exc)}") \
                from None
        session.executor.add_node(node)
        session.thread.start()
        return session

    def _declare(self, session: _Session) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        msg, srv = self._types.msg, self._types.srv
        node, options = session.node, self.options
        reliability = ReliabilityPolicy.RELIABLE if options.reliable else ReliabilityPolicy.BEST_EFFORT
        stream = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=options.depth, reliability=reliability)
        table = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
        session.broadcast = node.create_publisher(msg.Message, "broadcast", stream)
        # What ROS 2 nodes write is taken at a bounded pace, not as it comes: the executor would run Python for
        # every sample of a flood, holding the GIL from the gateway's readers. Its subscription sits on a node
        # no executor spins; a timer takes what `write_rate` allows, and Fast DDS drops the rest (rx_lost).
        session.intake = rclpy_node(f"{self.node_name}_write", options.namespace, session.context)
        session.writes = session.intake.create_subscription(msg.Message, "write", _ignored, stream, raw=True)
        node.create_timer(WRITE_POLL, lambda: self._take_writes(session.writes))
        session.heard = {link: node.create_publisher(msg.Message, f"heard/{ros_name(link)}", stream)
                         for link in self._links}
        served = self._served
        if served is None:
            return
        session.changes = node.create_publisher(msg.Change, "changes", table)
        node.create_service(srv.Put, "put", self._put)
        node.create_service(srv.Get, "get", self._get)
        node.create_service(srv.Table, "table", self._table)
        from diagnostic_msgs.msg import DiagnosticArray

        diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        node.create_timer(DIAGNOSTICS_PERIOD, lambda: self._diagnose(diagnostics, node))

    def _close_device(self, device: _Session) -> None:
        try:
            device.executor.shutdown(timeout_sec=2.0)
            device.node.destroy_node()
            if device.intake is not None:
                device.intake.destroy_node()
        except Exception as exc:  # a node whose context is gone may complain: it is closed either way
            log.debug("%s: error while closing: %s", self.name, exc)
        finally:
            if device.context.ok():
                device.context.try_shutdown()
        if device.thread.is_alive() and device.thread is not threading.current_thread():
            device.thread.join(timeout=2.0)

    def _read_device(self, device: _Session, timeout: float) -> list[Ros2Sample]:
        if device.failure is not None:
            raise OSError(device.failure)  # the executor stopped: an outage, reopened with backoff
        if not self._inbox:
            self._arrived.wait(timeout)
        taken = []
        while self._inbox:
            taken.append(self._inbox.popleft())
        return taken

    def write_nowait(self, unit: Ros2Sample) -> None:
        """Publish now (a gateway's writer needs no thread of its own for this link): KEEP_LAST never waits."""
        self.write(unit)

    def _write_device(self, device: _Session, unit: Ros2Sample) -> None:
        device.broadcast.publish(unit.payload)  # KEEP_LAST: never waits for a subscriber
        self._sent()

    # -- on the executor's threads ------------------------------------------------
    def _take_writes(self, subscription: Any) -> None:
        """Take what ROS 2 nodes wrote, as many as `write_rate` allows since the last time; hand them on."""
        now = time.monotonic()
        rate = self.options.write_rate
        self._tokens = min(float(rate), self._tokens + (now - self._refilled) * rate)
        self._refilled = now
        taken: list[Ros2Sample] = []
        while self._tokens >= 1.0:
            with subscription.handle:  # rclpy's executor takes a sample this way (Subscription.handle)
                sample = subscription.handle.take_message(subscription.msg_type, True)
            if sample is None:
                break
            self._tokens -= 1.0
            payload, info = sample
            taken.append(Ros2Sample(payload, self._writer_of(info)))
        if not taken:
            return
        self.counters["rx"] += len(taken)
        deliver = self._deliver
        if deliver is not None:
            deliver(taken)
            return
        dropped = len(self._inbox) + len(taken) - INBOX_LIMIT
        if dropped > 0:
            self.counters["rx_overflow"] += dropped
        self._inbox.extend(taken)
        self._arrived.set()

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
                self.counters["rx_lost"] += sequence - last - 1
            self._sequences[source] = sequence
        return source

    def _entry(self, key: int, entry: Entry | None) -> Any:
        found = self._types.msg.Entry()
        if entry is not None:
            found.key, found.value, found.timestamp, found.robot = key, entry.value, entry.timestamp, entry.robot
        return found

    def _put(self, request: Any, response: Any) -> Any:
        self.counters["put"] += 1
        served = self._served
        if served is None or not self._puts.acquire(blocking=False):
            self.counters["put_busy"] += 1
            response.taken, response.reason = False, f"busy: {PUTS_AT_ONCE} confirmed puts are in progress; ask again"
            return response
        try:
            answer = served.put(request.key, request.value)
        finally:
            self._puts.release()
        response.taken, response.reason = answer.taken, answer.reason
        response.entry = self._entry(answer.key, answer.entry)
        return response

    def _get(self, request: Any, response: Any) -> Any:
        self.counters["get"] += 1
        entry = self._served.get(request.key) if self._served is not None else None
        response.found, response.entry = entry is not None, self._entry(request.key, entry)
        return response

    def _table(self, request: Any, response: Any) -> Any:
        self.counters["table"] += 1
        rows = self._served.table() if self._served is not None else []
        response.entries = [self._entry(key, entry) for key, entry in sorted(rows)]
        return response

    def _diagnose(self, publisher: Any, node: Any) -> None:
        """The counters as one DiagnosticStatus per link (and the engine): WARN while drops grow, else OK."""
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        served = self._served
        if served is None:
            return
        array = DiagnosticArray()
        array.header.stamp = node.get_clock().now().to_msg()
        for part, counters in served.stats().items():
            dropped = sum(n for name, n in counters.items() if name.startswith(_DROPS))
            growing, self._dropped[part] = dropped > self._dropped.get(part, 0), dropped
            array.status.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN if growing else DiagnosticStatus.OK,
                name=f"vstig {self.options.namespace}: {part}", hardware_id=self.node_name,
                message=counters.summary(),
                values=[KeyValue(key=name, value=str(count)) for name, count in sorted(counters.items())]))
        publisher.publish(array)
