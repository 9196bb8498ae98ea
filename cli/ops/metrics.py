"""`--metrics [HOST:]PORT`: the gateway's counters in Prometheus' text format, on 127.0.0.1 unless a HOST is given.

What a scrape shows (prometheus_client's exposition, from `Node.stats()` read when scraped):

* `vstig_link_events_total{link,counter}`: every counter of every link (in, out, rx, tx, each drop reason...);
* `vstig_engine_outcomes_total{outcome}`: the engine's receive outcomes (stored, answered, stale...);
* `vstig_link_queued{link}`, `vstig_link_up{link}` (1 while its device is connected), `vstig_table_keys`;
* `vstig_relay_latency_seconds`: a histogram, per batch a link read, of the time from the read to what it caused
  being handed to the other links' devices (written, or queued behind a slow one);
* `vstig_clock_offset_seconds{peer}` and `..._error_seconds{peer}`: each Zenoh peer's clock against ours;
* `vstig_metrics_connections_total{outcome}`: the endpoint's own (served, evicted, timed_out, too_large).

The endpoint is never in the data path and never stalls the gateway: one thread serves it without blocking
(selectors), holds at most MAX_CONNECTIONS at once (a new one evicts the oldest that has not asked yet), gives
each CONNECTION_DEADLINE_S to ask and read its answer, reads requests of at most REQUEST_MAX_BYTES, and renders
the page at most once per RENDER_EVERY_S however often it is asked. The latency histogram is counted under the
Node's lock in a few list operations; prometheus_client only formats the page.
"""

from __future__ import annotations

import bisect
import collections
import contextlib
import selectors
import socket
import threading
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import click

from vstig_hw import __version__
from vstig_hw.counters import ENGINE_STATS, Counters
from vstig_hw.extras import MissingExtra, require

from ..options import LOOPBACK, Address, is_loopback, listen_address

if TYPE_CHECKING:
    from vstig_hw.gateway import Node

__all__ = ["LATENCY_BUCKETS", "MetricsServer", "RelayLatency", "metrics_option", "metrics_served"]

DOCS = "docs/how-to/service.md"
MAX_CONNECTIONS = 32  # a Prometheus server or two, a curl: far fewer at once
CONNECTION_DEADLINE_S = 5.0  # from accept to the last byte of the answer
REQUEST_MAX_BYTES = 8 * 1024  # a scrape's request is a few hundred bytes
RENDER_EVERY_S = 0.5  # scrapes closer than this share one page: a scraper in a loop costs the gateway little
LATENCY_BUCKETS = (0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0)


def _address(ctx: click.Context, param: click.Parameter, value: str | None) -> Address | None:
    if value is None:
        return None
    address = listen_address(value, ctx, param)
    try:
        require("metrics", "--metrics")  # before any link opens: one line, exit 1
    except MissingExtra as error:
        raise click.ClickException(str(error)) from None
    return address


metrics_option = click.option(
    "--metrics", metavar="[HOST:]PORT", callback=_address,
    help=f"Serve Prometheus metrics (every counter, table size, link states, relay latency) at "
         f"http://HOST:PORT/metrics, on {LOOPBACK} unless HOST is given. Needs the metrics extra. See {DOCS}.")


class RelayLatency:
    """A histogram of read-to-handed-over times, counted on the Node's threads under its lock (no lock of its own)."""

    def __init__(self, bounds: tuple[float, ...] = LATENCY_BUCKETS) -> None:
        self.bounds = bounds
        self.counts = [0] * (len(bounds) + 1)  # the last: above every bound
        self.total = 0.0

    def observe(self, read_at: float) -> None:
        """A batch read at `read_at` (wall clock, as the readers stamp it) was just handed over."""
        seconds = max(0.0, time.time() - read_at)
        self.counts[bisect.bisect_left(self.bounds, seconds)] += 1
        self.total += seconds

    def buckets(self) -> list[tuple[str, int]]:
        """Cumulative (upper bound, count) pairs, +Inf last, as Prometheus' histogram has them."""
        running, out = 0, []
        for bound, count in zip((*map(repr, self.bounds), "+Inf"), self.counts, strict=True):
            running += count
            out.append((bound, running))
        return out


