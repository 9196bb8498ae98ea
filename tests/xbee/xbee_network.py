"""An XBee radio network on ptys, written from Digi's published API frame format (not from vstig_hw).

Each `Module` owns a pty: its host (a `vstig` through pyserial, or a robot) opens the slave end as
it would /dev/ttyUSB0, and one network thread plays every module's firmware on the master ends:

- API mode 1, 2 (escaped: 0x7E, 0x7D, 0x11, 0x13 as 0x7D, byte ^ 0x20 after the start
  delimiter), or 0 (transparent: the host's bytes go on the air as they are and no frame is
  answered, which is what a host speaking API to a module left in AT mode meets);
- local AT commands (0x08, 0x09): AP, NP, SH, SL answered (0x88); any other is status 2;
  frame id 0 asks for no answer;
- Transmit Requests (0x10): RF data above NP is refused with a Transmit Status (0x8B) of
  0x74; otherwise it goes to every other module (broadcast 000000000000FFFF) or to the one
  addressed, each delivery lost with probability `loss` and late by `delay` (+ up to
  `jitter`) seconds, and the status (frame id not 0) says 0x00, or 0x21 for a unicast
  nobody has;
- Receive Packets (0x90) to each receiving module's host: 64-bit source, 16-bit 0xFFFE,
  options 0x02 (broadcast) or 0x01, RF data;
- its serial buffer toward the host: at most `host_buffer` bytes wait for the host to read
  (after what the pty itself holds); a frame that does not fit is dropped and counted
  (`host_overflow`), as a module with no flow control loses RF data its host does not take;
- `deaf`: the module stops reading its UART, so its host's writes fill the pty and block.

Bad frames from a host (checksum, escapes, lengths) are dropped silently, as modules do, and
counted (`bad_frames`). Every frame crossing a module's UART is kept as it was on the wire
(`from_host`, `to_host`), for the tests to parse with Digi's own digi-xbee.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import os
import random
import select
import threading
import time
import tty
from collections import Counter

BROADCAST = 0x000000000000FFFF
_SPECIAL = (0x7E, 0x7D, 0x11, 0x13)


def checksum(data: bytes) -> int:
    total = 0
    for byte in data:
        total = (total + byte) & 0xFF
    return 0xFF - total


def wire(frame_data: bytes, api: int, checksum_off: int = 0) -> bytes:
    """One API frame as the UART carries it, in mode `api` (1, or 2 escaped); `checksum_off` spoils its checksum."""
    check = (checksum(frame_data) + checksum_off) & 0xFF
    body = bytes((len(frame_data) >> 8, len(frame_data) & 0xFF)) + frame_data + bytes((check,))
    if api == 2:
        stuffed = bytearray()
        for byte in body:
            stuffed += bytes((0x7D, byte ^ 0x20)) if byte in _SPECIAL else bytes((byte,))
        body = bytes(stuffed)
    return b"\x7e" + body


class FrameParser:
    """Host bytes -> frame data, the way a module reads its UART: bad frames are skipped and counted."""

    def __init__(self, api: int, counters: Counter[str]) -> None:
        self.api = api
        self.counters = counters
        self.buffer = bytearray()

    def feed(self, data: bytes) -> list[tuple[bytes, bytes]]:
        """(the frame's bytes as sent, frame data) for every whole frame in the stream so far."""
        self.buffer += data
        frames = []
        while True:
            start = self.buffer.find(0x7E)
            if start < 0:
                self.buffer.clear()
                return frames
            del self.buffer[:start]
            body, used = self._unstuff(bytes(self.buffer[1:]))
            if body is None:
                self.counters["bad_frames"] += 1
                del self.buffer[:1]
                continue
            if len(body) < 2:
                return frames
            length = body[0] << 8 | body[1]
            if len(body) < length + 3:
                if self.api == 2 and 0x7E in self.buffer[1:]:  # a new frame began: this one was cut
                    self.counters["bad_frames"] += 1
                    del self.buffer[:1]
                    continue
                return frames
            data_part = body[2:2 + length]
            raw_length = 1 + used[length + 2]
            if length == 0 or checksum(data_part) != body[2 + length]:
                self.counters["bad_frames"] += 1
                del self.buffer[:1]
                continue
            frames.append((bytes(self.buffer[:raw_length]), data_part))
            del self.buffer[:raw_length]

    def _unstuff(self, raw: bytes) -> tuple[bytes | None, list[int]]:
        """(unescaped bytes, raw bytes consumed after each one) up to the next 0x7E in mode 2."""
        if self.api != 2:
            return raw, list(range(1, len(raw) + 1))
        out = bytearray()
        used = []
        i = 0
        while i < len(raw):
            byte = raw[i]
            if byte == 0x7E:
                break
            if byte == 0x7D:
                if i + 1 >= len(raw):
                    break
                if raw[i + 1] ^ 0x20 not in _SPECIAL:
                    return None, used
                out.append(raw[i + 1] ^ 0x20)
                i += 2
            else:
                out.append(byte)
                i += 1
            used.append(i)
        return bytes(out), used


class Module:
    """One XBee module: a pty for its host and the firmware's state (see the module docstring)."""

    def __init__(self, network: XBeeNetwork, address: int, api: int, np: int, host_buffer: int) -> None:
        self.network = network
        self.address = address
        self.api = api
        self.np = np
        self.host_buffer = host_buffer
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.counters: Counter[str] = Counter()
        self.from_host: list[bytes] = []  # every frame the host sent, as on the wire
        self.to_host: list[bytes] = []  # every frame the module handed its host, as on the wire
        self.deaf = False
        self.at_log: list[str] = []
        self._parser = FrameParser(api, self.counters)
        self._out = bytearray()

    # -- what the network thread does for this module ------------------------
    def _from_host(self, data: bytes) -> None:
        if self.api == 0:  # transparent: the bytes are the RF data
            self.network._send(self, BROADCAST, data)
            return
        for raw, frame in self._parser.feed(data):
            self.from_host.append(raw)
            kind = frame[0]
            if kind in (0x08, 0x09) and len(frame) >= 4:
                self._at(frame[1], frame[2:4].decode("ascii", "replace"), frame[4:])
            elif kind == 0x10 and len(frame) >= 14:
                self._transmit(frame[1], int.from_bytes(frame[2:10], "big"), frame[14:])
            else:
                self.counters["unsupported"] += 1

    def _at(self, frame_id: int, command: str, parameter: bytes) -> None:
        self.at_log.append(command)
        values = {"AP": bytes((self.api,)), "NP": self.np.to_bytes(2, "big"),
                  "SH": (self.address >> 32).to_bytes(4, "big"), "SL": (self.address & 0xFFFFFFFF).to_bytes(4, "big")}
        if frame_id == 0:
            return
        if command in values:
            answer = bytes((0x88, frame_id)) + command.encode() + b"\x00" + (b"" if parameter else values[command])
        else:
            answer = bytes((0x88, frame_id)) + command.encode() + b"\x02"
        self.hand_to_host(answer)

    def _transmit(self, frame_id: int, dest: int, rf: bytes) -> None:
        delivered = len(rf) <= self.np and (self.network._send(self, dest, rf) or dest == BROADCAST)
        status = 0x74 if len(rf) > self.np else 0x00 if delivered else 0x21
        if frame_id:
            self.hand_to_host(bytes((0x8B, frame_id, 0xFF, 0xFE, 0x00, status, 0x00)))

    def hand_to_host(self, frame_data: bytes) -> None:
        raw = wire(frame_data, self.api)
        if len(self._out) + len(raw) > self.host_buffer:
            self.counters["host_overflow"] += 1
            return
        self.to_host.append(raw)
        self._out += raw
        self._flush()

    def _flush(self) -> None:
        while self._out:
            try:
                written = os.write(self.master, self._out)
            except (BlockingIOError, OSError):
                return
            del self._out[:written]

    # -- for tests ---------------------------------------------------------------
    def inject(self, data: bytes) -> None:
        """Raw bytes to the host, as line noise or a module gone mad would put them."""
        with self.network.lock:
            self._out += data
            self._flush()

    def rx_frames(self, kind: int = 0x90) -> list[bytes]:
        """The frames of one type the module handed its host (as on the wire)."""
        with self.network.lock:
            return [raw for raw in self.to_host if _frame_type(raw, self.api) == kind]

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


def _frame_type(raw: bytes, api: int) -> int:
    """A frame's type byte: the fourth after unescaping."""
    parser = FrameParser(api, Counter())
    frames = parser.feed(raw)
    return frames[0][1][0] if frames else -1


class XBeeNetwork:
    """Modules on one broadcast network, with loss and delay; a thread plays their firmware."""

    def __init__(self, loss: float = 0.0, delay: float = 0.0, jitter: float = 0.0, seed: int = 1) -> None:
        self.loss, self.delay, self.jitter = loss, delay, jitter
        self.random = random.Random(seed)
        self.lock = threading.RLock()
        self.modules: list[Module] = []
        self.counters: Counter[str] = Counter()
        self._due: list[tuple[float, int, Module, bytes]] = []
        self._order = itertools.count()
        self._wake_r, self._wake_w = os.pipe()
        self._stop = threading.Event()
        self.turns = 0  # the network thread's loops: a test that timed out shows whether the firmware ran at all
        self._thread = threading.Thread(target=self._run, name="xbee-network", daemon=True)
        self._thread.start()

    def module(self, address: int, api: int = 1, np: int = 256, host_buffer: int = 4096) -> Module:
        with self.lock:
            module = Module(self, address, api, np, host_buffer)
            self.modules.append(module)
        self._wake()
        return module

    def set_deaf(self, module: Module, deaf: bool = True) -> None:
        with self.lock:
            module.deaf = deaf
        self._wake()

    def _send(self, sender: Module, dest: int, rf: bytes) -> bool:
        """Schedule `rf` to every module `dest` names; whether any module has that address."""
        targets = [m for m in self.modules if m is not sender and (dest == BROADCAST or m.address == dest)]
        now = time.monotonic()
        for target in targets:
            if self.random.random() < self.loss:
                self.counters["lost"] += 1
                continue
            late = self.delay + self.random.random() * self.jitter
            options = 0x02 if dest == BROADCAST else 0x01
            frame = bytes((0x90,)) + sender.address.to_bytes(8, "big") + b"\xff\xfe" + bytes((options,)) + rf
            heapq.heappush(self._due, (now + late, next(self._order), target, frame))
        return bool(targets)

    def _wake(self) -> None:
        os.write(self._wake_w, b"!")

    def _run(self) -> None:
        while not self._stop.is_set():
            self.turns += 1
            with self.lock:
                timeout = 0.05 if not self._due else max(0.0, min(0.05, self._due[0][0] - time.monotonic()))
                readers = {m.master: m for m in self.modules if not m.deaf}
                writers = {m.master: m for m in self.modules if m._out}
            try:
                readable, writable, _ = select.select([self._wake_r, *readers], list(writers), [], timeout)
            except (OSError, ValueError):  # a pty closed under us: look again
                self.counters["select_errors"] += 1
                time.sleep(0.01)
                continue
            with self.lock:
                if self._wake_r in readable:
                    os.read(self._wake_r, 4096)
                for fd in readable:
                    module = readers.get(fd)
                    if module is None or module.deaf:
                        continue
                    try:
                        data = os.read(fd, 4096)
                    except (BlockingIOError, OSError):
                        continue
                    module._from_host(data)
                for fd in writable:
                    writers[fd]._flush()
                now = time.monotonic()
                while self._due and self._due[0][0] <= now:
                    _, _, target, frame = heapq.heappop(self._due)
                    target.hand_to_host(frame)

    def close(self) -> None:
        self._stop.set()
        self._wake()
        self._thread.join(timeout=5)
        for module in self.modules:
            module.close()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def __enter__(self) -> XBeeNetwork:
        return self

    def __exit__(self, kind: object, *exc: object) -> None:
        if kind is not None:  # a failing test shows what the network did (pytest prints it with the failure)
            print(self.state())
        self.close()

    def state(self) -> str:
        """The network thread's liveness and each module's traffic, for a test that failed to read."""
        with self.lock:
            modules = "; ".join(f"{m.address:016X} api={m.api} deaf={m.deaf} from_host={len(m.from_host)} "
                                f"to_host={len(m.to_host)} at={m.at_log[:8]} {dict(m.counters)}" for m in self.modules)
            return (f"xbee network: thread alive={self._thread.is_alive()} turns={self.turns} due={len(self._due)} "
                    f"{dict(self.counters)}; {modules}")


class Host:
    """A module's host that is not vstig: it opens the pty through pyserial and speaks frames with this file's codec."""

    def __init__(self, module: Module) -> None:
        import serial

        self.module = module
        self.api = module.api
        self.port = serial.Serial(module.path, 230400, timeout=0)
        self.counters: Counter[str] = Counter()
        self._parser = FrameParser(module.api, self.counters)
        self._frame_id = 0

    def transmit(self, rf: bytes, dest: int = BROADCAST) -> None:
        self._frame_id = self._frame_id % 255 + 1
        frame = bytes((0x10, self._frame_id)) + dest.to_bytes(8, "big") + b"\xff\xfe\x00\x00" + rf
        self.port.write(wire(frame, self.api))

    def received(self, wait: float = 0.0) -> list[tuple[int, bytes]]:
        """(64-bit source, RF data) of every Receive Packet that came since the last call."""
        if wait:
            select.select([self.port.fileno()], [], [], wait)
        data = self.port.read(65536)
        return [(int.from_bytes(frame[1:9], "big"), frame[12:]) for _raw, frame in self._parser.feed(data)
                if frame[0] == 0x90 and len(frame) >= 12]

    def close(self) -> None:
        self.port.close()
