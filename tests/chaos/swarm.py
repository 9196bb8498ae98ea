"""The robots of the chaos soak, in a process of their own: their radios, the slcan adapter, and the judge.

Each robot owns its keys and writes them round-robin, a PUT whose value is its
timestamp (so anything else heard under those keys is a lie). A radio robot talks
cobs8 over a pty; the CAN robot sits behind an slcan adapter we play on a pty: it
answers the host's commands with CR, acknowledges each frame the host sends (z), and
reports the robot's frames as `t` lines. Every device is reached by the gateways
through a symlink in the run's folder, so an unplugged one comes back under the same
name on a new pty.

The judge: every write is owed to every other robot. A robot has it once it has heard
that key at that timestamp or later (anything newer supersedes it, as in a robot's
table). A pair settled within LATE_S is on time; one settled later is late, and one
never settled lost, unless a fault touched its path meanwhile (then it is excused:
`Faults.excuses`). Writes are registered when their last byte is on the wire.
"""

from __future__ import annotations

import collections
import contextlib
import os
import random
import select
import time
import tty
from dataclasses import dataclass, field
from typing import Any

import can

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.base import Framing
from vstig_hw.framing.can import CanFraming, CanIdScheme

LATE_S = 2.0  # a pair settled later than this is late
STEP = 0.005  # seconds between two looks at the radios
KEYS_EACH = 10  # keys each robot writes, round-robin
LIAR = 66  # the lying robot's id (it claims other robots' keys far ahead)


def key_of(robot: int, index: int) -> int:
    return robot * 100 + index


def owner_of(key: int) -> int:
    return key // 100


