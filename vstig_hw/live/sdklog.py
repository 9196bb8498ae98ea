"""What the foxglove-sdk server says through Python's logging (pyo3-log, called on the SDK's own threads): the
viewers it takes in, counted and capped, and its lines, made safe for a terminal.

The SDK has no limit on viewers: 5,000 WebSocket connections took its process to 1.84 GB. It does log
`Registered client ADDR` on the thread that took the viewer in, after the handshake and before that thread
writes to it again, and `Unregistered client ADDR` when it is gone. `SdkLog` counts them; a viewer beyond the
cap is sent a WebSocket close (1013, try again later, saying why) and its socket is shut down, so the SDK drops
it as a viewer that left. The SDK is pinned to 0.30.x; tests/cli/test_live_view.py holds it to these lines.

What the SDK logs about a viewer quotes the viewer's own bytes (an invalid message is echoed whole): newlines,
ANSI and OSC escape sequences went to the gateway's terminal, 347,400 lines (112 MB) in 10 s. Each line is
escaped (every character that is not printable becomes \\x.., \\u....), cut to LINE_CHARS, and at most
LINES_PER_S lines a second (bursts of LINES_BURST) are written; the rest are counted (`log_dropped`) and said
in one line at most every SUMMARY_S seconds.
"""

from __future__ import annotations

import collections
import logging
import os
import re
import socket
import stat
import struct
import sys
import time
from typing import TextIO

from ..counters import Counters
from ..wording import counted

__all__ = ["CLOSE_TRY_AGAIN", "LINES_BURST", "LINES_PER_S", "SdkLog", "safe_line"]

LINES_PER_S = 2.0  # the SDK's lines written a second, in the long run: a person reads no more
LINES_BURST = 10  # written at once before the rate applies
LINE_CHARS = 300  # an SDK line is cut here: a viewer's message can be megabytes
SUMMARY_S = 10.0  # how often the count of lines held back is said, while there are some
CLOSE_TRY_AGAIN = 1013  # the WebSocket close code for "the server is overloaded, try again later" (RFC 6455 ext.)

_REGISTERED = re.compile(r"(Un)?[Rr]egistered client (\S+)$")
_SDK_LOGGERS = ("foxglove", "tungstenite")  # the targets the SDK logs under, as pyo3-log names them


def safe_line(text: str, limit: int = LINE_CHARS) -> str:
    """`text` as one line a terminal shows as it is: every character that is not printable escaped, cut to
    `limit` characters (marked with ...)."""
    text = text[:limit * 2]  # escaping at most quadruples what is kept; never read megabytes
    if not text.isprintable():  # control characters, and format ones (bidi overrides) that reorder a line
        text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _address(text: str) -> tuple[str, int] | None:
    """(host, port) from the SDK's `127.0.0.1:50380` or `[::1]:50380`."""
    host, _, port = text.rpartition(":")
    return (host.strip("[]"), int(port)) if port.isdigit() and host else None


