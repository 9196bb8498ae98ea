"""The service manager of a `Type=notify` unit with `WatchdogSec`, played for one process's life.

`make supervised` and `make chaos` run their gateways under it: it gives the process a notify socket
(NOTIFY_SOCKET, WATCHDOG_USEC in `env`), keeps what the process says there, and ends it with SIGABRT,
as systemd does, when a watchdog ping is missing for `watchdog` seconds after READY=1, unless the
process is being stopped on purpose (`stopping()`, as systemd stops judging during ExecStop).
"""

from __future__ import annotations

import contextlib
import itertools
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path


class PlayedSystemd:
    def __init__(self, socket_path: Path, watchdog: float) -> None:
        self.path = socket_path
        self.watchdog = watchdog
        self.heard: list[tuple[float, str]] = []  # (monotonic time, datagram)
        self.fired = threading.Event()
        self._stopping = threading.Event()
        self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._socket.bind(str(socket_path))
        self._socket.settimeout(0.5)
        self._listener: threading.Thread | None = None

    def env(self) -> dict[str, str]:
        """What the manager puts into the service's environment."""
        return {"NOTIFY_SOCKET": str(self.path), "WATCHDOG_USEC": str(int(self.watchdog * 1e6))}

    def watch(self, process: subprocess.Popen[str]) -> None:
        """Listen to `process` until it ends, on a thread of its own."""
        self._listener = threading.Thread(target=self._listen, args=(process,), daemon=True)
        self._listener.start()

    def join(self, timeout: float = 2.0) -> None:
        """Once the process has ended: wait until everything it said has been read (STOPPING=1 included)."""
        if self._listener is not None:
            self._listener.join(timeout)

    def _listen(self, process: subprocess.Popen[str]) -> None:
        last = time.monotonic()
        try:
            while process.poll() is None:
                try:
                    text = self._socket.recv(4096).decode()
                except TimeoutError:
                    text = ""
                now = time.monotonic()
                if text:
                    self.heard.append((now, text))
                if "WATCHDOG=1" in text.split("\n"):
                    last = now
                elif (self.ready and now - last > self.watchdog and not self._stopping.is_set()
                      and not self.fired.is_set()):
                    self.fired.set()  # WatchdogSec: the service is ended with SIGABRT
                    process.send_signal(signal.SIGABRT)
            self._socket.setblocking(False)  # what it said just before it ended is still queued: read it too
            with contextlib.suppress(BlockingIOError):
                while True:
                    self.heard.append((time.monotonic(), self._socket.recv(4096).decode()))
        finally:
            self._socket.close()

    def stopping(self) -> None:
        """The process is being stopped on purpose: a missing ping is no longer the watchdog's business."""
        self._stopping.set()

    def said(self, word: str) -> bool:
        return any(word in text.split("\n") for _, text in self.heard)

    @property
    def ready(self) -> bool:
        return self.said("READY=1")

    @property
    def pings(self) -> list[float]:
        return [t for t, text in self.heard if "WATCHDOG=1" in text.split("\n")]

    @property
    def longest_gap(self) -> float:
        """The longest time between two pings (or from READY=1 to the first), in seconds."""
        start = [t for t, text in self.heard if "READY=1" in text.split("\n")][:1]
        return max((q - p for p, q in itertools.pairwise(start + self.pings)), default=0.0)