@dataclass
class Device:
    """A robot's radio or adapter: the pty master we hold, and the name the gateway opens."""

    link: str  # the symlink the gateway opens
    master: int = -1
    slave: int = -1  # held open, so the pty lives while no gateway has it
    out: bytearray = field(default_factory=bytearray)  # bytes begun and not yet taken
    listening: bool = True
    plugged: bool = False

    def plug(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        temporary = f"{self.link}.new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        os.symlink(os.ttyname(self.slave), temporary)
        os.replace(temporary, self.link)  # the gateway's next open finds the new one
        self.out.clear()
        self.listening, self.plugged = True, True

    def unplug(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.link)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        self.plugged = False

    def fill(self) -> None:
        """Stop reading, and fill the line to us until the gateway's writes would block (a hung adapter)."""
        self.listening = False
        fd = os.open(os.ttyname(self.slave), os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
        try:
            while True:
                try:
                    os.write(fd, b"x" * 4096)
                except BlockingIOError:
                    if not select.select([], [fd], [], 0.3)[1]:
                        return
        finally:
            os.close(fd)


class Robot:
    def __init__(self, robot_id: int, device: Device, rate: float, *, on_can: bool = False) -> None:
        self.id = robot_id
        self.device = device
        self.rate = rate
        self.on_can = on_can
        self.keys = [key_of(robot_id, i) for i in range(KEYS_EACH)]
        self.ts = dict.fromkeys(self.keys, 0)  # the last timestamp written per key
        self.sent = 0  # writes on the wire
        self._turn = 0
        self.encoder: Framing | CanFraming = CanFraming(CanIdScheme(), sender=robot_id) if on_can \
            else make_serial_framing("cobs8")
        self.decoder: Any = CanFraming(CanIdScheme(), sender=robot_id) if on_can else make_serial_framing("cobs8")
        self.lines = b""  # the adapter's half line from the host

    def next_write(self) -> Message:
        key = self.keys[self._turn % KEYS_EACH]
        self._turn += 1
        ts = self.ts[key] + 1
        return Message(Op.PUT, key, ts & 0xFFFF, ts, self.id)

    def wire(self, msg: Message) -> bytes:
        if not self.on_can:
            return b"".join(self.encoder.encode(msg))  # type: ignore[arg-type]
        return b"".join(slcan_line(frame) for frame in self.encoder.encode(msg))  # type: ignore[arg-type]


def slcan_line(frame: can.Message) -> bytes:
    head = f"T{frame.arbitration_id:08X}" if frame.is_extended_id else f"t{frame.arbitration_id:03X}"
    return f"{head}{len(frame.data)}{bytes(frame.data).hex().upper()}\r".encode()


def parse_host_line(line: bytes) -> can.Message | None:
    """A frame line the host (the gateway) wrote; None for a command or noise."""
    if line[:1] not in (b"t", b"T"):
        return None
    width = 3 if line[:1] == b"t" else 8
    try:
        can_id = int(line[1:1 + width], 16)
        size = int(line[1 + width:2 + width], 16)
        data = bytes.fromhex(line[2 + width:2 + width + 2 * size].decode())
    except (ValueError, UnicodeDecodeError):
        return None
    if len(data) != size:
        return None
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=width == 8)


class Faults:
    """What the harness says went wrong where, and when: each fault's parts and its window (end None: ongoing)."""

    def __init__(self) -> None:
        self.windows: dict[int, tuple[frozenset[tuple[Any, ...]], float, float | None]] = {}

    def open(self, fault: int, parts: frozenset[tuple[Any, ...]], start: float) -> None:
        self.windows[fault] = (parts, start, None)

    def close(self, fault: int, end: float) -> None:
        parts, start, _ = self.windows[fault]
        self.windows[fault] = (parts, start, end)

    def excuses(self, parts: frozenset[tuple[Any, ...]], start: float, end: float) -> bool:
        """Whether a fault touched any of `parts` between `start` and `end`."""
        return any(touched & parts and begun <= end and (over is None or over >= start)
                   for touched, begun, over in self.windows.values())


@dataclass
class Tally:
    on_time: int = 0
    late: int = 0
    lost: int = 0
    excused: int = 0
    delays: list[float] = field(default_factory=list)  # of pairs judged, sampled (1 in 16)
    late_examples: list[str] = field(default_factory=list)


class Judge:
    """Every write against every other robot (see the module docstring)."""

    def __init__(self, robots: list[Robot], gateway_of: dict[int, int], faults: Faults, t0: float = 0.0) -> None:
        self.t0 = t0  # when the run began (monotonic), for the examples it gives
        self.robots = robots
        self.gateway_of = gateway_of
        self.faults = faults
        self.tally = Tally()
        self.newest: dict[tuple[int, int], int] = {}  # (robot, key) -> newest timestamp it has heard
        self.owed: dict[tuple[int, int], collections.deque[tuple[int, float]]] = collections.defaultdict(
            collections.deque)  # (robot, key) -> writes not yet heard: (timestamp, when written)
        self.written: dict[int, int] = {}  # key -> newest timestamp on the wire
        self._sample = 0

    def parts(self, writer: int, reader: int) -> frozenset[tuple[Any, ...]]:
        a, b = self.gateway_of[writer], self.gateway_of[reader]
        parts = {("from", writer), ("to", reader), ("gateway", a), ("gateway", b)}
        if a != b:
            parts.add(("zenoh", min(a, b), max(a, b)))
        return frozenset(parts)

    def wrote(self, robot: Robot, msg: Message, now: float) -> None:
        self.written[msg.key] = msg.timestamp
        for other in self.robots:
            if other is not robot:
                self.owed[other.id, msg.key].append((msg.timestamp, now))

    def heard(self, robot: Robot, msg: Message, now: float) -> None:
        owner = owner_of(msg.key)
        if msg.robot != owner or msg.value != msg.timestamp & 0xFFFF or owner == robot.id:
            return  # not an honest write (a lie that got through would show as writes lost), or its own
        key = (robot.id, msg.key)
        if msg.timestamp <= self.newest.get(key, 0):
            return
        self.newest[key] = msg.timestamp
        owed = self.owed.get(key)
        while owed and owed[0][0] <= msg.timestamp:
            _, written = owed.popleft()
            self._settle(owner, robot.id, written, now)

    def _settle(self, writer: int, reader: int, written: float, now: float) -> None:
        delay = now - written
        tally = self.tally
        if delay <= LATE_S:
            tally.on_time += 1
        elif self.faults.excuses(self.parts(writer, reader), written, written + delay):
            tally.excused += 1
            return
        else:
            tally.late += 1
            if len(tally.late_examples) < 5:
                tally.late_examples.append(f"robot {writer} -> {reader}: {delay:.1f} s, written at "
                                           f"{written - self.t0:.0f} s")
        self._sample += 1
        if self._sample % 16 == 0:
            tally.delays.append(delay)

    def finish(self, now: float) -> None:
        """The end of the run: every write still owed is lost, unless a fault touched its path."""
        for (reader, key), owed in self.owed.items():
            for _, written in owed:
                if self.faults.excuses(self.parts(owner_of(key), reader), written, now):
                    self.tally.excused += 1
                else:
                    self.tally.lost += 1
            owed.clear()

    def converged(self, target: dict[int, int]) -> bool:
        """Whether every robot has heard every other robot's key at `target`'s timestamp or later."""
        newest = self.newest
        return all(newest.get((robot.id, key), 0) >= ts for robot in self.robots
                   for key, ts in target.items() if owner_of(key) != robot.id)


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


class Swarm:
    """The robots and their devices; `serve` runs them until the harness says "report"."""

    def __init__(self, folder: str, layout: list[tuple[int, int, bool]], rate: float, t0: float) -> None:
        """`layout`: (robot id, gateway index, on CAN) per robot; `rate`: writes a second, all robots together."""
        each = rate / len(layout)
        self.robots = []
        for robot_id, _, on_can in layout:
            device = Device(os.path.join(folder, f"can{robot_id}" if on_can else f"radio{robot_id}"))
            device.plug()
            self.robots.append(Robot(robot_id, device, each, on_can=on_can))
        self.by_id = {robot.id: robot for robot in self.robots}
        self.faults = Faults()
        self.judge = Judge(self.robots, {robot_id: gw for robot_id, gw, _ in layout}, self.faults, t0)
        self.writing = True
        self.lies = 0
        self.liar_on: Robot | None = None  # the robot whose radio the liar shares, while it lies
        self.converging: list[tuple[int, float, dict[int, int]]] = []  # (fault, healed at, what must arrive)
        self.convergence: dict[int, float | None] = {}  # fault -> seconds to converge after its heal (None: not)
        self.converge_within = 20.0
        self.garbage_bytes = 0
        self.noisy: tuple[Robot, int] | None = None  # a robot whose line gets a burst of noise every half second
        self._next_noise = 0.0

    # -- commands from the harness --------------------------------------------------
    def command(self, what: str, *args: Any) -> Any:
        now = time.monotonic()
        if what == "fault":
            fault, parts, start = args
            self.faults.open(fault, frozenset(parts), start)
        elif what == "healed":
            fault, end, settle = args
            self.faults.close(fault, end + settle)
            self.converging.append((fault, end, dict(self.judge.written)))
            self.convergence[fault] = None
        elif what == "deafen":
            self.by_id[args[0]].device.fill()
        elif what == "hear":
            self.by_id[args[0]].device.listening = True
        elif what == "unplug":
            self.by_id[args[0]].device.unplug()
        elif what == "replug":
            robot = self.by_id[args[0]]
            robot.device.plug()
            robot.decoder = CanFraming(CanIdScheme(), sender=robot.id) if robot.on_can \
                else make_serial_framing("cobs8")
            robot.lines = b""
        elif what == "garbage":
            self.noisy = (self.by_id[args[0]], args[1]) if args[1] else None
        elif what == "lie":
            self.liar_on = self.by_id[args[0]] if args[0] is not None else None
        elif what == "stop-writing":
            self.writing = False
        elif what == "converge-within":
            self.converge_within = args[0]
        return now

    def _garbage(self, robot: Robot, size: int) -> None:
        """Noise on the robot's line toward the gateway, ending as a frame or line does: it costs only itself."""
        noise = random.randbytes(size)
        noise = noise.replace(b"\r", b"") + b"\r" if robot.on_can else noise + b"\x00"  # it costs only itself
        if not robot.device.plugged or robot.device.out:  # never inside a frame the line has half taken
            return
        if self._put(robot.device, noise):
            self.garbage_bytes += len(noise)

    # -- the robots' loop --------------------------------------------------------
    def step(self, started: float) -> None:
        now = time.monotonic()
        if self.writing:
            for robot in self.robots:
                self._write(robot, now - started)
            if self.liar_on is not None:
                self._lie(self.liar_on)
            if self.noisy is not None and now >= self._next_noise:
                self._next_noise = now + 0.5
                self._garbage(*self.noisy)
        masters = {r.device.master: r for r in self.robots if r.device.plugged and r.device.listening}
        readable = select.select(list(masters), [], [], STEP)[0]
        now = time.monotonic()
        for fd in readable:
            robot = masters[fd]
            try:
                data = os.read(fd, 65536)
            except OSError:  # BlockingIOError, or EIO while no gateway has the pty open
                continue
            for msg in self._decode(robot, data):
                self.judge.heard(robot, msg, now)
        if now >= self._next_look:
            self._next_look = now + 0.1
            self._check_convergence(now)

    _next_look = 0.0  # when convergence is checked next

    def _write(self, robot: Robot, elapsed: float) -> None:
        device = robot.device
        if not device.plugged:
            return
        if device.out:  # what the line has not taken yet goes first, whole
            self._put(device, bytes(device.out))
            if device.out:
                return
        due = int(elapsed * robot.rate) - robot.sent
        for _ in range(max(0, min(due, 50))):
            msg = robot.next_write()
            if not self._put(device, robot.wire(msg)):  # the line takes nothing now: the robot waits
                return
            robot.ts[msg.key] = msg.timestamp
            robot.sent += 1
            self.judge.wrote(robot, msg, time.monotonic())  # begun: the rest goes before anything else
            if device.out:
                return
        if due > 50:  # fallen behind (a line that was full): the robot does not catch up in a burst
            robot.sent += due - 50

    def _put(self, device: Device, data: bytes) -> bool:
        """Write `data` (what the line does not take waits in `device.out`); False if the line took none."""
        try:
            taken = os.write(device.master, data)
        except (BlockingIOError, OSError):
            return False
        device.out[:] = data[taken:]
        return taken > 0

    def _lie(self, robot: Robot) -> None:
        """A robot sharing `robot`'s radio claims other robots' keys far ahead, a few times a second."""
        if random.random() > 0.05:
            return
        victim = random.choice([r for r in self.robots if r is not robot])
        key = random.choice(victim.keys)
        ts = (victim.ts[key] + 5000) & 0xFFFF
        lie = Message(Op.PUT, key, (ts + 1) & 0xFFFF, ts, victim.id)  # its value gives it away to the judge
        liar = Robot(LIAR, robot.device, 0.0, on_can=robot.on_can)
        if robot.device.plugged and not robot.device.out and self._put(robot.device, liar.wire(lie)):
            self.lies += 1

    def _decode(self, robot: Robot, data: bytes) -> list[Message]:
        if not robot.on_can:
            return list(robot.decoder.feed(data))
        lines = (robot.lines + data).split(b"\r")
        robot.lines = lines.pop()[-256:]
        heard: list[Message] = []
        answers = b""
        for line in lines:
            frame = parse_host_line(line.lstrip(b"x"))
            if frame is None:
                if line[:1] in (b"O", b"C", b"L", b"S", b"s", b"V", b"N", b"F"):
                    answers += b"\r"  # a command: OK
                continue
            answers += b"z\r"  # the frame went on the bus
            heard.extend(robot.decoder.feed(frame))
        if answers:
            with contextlib.suppress(OSError):
                os.write(robot.device.master, answers)
        return heard

    def _check_convergence(self, now: float) -> None:
        still = []
        for fault, healed, target in self.converging:
            if self.judge.converged(target):
                self.convergence[fault] = now - healed
            elif now - healed < self.converge_within:
                still.append((fault, healed, target))
        self.converging = still

    def report(self, now: float) -> dict[str, Any]:
        self.judge.finish(now)
        tally = self.judge.tally
        return {
            "writes": sum(r.sent for r in self.robots), "on_time": tally.on_time, "late": tally.late,
            "lost": tally.lost, "excused": tally.excused, "late_examples": tally.late_examples,
            "p50": percentile(tally.delays, 0.5), "p99": percentile(tally.delays, 0.99),
            "max": max(tally.delays, default=float("nan")), "convergence": self.convergence, "lies": self.lies,
            "garbage_bytes": self.garbage_bytes,
        }


def serve(folder: str, layout: list[tuple[int, int, bool]], rate: float, t0: float, conn: Any) -> None:
    """The child process: run the swarm, obey the harness's commands (answering each with the time it was done)."""
    swarm = Swarm(folder, layout, rate, t0)
    conn.send("ready")
    started = time.monotonic()
    while True:
        while conn.poll():
            what, *args = conn.recv()
            if what == "report":
                conn.send(swarm.report(time.monotonic()))
                return
            conn.send(swarm.command(what, *args))
        swarm.step(started)

