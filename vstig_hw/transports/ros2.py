"""Ros2Transport: a ros2: link as the gateway holds it, a pipe to its ROS 2 node in a process of its own.

The node (`ros2_node`: rclpy, Fast DDS, the executor) runs in a child process, so
none of ROS 2's threads or Python work takes a CPU turn or the GIL from the data
path; DECISIONS.md, "ROS 2". What the gateway hands it goes down the child's stdin
in frames written without waiting (a pipe write of at most PIPE_BUF bytes is whole
or refused): a child that cannot take them is behind, and what it missed is
counted (`drop_behind`), never waited for. What ROS 2 nodes write comes up its
stdout as this link's units (`Ros2Sample`), read by the link's reader thread as
any device's; service requests come up the same way and are answered on threads
of this transport's own (a confirmed put waits seconds).

A child that dies is an outage: logged once, counted (`lost`), and started again
with backoff. Closing the link closes its stdin, and the child ends.

A table answer is a snapshot (gateway.ros2.TableSnapshots) sent in pages, each a pipe write of
its own, once per snapshot: the child keeps the last one. The roster (`robots`) goes the same way, in
parts, made and sent on a request thread: the data path only asks for it.

Counters: `rx` (writes taken), `tx` (broadcasts), `drop_behind`, and the child's: `rx_lost` (writes Fast
DDS dropped: a writer above `write_rate`), `drop_bad_cdr` (writes refused), `published` (heard and change
samples), `put`, `put_busy`, `get`, `table`, `drop_table`.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import json
import logging
import os
import select
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO, Any, Protocol

from ..counters import Counters
from ..engine import Entry
from ..framing.ros2 import Ros2Sample, wire_sender
from ..ros2msgs import ros_environment
from ..wire import Message
from .base import DeviceTransport, TransportError

__all__ = ["CHANGE", "FRAME", "HEARD", "PUTS_AT_ONCE", "ROBOTS_PART", "TABLE_PAGE", "TABLE_RECORD", "PutAnswer",
           "Ros2Options", "Ros2Transport", "Served", "TableSnapshot"]

log = logging.getLogger(__name__)

# The pipe protocol: a frame is a kind byte and a payload length, then the payload.
FRAME = struct.Struct("<cI")
HEARD = struct.Struct("<HqHHHH")  # H records: link index, sender (as wire_sender has it), the four wire words
# C records: key, has_old, old and new entry (value, timestamp, robot), link index (NO_LINK: none), sender
CHANGE = struct.Struct("<HBHHHHHHHq")
NO_LINK = 0xFFFF
TABLE_RECORD = struct.Struct("<HHHH")  # a table snapshot's records: key, value, timestamp, robot; by key
TABLE_PAGE = struct.Struct("<II")  # T frames: the snapshot's serial and its first record's index, then records
ROBOTS_PART = struct.Struct("<B")  # O frames: 1 on the last part of a roster message (JSON), then the part
PIPE_BUF = 4096  # POSIX: a pipe write of at most this many bytes is never split nor interleaved
START_TIMEOUT = 360.0  # seconds the child may take to start: the first on a machine builds the interfaces
STATS_PERIOD = 1.0  # seconds between two counter snapshots sent for /diagnostics
PUTS_AT_ONCE = 2  # confirmed puts in flight in the node process; one more is answered busy at once (put_busy)
REQUEST_THREADS = PUTS_AT_ONCE + 3  # the puts in flight, a get and a table at once (the node asks no more), the roster


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


@dataclass(frozen=True, slots=True)
class TableSnapshot:
    serial: int  # a new number for each snapshot taken: the node process keeps the last one it was sent
    records: bytes  # TABLE_RECORD, one per key, by key


class Served(Protocol):
    """What a gateway answers through the services (gateway.ros2)."""

    def put(self, key: int, value: int) -> PutAnswer: ...
    def get(self, key: int) -> Entry | None: ...
    def table(self) -> TableSnapshot: ...


class _Child:
    """The node's process and our ends of its pipes."""

    def __init__(self, process: subprocess.Popen[bytes]) -> None:
        assert process.stdin is not None and process.stdout is not None
        self.process = process
        self.stdin: IO[bytes] = process.stdin
        self.fd = process.stdin.fileno()
        self.out = process.stdout.fileno()
        self.buffer = b""
        self.table = 0  # the serial of the table snapshot it was sent whole (0: none)


