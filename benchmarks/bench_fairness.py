"""A fair share for every source (issue 33): robot A -> robot B through a gateway with default options while a
participant floods it, beside the same run without the flood.

Robot A and robot B are each on a cobs8 pty radio of the gateway; A writes 200 new keys at 20 a second and B's far
end notes when each arrived. The floods (tests/cli/attacks.py, the same the tests play):

* (a) a local Zenoh session on the gateway's zenoh link, 20,000 distinct-key messages a second in samples of 64;
* (b) a third radio, 850 distinct-key PUTs a second (within a 115,200-baud radio);
* (c) a node on a CAN bus of the gateway (python-can's virtual bus, so that gateway is a Node built as `vstig
  bridge` builds it, in a process of its own), 8,000 distinct-key frames a second (a full 1 Mbit/s bus).

The goal with default options: p99 <= 250 ms and <= 2x the run without the flood, every honest write delivered.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from .registry import Result, benchmark

_REPO = Path(__file__).resolve().parents[1]
COUNT = 200  # robot A's writes per run, at 20 a second


def _run(flooded: bool, gateway: Callable[[Any, Any, bool], contextlib.AbstractContextManager[Any]]
         ) -> list[float | None]:
    """A -> B delays through `gateway(a, b, flooded)`, which starts the gateway (and the flood) and stops it."""
    from attacks import Radio, honest_delays, wait_until_relaying

    a, b = Radio(), Radio()
    try:
        with gateway(a, b, flooded):
            wait_until_relaying(a, b)
            if flooded:
                import time

                time.sleep(1.0)  # the flood fills every outlet first
            return honest_delays(a, b, count=COUNT)
    finally:
        a.close()
        b.close()


@contextlib.contextmanager
def _zenoh(a: Any, b: Any, flooded: bool) -> Iterator[None]:
    from attacks import Bridge, zenoh_flood

    from vstig_hw.links.zenoh import _free_loopback_port

    endpoint = f"tcp/127.0.0.1:{_free_loopback_port()}"
    with Bridge(a.spec, b.spec, f"zenoh:lab?listen={endpoint}"), \
            zenoh_flood(endpoint) if flooded else contextlib.nullcontext():
        yield


@contextlib.contextmanager
def _radio(a: Any, b: Any, flooded: bool) -> Iterator[None]:
    from attacks import Bridge, Radio, RadioFlood

    hostile = Radio()
    try:
        with Bridge(a.spec, b.spec, hostile.spec), RadioFlood(hostile) if flooded else contextlib.nullcontext():
            yield
    finally:
        hostile.close()


@contextlib.contextmanager
def _can(a: Any, b: Any, flooded: bool) -> Iterator[None]:
    from attacks import can_flood_bridge

    with can_flood_bridge(a, b, flooded):
        yield


def _results(name: str, gateway: Callable[[Any, Any, bool], contextlib.AbstractContextManager[Any]]
             ) -> Iterator[Result]:
    sys.path.insert(0, str(_REPO / "tests" / "cli"))
    from attacks import quantile

    quiet = _run(False, gateway)
    flooded = _run(True, gateway)
    for label, q in (("p50", 0.5), ("p99", 0.99)):
        yield Result(f"fairness.{name}_a_to_b_{label}", quantile(flooded, q) * 1e3, "ms",
                     f"same gateway, no flood {label}", quantile(quiet, q) * 1e3)
    yield Result(f"fairness.{name}_honest_delivered", sum(d is not None for d in flooded), "writes",
                 "robot A's writes", COUNT)


@benchmark("fairness")
def zenoh_flood() -> Iterator[Result]:
    """(a) a local Zenoh session floods distinct keys."""
    return _results("zenoh_flood", _zenoh)


@benchmark("fairness")
def radio_flood() -> Iterator[Result]:
    """(b) a radio floods distinct keys within its baud."""
    return _results("radio_flood", _radio)


@benchmark("fairness")
def can_flood() -> Iterator[Result]:
    """(c) a CAN node floods distinct keys as fast as its bus carries frames."""
    return _results("can_flood", _can)
