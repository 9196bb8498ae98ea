"""`vstig analyze` of a 1,000,000-frame candump log, beside `vstig decode` of the same file (goal: at least 0.5x).

The log is a swarm at work rather than random words: 64 robots on one bus, 200
keys, a new write every 500 frames, and every robot showing each key's entry a
few writes behind the newest, as gossip spreads it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from .registry import Result, benchmark

_FRAMES = 1_000_000
_ROBOTS = 64
_KEYS = 200
_WRITE_EVERY = 500  # frames between two writes


def _write_swarm_log(path: str, frames: int) -> None:
    newest: dict[int, int] = {}  # key -> newest timestamp written so far
    lines: list[str] = []
    with open(path, "w") as file:
        for i in range(frames):
            if i % _WRITE_EVERY == 0:
                key = (i // _WRITE_EVERY) % _KEYS
                newest[key] = newest.get(key, 0) + 1
            sender = i % _ROBOTS
            key = (i * 7 + sender) % _KEYS
            lag = (i // _ROBOTS + sender) % 3  # this robot is 0-2 writes behind on this key
            ts = max(0, newest.get(key, 0) - lag)
            op = 0 if lag == 0 and ts else 1  # a PUT relays the newest entry, a GET asks with an older one
            writer = (key * 31 + ts) % _ROBOTS if ts else sender
            # The wire words (wire.py's layout), written directly: building Messages would triple the set-up time.
            lines.append(f"({1700000000 + i // 10000}.{(i % 10000) * 100:06d}) can0 {0x600 | op << 8 | sender:03X}#"
                         f"{op << 15 | key:04X}{ts * 3 % 65536:04X}{ts:04X}{writer:04X}\n")
            if len(lines) == 100_000:
                file.writelines(lines)
                lines.clear()
        file.writelines(lines)


def _timed(*args: str) -> float:
    start = time.perf_counter()
    subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - start


@benchmark("cli")
def analyze_candump() -> Iterator[Result]:
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "swarm.log")
        _write_swarm_log(log, _FRAMES)
        vstig = str(Path(sys.executable).with_name("vstig"))
        decode = _timed(vstig, "decode", log, "--format", "jsonl")
        analyze = _timed(vstig, "analyze", log, "--json")
    yield Result("cli.analyze_candump", _FRAMES / analyze, "frames/s", "vstig decode --format jsonl, same file",
                 _FRAMES / decode)
