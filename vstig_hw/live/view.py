"""The live view, the gateway's side: hand what it hears to the live view's server process, never waiting.

`sniff/bridge --foxglove` serve Foxglove (docs/how-to/live-view.md). The server (`server`: the
SDK, CDR, the table, each write's spread, JSON) runs in a process of its own, so its Python work never
takes the GIL from the gateway's loop. The loop pays one call per unit heard (a `messages` listener) and
a bounded `deque` append (full: counted `drop_behind`, never a wait); a thread ships what piled up to
the server through a pipe every PUMP seconds (a slow server blocks that thread only, and the inbox
then fills and drops). Counters reach the server at most `rate` times a second; the roster kept for the
node (`KeptRoster.of`), as the /vstig/robots message, once a second, snapshot in that thread, not the loop.
"""

from __future__ import annotations

import collections
import contextlib
import json
import logging
import os
import select
import subprocess
import sys
import threading
import time
from typing import IO, Any

from ..counters import Counters
from ..gateway.kept_roster import KeptRoster
from ..gateway.node import Listening, Node
from ..gateway.roster_message import robots_message
from ..links.link import Heard
from ..values import ValueType
from ..wire import Message
from .server import BACKLOG, FRAME, LINK_RATE, LIVE_STATS, RECORD, VIEWERS, strict_json

__all__ = ["DEFAULT_PORT", "LIVE_STATS", "VIEWERS", "LiveView"]

log = logging.getLogger(__name__)

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
INBOX = 65_536  # units heard and not yet shipped: ~1 s of a saturated gateway
PUMP = 0.05  # seconds between two shipments: a message reaches Foxglove within ~50 ms
START = 30.0  # seconds the server may take to start (import the SDK, bind)
CLOSE_WAIT = 1.0  # seconds a stop gives the server to take what is left and say its counters
ROBOTS_EVERY = 1.0  # seconds between two /vstig/robots messages

Unit = tuple[str, float, "int | None", list[Message], "str | None"]  # link, heard at, sender, messages, refused


