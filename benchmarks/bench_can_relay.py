"""CAN -> CAN relays on SocketCAN: `vstig bridge` beside python-can's own `can.bridge`, in one run.

A sender on vcan0 puts vstig PUT frames (distinct keys, so an engine relays every
one) at a steady pace; a receiver on vcan1 notes each key's first arrival. Between
them one relay at a time, in alternating order: `python -m can.bridge` (python-can
4.6's bridge of two buses: a Notifier thread per bus and a RedirectReader, the
relay a user would run instead), then `vstig bridge --raw` and the engine bridge,
each on the compiled data path and on the pure-Python one (VSTIG_PURE=1).

vcan exists only inside User-Mode Linux here (tests/socketcan/uml.py), so the run
boots a guest unless this host has vcan0 and vcan1. A guest accounts CPU time in
whole 10 ms jiffies (it charged can.bridge 2 jiffies for 3,000 relayed frames), so
the figure per relay is the user-space instructions it executed per message, under
callgrind (`callgrind_control -e Ir`, read once the relay relays and again after
COUNT messages): what the bench's pty relays count too, and the same on a busy or an
idle machine. Every relay also makes its system calls (a guest's are slow alike for
all of them); instructions are what the relays' own code adds.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import can

from vstig_hw import Message, Op
from vstig_hw.wire import encode

from .guest import run_in_guest
from .registry import Result, benchmark

COUNT = 1000
RATE_HZ = 100  # slow enough for a relay under callgrind (~50x slower) in a guest to take each frame alone
_REPO = Path(__file__).resolve().parents[1]
_SENDER = 5
_CHANNELS = ("vcan0", "vcan1")
PROBE = 0x7FFF


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


def put_frame(key: int) -> can.Message:
    """A vstig PUT of `key` from sender 5 (distinct keys: an engine relays every one)."""
    return can.Message(arbitration_id=0x600 | _SENDER, is_extended_id=False,
                       data=encode(Message(Op.PUT, key, key & 0xFFFF, 1, _SENDER)))


class Arrivals:
    """A receiver on the far bus: the keys of the vstig PUTs that arrived there (any sender); `tid`: its thread's."""

    def __init__(self, channel: str, interface: str = "socketcan") -> None:
        self.bus = can.Bus(interface=interface, channel=channel)
        self.keys: set[int] = set()
        self.tid = 0
        self._stop = threading.Event()
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._read, name="bench-receiver", daemon=True)
        self._thread.start()
        self._started.wait()

    def _read(self) -> None:
        self.tid = threading.get_native_id()
        self._started.set()
        while not self._stop.is_set():
            frame = self.bus.recv(0.05)
            if frame is not None and frame.arbitration_id & 0x700 == 0x600 and len(frame.data) == 8:
                self.keys.add(int.from_bytes(frame.data[:2], "big") & 0x7FFF)

    def relayed(self, sender: can.BusABC, relay: str, pause: float) -> None:
        """Send probes every `pause` seconds (600 at most) until one arrives: the relay between relays."""
        for _ in range(600):
            sender.send(put_frame(PROBE))
            time.sleep(pause)
            if PROBE in self.keys:
                return
        raise RuntimeError(f"{relay} never relayed")

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()


def _instructions(pid: int) -> int:
    """The user-space instructions callgrind counted so far in process `pid`, every thread's."""
    shown = subprocess.run(["callgrind_control", "-e", "Ir", str(pid)], capture_output=True, text=True,
                           timeout=60, check=True).stdout
    threads = re.findall(r"^\s*Th\s+\d+\s+([\d,]+)\s*$", shown, flags=re.M)
    if not threads:
        raise RuntimeError(f"callgrind_control showed no Ir for {pid}: {shown}")
    return sum(int(count.replace(",", "")) for count in threads)


def _relay_run(argv: list[str], env: dict[str, str], out: Path) -> tuple[float, int]:
    """(instructions per message, delivered) of one relay from vcan0 to vcan1, under callgrind."""
    sender = can.Bus(interface="socketcan", channel=_CHANNELS[0])
    arrivals = Arrivals(_CHANNELS[1])
    callgrind = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out / 'callgrind.%p'}"]
    process = subprocess.Popen([*callgrind, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               env={**os.environ, **env})
    try:
        arrivals.relayed(sender, " ".join(argv[:3]), 0.5)  # a Python start under callgrind in a guest takes a while
        time.sleep(1.0)  # the probes still on their way
        before = _instructions(process.pid)
        start = time.perf_counter()
        for key in range(COUNT):
            delay = start + key / RATE_HZ - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            sender.send(put_frame(key))
        end = time.monotonic() + 60
        while len(arrivals.keys - {PROBE}) < COUNT and time.monotonic() < end:
            time.sleep(0.1)
        after = _instructions(process.pid)
    finally:
        process.terminate()
        process.wait(120)
        arrivals.close()
        sender.shutdown()
    return (after - before) / COUNT, len(arrivals.keys - {PROBE})


def guest(out: Path) -> None:
    """The relays, alternated, on this machine's vcan0 and vcan1: figures.json in `out`."""
    figures: dict[str, dict[str, float]] = {}
    for name, (argv, env) in _relays().items():
        instructions, delivered = _relay_run(argv, env, out)
        print(f"{name}: {instructions:,.0f} instructions/msg, {delivered} of {COUNT}", flush=True)
        figures[name] = {"instructions": instructions, "delivered": delivered}
    (out / "figures.json").write_text(json.dumps(figures))


@benchmark("can_relay")
def can_to_can_cost() -> list[Result]:
    import shutil

    if shutil.which("valgrind") is None:
        print("can_relay.can_to_can_cost: needs valgrind (apt-get install valgrind)", file=sys.stderr)
        return []
    with tempfile.TemporaryDirectory(prefix="vstig-bench-can-relay-") as tmp:
        out = Path(tmp)
        try:
            if all(Path(f"/sys/class/net/{c}").exists() for c in _CHANNELS):
                guest(out)
                figures = json.loads((out / "figures.json").read_text())
            else:
                figures = run_in_guest("bench_can_relay", out, timeout=1800)
        except RuntimeError as error:
            print(f"can_relay.can_to_can_cost: not run: {error}", file=sys.stderr)
            return []
    anchor = figures["can.bridge"]["instructions"]
    results = []
    for name in ("raw", "engine"):
        compiled, pure = figures[name]["instructions"], figures[f"{name}_pure"]["instructions"]
        results += [
            Result(f"can_relay.{name}_instructions_per_msg", compiled, "instr", "python-can can.bridge instr/msg",
                   anchor),
            Result(f"can_relay.{name}_pure_instructions_per_msg", pure, "instr", "python-can can.bridge instr/msg",
                   anchor),
            Result(f"can_relay.{name}_instructions_compiled_vs_pure", compiled, "instr",
                   "the pure-Python path instr/msg", pure),
        ]
        for variant in (name, f"{name}_pure"):
            results.append(Result(f"can_relay.{variant}_delivered", figures[variant]["delivered"] / COUNT * 100, "%",
                                  "can.bridge delivered", figures["can.bridge"]["delivered"] / COUNT * 100))
    return results


if __name__ == "__main__":  # inside the guest: python -m benchmarks.bench_can_relay OUT
    os.chdir(_REPO)
    guest(Path(sys.argv[1]))
