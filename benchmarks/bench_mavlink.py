"""MAVLink links (issue 49): a relay's CPU per message through mavlink: links, beside the same relay on cobs8 radios,
and pymavlink's own parse of the same frames as a second anchor.

Both relays are `vstig bridge` engine processes (robot 200) at the same pace and count, measured in the same run:

* the anchor: cobs8 frames in on pty A and out on pty B, one message per frame in (bench_xbee's);
* MAVLink: TUNNELs in on a udpin link (each from a drone, sysid 9, carrying one message, as a drone that sends at
  once), out on a udpout link to a UDP socket this bench reads; the bridge batches up to 16 to a TUNNEL and
  sends a HEARTBEAT a second on each link.

CPU from the bridge process's CPU-time clock, the median of three interleaved rounds; the goal is a MAVLink
relay within 1.3x the cobs8 relay's CPU per message, both on the compiled data path (a mavlink UDP link's socket is
read and written by it, see DECISIONS.md; both engines re-broadcast each message onto the link it came from). The same
MAVLink relay on the Python path (VSTIG_PURE=1) shows what the compiled path saves. pymavlink's parse: CPU per
message of `MAVLink.parse_buffer` over the same TUNNELs, one by one (what a pymavlink-based relay would spend on
reading alone).

`relay_instructions`: the two relays' user-space instructions per message under callgrind (a run of 2,500
messages less one of 500, as bench_datapath's), a figure a shared machine's load does not move.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from vstig_hw import Message, Op
from vstig_hw.framing.mavlink import MavlinkFraming

from .bench_datapath import VSTIG, _Arrivals, _instructions, _paced, _usage
from .bench_xbee import _ENGINE, COUNT, RATE_HZ, ROUNDS, _cobs8_run, _median, counted_instructions
from .registry import Result, benchmark

PROBE = 32767


class _UdpArrivals(_Arrivals):
    """bench_datapath's arrivals, read from the relay's udpout socket: TUNNELs instead of cobs8 frames."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        super().__init__(None)  # type: ignore[arg-type]  # no pty: `_read` reads the socket

    def _read(self) -> None:
        framing = MavlinkFraming(255)
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            data = self.sock.recv(65536)
            stamp = time.perf_counter()
            for msg in framing.feed(data):
                self.arrived.setdefault(msg.key, stamp)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@contextlib.contextmanager