class SdkLog(logging.Handler):
    """Installed on the SDK's loggers by `install`: caps its viewers at `viewers`, writes its lines to `out`
    safely; counts `viewers_refused` and `log_dropped` in `counters`."""

    def __init__(self, counters: Counters, viewers: int, out: TextIO | None = None) -> None:
        super().__init__(logging.INFO)
        self.counters = counters
        self.cap = viewers
        self.out = out
        self.viewers: set[str] = set()  # the addresses of the viewers taken in and still there
        self._allowance = float(LINES_BURST)
        self._refilled = time.monotonic()
        self._held = 0  # lines held back since the last summary
        self._said_at = 0.0
        self._peers: dict[int, tuple[int, tuple[str, int] | None]] = {}  # fd: (socket inode, its peer)
        self._refused: collections.deque[str] = collections.deque(maxlen=64)  # whose broken pipe is no news

    def install(self, *, everything: bool = False) -> None:
        """Take the SDK's log records from now on, before the SDK logs its first (pyo3-log caches levels);
        `everything`: every other logger's warnings too (the server's own process: no raw line on stderr)."""
        if everything:
            logging.getLogger().addHandler(self)
        for name in _SDK_LOGGERS:
            logger = logging.getLogger(name)
            logger.setLevel(logging.WARNING)
            logger.propagate = False  # never also on the root's handlers (or Python's last resort, raw on stderr)
            logger.addHandler(self)
        logging.getLogger("foxglove.websocket.server").setLevel(logging.INFO)  # where viewers come and go

    def uninstall(self) -> None:
        """Stop taking records; say how many lines were held back since it was last said."""
        for name in ("", *_SDK_LOGGERS):
            logging.getLogger(name).removeHandler(self)
        self._say_held()

    def handleError(self, record: logging.LogRecord) -> None:
        """Never a traceback on the SDK's thread: a line we could not write is a line held back."""
        self.counters["log_dropped"] += 1

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if record.levelno < logging.WARNING:
            came = _REGISTERED.match(message) if record.name == "foxglove.websocket.server" else None
            if came is not None and came.group(1):
                self.viewers.discard(came.group(2))
            elif came is not None:
                self._came(came.group(2))
            return
        if not any(f"client {address}:" in message for address in self._refused):
            self.say(message)

    # -- viewers ------------------------------------------------------------------------
    def _came(self, address: str) -> None:
        if len(self.viewers) < self.cap:
            self.viewers.add(address)
            return
        self.counters["viewers_refused"] += 1
        why = f"{counted(len(self.viewers), 'viewer')} already (--foxglove-viewers {self.cap})"
        peer = _address(address)
        fd = self._socket_of(peer) if peer is not None else None
        if fd is None:  # not found (the SDK's address form changed?): taken in rather than left half-open
            self.viewers.add(address)
            return
        _refuse(fd, why)
        self._refused.append(address)
        self.say(f"refused a viewer from {address}: {why}")

    def _socket_of(self, peer: tuple[str, int]) -> int | None:
        """This process's descriptor of the TCP connection from `peer`, or None."""
        for entry in os.scandir("/proc/self/fd"):
            try:
                fd = int(entry.name)
                inode = os.fstat(fd)
            except (OSError, ValueError):
                continue
            if not stat.S_ISSOCK(inode.st_mode):
                continue
            known = self._peers.get(fd)
            if known is None or known[0] != inode.st_ino:
                known = self._peers[fd] = (inode.st_ino, _peer_of(fd))
            if known[1] == peer:
                return fd
        return None

    # -- lines ---------------------------------------------------------------------------
    def say(self, message: str) -> None:
        """Write `message` as a safe line if the rate allows, else count it; say what was held back now and then."""
        now = time.monotonic()
        self._allowance = min(float(LINES_BURST), self._allowance + (now - self._refilled) * LINES_PER_S)
        self._refilled = now
        if self._held and now - self._said_at >= SUMMARY_S and self._allowance >= 1:
            self._allowance -= 1
            self._said_at = now
            self._say_held()
        if self._allowance < 1:
            self._held += 1
            self.counters["log_dropped"] += 1
            if not self._said_at:
                self._said_at = now  # the first summary comes SUMMARY_S after lines began to be held
            return
        self._allowance -= 1
        self._write(f"live view: {safe_line(message)}")

    def _say_held(self) -> None:
        if self._held:
            self._write(f"live view: {self._held} more lines from the server held back (counted: log_dropped)")
            self._held = 0

    def _write(self, line: str) -> None:
        out = self.out or sys.stderr
        out.write(line + "\n")
        out.flush()


def _peer_of(fd: int) -> tuple[str, int] | None:
    """(host, port) of the peer of socket `fd` (left open), or None for one with no IP peer."""
    try:
        sock = socket.socket(fileno=fd)
    except OSError:
        return None
    try:
        name = sock.getpeername()
    except OSError:
        return None
    finally:
        sock.detach()
    return (str(name[0]), int(name[1])) if isinstance(name, tuple) and len(name) >= 2 else None


def _refuse(fd: int, why: str) -> None:
    """A WebSocket close frame (server frames are not masked) on socket `fd`, then the socket shut both ways: the
    viewer is told why, and the SDK reads the end of its stream as a viewer leaving."""
    reason = why.encode()[:121]
    frame = struct.pack("!BBH", 0x88, 2 + len(reason), CLOSE_TRY_AGAIN) + reason
    sock = socket.socket(fileno=fd)
    try:
        sock.send(frame, socket.MSG_DONTWAIT)
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass  # gone already
    finally:
        sock.detach()
