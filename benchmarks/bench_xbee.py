"""XBee links (issue 34): a relay's CPU per message through XBee modules, beside the same relay on cobs8 radios.

Both are `vstig bridge` engine processes (robot 200, as a lab runs them) relaying radio A -> radio B, both
ptys, at the same pace and count, measured in the same run:

* the anchor: cobs8 frames in on A and out on B, one message per frame in;
* XBee: A and B are modules of tests/xbee's emulated network (two networks, so B's frames do not come back
  on A). Each message comes alone in its Receive Packet from a robot's module (a robot that sends at once),
  the bridge batches what it sends as the module's NP allows, and each module answers every frame the
  bridge sends with a Transmit Status, which the bridge reads and counts too.

CPU from the bridge process's CPU-time clock, context switches of all its threads, and the p50 delay from
the robot's send to the far module's host, each the median of three interleaved pairs of runs; the goal
is an XBee relay within 1.3x the cobs8 relay's CPU per message.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path

from vstig_hw import Message, Op, encode

from .bench_datapath import (
    INSTRUCTIONS_RATE_HZ,
    VSTIG,
    _Arrivals,
    _delays,
    _instructions,
    _paced,
    _quantiles,
    _relaying,
    _totals,
    _usage,
)
from .registry import Result, benchmark

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "xbee"))

RATE_HZ = 1000  # the emulated network is one Python thread: a pace it keeps without bunching frames up
COUNT = 5000
PROBE = 32767
_ENGINE = ("--robot-id", "200", "--budget", "2000", "--no-refresh")


class _XBeeArrivals(_Arrivals):
    """bench_datapath's arrivals, read from the far module's host: Receive Packets instead of cobs8 frames."""

    def __init__(self, host: object) -> None:
        self.host = host
        super().__init__(None)  # type: ignore[arg-type]  # no pty: `_read` reads the host

    def _read(self) -> None:
        while not self._stop.is_set():
            got = self.host.received(0.05)  # type: ignore[attr-defined]
            stamp = time.perf_counter()
            for _source, rf in got:
                for words in struct.iter_unpack(">HHHH", rf):
                    self.arrived.setdefault(words[0] & 0x7FFF, stamp)


@contextlib.contextmanager
def _xbee_relaying(prefix: tuple[str, ...] = ()) -> Iterator[tuple[int, object, int, _XBeeArrivals]]:
    """A bridge between two modules on two networks (run under `prefix`, e.g. callgrind); yields (its pid, the
    robot's host, A's address, B's far end)."""
    from xbee_network import Host, XBeeNetwork

    with XBeeNetwork() as near, XBeeNetwork() as far:
        a, b = near.module(0x0013A20040000001), far.module(0x0013A20040000002)
        robot, listener = Host(near.module(0x0013A20040000003)), Host(far.module(0x0013A20040000004))
        spec = "serial:{}?framing=xbee&baud=230400"
        process = subprocess.Popen([*prefix, VSTIG, "bridge", spec.format(a.path), spec.format(b.path), *_ENGINE],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        out = _XBeeArrivals(listener)
        echo = threading.Event()  # the bridge's re-broadcasts reach the robot's module: its host reads them

        def drain() -> None:
            while not echo.is_set():
                robot.received(0.05)

        draining = threading.Thread(target=drain, daemon=True)
        draining.start()
        try:
            for stamp in range(1, 3000):
                robot.transmit(encode(Message(Op.PUT, PROBE, 1, stamp, 7)), dest=a.address)
                time.sleep(0.1)
                if PROBE in out.arrived:
                    break
            else:
                raise RuntimeError("the XBee relay never came up")
            yield process.pid, robot, a.address, out
        finally:
            process.terminate()
            process.wait(timeout=120)
            echo.set()
            draining.join()
            out.close()
            robot.close()
            listener.close()


def _xbee_run() -> tuple[float, float, float, int]:
    """(CPU s per message, switches per message, p50 delay s, delivered) of an XBee -> XBee engine relay."""
    with _xbee_relaying() as (pid, robot, address, out):
        payloads = [encode(Message(Op.PUT, i, i, 1, 7)) for i in range(COUNT)]
        cpu0, sw0 = _usage(pid)
        sent = _paced(lambda rf: robot.transmit(rf, dest=address), payloads, rate_hz=RATE_HZ)  # type: ignore[attr-defined]
        out.wait(COUNT + 1)
        cpu1, sw1 = _usage(pid)
    delays = [out.arrived[i] - sent[i] for i in range(COUNT) if i in out.arrived]
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, _quantiles(delays)[0], len(delays)


def _cobs8_run() -> tuple[float, float, float, int]:
    """The same for a cobs8 -> cobs8 engine relay (bench_datapath's), at this file's pace and count."""
    from vstig_hw.framing import make_serial_framing

    cobs8 = make_serial_framing("cobs8")

    def argv(a: str, b: str) -> list[str]:
        return [VSTIG, "bridge", f"serial:{a}?framing=cobs8", f"serial:{b}?framing=cobs8", *_ENGINE]

    with _relaying(argv, echo_back=True) as (pid, a, out):
        frames = [cobs8.encode(Message(Op.PUT, i, i, 1, 7))[0] for i in range(COUNT)]
        cpu0, sw0 = _usage(pid)
        sent = _paced(lambda f: os.write(a.master, f), frames, rate_hz=RATE_HZ)
        out.wait(COUNT + 1)
        cpu1, sw1 = _usage(pid)
    delays = _delays(out, sent)
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, _quantiles(delays)[0], len(delays)


ROUNDS = 3  # interleaved pairs; each figure is the median of its rounds (preemption on a shared machine moves one)


def _median(runs: list[tuple[float, float, float, int]]) -> tuple[float, ...]:
    return tuple(statistics.median(column) for column in zip(*runs, strict=True))


@benchmark("xbee")
def relay_cost() -> Iterator[Result]:
    pairs = [(_cobs8_run(), _xbee_run()) for _ in range(ROUNDS)]
    cobs8, xbee = _median([c for c, _ in pairs]), _median([x for _, x in pairs])
    yield Result("xbee.relay_cpu_per_msg", xbee[0] * 1e6, "us", "cobs8 relay CPU/msg (goal <= 1.3x)", cobs8[0] * 1e6)
    yield Result("xbee.relay_switches_per_msg", xbee[1], "switches", "cobs8 relay switches/msg", cobs8[1])
    # The XBee p50 includes the emulated modules' two hops (a Python thread each way), which the cobs8 path lacks.
    yield Result("xbee.relay_p50", xbee[2] * 1e3, "ms", "cobs8 relay p50 (+2 emulated module hops)", cobs8[2] * 1e3)
    yield Result("xbee.relay_delivered", xbee[3] / COUNT * 100, "%", "cobs8 relay delivered %", cobs8[3] / COUNT * 100)



def counted_instructions(label: str, count: int, workdir: Path,
                         relaying: Callable[[tuple[str, ...]], AbstractContextManager[tuple[Callable[[bytes], object],
                                                                                        _Arrivals]]],
                         units: list[bytes]) -> int:
    """User-space instructions (callgrind's Ir) a relay executed in all, having relayed `count` messages:
    `relaying(prefix)` starts it after `prefix` and yields (a call sending one of `units`, the far end's arrivals)."""
    out_file = workdir / f"{label}.{count}.callgrind"
    with relaying(("valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}")) as (send, out):
        _paced(send, units, rate_hz=INSTRUCTIONS_RATE_HZ)
        out.wait(count + 1, seconds=60)
    if len(out.arrived) < count + 1:
        raise RuntimeError(f"the {label} relay under callgrind relayed {len(out.arrived) - 1} of {count} messages")
    return _totals(out_file)


def _xbee_instructions(count: int, workdir: Path) -> int:
    """User-space instructions (callgrind's Ir) an XBee relay executed in all, having relayed `count` messages."""
    @contextlib.contextmanager
    def relaying(prefix: tuple[str, ...]) -> Iterator[tuple[Callable[[bytes], object], _Arrivals]]:
        with _xbee_relaying(prefix=prefix) as (_pid, robot, address, out):
            yield lambda rf: robot.transmit(rf, dest=address), out  # type: ignore[attr-defined]

    return counted_instructions("XBee", count, workdir, relaying,
                                [encode(Message(Op.PUT, i, i, 1, 7)) for i in range(count)])


@benchmark("xbee")
def relay_instructions() -> Iterator[Result]:
    """Instructions per relayed message through XBee modules and through cobs8 radios, under callgrind (the same
    on a busy or an idle machine): the difference between runs of 2,500 and 500 messages, so start-up cancels."""
    import shutil
    import tempfile

    if shutil.which("valgrind") is None:
        print("xbee.relay_instructions: needs valgrind (apt-get install valgrind)", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory(prefix="vstig-bench-") as tmp:
        xbee = (_xbee_instructions(2500, Path(tmp)) - _xbee_instructions(500, Path(tmp))) / 2000
        cobs8 = (_instructions("engine", 2500, Path(tmp)) - _instructions("engine", 500, Path(tmp))) / 2000
    yield Result("xbee.relay_instructions_per_msg", xbee, "instr", "cobs8 engine relay instr/msg", cobs8)
