"""CAN -> CAN through a swarm joined with the Python API, beside python-can's own `can.bridge`, on virtual buses.

python-can's virtual bus lives inside one process, so each relay runs in a child of
its own (`python -m benchmarks.bench_can_peer RELAY`) with a sender on bus A and a
receiver on bus B: the sender puts vstig PUT frames (distinct keys, so an engine
relays every one) at a steady pace, the receiver notes each key's first arrival.
Between them one relay: `can.bridge` (python-can 4.6's bridge, built as its `main`
builds it: a Notifier thread per bus, each with a RedirectReader sending on the
other bus) or `api` (`vstig_hw.join` on both buses, as a program would: an engine,
the default guard, no budget and no refresh, so every PUT crosses). That is the path
of every python-can interface that is not SocketCAN (slcan, PCAN, Kvaser, Vector).

Figures per relayed message, each against can.bridge's of the same run, runs
alternated (can.bridge, api, can.bridge, api...) and the median of each:
* CPU: the child's CPU less its sender's and receiver's threads' (schedstat);
* context switches: likewise, voluntary and involuntary;
* instructions, under callgrind (`callgrind_control -e Ir`, every thread but the
  sender's and the receiver's, read once the relay relays and again after the run),
  which a loaded machine cannot move; and those of the thread that relays alone (the
  others wake by the second: under callgrind, ~50x slower, they weigh 50x more a frame).
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can

from .bench_can_relay import PROBE, Arrivals, put_frame
from .registry import Result, benchmark

RELAYS = ("can.bridge", "api")
ROUNDS = 3
COUNT, RATE_HZ = 6000, 2000  # the CPU runs: 3 s of a busy bus each
# Under callgrind (~50x slower, one thread at a time) a steady pace would queue frames behind a reader that waits
# its turn, and a relay that drains its queue would count fewer instructions a frame than it spends at full speed:
# there each frame is sent once the one before it arrived (RATE 0: lockstep), so every relay reads one at a time.
COUNT_GRIND, RATE_GRIND_HZ = 600, 0
_REPO = Path(__file__).resolve().parents[1]


def _thread_cpu_ns(tid: int) -> int:
    return int(Path(f"/proc/self/task/{tid}/schedstat").read_text().split()[0])


def _thread_switches(tid: int) -> int:
    status = Path(f"/proc/self/task/{tid}/status").read_text()
    return sum(int(n) for n in re.findall(r"^(?:non)?voluntary_ctxt_switches:\s+(\d+)$", status, flags=re.M))


def _process_switches() -> int:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_nvcsw + usage.ru_nivcsw


def _start_relay(relay: str, a: str, b: str) -> Callable[[], None]:
    """Start `relay` between virtual buses a and b; the call that stops it."""
    if relay == "can.bridge":  # as can.bridge.main builds it
        from can.listener import RedirectReader
        from can.notifier import Notifier

        bus1, bus2 = can.Bus(interface="virtual", channel=a), can.Bus(interface="virtual", channel=b)
        notifiers = [Notifier(bus1, [RedirectReader(bus2)]), Notifier(bus2, [RedirectReader(bus1)])]

        def stop_bridge() -> None:
            for notifier in notifiers:
                notifier.stop()
            bus1.shutdown()
            bus2.shutdown()

        return stop_bridge
    import vstig_hw

    swarm = vstig_hw.join(f"can:virtual:{a}", f"can:virtual:{b}", robot_id=200, budget=None, refresh=False)
    return swarm.close


def child(relay: str, count: int, rate_hz: float) -> None:
    """One relay's run in this process: prints `ready` once it relays, waits for a line, runs `count` frames at
    `rate_hz` (0: each once the one before arrived), prints the figures (JSON), waits for a line, stops (the
    parent reads callgrind's counts at the two waits)."""
    stamp = time.monotonic_ns()
    a, b = f"bench-peer-a-{stamp}", f"bench-peer-b-{stamp}"
    arrivals = Arrivals(b, "virtual")
    sender = can.Bus(interface="virtual", channel=a)
    me = threading.get_native_id()
    stop = _start_relay(relay, a, b)
    try:
        arrivals.relayed(sender, relay, 0.1)
        frames = [put_frame(key) for key in range(count)]
        time.sleep(0.5)
        print("ready", flush=True)
        sys.stdin.readline()
        cpu0, own0 = time.process_time_ns(), _thread_cpu_ns(me) + _thread_cpu_ns(arrivals.tid)
        switches0, own_switches0 = _process_switches(), _thread_switches(me) + _thread_switches(arrivals.tid)
        start = time.perf_counter()
        for key, frame in enumerate(frames):
            if rate_hz > 0:
                delay = start + key / rate_hz - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            elif key:  # lockstep: once the frame before arrived
                while key - 1 not in arrivals.keys:
                    time.sleep(0.0005)
            sender.send(frame)
        end = time.monotonic() + 30
        while len(arrivals.keys - {PROBE}) < count and time.monotonic() < end:
            time.sleep(0.01)
        cpu1, own1 = time.process_time_ns(), _thread_cpu_ns(me) + _thread_cpu_ns(arrivals.tid)
        switches1, own_switches1 = _process_switches(), _thread_switches(me) + _thread_switches(arrivals.tid)
        delivered = len(arrivals.keys - {PROBE})
        print(json.dumps({"cpu_us": ((cpu1 - cpu0) - (own1 - own0)) / 1e3 / count,
                          "switches": ((switches1 - switches0) - (own_switches1 - own_switches0)) / count,
                          "delivered": delivered / count}), flush=True)
        sys.stdin.readline()
    finally:
        stop()
        arrivals.close()
        sender.shutdown()


def _instructions(pid: int, skip: int = 2) -> dict[int, int]:
    """Instructions callgrind counted so far in `pid`, by thread, every thread's but the first `skip` (sender,
    receiver)."""
    shown = subprocess.run(["callgrind_control", "-e", "Ir", str(pid)], capture_output=True, text=True,
                           timeout=120, check=True).stdout
    threads = re.findall(r"^\s*Th\s+(\d+)\s+([\d,]+)\s*$", shown, flags=re.M)
    if not threads:
        raise RuntimeError(f"callgrind_control showed no Ir for {pid}: {shown}")
    return {int(number): int(count.replace(",", "")) for number, count in threads if int(number) > skip}


def run_one(relay: str, *, grind: bool = False, env: dict[str, str] | None = None) -> dict[str, float]:
    """One relay's figures from a child of its own (under callgrind when `grind`: then `instructions` too)."""
    count, rate_hz = (COUNT_GRIND, RATE_GRIND_HZ) if grind else (COUNT, RATE_HZ)
    argv = [sys.executable, "-m", "benchmarks.bench_can_peer", relay, str(count), str(rate_hz)]
    with tempfile.TemporaryDirectory(prefix="vstig-bench-can-peer-") as tmp:
        if grind:
            argv = ["valgrind", "-q", "--tool=callgrind", f"--callgrind-out-file={tmp}/callgrind.%p", *argv]
        process = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=_REPO,
                                   env={**os.environ, **(env or {})})
        assert process.stdin is not None and process.stdout is not None
        try:
            if process.stdout.readline().strip() != "ready":
                raise RuntimeError(f"{relay}: the child did not start relaying")
            before = _instructions(process.pid) if grind else {}
            process.stdin.write("go\n")
            process.stdin.flush()
            figures: dict[str, float] = json.loads(process.stdout.readline())
            if grind:  # every thread of the relay's, and the one that relays (the rest wait: per second, not frame)
                spent = [n - before.get(thread, 0) for thread, n in _instructions(process.pid).items()]
                figures["instructions"] = sum(spent) / count
                figures["relaying_thread_instructions"] = max(spent) / count
            process.stdin.write("stop\n")
            process.stdin.flush()
            process.wait(120)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
    return figures