def _mavlink_relaying(prefix: tuple[str, ...] = ()) -> Iterator[tuple[int, socket.socket, tuple[str, int],
                                                                       _UdpArrivals]]:
    """A bridge from a udpin link to a udpout link (after `prefix`: callgrind); yields (its pid, the drone's
    socket, the udpin address, the far end's arrivals)."""
    far = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    far.bind(("127.0.0.1", 0))
    into = ("127.0.0.1", _free_port())
    process = subprocess.Popen([*prefix, VSTIG, "bridge", f"mavlink:udpin:{into[0]}:{into[1]}",
                                f"mavlink:udpout:127.0.0.1:{far.getsockname()[1]}", *_ENGINE],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    drone = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    out = _UdpArrivals(far)
    sender = MavlinkFraming(9, 1)
    try:
        for stamp in range(1, 3000):
            drone.sendto(sender.encode(Message(Op.PUT, PROBE, 1, stamp, 7))[0], into)
            time.sleep(0.1)
            if PROBE in out.arrived:
                break
        else:
            raise RuntimeError("the MAVLink relay never came up")
        yield process.pid, drone, into, out
    finally:
        process.terminate()
        process.wait(timeout=120)
        out.close()
        drone.close()
        far.close()


def _tunnels(count: int = COUNT) -> list[bytes]:
    sender = MavlinkFraming(9, 1)
    return [sender.encode(Message(Op.PUT, i, i, 1, 7))[0] for i in range(count)]


def _mavlink_run() -> tuple[float, float, float, int]:
    """(CPU s per message, switches per message, p50 delay s, delivered) of a MAVLink -> MAVLink engine relay."""
    with _mavlink_relaying() as (pid, drone, into, out):
        frames = _tunnels()
        cpu0, sw0 = _usage(pid)
        sent = _paced(lambda frame: drone.sendto(frame, into), frames, rate_hz=RATE_HZ)
        out.wait(COUNT + 1)
        cpu1, sw1 = _usage(pid)
    delays = [out.arrived[i] - sent[i] for i in range(COUNT) if i in out.arrived]
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, statistics.median(delays) if delays else float("nan"), \
        len(delays)


def _pymavlink_parse() -> float:
    """CPU seconds per message of pymavlink's parse_buffer over the same TUNNELs (the best of three passes)."""
    from pymavlink.dialects.v20 import common as mav2

    frames = _tunnels()
    best = float("inf")
    for _ in range(3):
        parser = mav2.MAVLink(None)
        start = time.process_time()
        for frame in frames:
            for msg in parser.parse_buffer(frame) or ():
                struct.iter_unpack(">HHHH", bytes(msg.payload[:msg.payload_length]))
        best = min(best, (time.process_time() - start) / len(frames))
    return best


@contextlib.contextmanager
def _pure() -> Iterator[None]:
    """Relays started meanwhile take the Python data path (VSTIG_PURE=1)."""
    before = os.environ.get("VSTIG_PURE")
    os.environ["VSTIG_PURE"] = "1"
    try:
        yield
    finally:
        if before is None:
            del os.environ["VSTIG_PURE"]
        else:
            os.environ["VSTIG_PURE"] = before


def _mavlink_pure_run() -> tuple[float, float, float, int]:
    with _pure():
        return _mavlink_run()


@benchmark("mavlink")
def relay_cost() -> Iterator[Result]:
    """The cobs8 relay, the MAVLink relay and the MAVLink relay on the Python path, in turns, ROUNDS times."""
    runs = [(_cobs8_run(), _mavlink_run(), _mavlink_pure_run()) for _ in range(ROUNDS)]
    cobs8, mavlink = _median([c for c, _, _ in runs]), _median([m for _, m, _ in runs])
    pure = _median([p for _, _, p in runs])
    yield Result("mavlink.relay_cpu_per_msg", mavlink[0] * 1e6, "us", "cobs8 relay CPU/msg (goal <= 1.3x)",
                 cobs8[0] * 1e6)
    yield Result("mavlink.relay_cpu_compiled_vs_pure", mavlink[0] * 1e6, "us",
                 "the MAVLink relay on the Python path (VSTIG_PURE=1) CPU/msg", pure[0] * 1e6)
    yield Result("mavlink.relay_cpu_vs_pymavlink_parse", mavlink[0] * 1e6, "us",
                 "pymavlink parse_buffer CPU/msg, same TUNNELs", _pymavlink_parse() * 1e6)
    yield Result("mavlink.relay_switches_per_msg", mavlink[1], "switches", "cobs8 relay switches/msg", cobs8[1])
    yield Result("mavlink.relay_p50", mavlink[2] * 1e3, "ms", "cobs8 relay p50", cobs8[2] * 1e3)
    yield Result("mavlink.relay_delivered", mavlink[3] / COUNT * 100, "%", "cobs8 relay delivered %",
                 cobs8[3] / COUNT * 100)


def _mavlink_instructions(count: int, workdir: Path) -> int:
    """User-space instructions (callgrind's Ir) the MAVLink relay executed in all, having relayed `count`."""
    @contextlib.contextmanager
    def relaying(prefix: tuple[str, ...]) -> Iterator[tuple[Callable[[bytes], object], _Arrivals]]:
        with _mavlink_relaying(prefix) as (_pid, drone, into, out):
            yield lambda frame: drone.sendto(frame, into), out

    return counted_instructions("MAVLink", count, workdir, relaying, _tunnels(count))


@benchmark("mavlink")
def relay_instructions() -> Iterator[Result]:
    """Instructions per relayed message of the MAVLink relay against the cobs8 engine relay (bench_datapath's
    `engine`, the same bridge options): 2,500 messages less 500, so start-up cancels out; user space only."""
    import shutil

    if shutil.which("valgrind") is None:
        print("mavlink.relay_instructions: needs valgrind (apt-get install valgrind)", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory(prefix="vstig-bench-") as tmp:
        cobs8 = [_instructions("engine", count, Path(tmp)) for count in (500, 2500)]
        mavlink = [_mavlink_instructions(count, Path(tmp)) for count in (500, 2500)]
    yield Result("mavlink.relay_instructions_per_msg", (mavlink[1] - mavlink[0]) / 2000, "instr",
                 "cobs8 relay instr/msg", (cobs8[1] - cobs8[0]) / 2000)
