"""SlcanBus: python-can's slcan driver, read in chunks, written without blocking, with noise counted.

python-can's `slcanBus` is the reference: the commands it sends to open an adapter, the
frame lines it writes and the Messages it makes of the lines it reads are kept. Three of
its habits cannot stay in a gateway:

* it reads one byte per system call, so a burst of noise of N bytes costs N calls before
  the honest frame behind it is seen (delays of seconds at line rate);
* a line it cannot parse raises (ValueError, IndexError; a byte that is not ASCII even
  CanOperationError, which reads as an adapter lost), so noise tore the link down;
* its writes have no timeout: an adapter that stops reading (a hung USB adapter, its
  buffer full) holds its open, a send and its shutdown forever, and with them a stop.

Here `SlcanLines` (pure: bytes in, lines out) splits whatever one read returned into
lines; `parse_line` makes a Message of a well-formed frame line, strictly (exact length,
hex digits, DLC and identifier in range; a Lawicel timestamp may follow); a line that is
neither a frame nor an adapter's answer is counted as `rx_garbage` and skipped. Every
write goes to the port's non-blocking descriptor: the commands that open the adapter
must be taken within `open_timeout` (else CanInitializationError, with the port closed);
a frame the adapter cannot take within the send's timeout is refused as busy
(CanOperationError with errno EAGAIN: a full TX queue to the transport, not a lost
adapter), and the rest of a line taken in part goes out first the next time, so the
adapter never sees half a line run into the next. `shutdown` closes the channel if the
adapter takes the command at once and drops what it never took (nothing waits for it).

`sleep_after_open` defaults to 0 where python-can waits 2 s: its wait is for adapters
that reset when their port opens (Arduino-based ones), which give
`bus.sleep_after_open=2`; the wait is cut short when the transport is closed meanwhile.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import os
import queue
import re
import select
import threading
import time
from typing import Any

import can
import serial
from can.interfaces.slcan import slcanBus
from can.util import CAN_FD_DLC, check_or_adjust_timing_clock, len2dlc

from ..counters import Counters
from .serial import drain_briefly

__all__ = ["OPEN_TIMEOUT", "SlcanBus", "SlcanLines", "frame_line", "parse_line"]

OPEN_TIMEOUT = 0.5  # seconds the adapter may take to take the commands that open it (a dozen bytes)
CLOSE_TIMEOUT = 0.1  # seconds the channel-close command may take at shutdown: nothing more is owed
READ_SIZE = 65536  # bytes one read takes at most: what a pty or a USB adapter holds
MAX_LINE = 160  # bytes: the longest slcan line (an extended CAN FD frame, 64 bytes, a timestamp) with room
_TIMESTAMP_DIGITS = 4  # a Lawicel adapter with time stamps on ("Z1") adds 4 hex digits of milliseconds
# An adapter's answers: OK (CR) or error (BEL) alone, a transmit ack (z, Z), its version, serial number or status.
_ANSWER = re.compile(rb"(?:[zZ]|[Vv][0-9A-Fa-f]{4}|N[0-9A-Za-z]{4}|F[0-9A-Fa-f]{2})?[\r\x07]\Z")

# letter -> (identifier digits, extended, remote, CAN FD, bitrate switch)
_KINDS: dict[int, tuple[int, bool, bool, bool, bool]] = {
    ord("t"): (3, False, False, False, False),
    ord("T"): (8, True, False, False, False),
    ord("x"): (8, True, False, False, False),  # CANDapter's extended frame
    ord("r"): (3, False, True, False, False),
    ord("R"): (8, True, True, False, False),
    ord("d"): (3, False, False, True, False),
    ord("D"): (8, True, False, True, False),
    ord("b"): (3, False, False, True, True),
    ord("B"): (8, True, False, True, True),
}
_HEX = frozenset(b"0123456789abcdefABCDEF")
_DIGITS = frozenset(b"012345678")  # a classic frame's DLC: one decimal digit, 0..8
_LINE = re.compile(rb"(?<=[\r\x07])")  # a line ends at CR (OK) or BEL (error), which it keeps


def parse_line(line: bytes, timestamp: float = 0.0) -> can.Message | None:
    """The frame a well-formed slcan line (its terminator included) carries, as python-can's slcanBus makes it;
    None for anything else."""
    kind = _KINDS.get(line[0]) if line else None
    if kind is None:
        return None
    digits, extended, remote, fd, brs = kind
    dlc_at = 1 + digits
    body = line[:-1]
    if len(body) <= dlc_at or not _HEX.issuperset(body[1:]):
        return None
    can_id = int(body[1:dlc_at], 16)
    if can_id > (0x1FFFFFFF if extended else 0x7FF):
        return None
    code = body[dlc_at]
    if fd:
        length = CAN_FD_DLC[int(chr(code), 16)]
    elif code in _DIGITS:
        length = code - 0x30
    else:
        return None
    data_len = 0 if remote else 2 * length
    if len(body) - dlc_at - 1 not in (data_len, data_len + _TIMESTAMP_DIGITS):
        return None
    data = None if remote else bytes.fromhex(body[dlc_at + 1:dlc_at + 1 + data_len].decode("ascii"))
    return can.Message(arbitration_id=can_id, is_extended_id=extended, timestamp=timestamp, is_remote_frame=remote,
                       is_fd=fd, bitrate_switch=brs, dlc=length, data=data)


def is_answer(line: bytes) -> bool:
    """An adapter's answer to a command (OK, error, transmit ack, version...), not noise."""
    return _ANSWER.match(line) is not None


