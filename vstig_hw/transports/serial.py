"""SerialTransport: a pyserial port that survives its device vanishing.

Anything `serial.serial_for_url` opens works unchanged: a device path
(/dev/ttyUSB0, a pty), socket://host:port, rfc2217://host:port, loop://.
It moves raw byte chunks and never interprets them.

When the device disappears (a USB dongle pulled out, a server gone) the loss is
logged once, `read` returns nothing and `write` drops and counts, while the port
is retried with exponential backoff; when it comes back, traffic resumes and
`reconnects` counts it.

Reads and writes go straight to the port's non-blocking file descriptor where it
has one (a device or pty): a read is one select and one read, a write one write; only a device that does not take a
whole write at once is waited for, up to `write_timeout`, then the rest of that
write is dropped (`tx_timeout`). `write_nowait` never waits: the gateway's loop
writes through it while the device keeps up (see gateway/writer.py).

A `preamble` (the framing's: 0x00 for COBS framings) goes out ahead of the first
write after every open and reconnect, so a receiver that holds half a frame from
before drops it at once instead of losing our first frame too (SPEC 6.0.3).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import select
import time
from typing import Any

import serial

from ..counters import Counters
from .base import TransportError, errno_of

__all__ = ["SerialTransport", "open_error"]

log = logging.getLogger(__name__)

_MISSING = {errno.ENOENT, errno.ENODEV, errno.ENXIO}
_DENIED = {errno.EACCES, errno.EPERM}
_BUSY = {errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK}
_READ_SIZE = 65536  # bytes one read takes at most: all a pty or a USB adapter holds


def open_error(port: str, exc: BaseException) -> TransportError:
    """One clear line, naming the port, for why it cannot be opened."""
    code = errno_of(exc)
    if code in _MISSING:
        reason = "no such device (is it plugged in? `ls /dev/serial/by-id/` lists attached adapters)"
    elif code in _DENIED:
        reason = ("permission denied: add your user to the 'dialout' group "
                  "(sudo usermod -aG dialout $USER), then log out and back in")
    elif code in _BUSY:
        reason = f"port busy: another program has it open (`fuser {port}` names it)"
    elif code == errno.ECONNREFUSED:
        reason = "connection refused: is the server at that address running?"
    else:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return TransportError(f"serial port {port}: {reason}")


class SerialTransport:
    """Transport[bytes] over pyserial: read() returns the byte chunks that arrived."""

    def __init__(self, port: str, baudrate: int = 115200, *, bytesize: int = 8, parity: str = "N",
                 stopbits: float = 1, rtscts: bool = False, xonxoff: bool = False, write_timeout: float = 1.0,
                 backoff_initial: float = 0.1, backoff_max: float = 2.0, name: str | None = None,
                 preamble: bytes = b"") -> None:
        self.port = port
        self.name = name or port
        self.settings: dict[str, Any] = {
            "baudrate": baudrate, "bytesize": bytesize, "parity": parity, "stopbits": stopbits,
            "rtscts": rtscts, "xonxoff": xonxoff, "write_timeout": write_timeout,
        }
        self.backoff_initial = backoff_initial
        self.backoff_max = backoff_max
        self.preamble = preamble
        self.counters = Counters()
        self._serial: serial.Serial | None = None
        self._wanted = False  # open() was called and close() was not
        self._timeout: float | None = None  # the read timeout the port is configured with
        self._backoff = backoff_initial
        self._retry_at = 0.0
        self._lost_at = 0.0
        self._fresh = False  # the port was (re)opened and nothing written since: the preamble goes first
        self._fd: int | None = None  # the open port's file descriptor, where it has one: written directly

    @property
    def connected(self) -> bool:
        return self._serial is not None

    def open(self) -> None:
        """Open the port now; TransportError (one line naming the port) if it cannot be."""
        self._serial = self._connect()
        self._wanted = True

    def close(self) -> None:
        self._wanted = False
        self._drop_port()

    def read(self, timeout: float) -> list[bytes]:
        port = self._serial
        if port is None:
            self._require_open()
            self._reconnect_within(timeout)
            return []
        try:
            fd = self._fd
            if fd is not None:
                data = self._read_fd(fd, timeout)
            else:
                if self._timeout != timeout:
                    port.timeout = self._timeout = timeout
                waiting = port.in_waiting
                data = port.read(waiting) if waiting else port.read(1)
                if data and not waiting:
                    more = port.in_waiting
                    if more:
                        data += port.read(more)
        except (serial.SerialException, OSError) as exc:
            self._lose(exc)
            return []
        if not data:
            return []
        self.counters["rx"] += 1
        self.counters["rx_bytes"] += len(data)
        return [bytes(data)]

    @staticmethod
    def _read_fd(fd: int, timeout: float) -> bytes:
        """Whatever the device holds once it has something (one select, one read), or b"" after `timeout`."""
        if not select.select([fd], [], [], timeout)[0]:
            return b""
        try:
            data = os.read(fd, _READ_SIZE)
        except BlockingIOError:  # another reader took it
            return b""
        if not data:  # what pyserial reports too: readable, yet nothing to read
            raise serial.SerialException("device reports readiness to read but returned no data (disconnected?)")
        return data

    def write(self, unit: bytes) -> None:
        """Send `unit`, waiting up to `write_timeout` for the device to take it; the rest is dropped and counted."""
        port = self._port_for_write()
        if port is None:
            return
        unit = self._with_preamble(unit)
        fd = self._fd
        if fd is None:  # socket://, rfc2217://, loop://: pyserial's own write
            try:
                port.write(unit)
            except serial.SerialTimeoutException:
                self.counters["tx_timeout"] += 1  # flow control held us off: drop, the line stays ours
                self._fresh = bool(self.preamble)  # maybe half a frame went: the next one starts clean
                return
            except (serial.SerialException, OSError) as exc:
                self._lose(exc)
                self.counters["tx_dropped"] += 1
                return
            self._sent(len(unit))
            return
        limit = self.settings["write_timeout"]  # None: as long as it takes (pyserial's meaning)
        deadline = None if limit is None else time.monotonic() + limit
        while unit:
            rest = self._write_fd(fd, unit)
            if rest is None or self._fd != fd:  # sent, or the port was lost meanwhile (counted there)
                return
            unit = rest
            left = None if deadline is None else deadline - time.monotonic()
            if (left is not None and left <= 0) or not select.select([], [fd], [], left)[1]:
                self.counters["tx_timeout"] += 1  # flow control or a deaf device held us off: drop the rest
                self._fresh = bool(self.preamble)  # half a frame went: the next one starts clean
                return

    def write_nowait(self, unit: bytes) -> bytes | None:
        """Write what the device takes now, straight to the fd (no select); the rest, for `write`, or None.

        None also when the unit was dropped (the device is gone: counted as in `write`).
        Ports with no fd (socket://...) take nothing here: the whole unit is returned.
        """
        port = self._port_for_write()
        if port is None:
            return None
        fd = self._fd
        if fd is None:
            return unit
        return self._write_fd(fd, self._with_preamble(unit))

    def _write_fd(self, fd: int, data: bytes) -> bytes | None:
        """One os.write on the non-blocking fd: the part not taken (None: all of it went, or the port was lost)."""
        try:
            written = os.write(fd, data)
        except BlockingIOError:
            return data
        except OSError as exc:
            self._lose(exc)
            self.counters["tx_dropped"] += 1
            return None
        if written < len(data):
            self.counters["tx_bytes"] += written
            return data[written:]
        self._sent(written)
        return None

    def _sent(self, size: int) -> None:
        self.counters["tx"] += 1
        self.counters["tx_bytes"] += size

    def _port_for_write(self) -> serial.Serial | None:
        port = self._serial
        if port is None:
            self._require_open()
            port = self._reconnect_now()
            if port is None:
                self.counters["tx_dropped"] += 1
        return port

    def _with_preamble(self, unit: bytes) -> bytes:
        if self._fresh:
            self._fresh = False
            return self.preamble + unit
        return unit

    def __enter__(self) -> SerialTransport:
        self.open()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "connected" if self.connected else ("reconnecting" if self._wanted else "closed")
        return f"SerialTransport({self.port!r}, {self.settings['baudrate']}, {state})"

    def _connect(self) -> serial.Serial:
        try:
            port = serial.serial_for_url(self.port, exclusive=True, timeout=self._timeout, **self.settings)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise open_error(self.port, exc) from None
        self._fresh = bool(self.preamble)
        fd = getattr(port, "fd", None)  # a POSIX device: pyserial opened it O_NONBLOCK; make sure of it
        if isinstance(fd, int):
            os.set_blocking(fd, False)
            self._fd = fd
        else:
            self._fd = None
        return port

    def _require_open(self) -> None:
        if not self._wanted:
            raise TransportError(f"serial port {self.name}: not open (call open() first)")

    def _drop_port(self) -> None:
        port, self._serial = self._serial, None
        self._fd = None
        if port is not None:
            with contextlib.suppress(serial.SerialException, OSError):  # the device may be gone already
                port.close()

    def _lose(self, exc: BaseException) -> None:
        self._drop_port()
        self.counters["disconnects"] += 1
        self._lost_at = time.monotonic()
        self._backoff = self.backoff_initial
        self._retry_at = self._lost_at + self._backoff
        log.warning("serial port %s: lost (%s); reconnecting in the background", self.name, exc)

    def _reconnect_now(self) -> serial.Serial | None:
        """One attempt if the backoff allows it; the port, or None while it stays away."""
        now = time.monotonic()
        if now < self._retry_at:
            return None
        try:
            self._serial = self._connect()
        except TransportError as exc:
            self._backoff = min(self._backoff * 2, self.backoff_max)
            self._retry_at = now + self._backoff
            log.debug("%s (retrying in %.1f s)", exc, self._backoff)
            return None
        self.counters["reconnects"] += 1
        log.warning("serial port %s: back after %.1f s", self.name, now - self._lost_at)
        return self._serial

    def _reconnect_within(self, timeout: float) -> None:
        """Retry the port during `timeout` seconds, sleeping between attempts instead of spinning."""
        deadline = time.monotonic() + timeout
        while self._reconnect_now() is None:
            pause = min(deadline, self._retry_at) - time.monotonic()
            if time.monotonic() >= deadline:
                return
            if pause > 0:
                time.sleep(pause)
