"""The metrics endpoint's cost to the gateway: relay CPU per message with `--metrics` scraped ten times a second,
beside without.

The live view's bench setup (bench_live): an engine bridge between two python-can virtual buses relays a busy
swarm's traffic. With metrics on, the Node counts each batch into the relay latency histogram (a `delivered` listener)
and a scraper in another process reads /metrics every 100 ms (Prometheus' default is every 15 s: a worst case).
Figures: the gateway process's CPU per message heard (`time.process_time`, the endpoint's thread included).
"""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator

import can

from .bench_live import _frames, engine_bridge, relay
from .registry import Result, benchmark

_N = 20_000
_SCRAPER = """
import sys, time, urllib.request
url = sys.argv[1]
while True:
    try:
        urllib.request.urlopen(url, timeout=2).read()
    except OSError:
        pass
    time.sleep(0.1)
"""


def _relay_cpu(frames: list[can.Message], run: int, metrics: bool) -> float:
    node, sender, drain = engine_bridge(f"bench-metrics-{run}-{metrics}")
    server = scraper = None
    try:
        if metrics:
            from vstig_cli.ops.metrics import MetricsServer

            server = MetricsServer(node, "127.0.0.1", 0)
            server.start()
            scraper = subprocess.Popen([sys.executable, "-c", _SCRAPER, server.url])
            while not server.connections["served"]:
                time.sleep(0.05)
        with node:
            start = time.process_time()
            relay(node, sender, drain, frames)
            spent = time.process_time() - start
        return spent / len(frames)
    finally:
        if scraper is not None:
            scraper.kill()
            scraper.wait()
        if server is not None:
            server.close()
        sender.shutdown()
        drain.shutdown()


@benchmark("metrics")
def relay_cpu() -> Iterator[Result]:
    """Best of five runs each, alternated, so both see the same machine."""
    frames = _frames(_N)
    without, scraped = [], []
    for run in range(5):
        without.append(_relay_cpu(frames, run, metrics=False))
        scraped.append(_relay_cpu(frames, run, metrics=True))
    yield Result("metrics.gateway process CPU/msg, --metrics scraped at 10 Hz", min(scraped) * 1e6, "us",
                 "without --metrics", min(without) * 1e6)
