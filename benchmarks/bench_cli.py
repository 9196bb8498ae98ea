"""The CLI's speed goals (issue: gateway), each beside an anchor measured in the same run.

* `vstig decode` of a 1,000,000-frame candump log to JSON lines, beside
  can.LogReader plus a cantools decode of the same file (goal: at least 5x).
* Replay timing: total-duration error and p99 inter-frame error at 1,000 and
  5,000 frames/s, beside python-can's MessageSync on the same frames (medians of 3 interleaved runs).
* Gateway latency, frame in (virtual CAN bus) to frame out (pty radio, cobs8)
  at 5,000 frames/s (goal: p99 under 2 ms), beside the bare pty hop.
"""

from __future__ import annotations

import contextlib
import os
import select
import statistics
import subprocess
import sys
import tempfile
import time
import tty
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing

from .registry import Result, benchmark

_FRAMES = 1_000_000
_SENDERS = 16


def _write_log(path: str, frames: int) -> None:
    with open(path, "w") as file:
        lines = []
        for i in range(frames):
            op, sender = i & 1, (i >> 1) % _SENDERS
            msg = Message(Op(op), i % 3000, i % 65536, i % 65535 + 1, sender)
            lines.append(f"({1700000000 + i // 5000}.{(i % 5000) * 200:06d}) can0 "
                         f"{0x600 | op << 8 | sender:03X}#{encode(msg).hex().upper()}\n")
            if len(lines) == 100_000:
                file.writelines(lines)
                lines.clear()
        file.writelines(lines)


def _dbc() -> str:
    """A DBC with the paper's layout for every ID the log uses (what a cantools user would write)."""
    parts = ['VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_:\n']
    for op in (0, 1):
        for sender in range(_SENDERS):
            can_id = 0x600 | op << 8 | sender
            parts.append(
                f"\nBO_ {can_id} M{can_id:03X}: 8 Vector__XXX\n"
                ' SG_ op : 7|1@0+ (1,0) [0|1] "" Vector__XXX\n'
                ' SG_ key : 6|15@0+ (1,0) [0|32767] "" Vector__XXX\n'
                ' SG_ value : 23|16@0+ (1,0) [0|65535] "" Vector__XXX\n'
                ' SG_ timestamp : 39|16@0+ (1,0) [0|65535] "" Vector__XXX\n'
                ' SG_ robot_id : 55|16@0+ (1,0) [0|65535] "" Vector__XXX\n')
    return "".join(parts)


@benchmark("cli")
def decode_candump() -> Iterator[Result]:
    import cantools

    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "swarm.log")
        _write_log(log, _FRAMES)
        vstig = str(Path(sys.executable).with_name("vstig"))
        start = time.perf_counter()
        with open(os.path.join(tmp, "out.jsonl"), "w") as out:
            subprocess.run([vstig, "decode", log, "--format", "jsonl"], stdout=out, stderr=subprocess.DEVNULL,
                           check=True)
        ours = _FRAMES / (time.perf_counter() - start)
        with open(os.path.join(tmp, "out.jsonl"), "rb") as out_file:
            lines = sum(1 for _ in out_file)
        assert lines == _FRAMES, f"vstig decode wrote {lines} lines for {_FRAMES} frames"

        db = cantools.database.load_string(_dbc(), "dbc")
        start = time.perf_counter()
        count = 0
        for frame in can.LogReader(log):
            db.decode_message(frame.arbitration_id, frame.data)
            count += 1
        anchor = count / (time.perf_counter() - start)
    yield Result("cli.decode_candump_jsonl", ours, "frames/s", "can.LogReader + cantools decode", anchor)


def _replay_error(rate_hz: int, seconds: float, use_ours: bool) -> tuple[float, float]:
    """(total-duration error, p99 inter-frame error in seconds) replaying onto a virtual bus."""
    from vstig_hw.capture.records import Record
    from vstig_hw.capture.replay import replay

    frames = [can.Message(timestamp=1000.0 + i / rate_hz, arbitration_id=0x600, data=bytes(8), is_extended_id=False)
              for i in range(int(rate_hz * seconds))]
    bus = can.Bus(interface="virtual", channel=f"bench-replay-{rate_hz}-{use_ours}")
    sent: list[float] = []
    clock = time.perf_counter
    if use_ours:
        def send(record: Record) -> None:
            bus.send(record.unit)
            sent.append(clock())

        replay([Record(f.timestamp, "b", "can", f) for f in frames], send)
    else:
        for frame in can.MessageSync(frames):
            bus.send(frame)
            sent.append(clock())
    bus.shutdown()
    logged = frames[-1].timestamp - frames[0].timestamp
    took = sent[-1] - sent[0]
    gaps = sorted(abs((sent[i + 1] - sent[i]) - 1 / rate_hz) for i in range(len(sent) - 1))
    return abs(took - logged) / logged, gaps[int(0.99 * (len(gaps) - 1))]


_REPLAY_RUNS = 3  # runs of each, interleaved; the median of each figure, so one preempted run does not decide


