"""`--metrics [HOST:]PORT`: the gateway's counters in Prometheus' text format, on 127.0.0.1 unless a HOST is given.

What a scrape shows (prometheus_client's exposition, from `Node.stats()` read when scraped):

* `vstig_link_events_total{link,counter}`: every counter of every link (in, out, rx, tx, each drop reason...);
* `vstig_engine_outcomes_total{outcome}`: the engine's receive outcomes (stored, answered, stale...);
* `vstig_link_queued{link}`, `vstig_link_up{link}` (1 while its device is connected), `vstig_table_keys`;
* `vstig_relay_latency_seconds`: a histogram, per batch a link read, of the time from the read to what it caused
  being handed to the other links' devices (written, or queued behind a slow one);
* `vstig_clock_offset_seconds{peer,proved_by}` and `..._error_seconds{...}`: each Zenoh peer's clock against ours
  (at most 64 peers a link: vstig_hw.clocks.MAX_PEERS);
* `vstig_robots{link,state}`: robots the roster holds per link and state (alive, quiet, gone; never one series
  per robot), `vstig_robot_state_changes_total{from,to}`, `vstig_robots_untracked_total` (heard while the roster
  was full); none with --no-roster (docs/how-to/robots.md);
* `vstig_metrics_connections_total{outcome}`: the endpoint's own (served, evicted, timed_out, too_large,
  bad_host, bad_request).

The endpoint is never in the data path and never stalls the gateway: a `PageServer` (page_server.py) serves
it, bounded in connections, bytes and time, to requests whose Host names it (an IP address, localhost, the
listening host, a `--metrics-host NAME`). The latency histogram is counted under the Node's lock in a few
list operations; prometheus_client only formats the page.
"""

from __future__ import annotations

import bisect
import contextlib
import functools
import re
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import click

from vstig_hw import __version__
from vstig_hw.counters import ENGINE_STATS, Counters
from vstig_hw.extras import MissingExtra, require

from ..options import LOOPBACK, Address, is_loopback, listen_address
from .page_server import PageServer

if TYPE_CHECKING:
    from vstig_hw.clocks import ClockOffset
    from vstig_hw.gateway.node import Listening, Node

__all__ = ["LATENCY_BUCKETS", "MetricsServer", "RelayLatency", "metrics_option", "metrics_served"]

DOCS = "docs/how-to/service.md"
_NAMES = "vstig.metrics.names"  # ctx.meta: the --metrics-host names, for metrics_served
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


_HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,252})")


def _names(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> tuple[str, ...]:
    for value in values:
        if not _HOST_NAME.fullmatch(value):
            raise click.BadParameter(f"{value[:80]!r} is not a host name (e.g. gateway.lab)", ctx, param)
    return values


def metrics_option(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Add --metrics (the command receives it as `metrics`) and --metrics-host (kept for `metrics_served`)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, metrics_names: tuple[str, ...], **kwargs: Any) -> Any:
        click.get_current_context().meta[_NAMES] = metrics_names
        return fn(*args, **kwargs)

    wrapper = click.option(
        "--metrics-host", "metrics_names", multiple=True, metavar="NAME", callback=_names,
        help="Also answer scrapes that call this PC NAME (their Host header); IP addresses, localhost and the "
             "--metrics HOST always are, any other name is refused (421) against DNS rebinding. Repeatable.")(wrapper)
    return click.option(
        "--metrics", metavar="[HOST:]PORT", callback=_address,
        help=f"Serve Prometheus metrics (every counter, table size, link states, relay latency) at "
             f"http://HOST:PORT/metrics, on {LOOPBACK} unless HOST is given. Needs the metrics extra. "
             f"See {DOCS}.")(wrapper)


class RelayLatency:
    """A histogram of read-to-handed-over times, counted on the Node's threads under its lock (no lock of its own:
    a scrape reads the fixed list as it is, at worst one batch ahead in a bucket of the sum)."""

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
        stats = node.stats()  # one consistent view of the counters: the Node takes them under its lock
        keys = node.engine.size() if node.engine is not None else None
        up = {link.name: link.connected for link in node.links}
        buckets, total = self.latency.buckets(), self.latency.total
        clocks = _clock_estimates(node)
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
                                       "recent round trip); proved_by: the certificate that proved who answered, "
                                       "empty if none did.", labels=["peer", "proved_by"])
            bound = GaugeMetricFamily("vstig_clock_offset_error_seconds", "The bound of that offset: half its round "
                                      "trip.", labels=["peer", "proved_by"])
            for (peer, proof), trip in sorted(clocks.items()):
                offset.add_metric([peer, proof], trip.offset)
                bound.add_metric([peer, proof], trip.error)
            yield offset
            yield bound
        yield from _robot_families(node)
        served = CounterMetricFamily("vstig_metrics_connections", "This endpoint's connections by outcome.",
                                     labels=["outcome"])
        for outcome, value in sorted(self.connections.items()):
            served.add_metric([outcome], value)
        yield served
        info = GaugeMetricFamily("vstig_info", "The gateway: version and mode.", labels=["version", "mode"])
        info.add_metric([__version__, node.mode.value], 1.0)
        yield info


