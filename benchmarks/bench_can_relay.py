"""CAN -> CAN relays on SocketCAN: `vstig bridge` beside python-can's own `can.bridge`, in one run.

A sender on vcan0 puts COUNT vstig PUT frames (distinct keys, so an engine relays
every one) at RATE_HZ; a receiver on vcan1 notes each key's first arrival. Between
them one relay at a time, in alternating order: `python -m can.bridge` (python-can
4.6's bridge of two buses: a Notifier thread per bus and a RedirectReader, the
relay a user would run instead), then `vstig bridge --raw` and the engine bridge,
each on the compiled data path and on the pure-Python one (VSTIG_PURE=1). The
figure is each relay process's CPU per message (the kernel's process CPU clock,
every thread), beside can.bridge's; and how many arrived.

vcan exists only inside User-Mode Linux here (tests/socketcan/uml.py), so the run
boots a guest unless this host has vcan0 and vcan1. A guest's system calls are
slow (every one traps to the host), so both relays' CPU is higher than on a real
machine; the ratio is what the gateway's own work adds or saves.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import can

from vstig_hw import Message, Op
from vstig_hw.wire import encode

from .registry import Result, benchmark

COUNT = 3000
RATE_HZ = 300  # a guest keeps this pace with every relay; each frame is read alone (no batching flatters anyone)
ROUNDS = 2  # every relay runs this many times, the rounds alternating; the least CPU of each is kept
_REPO = Path(__file__).resolve().parents[1]
_SENDER = 5
_CHANNELS = ("vcan0", "vcan1")

def _relays() -> dict[str, tuple[list[str], dict[str, str]]]:
    """Each relay's argv and extra environment, in the order they run."""
    vstig = str(Path(sys.executable).with_name("vstig"))
    a, b = _CHANNELS
    bridge = [vstig, "bridge", f"can:socketcan:{a}", f"can:socketcan:{b}"]
    engine = [*bridge, "--robot-id", "200", "--budget", "2000", "--no-refresh"]
    pure = {"VSTIG_PURE": "1"}
    return {
        "can.bridge": ([sys.executable, "-m", "can.bridge", "--bus1-interface", "socketcan", "--bus1-channel", a,
                        "--bus2-interface", "socketcan", "--bus2-channel", b], {}),
        "raw": ([*bridge, "--raw"], {}),
        "raw_pure": ([*bridge, "--raw"], pure),
        "engine": (engine, {}),
        "engine_pure": (engine, pure),
    }


def _cpu(pid: int) -> float:
    """CPU seconds of every thread of process `pid` so far (the kernel's process CPU clock)."""
    return time.clock_gettime((~pid << 3) | 2)  # MAKE_PROCESS_CPUCLOCK(pid, CPUCLOCK_SCHED)


def _frame(key: int) -> can.Message:
    return can.Message(arbitration_id=0x600 | _SENDER, is_extended_id=False,
                       data=encode(Message(Op.PUT, key, key & 0xFFFF, 1, _SENDER)))


