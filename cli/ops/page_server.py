"""A server of one page over HTTP/1.1 that nobody can hold up: the metrics endpoint's (`--metrics`).

One thread serves it without blocking (selectors): it holds at most MAX_CONNECTIONS at once, gives each
ASK_WITHIN_S to send its request and CONNECTION_DEADLINE_S in all, reads requests of at most REQUEST_MAX_BYTES,
answers one request per connection and renders the page at most once per RENDER_EVERY_S however often it is
asked. A crowd of connections that do not ask (or ask a byte at a time) cannot keep an honest scraper out: what
a connection sent is read as soon as it is accepted and again before it is evicted, a whole request is answered
at once from the page rendered last, and a newcomer evicts the oldest that has not asked (else the oldest still
being answered).

Only requests that name this server answer (DNS rebinding: a web page whose name an attacker points at
127.0.0.1 makes the browser send that name): a Host that is an IP address, `localhost`, the host it listens on
or one of the `names` it is given, with any port; any other gets 421 (counted bad_host). Empty lines before
the request line are skipped (RFC 9112 section 2.2).
"""

from __future__ import annotations

import collections
import contextlib
import ipaddress
import selectors
import socket
import threading
import time
from collections.abc import Callable, Iterable

from vstig_hw.counters import Counters

__all__ = ["ASK_WITHIN_S", "CONNECTION_DEADLINE_S", "MAX_CONNECTIONS", "PageServer"]

MAX_CONNECTIONS = 32  # a Prometheus server or two, a curl: far fewer at once
ASK_WITHIN_S = 2.0  # from accept to the whole request: a scraper sends it in one packet
CONNECTION_DEADLINE_S = 5.0  # from accept to the last byte of the answer
BACKLOG = 1024  # connections the kernel holds for us: a crowd of 200 leaves room for the scraper behind it
REQUEST_MAX_BYTES = 8 * 1024  # a scrape's request is a few hundred bytes
RENDER_EVERY_S = 0.5  # requests closer than this share one page: a client in a loop costs the process little


class _Client:
    __slots__ = ("accepted", "answer", "asked", "deadline", "request", "sock")

    def __init__(self, sock: socket.socket, now: float) -> None:
        self.sock = sock
        self.deadline = now + ASK_WITHIN_S  # then CONNECTION_DEADLINE_S from accept, once it asked
        self.accepted = now
        self.request = b""
        self.answer = b""
        self.asked = False  # a whole request came: never evicted for a newcomer


class PageServer:
    """One page (`render()`, bytes of `content_type`) at `path`, served on its own thread: non-blocking,
    bounded in connections, bytes and time; `connections` counts them by outcome. `names`: host names beyond
    IP addresses, localhost and `host` that requests may give as their Host."""

    def __init__(self, host: str, port: int, path: bytes, content_type: bytes, render: Callable[[], bytes],
                 names: Iterable[str] = ()) -> None:
        self.connections = Counters()
        self._names = {_bare(name) for name in ("localhost", host, *names)}
        self._path, self._content_type, self._render_page = path, content_type, render
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, _, _, _, where = infos[0]
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind(where)
            self._listener.listen(BACKLOG)
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
            newcomers = False
            for key, events in self._selector.select(timeout=0.2):
                if key.fileobj is self._listener:
                    newcomers = True  # after what the connections we hold sent: they are read before any eviction
                    continue
                client = self._clients.get(key.fd)
                if client is not None:
                    self._read(client) if events & selectors.EVENT_READ else self._write(client)
            if newcomers:
                self._accept()
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
            client = _Client(sock, time.monotonic())
            self._clients[sock.fileno()] = client
            self._selector.register(sock, selectors.EVENT_READ)
            self._read(client)  # a scraper's request is usually there already: answered, it takes no room
            if len(self._clients) > MAX_CONNECTIONS:
                self._evict()

    def _evict(self) -> None:
        """Drop the oldest connection that has not asked, once a last read shows it still has not (else the
        oldest still being answered): the newest stays, so one that asks soon after connecting gets its page."""
        for client in [c for c in self._clients.values() if not c.asked]:
            self._read(client)
            if len(self._clients) <= MAX_CONNECTIONS:
                return  # it asked and was answered, or hung up: room enough
            if not client.asked:
                self.connections["evicted"] += 1
                self._drop(client)
                return
        self.connections["evicted"] += 1
        self._drop(next(iter(self._clients.values())))

    def _read(self, client: _Client) -> None:
        if client.asked:
            return
        try:
            data = client.sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(client)
            return
        if len(client.request) + len(data) > REQUEST_MAX_BYTES:  # empty lines before the request count too
            self.connections["too_large"] += 1
            self._drop(client)
            return
        client.request += data
        head = client.request.lstrip(b"\r\n")
        if b"\r\n\r\n" not in head and b"\n\n" not in head:
            return
        client.asked = True
        client.deadline = client.accepted + CONNECTION_DEADLINE_S
        client.answer = self._answer(head)
        self._selector.modify(client.sock, selectors.EVENT_WRITE)
        self._write(client)

    def _answer(self, request: bytes) -> bytes:
        lines = request.split(b"\n")
        words = lines[0].split()
        hosts = [value.strip() for name, colon, value in (line.partition(b":") for line in lines[1:])
                 if colon and name.strip().lower() == b"host"]
        if len(words) != 3 or not words[2].startswith(b"HTTP/") or len(hosts) > 1 or (
                not hosts and words[2] != b"HTTP/1.0"):  # HTTP/1.1 requires one Host (RFC 9112 section 3.2)
            self.connections["bad_request"] += 1
            return _response(b"400 Bad Request", b"text/plain", b"GET " + self._path + b" HTTP/1.1, with a Host\n")
        if hosts and not self._names_us(hosts[0]):
            self.connections["bad_host"] += 1
            return _response(b"421 Misdirected Request", b"text/plain", b"not a name of this server (--metrics-host "
                             b"NAME adds one)\n")
        method, path = words[0], words[1].split(b"?", 1)[0]
        if method not in (b"GET", b"HEAD"):
            return _response(b"405 Method Not Allowed", b"text/plain", b"GET " + self._path + b"\n")
        if path != self._path:
            return _response(b"404 Not Found", b"text/plain", b"see " + self._path + b"\n")
        self.connections["served"] += 1
        body = self._render()
        return _response(b"200 OK", self._content_type, b"" if method == b"HEAD" else body, len(body))

    def _names_us(self, host: bytes) -> bool:
        """Whether a Host header names this server: an IP address (no DNS to rebind), or one of our names."""
        text = host.decode("ascii", "replace").lower()
        if text.startswith("["):
            address = text[1:].partition("]")[0]
        else:
            address = text.rpartition(":")[0] if text.count(":") == 1 else text
        try:
            ipaddress.ip_address(address)
            return True
        except ValueError:
            return _bare(address) in self._names

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


def _bare(name: str) -> str:
    """A host name as Host headers are compared: lower case, no brackets, no trailing dot."""
    return name.lower().strip("[]").rstrip(".")


def _response(status: bytes, content_type: bytes, body: bytes, length: int | None = None) -> bytes:
    return (b"HTTP/1.1 " + status + b"\r\nContent-Type: " + content_type + b"\r\nContent-Length: "
            + str(len(body) if length is None else length).encode() + b"\r\nConnection: close\r\n\r\n" + body)
