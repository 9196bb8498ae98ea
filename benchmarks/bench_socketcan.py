"""`vstig record` on a saturated SocketCAN bus, beside candump recording the same bus.

cangen sends classic 8-byte frames on vcan0 as fast as a 1 Mbit/s bus carries them
(a 111-bit frame every 111 us: about 9,000 frames/s, sent 90 every 10 ms, since a
guest cannot sleep 111 us; a guest oversleeps, so the rate reached is printed), then a
5,000-frame burst with no gap at all (`cangen -g 0`, faster than any 1 Mbit/s bus);
candump and `vstig record` both capture each. The figure is the share of sent frames
in our file, the anchor candump's share. vcan exists only inside User-Mode Linux here (tests/socketcan/uml.py),
so the run boots a guest unless this host has vcan0; a guest's system calls are
slow, so both figures there are lower than on real hardware.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .guest import run_in_guest
from .registry import Result, benchmark

# name: (frames, cangen gap in ms, frames per gap)
_LOADS = {"paced as 1 Mbit/s (9,000 frames/s asked)": (9_000, 10.0, 90), "burst, no gap": (5_000, 0.0, 1)}
_CHANNEL = "vcan0"
_REPO = Path(__file__).resolve().parents[1]


def _count(path: Path) -> int:
    with open(path, "rb") as file:
        return sum(1 for line in file if line.strip())


def _wait_until_still(path: Path, seconds: float = 60.0) -> None:
    """Until the file has not grown for a second (or `seconds` pass)."""
    sizes = [-1]
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and (len(sizes) < 3 or sizes[-1] != sizes[-3]):
        time.sleep(0.5)
        sizes.append(path.stat().st_size if path.exists() else 0)


def guest(out: Path, name: str, frames: int, gap_ms: float, per_gap: int) -> dict[str, float]:
    """Record one cangen run with candump and `vstig record` on this machine's vcan0."""
    vstig = str(Path(sys.executable).with_name("vstig"))
    stem = re.sub(r"\W+", "-", name)
    ours, theirs = out / f"vstig-{stem}.log", out / f"candump-{stem}.log"
    with open(theirs, "wb") as candump_out:
        candump = subprocess.Popen(["candump", "-L", _CHANNEL], stdout=candump_out)
        record = subprocess.Popen([vstig, "record", f"can:socketcan:{_CHANNEL}", "-o", str(ours)],
                                  stderr=subprocess.PIPE, text=True)
        try:
            assert record.stderr is not None
            started = record.stderr.readline()  # "recording ..." once the link is open
            if not started.startswith("recording"):
                raise RuntimeError(f"vstig record did not start: {started}")
            time.sleep(0.5)
            began = time.monotonic()
            subprocess.run(["cangen", _CHANNEL, "-g", str(gap_ms), "-c", str(per_gap), "-n", str(frames),
                            "-I", "601", "-L", "8", "-D", "i", "-p", "100"], check=True, timeout=120)
            sent_in = time.monotonic() - began
            _wait_until_still(ours)  # both have read their queues dry (ours is the slower to write)
            time.sleep(0.5)
        finally:
            for process in (candump, record):
                process.send_signal(signal.SIGINT)
            candump.wait(30)
            _, summary = record.communicate(timeout=60)
    dropped = sum(int(n) for n in re.findall(r"(?:kernel_dropped|interface_dropped|unread_at_close)=(\d+)", summary))
    return {"sent": frames, "rate": frames / sent_in, "ours": _count(ours), "candump": _count(theirs),
            "kernel_dropped": dropped}


def _all_loads(out: Path) -> dict[str, dict[str, float]]:
    figures = {}
    for name, load in _LOADS.items():
        print(f"load {name}: {load}", flush=True)
        figures[name] = guest(out, name, *load)
        print(f"load {name}: {figures[name]}", flush=True)
    return figures


@benchmark("socketcan")
def record_saturated_bus() -> list[Result]:
    with tempfile.TemporaryDirectory(prefix="vstig-bench-socketcan-") as tmp:
        out = Path(tmp)
        try:
            loads = _all_loads(out) if Path(f"/sys/class/net/{_CHANNEL}").exists() else \
                run_in_guest("bench_socketcan", out, timeout=240)
        except RuntimeError as error:
            print(f"socketcan.record_saturated_bus: not run: {error}", file=sys.stderr)
            return []
    results = []
    for name, f in loads.items():
        print(f"socketcan {name}: cangen sent {f['sent']:.0f} frames at {f['rate']:,.0f}/s; vstig recorded "
              f"{f['ours']:.0f} (counted as dropped: {f['kernel_dropped']:.0f}), candump {f['candump']:.0f}",
              file=sys.stderr)
        results.append(Result(f"socketcan.record {name} (share of sent frames)", f["ours"] / f["sent"], "share",
                              "candump on the same bus", f["candump"] / f["sent"]))
    return results


if __name__ == "__main__":  # inside the guest: python -m benchmarks.bench_socketcan OUT
    where = Path(sys.argv[1])
    os.chdir(_REPO)
    (where / "figures.json").write_text(json.dumps(_all_loads(where)))