class _Arrivals:
    """A receiver on the far bus: the keys of the vstig PUTs that arrived there (any sender)."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="socketcan", channel=channel)
        self.keys: set[int] = set()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            frame = self.bus.recv(0.05)
            if frame is not None and frame.arbitration_id & 0x700 == 0x600 and len(frame.data) == 8:
                self.keys.add(int.from_bytes(frame.data[:2], "big") & 0x7FFF)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()


def _relay_run(argv: list[str], env: dict[str, str]) -> tuple[float, int]:
    """(CPU seconds per message, delivered) of one relay from vcan0 to vcan1."""
    sender = can.Bus(interface="socketcan", channel=_CHANNELS[0])
    out = _Arrivals(_CHANNELS[1])
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, **env})
    try:
        probe = 0x7FFF
        for _ in range(300):  # until it relays
            sender.send(_frame(probe))
            time.sleep(0.1)
            if probe in out.keys:
                break
        else:
            raise RuntimeError(f"{argv[:3]} never relayed")
        frames = [_frame(key) for key in range(COUNT)]
        cpu0 = _cpu(process.pid)
        start = time.perf_counter()
        for i, frame in enumerate(frames):
            delay = start + i / RATE_HZ - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            sender.send(frame)
        end = time.monotonic() + 10
        while len(out.keys) <= COUNT and time.monotonic() < end:
            time.sleep(0.05)
        cpu = _cpu(process.pid) - cpu0
    finally:
        process.terminate()
        process.wait(30)
        out.close()
        sender.shutdown()
    return cpu / COUNT, len(out.keys - {0x7FFF})


def guest(out: Path) -> None:
    """The relays, alternated, on this machine's vcan0 and vcan1: figures.json in `out`.

    A guest's CPU accounting is noisy (its every system call is the host's work too), so each relay runs ROUNDS
    times, one round after the other, and its least CPU is kept (with the fewest delivered of its rounds).
    """
    figures: dict[str, dict[str, float]] = {}
    for _ in range(ROUNDS):
        for name, (argv, env) in _relays().items():
            cpu, delivered = _relay_run(argv, env)
            print(f"{name}: {cpu * 1e6:.1f} us/msg, {delivered} of {COUNT}", flush=True)
            best = figures.setdefault(name, {"cpu": cpu, "delivered": delivered})
            best["cpu"], best["delivered"] = min(best["cpu"], cpu), min(best["delivered"], delivered)
    (out / "figures.json").write_text(json.dumps(figures))


def _in_guest(out: Path) -> dict[str, dict[str, float]]:
    sys.path.insert(0, str(_REPO / "tests" / "socketcan"))
    import uml  # type: ignore[import-not-found]

    reason = uml.unavailable_reason()
    if reason:
        raise RuntimeError(f"no vcan here and no User-Mode Linux to make one: {reason}")
    run = uml.run([], out, program=[sys.executable, "-m", "benchmarks.bench_can_relay", str(out)], timeout=600)
    if run.exit_code != 0:
        raise RuntimeError(run.explain())
    figures: dict[str, dict[str, float]] = json.loads((out / "figures.json").read_text())
    return figures


@benchmark("can_relay")
def can_to_can_cost() -> list[Result]:
    with tempfile.TemporaryDirectory(prefix="vstig-bench-can-relay-") as tmp:
        out = Path(tmp)
        try:
            if all(Path(f"/sys/class/net/{c}").exists() for c in _CHANNELS):
                guest(out)
                figures = json.loads((out / "figures.json").read_text())
            else:
                figures = _in_guest(out)
        except RuntimeError as error:
            print(f"can_relay.can_to_can_cost: not run: {error}", file=sys.stderr)
            return []
    anchor = figures["can.bridge"]["cpu"] * 1e6
    results = []
    for name in ("raw", "engine"):
        compiled, pure = figures[name]["cpu"] * 1e6, figures[f"{name}_pure"]["cpu"] * 1e6
        results += [
            Result(f"can_relay.{name}_cpu_per_msg", compiled, "us", "python-can can.bridge CPU/msg", anchor),
            Result(f"can_relay.{name}_pure_cpu_per_msg", pure, "us", "python-can can.bridge CPU/msg", anchor),
            Result(f"can_relay.{name}_compiled_vs_pure", compiled, "us", "the pure-Python path CPU/msg", pure),
        ]
        for variant in (name, f"{name}_pure"):
            results.append(Result(f"can_relay.{variant}_delivered", figures[variant]["delivered"] / COUNT * 100, "%",
                                  "can.bridge delivered", figures["can.bridge"]["delivered"] / COUNT * 100))
    return results


if __name__ == "__main__":  # inside the guest: python -m benchmarks.bench_can_relay OUT
    os.chdir(_REPO)
    guest(Path(sys.argv[1]))
