"""The data path (issue 25): a relay's cost and isolation, each beside an anchor measured in the same run.

* CPU and context switches per message of a `vstig bridge` process relaying pty -> pty
  (raw and engine mode), from the process's own accounting (the kernel's CPU-time
  clock of the process, in nanoseconds; voluntary+involuntary switches of every
  thread), beside a bare pty hop:
  a Python process that reads one pty and writes what it read to the other. Also beside
  the framing floor: a Python process that only cuts, checks and re-encodes the cobs8
  frames (what any relay that checks frames must do), which tells the Node's own cost.
* The same relays' user-space instructions per message under callgrind: a figure the
  shared VM's load cannot move, for judging a change to the path.
* The healthy link's p50 delay in a three-radio engine bridge where one radio is
  never read, beside the same bridge without that radio; and how many it lost.
* Zenoh samples the bridge publishes per message it relays onto zenoh, with a peer
  also publishing (an echo would add one sample per message heard from zenoh).
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tty
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing
from vstig_hw.wire import decode

from .bench_cli import _sleep_paced
from .registry import Result, benchmark

VSTIG = str(Path(sys.executable).with_name("vstig"))
_TICK = os.sysconf("SC_CLK_TCK")
RATE_HZ = 2000
COUNT = 10_000  # 5 s at RATE_HZ: enough CPU ticks (10 ms each) for a figure per message
ROUNDS = 3  # the pty relays' CPU: each relay's median of this many runs, the runs alternating
# Messages a relay takes per read: one per write (a radio's regime: the relay reads each as it comes), or ten at a
# time (a burst); both at RATE_HZ messages a second.
PER_READ = (1, 10)


class _Pty:
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


class _Arrivals:
    """Reads a pty's far end in a thread: the perf_counter time each message (by key) first arrived."""

    def __init__(self, pty: _Pty, record: bool = True) -> None:
        self.pty, self.record = pty, record
        self.arrived: dict[int, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        framing = make_serial_framing("cobs8")
        while not self._stop.is_set():
            if not select.select([self.pty.master], [], [], 0.05)[0]:
                continue
            data = os.read(self.pty.master, 65536)
            stamp = time.perf_counter()
            if self.record:
                for msg in framing.feed(data):
                    self.arrived.setdefault(msg.key, stamp)

    def wait(self, count: int, seconds: float = 10.0) -> None:
        end = time.monotonic() + seconds
        while len(self.arrived) < count and time.monotonic() < end:
            time.sleep(0.05)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def cobs8_frame(msg: Message) -> bytes:
    """The cobs8 frame a robot sends for `msg` (untagged)."""
    return make_serial_framing("cobs8").encode(msg)[0]


# What a robot sends for a message: its cobs8 frame (a relay's probe and the messages it is offered)
Frame = Callable[[Message], bytes]


def _frames(count: int, frame: Frame = cobs8_frame) -> list[bytes]:
    return [frame(Message(Op.PUT, i, i, 1, 7)) for i in range(count)]


def _writes(count: int, per_read: int, frame: Frame = cobs8_frame) -> list[bytes]:
    """`count` messages' frames, `per_read` of them a write (each write one read of the relay's)."""
    frames = _frames(count, frame)
    return [b"".join(frames[i:i + per_read]) for i in range(0, count, per_read)]


def _paced(write: Callable[[bytes], object], frames: list[bytes], rate_hz: int = RATE_HZ) -> list[float]:
    return _sleep_paced(len(frames), rate_hz, lambda i: write(frames[i]))


def _usage(pid: int) -> tuple[float, int]:
    """(CPU seconds, context switches) of every thread of process `pid` so far.

    CPU from the kernel's CPU-time clock of the whole process (clock_getcpuclockid(3): nanoseconds), where the
    kernel lets us read it; else utime+stime from /proc, in clock ticks (10 ms each).
    """
    try:
        cpu = time.clock_gettime((~pid << 3) | 2)  # MAKE_PROCESS_CPUCLOCK(pid, CPUCLOCK_SCHED)
    except OSError:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        cpu = (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime: the whole thread group
    switches = 0
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/status") as status:
                switches += sum(int(line.split()[1]) for line in status if "ctxt_switches" in line)
        except FileNotFoundError:  # a thread that ended meanwhile
            continue
    return cpu, switches


def _thread_cpu(task: str) -> float:
    """CPU seconds of one thread of this process: the scheduler's own sum (nanoseconds) where /proc shows it
    (`sched`), else utime+stime in clock ticks."""
    try:
        with open(f"{task}/sched") as sched:
            for line in sched:
                if line.startswith("se.sum_exec_runtime"):
                    return float(line.split(":")[1]) / 1e3  # milliseconds
    except FileNotFoundError:
        pass
    with open(f"{task}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICK


def _threads_usage(threads: list[threading.Thread]) -> tuple[float, int]:
    """(CPU seconds, context switches) of these threads of this process so far (Linux: /proc/self/task)."""
    cpu, switches = 0.0, 0
    for thread in threads:
        task = f"/proc/self/task/{thread.native_id}"
        try:
            thread_cpu = _thread_cpu(task)
            with open(f"{task}/status") as status:
                switches += sum(int(line.split()[1]) for line in status if "ctxt_switches" in line)
        except FileNotFoundError:
            continue
        cpu += thread_cpu
    return cpu, switches


def _delays(out: _Arrivals, sent: list[float]) -> list[float]:
    """Per message that arrived (keyed by its index), the time from sending it to its arrival."""
    return [out.arrived[i] - sent[i] for i in range(len(sent)) if i in out.arrived]


def _p50(values: list[float]) -> float:
    return _quantiles(values)[0]


QUANTILES = (("p50", 0.5), ("p90", 0.9), ("p99", 0.99))


def _quantiles(values: list[float]) -> tuple[float, ...]:
    """p50, p90, p99 of `values` (nan if none)."""
    ordered = sorted(values)
    return tuple(ordered[min(int(q * len(ordered)), len(ordered) - 1)] if ordered else float("nan")
                 for _, q in QUANTILES)


_BARE_HOP = """
import os, select, sys
a, b = (os.open(path, os.O_RDWR | os.O_NOCTTY) for path in sys.argv[1:3])
print("ready", flush=True)
while True:
    select.select([a], [], [])
    os.write(b, os.read(a, 65536))
"""

# The same hop writing what it read back onto A as well: the system calls an engine makes at one message per read
# (a serial radio gets its PUTs back, "Which links get a PUT back"), so the engine's anchor beside the bare hop.
_ECHOING_HOP = _BARE_HOP.replace("    os.write(b, os.read(a, 65536))",
                                 "    heard = os.read(a, 65536)\n    os.write(b, heard)\n    os.write(a, heard)")


# The least a Python relay of cobs8 frames does: cut and check the frames (our framing), re-encode, write.
# Beside it, the Node's own cost (threads, guard, outlets, counters) shows apart from the framing's.
_FRAMING_FLOOR = """
import os, select, sys
from vstig_hw.framing import make_serial_framing
inward, outward = make_serial_framing("cobs8"), make_serial_framing("cobs8")
a, b = (os.open(path, os.O_RDWR | os.O_NOCTTY) for path in sys.argv[1:3])
print("ready", flush=True)
while True:
    select.select([a], [], [])
    messages = inward.feed(os.read(a, 65536))
    if messages:
        os.write(b, b"".join(unit for msg in messages for unit in outward.encode(msg)))
"""


def _await(into: _Pty, out: _Arrivals, probe_key: int = 32767, seconds: float = 30.0,
           frame: Frame = cobs8_frame) -> None:
    end = time.monotonic() + seconds
    stamp = 0
    while time.monotonic() < end:
        stamp += 1
        os.write(into.master, frame(Message(Op.PUT, probe_key, 1, stamp, 7)))
        time.sleep(0.1)
        if probe_key in out.arrived:
            return
    raise RuntimeError(f"the relay never came up in {seconds:g} s")


@contextlib.contextmanager
def _relaying(argv: Callable[[str, str], list[str]], echo_back: bool, env: dict[str, str] | None = None,
              prefix: tuple[str, ...] = (), frame: Frame = cobs8_frame) -> Iterator[tuple[int, _Pty, _Arrivals]]:
    """Start a relay from a new pty A to a new pty B (`argv(A, B)`, after `prefix`, `env` added to its
    environment) and wait until it relays.

    Yields (its pid, A, B's arrivals); stops it and closes both ptys after.
    """
    a, b = _Pty(), _Pty()
    try:
        process = subprocess.Popen([*prefix, *argv(a.path, b.path)], stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, env={**os.environ, **(env or {})})
    except BaseException:
        a.close()
        b.close()
        raise
    out = _Arrivals(b)
    echo = _Arrivals(a, record=False) if echo_back else None  # an engine re-broadcasts onto A too: read it
    try:
        _await(a, out, seconds=150.0 if prefix else 30.0, frame=frame)  # a busy VM starts callgrind slowly
        yield process.pid, a, out
    finally:
        process.terminate()  # (callgrind writes its totals as the process exits)
        process.wait(timeout=120)
        out.close()
        if echo is not None:
            echo.close()
        a.close()
        b.close()


def _relay_run(argv: Callable[[str, str], list[str]], echo_back: bool, env: dict[str, str] | None = None,
               per_read: int = 1, frame: Frame = cobs8_frame) -> tuple[float, float, tuple[float, ...], int]:
    """(CPU s per message, switches per message, (p50, p90, p99) delay s, delivered) of a process relaying pty A ->
    pty B, offered COUNT messages at RATE_HZ, `per_read` a write (the delays: one per message of a one-per-read run),
    each message as `frame` makes it."""
    with _relaying(argv, echo_back, env, frame=frame) as (pid, a, out):
        writes = _writes(COUNT, per_read, frame)
        cpu0, sw0 = _usage(pid)
        sent = _paced(lambda w: os.write(a.master, w), writes, rate_hz=RATE_HZ // per_read)
        out.wait(COUNT + 1)
        cpu1, sw1 = _usage(pid)
    delays = _delays(out, sent) if per_read == 1 else []
    delivered = len(delays) if per_read == 1 else sum(1 for i in range(COUNT) if i in out.arrived)
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, _quantiles(delays), delivered


def _raw(a: str, b: str) -> list[str]:
    return [VSTIG, "bridge", f"serial:{a}?framing=cobs8", f"serial:{b}?framing=cobs8", "--raw"]


def _engine(a: str, b: str) -> list[str]:
    return [VSTIG, "bridge", f"serial:{a}?framing=cobs8", f"serial:{b}?framing=cobs8", "--robot-id", "200",
            "--budget", "2000", "--no-refresh"]


# A relay: its argv for pty paths A, B; whether it re-broadcasts onto A; extra environment.
Relay = tuple[Callable[[str, str], list[str]], bool, dict[str, str]]

_PURE = {"VSTIG_PURE": "1"}  # the bridge's pure-Python path (vstig_hw/native.py)

# The pty -> pty relays measured, in the order they run (argv for pty paths A, B; whether it re-broadcasts onto A;
# extra environment): each bridge on the compiled data path, then on the pure-Python one, alternating.
_RELAYS: dict[str, Relay] = {
    "bare": (lambda a, b: [sys.executable, "-c", _BARE_HOP, a, b], False, {}),
    "echoing": (lambda a, b: [sys.executable, "-c", _ECHOING_HOP, a, b], True, {}),
    "floor": (lambda a, b: [sys.executable, "-c", _FRAMING_FLOOR, a, b], False, {}),
    "raw": (_raw, False, {}),
    "raw_pure": (_raw, False, _PURE),
    "engine": (_engine, True, {}),
    "engine_pure": (_engine, True, _PURE),
}


# The relays measured again at ten messages per read (the pure ones and the floor only at one: they tell the
# compiled path's gain, which a burst does not change).
_TEN_PER_READ = ("bare", "raw", "engine")

Run = tuple[float, float, tuple[float, ...], int]


def _median_run(runs: list[Run]) -> Run:
    """The run of median CPU (of an odd count; the upper one of an even count)."""
    return sorted(runs, key=lambda run: run[0])[len(runs) // 2]


@benchmark("datapath")
def relay_cost() -> Iterator[Result]:
    """Every relay, the bare hop included, runs ROUNDS times at one message per read and the compiled ones and the
    bare hop at ten, round after round (one run of each in turn); each keeps its run of median CPU (a shared VM's
    load moves one run of the bare hop by half: 10 to 17 us a message)."""
    rounds: dict[tuple[str, int], list[Run]] = {}
    for _ in range(ROUNDS):
        for per_read in PER_READ:
            for name, relay in _RELAYS.items():
                if per_read == 1 or name in _TEN_PER_READ:
                    rounds.setdefault((name, per_read), []).append(_relay_run(*relay, per_read=per_read))
    runs = {name: _median_run(rounds[name, 1]) for name in _RELAYS}
    bare, floor = runs["bare"], runs["floor"]
    bare_ten = _median_run(rounds["bare", 10])
    for name in _TEN_PER_READ[1:]:
        ten = _median_run(rounds[name, 10])
        yield Result(f"datapath.relay_{name}_ten_per_read_cpu_per_msg", ten[0] * 1e6, "us",
                     "bare pty hop CPU/msg, ten per read", bare_ten[0] * 1e6)
        yield Result(f"datapath.relay_{name}_ten_per_read_delivered", ten[3] / COUNT * 100, "%", "offered", 100.0)
    yield Result("datapath.relay_engine_cpu_vs_echoing_hop", runs["engine"][0] * 1e6, "us",
                 "pty hop writing back too CPU/msg", runs["echoing"][0] * 1e6)
    yield Result("datapath.relay_echoing_hop_cpu_per_msg", runs["echoing"][0] * 1e6, "us", "bare pty hop CPU/msg",
                 bare[0] * 1e6)
    for name, run in ((name, runs[name]) for name in ("raw", "raw_pure", "engine", "engine_pure")):
        yield Result(f"datapath.relay_{name}_cpu_per_msg", run[0] * 1e6, "us", "bare pty hop CPU/msg", bare[0] * 1e6)
        yield Result(f"datapath.relay_{name}_switches_per_msg", run[1], "switches", "bare pty hop switches/msg",
                     bare[1])
        for (label, _), ours, anchor in zip(QUANTILES, run[2], bare[2], strict=True):
            yield Result(f"datapath.relay_{name}_{label}", ours * 1e3, "ms", f"bare pty hop {label}", anchor * 1e3)
        yield Result(f"datapath.relay_{name}_delivered", run[3] / COUNT * 100, "%", "offered", 100.0)
        yield Result(f"datapath.relay_{name}_cpu_vs_framing_floor", run[0] * 1e6, "us",
                     "Python cobs8 relay without a Node CPU/msg", floor[0] * 1e6)
    for name in ("raw", "engine"):
        yield Result(f"datapath.relay_{name}_cpu_compiled_vs_pure", runs[name][0] * 1e6, "us",
                     "the pure-Python path CPU/msg", runs[f"{name}_pure"][0] * 1e6)
    yield Result("datapath.relay_framing_floor_cpu_per_msg", floor[0] * 1e6, "us", "bare pty hop CPU/msg",
                 bare[0] * 1e6)


def _instructions(name: str, count: int, workdir: Path, relay: Relay | None = None, per_read: int = 1,
                  frame: Frame = cobs8_frame) -> int:
    """User-space instructions (callgrind's Ir) relay `name` (of _RELAYS, unless `relay` gives its argv, echo and
    environment) executed in all, having relayed `count` messages, `per_read` a write, each as `frame` makes it."""
    out_file = workdir / f"{name}.{count}.{per_read}.callgrind"
    callgrind = ("valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}")
    with _relaying(*(relay or _RELAYS[name]), prefix=callgrind, frame=frame) as (_pid, a, out):  # (env passed on)
        _paced(lambda w: os.write(a.master, w), _writes(count, per_read, frame),
               rate_hz=INSTRUCTIONS_RATE_HZ // per_read)
        out.wait(count + 1, seconds=60)
    if len(out.arrived) < count + 1:
        raise RuntimeError(f"{name} under callgrind relayed {len(out.arrived) - 1} of {count} messages")
    return _totals(out_file)


def _totals(out_file: Path) -> int:
    """The instructions a callgrind output file counts in all."""
    for line in out_file.read_text().splitlines():
        if line.startswith(("totals:", "summary:")):
            return int(line.split()[1])
    raise RuntimeError(f"no totals in {out_file}")


INSTRUCTIONS_RATE_HZ = 200  # slow enough for an engine under callgrind (~50x slower) to take each message alone


def instructions_per_msg(label: str, relays: Mapping[str, Relay], per_read: int = 1,
                         frames: Mapping[str, Frame] | None = None, many: int = 2500) -> dict[str, float] | None:
    """User-space instructions per relayed message of each relay, in order (callgrind), `per_read` messages a
    write (each as `frames` says for that relay, else untagged): a run of `many` messages less one of 500, so
    start-up and imports cancel out (start-up itself wobbles by ~1M instructions a run: +-500 a message at 2,500, +-100
    at 10,000). None, said on stderr under `label`, without valgrind; a RuntimeError naming the relay when one does
    not relay."""
    if shutil.which("valgrind") is None:
        print(f"{label}: needs valgrind (apt-get install valgrind)", file=sys.stderr)
        return None
    per_msg = {}
    with tempfile.TemporaryDirectory(prefix="vstig-bench-") as tmp:
        for name, relay in relays.items():
            try:
                frame = (frames or {}).get(name, cobs8_frame)
                few, most = (_instructions(name, count, Path(tmp), relay, per_read, frame) for count in (500, many))
            except RuntimeError as error:
                raise RuntimeError(f"{name}: {error}") from error
            per_msg[name] = (most - few) / (many - 500)
    return per_msg


@benchmark("datapath")
def relay_instructions() -> Iterator[Result]:
    """Instructions per relayed message (callgrind, so the same on a busy or an idle VM). User space only: the
    kernel's pty and wake-up work, which every relay pays alike, is not counted."""
    per_msg = instructions_per_msg("datapath.relay_instructions", _RELAYS)
    if per_msg is None:
        return
    for name in ("floor", "raw", "raw_pure", "engine", "engine_pure"):
        yield Result(f"datapath.relay_{name}_instructions_per_msg", per_msg[name], "instr", "bare pty hop instr/msg",
                     per_msg["bare"])
    yield Result("datapath.relay_engine_instructions_vs_echoing_hop", per_msg["engine"], "instr",
                 "pty hop writing back too instr/msg", per_msg["echoing"])
    for name in ("raw", "engine"):
        yield Result(f"datapath.relay_{name}_instructions_vs_framing_floor", per_msg[name], "instr",
                     "Python cobs8 relay without a Node instr/msg", per_msg["floor"])
        yield Result(f"datapath.relay_{name}_instructions_compiled_vs_pure", per_msg[name], "instr",
                     "the pure-Python path instr/msg", per_msg[f"{name}_pure"])
    ten = instructions_per_msg("datapath.relay_instructions", {name: _RELAYS[name] for name in _TEN_PER_READ},
                               per_read=10)
    assert ten is not None  # valgrind was there a moment ago
    for name in _TEN_PER_READ[1:]:
        yield Result(f"datapath.relay_{name}_ten_per_read_instructions_per_msg", ten[name], "instr",
                     "bare pty hop instr/msg, ten per read", ten["bare"])


def _healthy_delay(deaf: bool) -> tuple[float, int]:
    """(p50 delay, delivered) from radio A to radio B of an engine bridge, beside a radio never read if `deaf`."""
    source, healthy, stuck = _Pty(), _Pty(), _Pty()
    radios = [source, healthy, stuck] if deaf else [source, healthy]
    process = subprocess.Popen([VSTIG, "bridge", *(f"serial:{r.path}?framing=cobs8" for r in radios),
                                "--robot-id", "200", "--budget", "2000", "--no-refresh"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out, echo = _Arrivals(healthy), _Arrivals(source, record=False)
    count = 5000
    try:
        _await(source, out)
        sent = _paced(lambda f: os.write(source.master, f), _frames(count), rate_hz=500)
        out.wait(count + 1)
    finally:
        process.terminate()
        process.wait(timeout=20)
        out.close()
        echo.close()
        for radio in (source, healthy, stuck):
            radio.close()
    delays = _delays(out, sent)
    return _p50(delays), len(delays)


@benchmark("datapath")
def deaf_radio() -> Iterator[Result]:
    alone, alone_got = _healthy_delay(deaf=False)
    beside, beside_got = _healthy_delay(deaf=True)
    yield Result("datapath.healthy_p50_beside_deaf_radio", beside * 1e3, "ms", "same bridge, no deaf radio",
                 alone * 1e3)
    yield Result("datapath.healthy_delivered_beside_deaf_radio", beside_got, "messages", "same bridge, no deaf radio",
                 alone_got)


def _zenoh_session(endpoint: str) -> Any:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


@benchmark("datapath")
def zenoh_samples_per_relayed_message() -> Iterator[Result]:
    from .zenoh_peer import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    radio = _Pty()
    process = subprocess.Popen([VSTIG, "bridge", f"zenoh:lab?listen={endpoint}", f"serial:{radio.path}?framing=cobs8",
                                "--robot-id", "200", "--no-refresh"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    out = _Arrivals(radio)
    peer = None
    samples = messages = 0
    lock = threading.Lock()

    def heard(sample: Any) -> None:
        nonlocal samples, messages
        with lock:
            samples += 1
            messages += len(sample.payload) // 8

    count = 500
    try:
        time.sleep(0.5)
        peer = _zenoh_session(endpoint)
        subscriber = peer.declare_subscriber("vstig/lab/0/200", heard)
        for stamp in range(1, 300):  # until the bridge hears this session
            peer.put("vstig/lab/0/301", encode(Message(Op.PUT, 32767, 1, stamp, 301)))
            time.sleep(0.1)
            if 32767 in out.arrived:
                break
        time.sleep(0.5)
        with lock:
            samples = messages = 0
        cobs8 = make_serial_framing("cobs8")
        for i in range(count):  # one message from zenoh, one from the radio, every 4 ms
            peer.put("vstig/lab/0/301", encode(Message(Op.PUT, i, i, 1, 301)))
            os.write(radio.master, cobs8.encode(Message(Op.PUT, 10_000 + i, i, 1, 7))[0])
            time.sleep(0.004)
        time.sleep(1.0)
        subscriber.undeclare()
    finally:
        if peer is not None:
            peer.close()
        process.terminate()
        process.wait(timeout=20)
        out.close()
        radio.close()
    yield Result("datapath.zenoh_samples_per_relayed_msg", samples / count, "samples/msg",
                 "one per message relayed onto zenoh", 1.0)
    yield Result("datapath.zenoh_msgs_published_per_relayed_msg", messages / count, "msgs/msg",
                 "no echo of what zenoh carried", 1.0)


def _can_to_pty(relay: str) -> tuple[float, float, int, tuple[float, ...]]:
    """(CPU s and switches per message of the relay's own threads, delivered, (p50, p90, p99) delay s), in this
    process: a robot on a python-can virtual bus, a relay to a cobs8 pty radio (our gateway's loop, reader and
    writer threads, or a bare recv -> encode -> os.write thread), the radio's far end read here."""
    import can

    from vstig_hw.framing.can import can_framing_for
    from vstig_hw.gateway import Node
    from vstig_hw.links import parse

    channel = f"bench-datapath-{os.getpid()}-{relay}"
    robot = can.Bus(interface="virtual", channel=channel)
    radio = _Pty()
    out = _Arrivals(radio)
    codec = can_framing_for(7)
    frames = [codec.encode(Message(Op.PUT, i, i, 1, 7))[0] for i in range(COUNT)]
    probe = codec.encode(Message(Op.PUT, 32767, 1, 1, 7))[0]
    stop = threading.Event()
    cobs8 = make_serial_framing("cobs8")
    if relay == "bare":
        bus = can.Bus(interface="virtual", channel=channel)

        def bare() -> None:
            while not stop.is_set():
                frame = bus.recv(0.05)
                if frame is not None:
                    os.write(radio.slave, cobs8.encode(decode(bytes(frame.data)))[0])

        worker = threading.Thread(target=bare, daemon=True)
        node = None
    else:
        links = [parse(f"can:virtual:{channel}").build("bus", robot_id=200),
                 parse(f"serial:{radio.path}?framing=cobs8").build("radio", robot_id=200)]
        node = Node(links, 200, budget=20_000)
    if node is None:
        worker.start()
    else:
        node.open()  # the loop runs on the node's own thread
        worker = node._loop.thread
    try:
        for _ in range(100):
            robot.send(probe)
            time.sleep(0.05)
            if 32767 in out.arrived:
                break
        relay_threads = [worker] if node is None else [worker, *node._lifecycle.reader_threads]  # loop, readers
        cpu0, sw0 = _threads_usage(relay_threads)
        sent = _paced(robot.send, frames)  # type: ignore[arg-type]
        out.wait(COUNT + 1)
        if node is not None:  # a writer thread starts only when a device is slow: count it if it did
            relay_threads += [t for t in (o.writer._thread for o in node.outlets) if t is not None]
        cpu1, sw1 = _threads_usage(relay_threads)
    finally:
        stop.set()
        if node is not None:
            node.close()
        else:
            worker.join(timeout=5)
            bus.shutdown()
        robot.shutdown()
        out.close()
        radio.close()
    delays = _delays(out, sent)
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, len(delays), _quantiles(delays)


@benchmark("datapath")
def can_to_pty_cost() -> Iterator[Result]:
    bare = _can_to_pty("bare")
    ours = _can_to_pty("gateway")
    yield Result("datapath.relay_can_pty_cpu_per_msg", ours[0] * 1e6, "us",
                 "bare virtual bus -> pty hop thread CPU/msg", bare[0] * 1e6)
    yield Result("datapath.relay_can_pty_switches_per_msg", ours[1], "switches",
                 "bare virtual bus -> pty hop switches/msg", bare[1])
    yield Result("datapath.relay_can_pty_delivered", ours[2] / COUNT * 100, "%", "offered", 100.0)
    # The gateway's latency against the same hop without it (cli.gateway_latency's anchor is a write with no hop).
    for (label, _), our_delay, bare_delay in zip(QUANTILES, ours[3], bare[3], strict=True):
        yield Result(f"datapath.relay_can_pty_{label}", our_delay * 1e3, "ms", f"bare virtual bus -> pty hop {label}",
                     bare_delay * 1e3)


FD_BUS_MSGS_PER_S = 47_400  # a saturated CAN FD bus, 5 Mbit/s data phase, 8 messages (64 bytes) per frame


@benchmark("datapath")
def canfd_relay_capacity() -> Iterator[Result]:
    """Messages a raw bridge relays CAN FD -> CAN FD (python-can virtual buses, in this process), offered at the
    rate of a saturated 5 Mbit/s FD bus, per second of its own threads' CPU: what one core would carry."""
    import can

    from vstig_hw.framing.can import CanFraming, CanIdScheme
    from vstig_hw.gateway import Mode, Node
    from vstig_hw.links import parse

    tag = f"{os.getpid()}"
    robot = can.Bus(interface="virtual", channel=f"fd-in-{tag}")
    sink = can.Bus(interface="virtual", channel=f"fd-out-{tag}")  # a receiver on the far bus (never read)
    codec = CanFraming(CanIdScheme(), sender=7, fd=True)
    frames = codec.encode_batch([Message(Op.PUT, i % 32768, i // 32768, 1, 7) for i in range(8 * 20_000)])
    links = [parse(f"can:virtual:fd-in-{tag}?fd=1").build("in", robot_id=200),
             parse(f"can:virtual:fd-out-{tag}?fd=1").build("out", robot_id=200)]
    node = Node(links, 200, mode=Mode.RAW, budget=None)
    node.open()  # the loop runs on the node's own thread
    try:
        threads = [node._loop.thread, *node._lifecycle.reader_threads]
        cpu0, _ = _threads_usage(threads)
        _sleep_paced(len(frames), FD_BUS_MSGS_PER_S // 8, lambda i: robot.send(frames[i]))  # a saturated FD bus
        end = time.monotonic() + 20
        while links[1].counters["out"] < 8 * len(frames) and time.monotonic() < end:
            time.sleep(0.05)
        threads += [t for t in (o.writer._thread for o in node.outlets) if t is not None]
        cpu1, _ = _threads_usage(threads)
        relayed = links[1].counters["out"]
    finally:
        node.close()
        robot.shutdown()
        sink.shutdown()
    yield Result("datapath.canfd_relay_msgs_per_cpu_s", relayed / max(cpu1 - cpu0, 1e-9), "msg/s of a core",
                 "saturated 5 Mbit/s CAN FD bus", FD_BUS_MSGS_PER_S)
    yield Result("datapath.canfd_relay_delivered", relayed / (8 * len(frames)) * 100, "%", "offered", 100.0)