class Ros2Transport(DeviceTransport[Ros2Sample, _Child]):
    """A ROS 2 node (in a child process) as a Transport[Ros2Sample]; see the module's docstring."""

    device_word = "ROS 2 node process"
    reopen_on_write = False  # starting it takes a while: only `read` retries it

    def __init__(self, options: Ros2Options, *, name: str, node_name: str, robot_id: int,
                 backoff: tuple[float, float] = (1.0, 10.0)) -> None:
        super().__init__(name, backoff)
        self.options = options
        self.node_name = node_name
        self.robot_id = robot_id
        self._served: Served | None = None
        self._links: dict[str, int] = {}
        self._writing = threading.Lock()  # one frame at a time; the data path never waits for it
        self._requests: concurrent.futures.ThreadPoolExecutor | None = None
        self._next_stats = 0.0
        self._robots_queued = False  # a roster message is being made or sent: another waits for the next tick
        self._robots_sent: tuple[_Child | None, bytes | None] = (None, None)  # the last one, and to which child

    @property
    def about(self) -> str:
        """Where ROS 2 sees the gateway, for the start line."""
        domain = self.options.domain if self.options.domain is not None else os.environ.get("ROS_DOMAIN_ID", "0")
        reach = (f"Fast DDS profile {self.options.profile}" if self.options.profile
                 else "discovery on this PC only" if self.options.discovery == "localhost"
                 else "discovery on the LAN")
        return f"ROS 2 domain {domain}, namespace {self.options.namespace}, {reach}"

    # -- what a gateway adds (gateway.ros2) ------------------------------------------
    def serve(self, served: Served | None, links: list[str]) -> None:
        """Answer the services from `served` (None: a gateway with no table) and publish `heard/<link>` for each
        of `links`. Called before `open`."""
        self._served = served
        self._links = {link: index for index, link in enumerate(links)}

    def publish_heard(self, link: str, messages: list[Message], sender: int | None) -> None:
        """`messages` heard on `link`, for its `heard/<link>` topic."""
        index = self._links.get(link)
        if index is None:
            return
        who = wire_sender(sender)
        pack = HEARD.pack
        self._send_records(b"H", b"".join([pack(index, who, *message) for message in messages]), HEARD.size)

    def publish_change(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        """One change of the table, for `changes`."""
        old_fields = old if old is not None else (0, 0, 0)
        index = NO_LINK if link is None else self._links.get(link, NO_LINK)
        self._send_records(b"C", CHANGE.pack(key, old is not None, *old_fields, *new, index,
                                             wire_sender(sender)), CHANGE.size)

    def publish_stats(self, stats: dict[str, Counters]) -> None:
        """The gateway's counters, for /diagnostics: at most once a STATS_PERIOD."""
        now = time.monotonic()
        if now >= self._next_stats:
            self._next_stats = now + STATS_PERIOD
            self._send_frame(b"S", json.dumps(stats).encode())

    def publish_robots(self, make: Callable[[], bytes | None]) -> None:
        """The roster for `robots`: `make` (its JSON; None: unchanged since the last) runs on a request thread, not
        the caller's; one at a time (asked while one is under way: skipped). A child started again gets the last."""
        requests, child = self._requests, self._device
        if requests is None or child is None or self._robots_queued:
            return
        self._robots_queued = True
        requests.submit(self._send_robots, child, make)

    # -- the pipe down ----------------------------------------------------------------------
    def _send_records(self, kind: bytes, data: bytes, size: int) -> None:
        """Fixed-size records, in frames that fit a pipe write whole."""
        step = (PIPE_BUF - FRAME.size) // size * size
        for start in range(0, len(data), step):
            chunk = data[start:start + step]
            if not self._send_frame(kind, chunk):
                self.counters["drop_behind"] += len(chunk) // size

    def _send_frame(self, kind: bytes, payload: bytes) -> bool:
        """Write one frame (at most PIPE_BUF bytes) if the child takes it now; False if it is behind or gone."""
        child = self._device
        if child is None or not self._writing.acquire(blocking=False):
            return False
        try:
            os.write(child.fd, FRAME.pack(kind, len(payload)) + payload)
            return True
        except OSError:  # full (BlockingIOError), or the child is gone: `read` notices that
            return False
        finally:
            self._writing.release()

    def _send_pages(self, child: _Child, snapshot: TableSnapshot) -> None:
        """A table snapshot in T frames that each fit a pipe write whole, waiting for room between them: on a
        request thread; the data path's frames go between the pages, never behind the whole table."""
        step = (PIPE_BUF - FRAME.size - TABLE_PAGE.size) // TABLE_RECORD.size * TABLE_RECORD.size
        records = snapshot.records
        for start in range(0, max(len(records), 1), step):
            page = TABLE_PAGE.pack(snapshot.serial, start // TABLE_RECORD.size) + records[start:start + step]
            if not self._send_waiting(child, b"T", page):
                return
        child.table = snapshot.serial

    def _send_robots(self, child: _Child, make: Callable[[], bytes | None]) -> None:
        """On a request thread: the roster message in O frames that each fit a pipe write whole."""
        try:
            data = make()
            last_child, last = self._robots_sent
            if data is None and child is not last_child:
                data = last
            if data is None:
                return
            step = PIPE_BUF - FRAME.size - ROBOTS_PART.size
            for start in range(0, len(data), step):
                if not self._send_waiting(child, b"O", ROBOTS_PART.pack(start + step >= len(data)) +
                                          data[start:start + step]):
                    return
            self._robots_sent = (child, data)
        except Exception:  # the roster's topic may lag; it never ends the link
            log.exception("%s: publishing the roster failed", self.name)
        finally:
            self._robots_queued = False

    def _send_waiting(self, child: _Child, kind: bytes, payload: bytes) -> bool:
        """One frame (at most PIPE_BUF bytes), waiting for room: on a request thread, so the data path's frames
        go between a long message's parts; False if the child ended or the link closed it."""
        while not self._send_frame(kind, payload):
            if self._device is not child or child.process.poll() is not None:  # its fd may be closed: no select
                return False
            select.select([], [child.fd], [], 0.1)
        return True

    def _send_whole(self, child: _Child, kind: bytes, payload: bytes) -> None:
        """A frame of any size (an answer), waiting for room: on a request thread, never the data path."""
        data = FRAME.pack(kind, len(payload)) + payload
        with self._writing:
            while data:
                select.select([], [child.fd], [], 1.0)
                try:
                    data = data[os.write(child.fd, data):]
                except BlockingIOError:
                    continue
                except OSError:
                    return

    # -- the device calls ----------------------------------------------------------------
    def _open_device(self) -> _Child:
        config = {"options": dataclasses.asdict(self.options), "links": list(self._links),
                  "robot_id": self.robot_id, "node_name": self.node_name, "served": self._served is not None}
        try:
            # the wheels' library path, computed: the gateway itself runs without it (ros2msgs.ros_environment)
            process = subprocess.Popen([sys.executable, "-m", "vstig_hw.transports.ros2_node", json.dumps(config)],
                                       stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                       env={**os.environ, **ros_environment()})
        except OSError as error:
            raise TransportError(f"{self.name}: cannot start its ROS 2 node: {error}") from None
        child = _Child(process)
        kind, payload = self._first_frame(child)
        if kind != b"R":
            self._close_device(child)
            said = payload.decode(errors="replace") if kind == b"E" else "it ended before it was ready"
            raise TransportError(f"{self.name}: its ROS 2 node did not start: {said}")
        os.set_blocking(child.fd, False)  # the data path's writes never wait (`_send_frame`)
        if self._requests is None:
            self._requests = concurrent.futures.ThreadPoolExecutor(REQUEST_THREADS, f"ros2-{self.name}")
        return child

    def _first_frame(self, child: _Child) -> tuple[bytes, bytes]:
        end = time.monotonic() + START_TIMEOUT
        while time.monotonic() < end:
            frames = self._frames(child, min(1.0, end - time.monotonic()))
            if frames:
                kind, payload = frames[0]
                child.buffer = b"".join(FRAME.pack(k, len(p)) + p for k, p in frames[1:]) + child.buffer
                return kind, payload
            if child.process.poll() is not None:
                break
        return b"", b""

    def _close_device(self, device: _Child) -> None:
        with contextlib.suppress(OSError):
            device.stdin.close()
        end = time.monotonic() + 10.0
        while device.process.poll() is None and time.monotonic() < end:
            try:
                self._take(device, self._frames(device, 0.2))  # its last counters
            except OSError:
                break
        if device.process.poll() is None:
            device.process.kill()
        device.process.wait()
        if device.process.stdout is not None:
            device.process.stdout.close()

    def _read_device(self, device: _Child, timeout: float) -> list[Ros2Sample]:
        return self._take(device, self._frames(device, timeout))

    def _write_device(self, device: _Child, unit: Ros2Sample) -> None:
        if self._send_frame(b"B", unit.payload):
            self._sent()
        else:
            self.counters["drop_behind"] += 1

    def write_nowait(self, unit: Ros2Sample) -> None:
        """Hand a broadcast to the child now (a gateway's writer needs no thread of its own for this link)."""
        self.write(unit)

    # -- the pipe up -----------------------------------------------------------------------
    def _frames(self, child: _Child, timeout: float) -> list[tuple[bytes, bytes]]:
        """Whole frames from the child within `timeout`; OSError when it has ended."""
        whole = len(child.buffer) >= FRAME.size and \
            len(child.buffer) >= FRAME.size + FRAME.unpack_from(child.buffer)[1]
        if not whole and select.select([child.out], [], [], max(timeout, 0.0))[0]:
            data = os.read(child.out, 65536)
            if not data:
                raise OSError(f"its ROS 2 node process ended (exit {child.process.wait()})")
            child.buffer += data
        frames = []
        buffer = child.buffer
        while len(buffer) >= FRAME.size:
            kind, size = FRAME.unpack_from(buffer)
            if len(buffer) < FRAME.size + size:
                break
            frames.append((kind, buffer[FRAME.size:FRAME.size + size]))
            buffer = buffer[FRAME.size + size:]
        child.buffer = buffer
        return frames

    def _take(self, child: _Child, frames: list[tuple[bytes, bytes]]) -> list[Ros2Sample]:
        units: list[Ros2Sample] = []
        for kind, payload in frames:
            if kind == b"W":
                units.extend(Ros2Sample(bytes.fromhex(data), source) for data, source in json.loads(payload))
            elif kind == b"Q" and self._requests is not None:
                self._requests.submit(self._answer, child, json.loads(payload))
            elif kind == b"K":
                self.counters.update({name: n for name, n in json.loads(payload).items() if name != "rx"})
        return units

    def _answer(self, child: _Child, request: dict[str, Any]) -> None:
        """On a request thread: what the gateway says, sent back to the child."""
        served, answer = self._served, {"id": request["id"]}
        try:
            if served is None:
                answer.update(taken=False, entry=None, reason="this gateway has no table (a raw bridge)")
            elif "put" in request:
                put = served.put(*request["put"])
                answer.update(taken=put.taken, entry=None if put.entry is None else list(put.entry),
                              reason=put.reason)
            elif "get" in request:
                entry = served.get(request["get"])
                answer.update(entry=None if entry is None else list(entry))
            else:
                snapshot = served.table()
                if child.table != snapshot.serial:
                    self._send_pages(child, snapshot)
                answer.update(table=snapshot.serial, count=len(snapshot.records) // TABLE_RECORD.size)
        except Exception as error:  # nothing a request does may end the link: the service says why
            log.exception("%s: answering %s failed", self.name, request)
            answer.update(taken=False, entry=None, reason=f"the gateway failed: {type(error).__name__}: {error}")
        self._send_whole(child, b"A", json.dumps(answer).encode())

    def close(self) -> None:
        super().close()
        requests, self._requests = self._requests, None
        if requests is not None:
            requests.shutdown(wait=False, cancel_futures=True)