def alternated(rounds: int = ROUNDS, *, grind: bool = False,
               envs: dict[str, dict[str, str]] | None = None) -> dict[str, list[dict[str, float]]]:
    """Each relay's figures, `rounds` times, in alternating order; `envs`: more relays, by name, each the API
    relay under that environment (e.g. VSTIG_PURE=1)."""
    kinds: dict[str, tuple[str, dict[str, str]]] = {name: (name, {}) for name in RELAYS}
    for name, env in (envs or {}).items():
        kinds[name] = ("api", env)
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in kinds}
    for _ in range(rounds):
        for name, (relay, env) in kinds.items():
            runs[name].append(run_one(relay, grind=grind, env=env))
    return runs


def _median(runs: list[dict[str, float]], figure: str) -> float:
    return statistics.median(run[figure] for run in runs)


@benchmark("can_peer")
def api_relay_against_can_bridge() -> Iterator[Result]:
    runs = alternated(envs={"api_pure": {"VSTIG_PURE": "1"}})
    anchor = runs["can.bridge"]
    for name in ("api", "api_pure"):
        yield Result(f"can_peer.{name}_cpu_per_msg", _median(runs[name], "cpu_us"), "us",
                     "can.bridge CPU/msg", _median(anchor, "cpu_us"))
        yield Result(f"can_peer.{name}_switches_per_msg", _median(runs[name], "switches"), "switches",
                     "can.bridge switches/msg", _median(anchor, "switches"))
        yield Result(f"can_peer.{name}_delivered", _median(runs[name], "delivered") * 100, "%",
                     "can.bridge delivered", _median(anchor, "delivered") * 100)
    if shutil.which("valgrind") is None:
        print("can_peer: instructions need valgrind (apt-get install valgrind)", file=sys.stderr)
        return
    grind = alternated(1, grind=True)
    yield Result("can_peer.api_instructions_per_msg", _median(grind["api"], "instructions"), "instr",
                 "can.bridge instr/msg", _median(grind["can.bridge"], "instructions"))
    yield Result("can_peer.api_relaying_thread_instructions_per_msg",
                 _median(grind["api"], "relaying_thread_instructions"), "instr", "can.bridge's instr/msg",
                 _median(grind["can.bridge"], "relaying_thread_instructions"))


def _print(runs: dict[str, list[dict[str, Any]]]) -> None:
    for name, figures in runs.items():
        print(name, json.dumps(figures))


if __name__ == "__main__":  # python -m benchmarks.bench_can_peer RELAY COUNT RATE (a child), or nothing: a run
    if len(sys.argv) == 4:
        child(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))
    else:
        _print(alternated(int(os.environ.get("ROUNDS", ROUNDS)), grind=bool(os.environ.get("GRIND"))))
