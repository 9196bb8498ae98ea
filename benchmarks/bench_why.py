"""`vstig why` on a 1,000,000-message capture: reading it once beside analyze reading the same file (goal: at
most 1x analyze's time), then each question's time once read (goal: under 2 s).

The capture is bench_analyze's swarm at work (64 robots, 200 keys, a new write every 500 frames), written
as a candump log and as our serial line capture (what `bridge --record` writes), one frame per line.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable, Iterator

from vstig_hw.analysis import Analyzer
from vstig_hw.capture.analyzefile import analyze_captures
from vstig_hw.capture.trace import read_trace
from vstig_hw.capture.why import explain

from .bench_analyze import _write_swarm_log
from .registry import Result, benchmark

_MESSAGES = 1_000_000
_QUESTIONS = 20  # keys asked about, each for every sender and for one


def _as_serial_capture(log: str, path: str) -> None:
    """The candump log's frames as cobs8 lines of our serial capture (the frames' 8 bytes, COBS-framed)."""
    from vstig_hw.framing.cobs8 import Cobs8Framing
    from vstig_hw.wire import decode

    framing = Cobs8Framing()
    with open(log) as source, open(path, "w") as out:
        out.write("# vstig serial capture v1\n")
        for line in source:
            stamp, _bus, frame = line.split()
            sender = int(frame[:3], 16) & 0xFF
            (unit,) = framing.encode(decode(bytes.fromhex(frame[4:])))
            out.write(f"{stamp} radio{sender % 8} cobs8 rx {unit.hex()}\n")


def _timed(call: Callable[[], object]) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def _figures(path: str, name: str) -> Iterator[Result]:
    analyzing = _timed(lambda: analyze_captures([path], Analyzer()))
    start = time.perf_counter()
    trace = read_trace([path])
    reading = time.perf_counter() - start
    keys = sorted(trace.keys, key=lambda k: -trace.count(k))[:_QUESTIONS]
    sender = trace.senders[len(trace.senders) // 2]
    slowest = 0.0
    for key in keys:
        slowest = max(slowest, _timed(lambda key=key: explain(trace, key)),  # type: ignore[misc]
                      _timed(lambda key=key: explain(trace, key, sender, at=trace.end / 2)))  # type: ignore[misc]
    yield Result(f"cli.why_read_{name}", reading, "s", "analyze reading the same capture", analyzing)
    yield Result(f"cli.why_question_{name}", slowest, "s", "the 2 s goal", 2.0)


@benchmark("cli")
def why_capture() -> Iterator[Result]:
    with tempfile.TemporaryDirectory() as tmp:
        log, cap = os.path.join(tmp, "swarm.log"), os.path.join(tmp, "swarm.cap")
        _write_swarm_log(log, _MESSAGES)
        _as_serial_capture(log, cap)
        yield from _figures(cap, "serial")
        yield from _figures(log, "candump")
