"""XBee links (issue 34): a relay's CPU per message through XBee modules, beside the same relay on cobs8 radios.

Both are `vstig bridge` engine processes (robot 200, as a lab runs them) relaying radio A -> radio B, both
ptys, at the same pace and count, measured in the same run:

* the anchor: cobs8 frames in on A and out on B, one message per frame in;
* XBee: A and B are modules of tests/xbee's emulated network (two networks, so B's frames do not come back
  on A). Each message comes alone in its Receive Packet from a robot's module (a robot that sends at once),
  the bridge batches what it sends as the module's NP allows, and each module answers every frame the
  bridge sends with a Transmit Status, which the bridge reads and counts too.

CPU from the bridge process's CPU-time clock, context switches of all its threads, and the p50 delay from
the robot's send to the far module's host; the goal is an XBee relay within 1.3x the cobs8 relay's CPU
per message.
"""

from __future__ import annotations

import contextlib
import os
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from vstig_hw import Message, Op, encode

from .bench_datapath import VSTIG, _Arrivals, _delays, _paced, _quantiles, _relaying, _usage
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
def _xbee_relaying() -> Iterator[tuple[int, object, int, _XBeeArrivals]]:
    """A bridge between two modules on two networks; yields (its pid, the robot's host, A's address, B's far end)."""
    from xbee_network import Host, XBeeNetwork

    with XBeeNetwork() as near, XBeeNetwork() as far:
        a, b = near.module(0x0013A20040000001), far.module(0x0013A20040000002)
        robot, listener = Host(near.module(0x0013A20040000003)), Host(far.module(0x0013A20040000004))
        spec = "serial:{}?framing=xbee&baud=230400"
        process = subprocess.Popen([VSTIG, "bridge", spec.format(a.path), spec.format(b.path), *_ENGINE],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        out = _XBeeArrivals(listener)
        echo = threading.Event()  # the bridge's re-broadcasts reach the robot's module: its host reads them

        def drain() -> None:
            while not echo.is_set():
                robot.received(0.05)

        draining = threading.Thread(target=drain, daemon=True)
        draining.start()
        try:
            for stamp in range(1, 300):
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


@benchmark("xbee")
def relay_cost() -> Iterator[Result]:
    cobs8, xbee = _cobs8_run(), _xbee_run()
    yield Result("xbee.relay_cpu_per_msg", xbee[0] * 1e6, "us", "cobs8 relay CPU/msg (goal <= 1.3x)", cobs8[0] * 1e6)
    yield Result("xbee.relay_switches_per_msg", xbee[1], "switches", "cobs8 relay switches/msg", cobs8[1])
    # The XBee p50 includes the emulated modules' two hops (a Python thread each way), which the cobs8 path lacks.
    yield Result("xbee.relay_p50", xbee[2] * 1e3, "ms", "cobs8 relay p50 (+2 emulated module hops)", cobs8[2] * 1e3)
    yield Result("xbee.relay_delivered", xbee[3] / COUNT * 100, "%", "cobs8 relay delivered %", cobs8[3] / COUNT * 100)

