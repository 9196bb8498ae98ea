"""A server of one page over HTTP/1.1 that nobody can hold up: the metrics endpoint's (`--metrics`).

One thread serves it without blocking (selectors): it holds at most MAX_CONNECTIONS at once (a new one evicts
the oldest that has not asked yet, so an honest client still gets in during a flood), gives each
CONNECTION_DEADLINE_S to ask and read its answer, reads requests of at most REQUEST_MAX_BYTES, answers one
request per connection and renders the page at most once per RENDER_EVERY_S however often it is asked.
"""

from __future__ import annotations

import collections
import contextlib
import selectors
import socket
import threading
import time
from collections.abc import Callable

from vstig_hw.counters import Counters

__all__ = ["CONNECTION_DEADLINE_S", "MAX_CONNECTIONS", "PageServer"]

MAX_CONNECTIONS = 32  # a Prometheus server or two, a curl: far fewer at once
CONNECTION_DEADLINE_S = 5.0  # from accept to the last byte of the answer
REQUEST_MAX_BYTES = 8 * 1024  # a scrape's request is a few hundred bytes
RENDER_EVERY_S = 0.5  # requests closer than this share one page: a client in a loop costs the process little


class _Client:
    __slots__ = ("answer", "asked", "deadline", "request", "sock")

    def __init__(self, sock: socket.socket, deadline: float) -> None:
        self.sock = sock
        self.deadline = deadline
        self.request = b""
        self.answer = b""
        self.asked = False  # a whole request came: never evicted for a newcomer


class PageServer:
    """One page (`render()`, bytes of `content_type`) at `path`, served on its own thread: non-blocking,
    bounded in connections, bytes and time; `connections` counts them by outcome."""

    def __init__(self, host: str, port: int, path: bytes, content_type: bytes, render: Callable[[], bytes]) -> None:
        self.connections = Counters()
        self._path, self._content_type, self._render_page = path, content_type, render
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, _, _, _, where = infos[0]
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind(where)
            self._listener.listen(128)
        except OSError:
            self._listener.close()
            raise
        self._listener.setblocking(False)
        bound = self._listener.getsockname()
        self.host, self.port = host, int(bound[1])
        self._clients: collections.OrderedDict[int, _Client] = collections.OrderedDict()  # oldest first
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._listener, selectors.EVENT_READ)
        self._page = b""
        self._rendered_at = -RENDER_EVERY_S
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="page-server", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}{self._path.decode()}"

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        for client in list(self._clients.values()):
            self._drop(client)
        self._selector.close()
        self._listener.close()

    # -- the thread ---------------------------------------------------------------
    def _serve(self) -> None:
        while not self._stop.is_set():
            for key, events in self._selector.select(timeout=0.2):
                if key.fileobj is self._listener:
                    self._accept()
                else:
                    client = self._clients.get(key.fd)
                    if client is not None:
                        self._read(client) if events & selectors.EVENT_READ else self._write(client)
            now = time.monotonic()
            for client in [c for c in self._clients.values() if c.deadline < now]:
                self.connections["timed_out"] += 1
                self._drop(client)

    def _accept(self) -> None:
        for _ in range(64):  # a burst of connections is taken in, a bounded number per turn
            try:
                sock, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # out of descriptors, a connection reset before we took it: the next turn retries
                return
            sock.setblocking(False)
            if len(self._clients) >= MAX_CONNECTIONS:
                idle = next((c for c in self._clients.values() if not c.asked), None)
                if idle is None:
                    self.connections["evicted"] += 1
                    sock.close()
                    continue
                self.connections["evicted"] += 1
                self._drop(idle)
            client = _Client(sock, time.monotonic() + CONNECTION_DEADLINE_S)
            self._clients[sock.fileno()] = client
            self._selector.register(sock, selectors.EVENT_READ)

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(client)
            return
        client.request += data
        if b"\r\n\r\n" not in client.request and b"\n\n" not in client.request:
            if len(client.request) > REQUEST_MAX_BYTES:
                self.connections["too_large"] += 1
                self._drop(client)
            return
        client.asked = True
        client.answer = self._answer(client.request)
        self._selector.modify(client.sock, selectors.EVENT_WRITE)
        self._write(client)

    def _answer(self, request: bytes) -> bytes:
        method, _, rest = request.partition(b" ")
        path = rest.split(b" ", 1)[0].split(b"?", 1)[0]
        if method not in (b"GET", b"HEAD"):
            return _response(b"405 Method Not Allowed", b"text/plain", b"GET " + self._path + b"\n")
        if path != self._path:
            return _response(b"404 Not Found", b"text/plain", b"see " + self._path + b"\n")
        self.connections["served"] += 1
        body = self._render()
        return _response(b"200 OK", self._content_type, b"" if method == b"HEAD" else body, len(body))

    def _render(self) -> bytes:
        now = time.monotonic()
        if now - self._rendered_at >= RENDER_EVERY_S:
            self._page = self._render_page()
            self._rendered_at = now
        return self._page

    def _write(self, client: _Client) -> None:
        try:
            sent = client.sock.send(client.answer)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._drop(client)
            return
        client.answer = client.answer[sent:]
        if not client.answer:
            self._drop(client)

    def _drop(self, client: _Client) -> None:
        self._clients.pop(client.sock.fileno(), None)
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(client.sock)
        client.sock.close()


def _response(status: bytes, content_type: bytes, body: bytes, length: int | None = None) -> bytes:
    return (b"HTTP/1.1 " + status + b"\r\nContent-Type: " + content_type + b"\r\nContent-Length: "
            + str(len(body) if length is None else length).encode() + b"\r\nConnection: close\r\n\r\n" + body)