class LiveView:
    """Serve `node`'s traffic on host:port until `close()`; `open()` first (binding may fail: RuntimeError)."""

    def __init__(self, node: Node, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *,
                 value_type: ValueType = "uint16", larger_value_wins: bool = False, rate: float = 10.0,
                 inbox: int = INBOX, backlog: int | None = None, link_rate: float | None = None,
                 viewers: int = VIEWERS) -> None:
        self.node = node
        self.host, self.port = host, port
        self._kept = KeptRoster.of(node)  # None: the gateway keeps no roster (--no-roster), no /vstig/robots
        self._next_robots = 0.0
        self._config = {"robots": self._kept is not None,
                        "links": [link.name for link in node.links], "host": host, "value_type": value_type,
                        "larger_value_wins": larger_value_wins, "backlog": backlog or BACKLOG,
                        "link_rate": link_rate or LINK_RATE, "viewers": viewers}
        self.interval = 1.0 / rate
        self.counters = Counters(drop_behind=0)  # the server's join them on close()
        self._index = {link.name: i for i, link in enumerate(node.links)}
        self._capacity = inbox
        self._inbox: collections.deque[Unit] = collections.deque()
        self._stats: dict[str, Any] | None = None
        self._next_stats = 0.0
        self._stop = threading.Event()
        self._shipping = threading.Lock()
        self._thread: threading.Thread | None = None
        self._server: subprocess.Popen[bytes] | None = None
        self._pipe: IO[bytes] | None = None
        self._listening: Listening | None = None

    # -- lifetime -------------------------------------------------------------
    def open(self) -> None:
        config = json.dumps({**self._config, "port": self.port})
        server = subprocess.Popen([sys.executable, "-m", "vstig_hw.live.server", config],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        assert server.stdout is not None and server.stdin is not None
        ready: list[bytes] = []
        reader = threading.Thread(target=lambda: ready.append(server.stdout.readline()), daemon=True)  # type: ignore[union-attr]
        reader.start()
        reader.join(START)
        line = ready[0].decode(errors="replace").strip() if ready else ""
        if not line.startswith("ready "):
            server.kill()
            server.wait()
            raise RuntimeError(line.removeprefix("error ") or f"the live view's server did not start in {START:g} s")
        self.port = int(line.split()[1])
        self._started_cpu = float(line.split()[2])
        self._server, self._pipe = server, server.stdin
        self._listening = self.node.listen(messages=self._heard, refused=self._refused, tick=self._tick)
        self._thread = threading.Thread(target=self._run, name="vstig-live-view", daemon=True)
        self._thread.start()

    def close(self, wait: float = CLOSE_WAIT) -> None:
        """Stop serving: the server gets `wait` seconds to take what is left and say its counters, then it is
        ended. A server flooded by viewers (thousands of connections) may not read us for long: a stop of the
        gateway never waits for it beyond that."""
        if self._listening is not None:
            self._listening.cancel()
        deadline = time.monotonic() + wait
        self._stop.set()  # the pump ships what is left and closes the server's input (see `_run`)
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(wait)
        server, self._server = self._server, None
        if server is None:
            return
        said = _read_until(server, deadline) if thread is None or not thread.is_alive() else b""
        for line in said.decode(errors="replace").splitlines():
            if line.startswith("counters "):
                counters = json.loads(line.removeprefix("counters "))
                self.counters.update({k: v for k, v in counters.items() if isinstance(v, int)})
                self.server_cpu = counters["cpu_seconds"] - self._started_cpu
        try:
            server.wait(max(deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            server.kill()  # also ends a pump stuck writing to it (EPIPE)
            server.wait()
            log.warning("live view: its server did not end within %g s of the stop (flooded by viewers?); "
                        "ended it", wait)
        if thread is not None:
            thread.join(wait)

    server_cpu = 0.0  # CPU seconds the server process spent serving (its start left out), once closed
    _started_cpu = 0.0

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
        if now >= self._next_stats:
            self._next_stats = now + self.interval
            stats: dict[str, Any] = {name: dict(counters) for name, counters in node.stats().items()}
            stats[LIVE_STATS] = dict(self.counters)
            self._stats = stats

    # -- our thread ------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.wait(PUMP):
            self.flush()
        self.flush()  # what is left, then the server's input ends: it says its counters and exits
        pipe, self._pipe = self._pipe, None
        if pipe is not None:
            with contextlib.suppress(OSError):
                pipe.close()

    def flush(self) -> None:
        """Ship what the gateway heard, and the latest counters, to the server now."""
        with self._shipping:
            pipe = self._pipe
            inbox, index, pack = self._inbox, self._index, RECORD.pack
            records: list[bytes] = []
            refused: list[Any] = []
            while inbox:
                link, t, sender, messages, reason = inbox.popleft()
                at, who = index[link], -1 if sender is None else sender
                if reason is None:
                    records.extend([pack(at, t, who, *msg) for msg in messages])
                else:
                    refused.extend([at, t, sender, list(msg), reason] for msg in messages)
            stats, self._stats = self._stats, None
            robots = self._robots_due()
            if pipe is None:  # the server is gone
                self.counters["drop_behind"] += len(records) + len(refused)
                return
            frames = []
            if records:
                data = b"".join(records)
                frames.append(FRAME.pack(b"M", len(data)) + data)
            for kind, item in ((b"R", refused or None), (b"S", stats)):
                if item is not None:
                    data = json.dumps(item).encode()
                    frames.append(FRAME.pack(kind, len(data)) + data)
            if robots is not None:
                frames.append(FRAME.pack(b"B", len(robots)) + robots)
            try:
                pipe.write(b"".join(frames))
                pipe.flush()
            except (BrokenPipeError, OSError, ValueError):  # the server died: the gateway goes on without it
                self._pipe = None
                self.counters["drop_behind"] += len(records) + len(refused)
                if self._stop.is_set():  # ended by close(): it says so itself
                    return
                log.warning("live view: its server process ended; the gateway goes on without it (what it "
                            "hears from now on is counted under live: drop_behind)")

    def _robots_due(self) -> bytes | None:
        """The /vstig/robots message, once every ROBOTS_EVERY seconds while the gateway keeps a roster."""
        now = time.monotonic()
        if self._kept is None or now < self._next_robots:
            return None
        self._next_robots = now + ROBOTS_EVERY
        return strict_json(robots_message(self._kept))


def _read_until(server: subprocess.Popen[bytes], deadline: float) -> bytes:
    """What the server writes on its stdout until it closes it or `deadline` (monotonic) passes."""
    assert server.stdout is not None
    fd, said = server.stdout.fileno(), b""
    while (left := deadline - time.monotonic()) > 0 and select.select([fd], [], [], left)[0]:
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        said += chunk
    return said