class GatewayCollector:
    """prometheus_client's custom collector over one Node: everything read when scraped, nothing kept."""

    def __init__(self, node: Node, latency: RelayLatency, connections: Counters) -> None:
        self.node = node
        self.latency = latency
        self.connections = connections

    def collect(self) -> Iterator[Any]:
        from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily

        node = self.node
        with node.lock:  # one consistent view: the readers count under it
            stats = node.stats()
            keys = node.engine.size() if node.engine is not None else None
            up = {link.name: bool(getattr(link.transport, "connected", True)) for link in node.links}
            buckets, total = self.latency.buckets(), self.latency.total
        clocks = {peer: trip for link in node.links if (clock := getattr(link.transport, "clock", None)) is not None
                  for peer, trip in clock.estimates().items()}
        events = CounterMetricFamily("vstig_link_events", "Every counter of every link: units and messages moved, "
                                     "each drop by reason (docs/reference/counters.md).", labels=["link", "counter"])
        queued = GaugeMetricFamily("vstig_link_queued", "Units waiting in a link's outgoing queues.", labels=["link"])
        for name, counters in stats.items():
            if name == ENGINE_STATS:
                continue
            moved = {"in": 0, "out": 0, **counters}  # in and out from the start: rate() needs a first sample
            for counter, value in sorted(moved.items()):
                if counter != "queued":
                    events.add_metric([name, counter], value)
            queued.add_metric([name], counters.get("queued", 0))
        yield events
        yield queued
        outcomes = CounterMetricFamily("vstig_engine_outcomes", "The engine's receive outcomes (SPEC section 4).",
                                       labels=["outcome"])
        for outcome, value in sorted(stats.get(ENGINE_STATS, Counters()).items()):
            outcomes.add_metric([outcome], value)
        yield outcomes
        link_up = GaugeMetricFamily("vstig_link_up", "1 while the link's device is connected.", labels=["link"])
        for name, connected in up.items():
            link_up.add_metric([name], 1.0 if connected else 0.0)
        yield link_up
        if keys is not None:
            yield GaugeMetricFamily("vstig_table_keys", "Keys in the gateway's table.", value=keys)
        yield HistogramMetricFamily("vstig_relay_latency_seconds", "From a batch's read to what it caused being "
                                    "handed to the other links' devices.", buckets=buckets, sum_value=total)
        if clocks:
            offset = GaugeMetricFamily("vstig_clock_offset_seconds", "A Zenoh peer's clock minus ours (the tightest "
                                       "recent round trip).", labels=["peer"])
            bound = GaugeMetricFamily("vstig_clock_offset_error_seconds", "The bound of that offset: half its round "
                                      "trip.", labels=["peer"])
            for peer, trip in sorted(clocks.items()):
                offset.add_metric([peer], trip.offset)
                bound.add_metric([peer], trip.error)
            yield offset
            yield bound
        served = CounterMetricFamily("vstig_metrics_connections", "This endpoint's connections by outcome.",
                                     labels=["outcome"])
        for outcome, value in sorted(self.connections.items()):
            served.add_metric([outcome], value)
        yield served
        info = GaugeMetricFamily("vstig_info", "The gateway: version and mode.", labels=["version", "mode"])
        info.add_metric([__version__, node.mode.value], 1.0)
        yield info


class _Client:
    __slots__ = ("answer", "asked", "deadline", "request", "sock")

    def __init__(self, sock: socket.socket, deadline: float) -> None:
        self.sock = sock
        self.deadline = deadline
        self.request = b""
        self.answer = b""
        self.asked = False  # a whole request came: never evicted for a newcomer


class MetricsServer:
    """The /metrics endpoint on its own thread: non-blocking, bounded in connections, bytes and time."""

    def __init__(self, node: Node, host: str, port: int) -> None:
        from prometheus_client import CollectorRegistry

        self.latency = RelayLatency()
        self.connections = Counters()
        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(GatewayCollector(node, self.latency, self.connections))
        self._node = node
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
        self._thread = threading.Thread(target=self._serve, name="metrics", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/metrics"

    def start(self) -> None:
        self._node.on_delivered.append(self.latency.observe)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        with contextlib.suppress(ValueError):
            self._node.on_delivered.remove(self.latency.observe)
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
            return _response(b"405 Method Not Allowed", b"text/plain", b"GET /metrics\n")
        if path != b"/metrics":
            return _response(b"404 Not Found", b"text/plain", b"the metrics are at /metrics\n")
        self.connections["served"] += 1
        from prometheus_client import CONTENT_TYPE_LATEST

        body = self._render()
        return _response(b"200 OK", CONTENT_TYPE_LATEST.encode(), b"" if method == b"HEAD" else body,
                         len(body))

    def _render(self) -> bytes:
        now = time.monotonic()
        if now - self._rendered_at >= RENDER_EVERY_S:
            from prometheus_client import generate_latest

            self._page = generate_latest(self.registry)
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


@contextlib.contextmanager
def metrics_served(node: Node, address: Address | None) -> Iterator[MetricsServer | None]:
    """Serve `node`'s metrics at `address` for the duration (nothing when None). Enter it before the node opens:
    a port in use or a bad host fails before any link opens."""
    if address is None:
        yield None
        return
    host, port = address
    try:
        server = MetricsServer(node, host, port)
    except OSError as error:
        raise click.ClickException(f"--metrics {host}:{port}: cannot listen: {error.strerror or error}") from None
    if not is_loopback(host):
        click.echo(f"--metrics: WARNING: the metrics listen on {server.url} with no authentication: anyone on the "
                   f"network can read the gateway's counters (the default, {LOOPBACK}, keeps them to this PC; "
                   f"see {DOCS})", err=True)
    click.echo(f"metrics: {server.url}", err=True)
    server.start()
    try:
        yield server
    finally:
        server.close()