def frame_line(msg: can.Message) -> bytes:
    """The line python-can's slcanBus writes for `msg`, terminator included."""
    ext = int(msg.is_extended_id)
    ident = f"{msg.arbitration_id:08X}" if ext else f"{msg.arbitration_id:03X}"
    if msg.is_remote_frame:
        return f"{'rR'[ext]}{ident}{msg.dlc:d}\r".encode()
    data = msg.data.hex().upper()
    if msg.is_fd:
        return f"{('bB' if msg.bitrate_switch else 'dD')[ext]}{ident}{len2dlc(msg.dlc):X}{data}\r".encode()
    return f"{'tT'[ext]}{ident}{msg.dlc:d}{data}\r".encode()


class SlcanLines:
    """The lines in an adapter's byte stream, whatever the chunks it came in (sans I/O).

    A line longer than MAX_LINE (noise with no terminator) is cut off: counted once in
    `overlong`, and what follows of it up to its terminator is dropped.
    """

    def __init__(self) -> None:
        self._partial = b""
        self._skipping = False  # inside a line that grew past MAX_LINE
        self.overlong = 0

    def feed(self, data: bytes) -> list[bytes]:
        parts = _LINE.split(self._partial + data if self._partial else data)
        tail = parts.pop()
        if self._skipping and parts:  # the end of the overlong line
            parts.pop(0)
            self._skipping = False
        if self._skipping or len(tail) > MAX_LINE:
            if not self._skipping:
                self.overlong += 1
            self._skipping, tail = True, b""
        self._partial = tail
        return parts


