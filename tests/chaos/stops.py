"""Stop `vstig record can:slcan:... serial:... -o x.mcap` under load, many times; dump any that outlives its stop.

    python tests/chaos/stops.py [--runs 200] [--burners 2]

Issue 38 item 8: such a recorder was once seen alive 35 minutes after SIGTERM, a
thread in a futex wait. Each run starts a recorder on an slcan adapter (2,000
frames/s) and a cobs8 radio (1,000 messages/s), both on ptys, with --burners
processes spinning beside it, stops it at a random moment of its first 1.5 s (SIGTERM,
SIGINT or SIGHUP, sometimes twice), and checks that it ended within 2 s, with status
0, and left a capture `decode` reads. One alive 5 s after its first signal is dumped
with py-spy (every thread, native frames too) before it is killed.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import tty
from pathlib import Path

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing

VSTIG = str(Path(sys.executable).with_name("vstig"))
PY_SPY = os.environ.get("PY_SPY") or shutil.which("py-spy", path=str(Path(sys.executable).parent)) \
    or shutil.which("py-spy")


def _pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def _burn(stop: multiprocessing.synchronize.Event) -> None:  # type: ignore[name-defined]
    while not stop.is_set():
        sum(range(10_000))


def _talk(adapter: int, radio: int, stop: threading.Event) -> None:
    """The adapter's bus and the radio's robot: honest traffic, and the adapter answers the host's commands."""
    cobs = make_serial_framing("cobs8")
    seq = 0
    os.set_blocking(adapter, False)
    os.set_blocking(radio, False)
    while not stop.is_set():
        seq += 1
        lines = f"t6058{seq:016X}\r".encode() * 20
        radio_bytes = b"".join(u for k in range(10) for u in cobs.encode(Message(Op.PUT, k, seq & 0xFFFF,
                                                                                 seq & 0xFFFF or 1, 5)))
        for fd, data in ((adapter, lines), (radio, radio_bytes)):
            with contextlib.suppress(OSError):
                os.write(fd, data)
        try:
            if os.read(adapter, 4096):
                os.write(adapter, b"\r")
        except OSError:
            pass
        time.sleep(0.01)


def one_stop(folder: Path, n: int) -> tuple[str, float | None, str]:
    (am, aslave, apath), (rm, rslave, rpath) = _pty(), _pty()
    stop = threading.Event()
    talker = threading.Thread(target=_talk, args=(am, rm, stop), daemon=True)
    talker.start()
    out = folder / f"run{n}.mcap"
    process = subprocess.Popen([VSTIG, "record", f"can:slcan:{apath}", f"serial:{rpath}?framing=cobs8", "-o",
                                str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    said: list[str] = []
    pump = threading.Thread(target=lambda: said.extend(process.stderr or ()), daemon=True)
    pump.start()
    try:
        end = time.monotonic() + 30
        while not any("Ctrl-C stops" in line for line in said) and time.monotonic() < end and process.poll() is None:
            time.sleep(0.005)
        time.sleep(random.uniform(0, 1.5))
        signum = random.choice([signal.SIGTERM, signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
        first = time.monotonic()
        process.send_signal(signum)
        if random.random() < 0.2:  # as `timeout` does: the same signal again at once
            process.send_signal(signum)
        try:
            status = process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            dump = "py-spy is not installed (pip install py-spy)"
            if PY_SPY:
                dump = subprocess.run([PY_SPY, "dump", "--native", "--pid", str(process.pid)], capture_output=True,
                                      text=True, timeout=60, check=False).stdout
            process.kill()
            process.wait()
            return "hung", None, f"{signum.name}\n{dump}\n{''.join(said)[-2000:]}"
        took = time.monotonic() - first
        pump.join(timeout=5)
        if status != 0 or not any(line.startswith("engine") or "units in" in line for line in said):
            return "unclean", took, f"status {status}: {''.join(said)[-2000:]}"
        decoded = subprocess.run([VSTIG, "decode", str(out)], capture_output=True, text=True, timeout=120,
                                 check=False)
        if decoded.returncode != 0:
            return "unreadable", took, decoded.stderr[-1000:]
        return ("slow" if took > 2.0 else "ok"), took, ""
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        stop.set()
        talker.join(timeout=5)
        for fd in (am, aslave, rm, rslave):
            os.close(fd)
        out.unlink(missing_ok=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--burners", type=int, default=2, help="busy processes beside the recorder (the load)")
    args = parser.parse_args()
    fork = multiprocessing.get_context("fork")
    burning = fork.Event()
    burners = [fork.Process(target=_burn, args=(burning,), daemon=True) for _ in range(args.burners)]
    for burner in burners:
        burner.start()
    folder = Path(tempfile.mkdtemp(prefix="vstig-stops-"))
    outcomes: dict[str, int] = {}
    took: list[float] = []
    try:
        for n in range(args.runs):
            outcome, seconds, detail = one_stop(folder, n)
            outcomes[outcome] = outcomes.get(outcome, 0) + 1
            if seconds is not None:
                took.append(seconds)
            if detail:
                print(f"run {n}: {outcome}\n{detail}", flush=True)
    finally:
        burning.set()
        for burner in burners:
            burner.join(timeout=5)
        shutil.rmtree(folder, ignore_errors=True)
    took.sort()
    print(f"{args.runs} stops under {args.burners} busy processes: {outcomes}; stop took p50 "
          f"{took[len(took) // 2]:.2f} s, max {took[-1]:.2f} s" if took else outcomes)
    return 0 if set(outcomes) == {"ok"} else 1


if __name__ == "__main__":
    sys.exit(main())
