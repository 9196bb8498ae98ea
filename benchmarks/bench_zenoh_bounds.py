"""What vstig's Zenoh bounds cost local peers: round trips and one-way throughput between two processes on this
PC, with the config a zenoh: link builds (no shared memory, a peer's sample bounded, glibc returning big blocks at
once) beside Zenoh's own defaults, for 64-byte, 4 KiB (a gateway's batch of 512 messages) and 64 KiB samples."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from .registry import Result, benchmark

_ROOT = Path(__file__).parents[1]
SIZES = {64: (2000, 20_000), 4096: (2000, 20_000), 65536: (1000, 5_000)}  # bytes: (round trips, flood samples)


def _measure(setting: str, size: int, pings: int, flood: int) -> dict[str, float]:
    done = subprocess.run([sys.executable, "-m", "benchmarks.zenoh_bounds_peer", "run", setting, str(size),
                           str(pings), str(flood)], capture_output=True, text=True, timeout=600, cwd=_ROOT,
                          check=True)
    return dict(json.loads(done.stdout))


@benchmark("zenoh_bounds")
def local_peer_cost() -> Iterator[Result]:
    for size, (pings, flood) in SIZES.items():
        ours, zenohs = _measure("vstig", size, pings, flood), _measure("zenoh", size, pings, flood)
        for q in ("p50", "p99"):
            yield Result(f"zenoh_bounds.round_trip_{size}B_{q}", ours[q] * 1e6, "us",
                         f"Zenoh's defaults {q}", zenohs[q] * 1e6)
        yield Result(f"zenoh_bounds.throughput_{size}B", ours["rate"], "samples/s", "Zenoh's defaults",
                     zenohs["rate"])