class SlcanBus(slcanBus):
    """python-can's slcan interface with chunked reads, bounded writes and counted noise (see the module)."""

    def __init__(self, channel: str, tty_baudrate: int = 115200, bitrate: int | None = None,
                 timing: can.BitTiming | can.BitTimingFd | None = None, sleep_after_open: float = 0.0,
                 rtscts: bool = False, listen_only: bool = False, timeout: float = 0.001, *,
                 open_timeout: float = OPEN_TIMEOUT, counters: Counters | None = None,
                 abort: threading.Event | None = None, **kwargs: Any) -> None:
        if not channel:
            raise ValueError("Must specify a serial port.")
        if "@" in channel:
            channel, baudrate = channel.split("@")
            tty_baudrate = int(baudrate)
        self._listen_only = listen_only
        self.counters = Counters() if counters is None else counters
        self._lines = SlcanLines()
        self._ready: collections.deque[bytes] = collections.deque()  # lines read, not yet taken
        self._pending = b""  # the rest of a line the adapter took in part: it goes out before anything else
        self._writing = threading.Lock()
        self._open_timeout = open_timeout
        self._deadline: float | None = None  # while opening: when every command must have been taken
        self._queue: queue.SimpleQueue[str] = queue.SimpleQueue()  # lines python-can's get_version() put aside
        self._buffer = bytearray()
        self._can_protocol = can.CanProtocol.CAN_20
        try:
            self.serialPortOrig = serial.serial_for_url(channel, baudrate=tty_baudrate, rtscts=rtscts,
                                                        timeout=timeout)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise can.CanInitializationError(str(exc)) from exc
        fd = getattr(self.serialPortOrig, "fd", None)  # a POSIX device: pyserial opened it O_NONBLOCK; make sure of it
        self._fd: int | None = fd if isinstance(fd, int) else None
        if self._fd is not None:
            os.set_blocking(self._fd, False)
        try:
            if sleep_after_open > 0:
                (abort or threading.Event()).wait(sleep_after_open)
            self._deadline = time.monotonic() + open_timeout
            self._configure(bitrate, timing, kwargs.get("btr"))
            self.open()
        except BaseException:
            self.serialPortOrig.close()  # python-can leaves the port open when the handshake fails
            raise
        self._deadline = None
        can.BusABC.__init__(self, channel, **kwargs)

    def _configure(self, bitrate: int | None, timing: can.BitTiming | can.BitTimingFd | None, btr: str | None) -> None:
        """The bit rate, as python-can's slcanBus sets it (and refuses what it refuses)."""
        if isinstance(timing, can.BitTiming):
            timing = check_or_adjust_timing_clock(timing, valid_clocks=[8_000_000])
            self.set_bitrate_reg(f"{timing.btr0:02X}{timing.btr1:02X}")
        elif isinstance(timing, can.BitTimingFd):
            self.set_bitrate(timing.nom_bitrate, timing.data_bitrate)
        else:
            if bitrate is not None and btr is not None:
                raise ValueError("Bitrate and btr mutually exclusive.")
            if bitrate is not None:
                self.set_bitrate(bitrate)
            if btr is not None:
                self.set_bitrate_reg(btr)

    # -- writing: never waits beyond its timeout --------------------------------------
    def _write(self, string: str) -> None:
        """A command (python-can's O, C, S6, V...): taken within the open's deadline (`open_timeout` after the
        open began; later, `open_timeout` each), else CanOperationError."""
        limit = self._open_timeout if self._deadline is None else self._deadline - time.monotonic()
        if not self._put(string.encode() + b"\r", limit):
            raise can.CanOperationError(f"the adapter took no command within {self._open_timeout:g} s (is it "
                                        "hung? its buffer is full)")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Write `msg`'s line; CanOperationError (errno EAGAIN) if the adapter takes none of it within `timeout`
        (None: at once; nothing here waits without a bound)."""
        if not self._put(frame_line(msg), 0.0 if timeout is None else timeout):
            raise can.CanOperationError("the adapter is not taking data (its buffer is full)",
                                        error_code=errno.EAGAIN)

    def _put(self, line: bytes, timeout: float) -> bool:
        """Begin writing `line` within `timeout` (what is pending first); the rest of it waits in `_pending`."""
        end = time.monotonic() + timeout
        if not self._writing.acquire(timeout=max(timeout, 0.0)):  # the reader may be finishing a line
            return False
        try:
            while self._pending:
                self._pending = self._pending[self._write_some(self._pending):]
                if self._pending and not self._writable(end):
                    return False
            while True:
                taken = self._write_some(line)
                if taken:
                    self._pending = line[taken:]
                    return True
                if not self._writable(end):
                    return False
        finally:
            self._writing.release()

    def _flush_pending(self) -> None:
        """Write what is left of a line the adapter took in part, if it takes it now (from the reading side)."""
        if self._writing.acquire(False):
            try:
                if self._pending:
                    self._pending = self._pending[self._write_some(self._pending):]
            finally:
                self._writing.release()

    def _write_some(self, data: bytes) -> int:
        """One write that cannot block: the bytes the port took (0: none now). A failing port raises."""
        fd = self._fd
        try:
            if fd is not None:
                return os.write(fd, data)
            port = self.serialPortOrig  # socket://, loop://: pyserial's own write, with no wait
            port.write_timeout = 0
            return int(port.write(data) or 0)
        except (BlockingIOError, serial.SerialTimeoutException):
            return 0
        except (OSError, serial.SerialException) as exc:
            raise can.CanOperationError(f"cannot write to {self.serialPortOrig.port}: {exc}",
                                        error_code=getattr(exc, "errno", None)) from exc

    def _writable(self, end: float) -> bool:
        """Wait until the port can take more, or `end` (monotonic) passes."""
        left = end - time.monotonic()
        if left <= 0:
            return False
        if self._fd is None:
            time.sleep(min(left, 0.01))
            return True
        return bool(select.select([], [self._fd], [], left)[1])

    # -- reading: whatever the port holds, in one call ---------------------------
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._pending:
            self._flush_pending()
        if not self._queue.empty():  # lines get_version() read past, first
            stashed = []
            while not self._queue.empty():
                stashed.append(self._queue.get_nowait().encode("latin-1"))
            self._ready.extendleft(reversed(stashed))
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            while self._ready:
                msg = self._take(self._ready.popleft())
                if msg is not None:
                    return msg, False
            left = None if end is None else max(end - time.monotonic(), 0.0)
            data = self._read_chunk(left)
            if data:
                self._stamp = time.time()
                self._ready.extend(self._lines.feed(data))
                if self._lines.overlong:
                    self.counters["rx_garbage"] += self._lines.overlong
                    self._lines.overlong = 0
            elif end is not None and time.monotonic() >= end:
                return None, False

    _stamp = 0.0  # wall-clock time of the read that brought the lines in `_ready`

    def _take(self, line: bytes) -> can.Message | None:
        msg = parse_line(line, self._stamp)
        if msg is None and not is_answer(line):
            self.counters["rx_garbage"] += 1
        return msg

    def _read_chunk(self, timeout: float | None) -> bytes:
        """What the port holds once it has something (one select, one read), or b"" after `timeout`."""
        fd = self._fd
        try:
            if fd is None:
                port = self.serialPortOrig
                port.timeout = timeout
                waiting = port.in_waiting
                return bytes(port.read(waiting or 1))
            if not select.select([fd], [], [], timeout)[0]:
                return b""
            data = os.read(fd, READ_SIZE)
        except BlockingIOError:
            return b""
        except (OSError, serial.SerialException) as exc:
            raise can.CanOperationError(f"cannot read from {self.serialPortOrig.port}: {exc}",
                                        error_code=getattr(exc, "errno", None)) from exc
        if not data:  # readable, yet nothing: the far end hung up (pyserial says the same)
            raise can.CanOperationError(f"{self.serialPortOrig.port}: the adapter hung up", error_code=errno.EIO)
        return data

    def _read(self, timeout: float | None) -> str | None:
        """The next line, as python-can's own `_read` gives it (for `get_version`, `get_serial_number`)."""
        end = None if timeout is None else time.monotonic() + timeout
        while not self._ready:
            left = None if end is None else end - time.monotonic()
            if left is not None and left <= 0:
                return None
            data = self._read_chunk(left)
            if data:
                self._stamp = time.time()
                self._ready.extend(self._lines.feed(data))
        return self._ready.popleft().decode("latin-1")

    def flush(self) -> None:
        self._ready.clear()
        self._lines = SlcanLines()
        super().flush()

    # -- closing: nothing waits for an adapter that does not read ----------------
    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        can.BusABC.shutdown(self)
        with contextlib.suppress(can.CanError):
            self._put(b"C\r", CLOSE_TIMEOUT)
        if self._fd is not None:  # what the adapter never took would hold close() on a real UART
            drain_briefly(self._fd, CLOSE_TIMEOUT)
        with contextlib.suppress(OSError, serial.SerialException):
            self.serialPortOrig.close()