@benchmark("cli")
def replay_timing() -> Iterator[Result]:
    for rate_hz in (1000, 5000):
        ours, sync = [], []
        for _ in range(_REPLAY_RUNS):
            ours.append(_replay_error(rate_hz, 2.0, True))
            sync.append(_replay_error(rate_hz, 2.0, False))
        ours_total, ours_p99 = (statistics.median(run[i] for run in ours) for i in (0, 1))
        sync_total, sync_p99 = (statistics.median(run[i] for run in sync) for i in (0, 1))
        yield Result(f"cli.replay_{rate_hz}fps_duration_error", ours_total * 100, "%",
                     "can.MessageSync duration error", sync_total * 100)
        yield Result(f"cli.replay_{rate_hz}fps_p99_gap_error", ours_p99 * 1e6, "us",
                     "can.MessageSync p99 gap error", sync_p99 * 1e6)


def _raw_pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    os.set_blocking(master, False)  # a stalled peer must not hang the benchmark
    return master, slave, os.ttyname(slave)


def _p(values: list[float], q: float) -> float:
    return values[int(q * (len(values) - 1))] if values else float("nan")


def _radio_listener(master: int, count: int, done: Any, settle: float) -> None:
    """In a child process: timestamp each cobs8 frame the gateway sends (perf_counter is system-wide)."""
    cobs = make_serial_framing("cobs8")
    arrived: dict[int, float] = {}
    last = time.perf_counter() + 30
    while len(arrived) < count and time.perf_counter() < last:
        if select.select([master], [], [], 0.05)[0]:
            try:
                data = os.read(master, 65536)
            except BlockingIOError:
                continue
            stamp = time.perf_counter()
            for msg in cobs.feed(data):
                arrived.setdefault(msg.key << 16 | msg.value, stamp)
                last = min(last, stamp + settle)
    done.send(arrived)


def _numbered(i: int) -> Message:
    """Frame i as a fresh entry: its own key (so no newer message for the key supersedes it in a queue)."""
    return Message(Op.PUT, i % 32768, i // 32768, 1, 7)


def _tag(i: int) -> int:
    return (i % 32768) << 16 | i // 32768


def _sleep_paced(count: int, rate_hz: int, send: Callable[[int], None]) -> list[float]:
    """send(i) at start + i/rate by sleeping (never spinning: a spinning thread would hold the GIL)."""
    sent = []
    start = time.perf_counter() + 0.05
    for i in range(count):
        remaining = start + i / rate_hz - time.perf_counter()
        if remaining > 0:
            time.sleep(remaining)
        sent.append(time.perf_counter())
        send(i)
    return sent


@benchmark("cli")
def gateway_latency() -> Iterator[Result]:
    """Frame in on a python-can virtual bus to frame out on a cobs8 pty radio, at 5,000 frames/s.

    The gateway and the bus robot share this process (the virtual bus exists only in-process), so
    the robot takes GIL turns a robot on a real bus never would: the figure is pessimistic by that
    much. The radio's far end is a child process that timestamps what arrives; it is forked before
    any gateway thread exists (a fork copies only the calling thread, and a lock another thread
    held would stay locked in the child). Values count up so every frame is a new entry the engine
    stores and re-broadcasts. The anchor is the bare pty hop, same method. The gateway is tuned with
    `favour_latency()` where `vstig bridge` does it. (python-can's slcan driver reads a byte per
    system call and cannot carry 5,000 frames/s, so a subprocess bridge over slcan would measure
    the driver, not the gateway.)"""
    import multiprocessing

    from vstig_hw.framing.can import can_framing_for
    from vstig_hw.gateway import Node, favour_latency
    from vstig_hw.links import parse

    rate_hz, count = 5000, 10_000
    fork = multiprocessing.get_context("fork")

    def hop(send: Callable[[int], None], master: int, start: Callable[[], None] = lambda: None) -> list[float]:
        receive, done = fork.Pipe(duplex=False)
        listener = fork.Process(target=_radio_listener, args=(master, count, done, 3.0))
        listener.start()
        start()
        sent = _sleep_paced(count, rate_hz, send)
        arrived = receive.recv()
        listener.join()
        return sorted(arrived[_tag(i)] - sent[i] for i in range(count) if _tag(i) in arrived)

    master, slave, path = _raw_pty()
    channel = f"bench-gw-{os.getpid()}"
    robot = can.Bus(interface="virtual", channel=channel)
    codec = can_framing_for(7)
    frames = [codec.encode(_numbered(i))[0] for i in range(count)]
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=200),
             parse(f"serial:{path}").build("radio", robot_id=200)]
    node = Node(links, 200, budget=2000)  # 20,000 messages/s per link: above the offered load
    favour_latency()  # where `vstig bridge` calls it: after building the node, before opening it

    try:  # the node opens after the listener is forked; its loop runs on its own thread
        latencies = hop(lambda i: robot.send(frames[i]), master, node.open)
    finally:
        node.close()
    robot.shutdown()
    cobs = make_serial_framing("cobs8")
    units = [cobs.encode(_numbered(i))[0] for i in range(count)]
    os.set_blocking(slave, False)

    def bare_write(i: int) -> None:
        with contextlib.suppress(BlockingIOError):  # the listener fell behind and the pty is full: a lost frame
            os.write(slave, units[i])

    bare = hop(bare_write, master)
    os.close(master)
    os.close(slave)
    yield Result("cli.gateway_latency_p50", _p(latencies, 0.5) * 1e3, "ms", "bare pty hop p50", _p(bare, 0.5) * 1e3)
    yield Result("cli.gateway_latency_p99", _p(latencies, 0.99) * 1e3, "ms", "bare pty hop p99",
                 _p(bare, 0.99) * 1e3)
    yield Result("cli.gateway_delivered", len(latencies) / count * 100, "%", "offered", 100.0)
