"""BlabbermouthTransport: take the place of MISTLab's blabbermouth relay in a Khepera IV swarm.

Each Khepera IV running BuzzKH4 (`bzzkh4 tcp <msg_size> ...`) listens on TCP port
24580, accepts one connection and waits for it before it starts; every control
step it writes exactly `msg_size` bytes and reads frames of the same size.
blabbermouth (MISTLab/blabbermouth src/bm_dispatcher.c) connects to every robot
and writes each frame it reads from one robot to every other robot: the robots
only hear each other through it, so a relay that stops relaying splits the swarm.

This transport does the same, with every frame also handed to `read` (the unit is
one whole frame), and `write` sends the gateway's own frames to every robot. It
never interprets a frame. A robot that hangs up is logged once, counted, and
dialled again with backoff while the others carry on. So is a robot that takes no
frame for `send_timeout` seconds (`robot_stalled`): one robot that stops reading
must not stop the relay between the others.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import socket
import struct
import threading
import time

from ..counters import Counters
from .base import Backoff, Transport, TransportError, one_line

__all__ = ["BlabbermouthTransport"]

log = logging.getLogger(__name__)

REDIAL_AFTER = 0.1  # seconds between the first redials of a robot that hung up (then doubling)
SEND_TIMEOUT = 1.0  # seconds a robot may take no frame before we hang up on it (and dial it again)


class _Robot:
    """One robot's connection and its reader thread."""

    def __init__(self, owner: BlabbermouthTransport, host: str, port: int) -> None:
        self.owner, self.host, self.port = owner, host, port
        self.name = f"{host}:{port}"
        self.sock: socket.socket | None = None
        self.send_lock = threading.Lock()
        self.thread: threading.Thread | None = None

    def connect(self, timeout: float) -> None:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except OSError as error:
            raise TransportError(f"blabbermouth robot {self.name}: {one_line(error)} (is bzzkh4 running "
                                 "and listening on that port?)") from None
        sock.settimeout(None)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        seconds = self.owner.send_timeout  # a send waits this long at most (reads stay blocking)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO,
                        struct.pack("ll", int(seconds), int(seconds % 1 * 1_000_000)))
        self.sock = sock
        self.thread = threading.Thread(target=self._read_frames, name=f"blabbermouth {self.name}", daemon=True)
        self.thread.start()

    def _read_frames(self) -> None:
        sock, size = self.sock, self.owner.frame_size
        assert sock is not None
        buffer = bytearray()
        while True:
            try:
                chunk = sock.recv(65536)
            except OSError:
                chunk = b""
            if not chunk:
                self.owner._lost(self)
                return
            buffer += chunk
            while len(buffer) >= size:
                frame = bytes(buffer[:size])
                del buffer[:size]
                self.owner._relay(frame, self)

    def send(self, data: bytes) -> bool:
        sock = self.sock
        if sock is None:
            return False
        try:
            with self.send_lock:
                sock.sendall(data)
        except OSError as error:
            if isinstance(error, BlockingIOError):  # SO_SNDTIMEO ran out: the robot stopped reading
                self.owner.counters["robot_stalled"] += 1
                log.warning("blabbermouth robot %s took no frame for %g s; hanging up on it so the others' "
                            "frames go on", self.name, self.owner.send_timeout)
            self.close()  # part of a frame may have gone: its stream is out of step, so it is dialled again
            return False
        return True

    def close(self) -> None:
        sock, self.sock = self.sock, None
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()


class BlabbermouthTransport(Transport[bytes]):
    """Transport[bytes]: one unit is one fixed-size frame from any robot."""

    def __init__(self, robots: list[tuple[str, int]], frame_size: int, *, name: str | None = None,
                 connect_timeout: float = 5.0, backoff_max: float = 2.0, send_timeout: float = SEND_TIMEOUT) -> None:
        if frame_size < 5:
            raise ValueError(f"a BuzzKH4 frame holds at least a robot id and one message, got size {frame_size}")
        if not robots:
            raise ValueError("blabbermouth needs at least one robot address")
        self.frame_size = frame_size
        self.name = name or ",".join(f"{h}:{p}" for h, p in robots)
        self.counters = Counters()
        self.connect_timeout = connect_timeout
        self.send_timeout = send_timeout
        self.backoff_max = backoff_max
        self._robots = [_Robot(self, host, port) for host, port in robots]
        self._frames: queue.Queue[bytes] = queue.Queue()
        self._lock = threading.Lock()
        self._retry: dict[_Robot, Backoff] = {}  # lost robot -> when to dial it again
        self._open = False

    @property
    def connected(self) -> bool:
        return self._open and all(robot.sock is not None for robot in self._robots)

    def open(self) -> None:
        """Connect to every robot (each waits for this before it starts); TransportError names one that fails."""
        try:
            for robot in self._robots:
                robot.connect(self.connect_timeout)
        except TransportError:
            self.close()
            raise
        self._open = True

    def close(self) -> None:
        self._open = False
        for robot in self._robots:
            robot.close()

    def _relay(self, frame: bytes, origin: _Robot) -> None:
        """What blabbermouth does with a frame: write it to every other robot. Then keep it for `read`."""
        self.counters["rx"] += 1
        for robot in self._robots:
            if robot is not origin:
                self.counters["relayed" if robot.send(frame) else "relay_failed"] += 1
        self._frames.put(frame)

    def _lost(self, robot: _Robot) -> None:
        robot.close()
        if not self._open:
            return
        log.warning("blabbermouth robot %s hung up; dialling it again", robot.name)
        self.counters["robot_lost"] += 1
        backoff = Backoff(REDIAL_AFTER, self.backoff_max)
        backoff.start(time.monotonic(), at_once=True)  # the first redial at once, then REDIAL_AFTER doubling
        with self._lock:
            self._retry[robot] = backoff

    def _redial(self) -> None:
        now = time.monotonic()
        with self._lock:
            due = [(robot, backoff) for robot, backoff in self._retry.items() if backoff.next_at <= now]
        for robot, backoff in due:
            try:
                robot.connect(self.connect_timeout)
            except TransportError:
                backoff.failed(time.monotonic())
                continue
            with self._lock:
                del self._retry[robot]
            self.counters["reconnects"] += 1

    def read(self, timeout: float) -> list[bytes]:
        if self._retry:
            self._redial()
        try:
            frames = [self._frames.get(timeout=timeout)]
        except queue.Empty:
            return []
        while True:
            try:
                frames.append(self._frames.get_nowait())
            except queue.Empty:
                return frames

    def write(self, unit: bytes) -> None:
        """The gateway's own frame(s), to every robot; a whole number of frames, or ValueError."""
        if len(unit) % self.frame_size:
            raise ValueError(f"blabbermouth writes whole {self.frame_size}-byte frames, got {len(unit)} bytes")
        for robot in self._robots:
            if not robot.send(unit):
                self.counters["tx_dropped"] += 1
        self.counters["tx"] += len(unit) // self.frame_size