def _robot_families(node: Node) -> Iterator[Any]:
    """The roster's series: robots per link and state, state changes, robots it had no room for."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    from vstig_hw.gateway.kept_roster import KeptRoster
    from vstig_hw.gateway.roster import RobotState

    kept = KeptRoster.of(node)
    if kept is None:
        return
    roster = kept.roster
    counts = roster.counts()
    robots = GaugeMetricFamily("vstig_robots", "Robots heard on a link, by state (docs/how-to/robots.md).",
                               labels=["link", "state"])
    for link in node.links:
        for state in RobotState:  # every state from the start: a series that appears late breaks rate()
            robots.add_metric([link.name, state.value], counts.get((link.name, state), 0))
    yield robots
    changes = CounterMetricFamily("vstig_robot_state_changes", "Robots' state changes (alive, quiet, gone).",
                                  labels=["from", "to"])
    for change, value in sorted(roster.changes.items()):
        changes.add_metric(change.split("->"), value)
    yield changes
    yield CounterMetricFamily("vstig_robots_untracked", "Robots heard while the roster was full (--max-robots).",
                              value=roster.untracked)


def _clock_estimates(node: Node) -> dict[tuple[str, str], ClockOffset]:
    """Per peer clock and proof (empty: unproved), the tightest estimate any of the node's Zenoh links has."""
    best: dict[tuple[str, str], ClockOffset] = {}
    for link in node.links:
        clock = link.clock
        for trip in clock.estimates() if clock is not None else ():
            key = (trip.peer, trip.proof or "")
            if key not in best or trip.error < best[key].error:
                best[key] = trip
    return best


class MetricsServer:
    """The /metrics endpoint of one Node: its collector on a PageServer, and the Node's latency hook."""

    def __init__(self, node: Node, host: str, port: int, names: tuple[str, ...] = ()) -> None:
        from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest

        self.latency = RelayLatency()
        self._node = node
        self._listening: Listening | None = None
        self.registry = CollectorRegistry(auto_describe=False)
        self.server = PageServer(host, port, b"/metrics", CONTENT_TYPE_LATEST.encode(),
                                 lambda: generate_latest(self.registry), names)
        self.connections = self.server.connections
        self.registry.register(GatewayCollector(node, self.latency, self.connections))
        self.host, self.port, self.url = self.server.host, self.server.port, self.server.url

    def start(self) -> None:
        self._listening = self._node.listen(delivered=self.latency.observe)
        self.server.start()

    def close(self) -> None:
        self.server.close()
        if self._listening is not None:
            self._listening.cancel()


@contextlib.contextmanager
def metrics_served(node: Node, address: Address | None) -> Iterator[MetricsServer | None]:
    """Serve `node`'s metrics at `address` for the duration (nothing when None), to the command's --metrics-host
    names too. Enter it before the node opens: a port in use or a bad host fails before any link opens."""
    if address is None:
        yield None
        return
    host, port = address
    ctx = click.get_current_context(silent=True)
    try:
        server = MetricsServer(node, host, port, ctx.meta.get(_NAMES, ()) if ctx is not None else ())
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
