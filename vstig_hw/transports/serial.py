"""SerialTransport: a pyserial port that survives its device vanishing.

C twin: vstig_hw/_cext/path.c (its read), vstig_hw/_cext/outlet.c (its write_nowait); held equal by tests/native
(index: vstig_hw/_vstig.pyi).

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
import fcntl
import os
import select
import struct
import termios
import time
from typing import Any

import serial

from .base import DeviceTransport, TransportError, errno_of

__all__ = ["SerialTransport", "drain_briefly", "open_error"]

_MISSING = {errno.ENOENT, errno.ENODEV, errno.ENXIO}
_DENIED = {errno.EACCES, errno.EPERM}
_BUSY = {errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK}
_READ_SIZE = 65536  # bytes one read takes at most: all a pty or a USB adapter holds


CLOSE_DRAIN = 0.5  # seconds a closing port gives the device to take what the kernel still holds for it


def drain_briefly(fd: int, seconds: float = CLOSE_DRAIN) -> None:
    """Let the device take what the kernel holds for it, for `seconds` at most, then drop the rest.

    A terminal's close waits for its output to drain, on a real UART up to its `closing_wait`
    (30 s by default) and for ever under flow control: a device that takes nothing would hold the
    close, and with it a stop. What a working device takes within the moment still goes out.
    """
    end = time.monotonic() + seconds
    with contextlib.suppress(OSError, termios.error):
        while (unsent := _unsent(fd)) and time.monotonic() < end:
            time.sleep(0.005)
        if unsent:  # only then: a pty reports none, and flushing it could drop bytes on their way to the far end
            termios.tcflush(fd, termios.TCOFLUSH)


def _unsent(fd: int) -> int:
    return int(struct.unpack("i", fcntl.ioctl(fd, termios.TIOCOUTQ, b"\0\0\0\0"))[0])


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


class SerialTransport(DeviceTransport[bytes, serial.Serial]):
    """Transport[bytes] over pyserial: read() returns the byte chunks that arrived."""

    device_word = "serial port"
    lost_counter = "disconnects"
    device_errors = (serial.SerialException, OSError)

    def __init__(self, port: str, baudrate: int = 115200, *, bytesize: int = 8, parity: str = "N",
                 stopbits: float = 1, rtscts: bool = False, xonxoff: bool = False, write_timeout: float = 1.0,
                 backoff_initial: float = 0.1, backoff_max: float = 2.0, name: str | None = None,
                 preamble: bytes = b"") -> None:
        super().__init__(name or port, (backoff_initial, backoff_max))
        self.port = port
        self.settings: dict[str, Any] = {
            "baudrate": baudrate, "bytesize": bytesize, "parity": parity, "stopbits": stopbits,
            "rtscts": rtscts, "xonxoff": xonxoff, "write_timeout": write_timeout,
        }
        self._timeout: float | None = None  # the read timeout the port is configured with
        # the port's fd (written directly where it has one) and whether the preamble goes first live in the
        # handle the compiled data path shares (`compiled_handle`)
        self._live.preamble = preamble

    @property
    def preamble(self) -> bytes:
        """What goes ahead of the first write after the port (re)opened (the framing's: 0x00 for COBS)."""
        return self._live.preamble

    # -- the device calls ------------------------------------------------------
    def _open_device(self) -> serial.Serial:
        try:
            port = serial.serial_for_url(self.port, exclusive=True, timeout=self._timeout, **self.settings)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise open_error(self.port, exc) from None
        except (KeyError, TypeError) as exc:  # pyserial's URL handlers fail so on some bad URLs (specs check them)
            raise TransportError(f"serial port {self.port}: pyserial cannot read this URL ({exc!r}); "
                                 "`vstig links` shows the forms it takes") from None
        live = self._live
        live.fresh = bool(live.preamble)
        fd = getattr(port, "fd", None)  # a POSIX device: pyserial opened it O_NONBLOCK; make sure of it
        if isinstance(fd, int):
            os.set_blocking(fd, False)
            live.fd = fd
        else:
            live.fd = None
        return port

    def _close_device(self, device: serial.Serial) -> None:
        live = self._live
        fd, live.fd = live.fd, None
        if fd is not None:
            drain_briefly(fd)
        with contextlib.suppress(serial.SerialException, OSError):  # the device may be gone already
            device.close()

    def _read_device(self, device: serial.Serial, timeout: float) -> list[bytes]:
        fd = self._live.fd
        if fd is not None:
            data = self._read_fd(fd, timeout)
        else:
            if self._timeout != timeout:
                device.timeout = self._timeout = timeout
            waiting = device.in_waiting
            data = device.read(waiting) if waiting else device.read(1)
            if data and not waiting:
                more = device.in_waiting
                if more:
                    data += device.read(more)
        if not data:
            return []
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

    def _write_device(self, device: serial.Serial, unit: bytes) -> None:
        """Send `unit`, waiting up to `write_timeout` for the device to take it; the rest is dropped and counted."""
        unit = self._with_preamble(unit)
        fd = self._live.fd
        if fd is None:  # socket://, rfc2217://, loop://: pyserial's own write (a failure: the base loses it)
            try:
                device.write(unit)
            except serial.SerialTimeoutException:
                self._not_taken("tx_timeout")  # flow control held us off: drop, the line stays ours
                self._live.fresh = bool(self._live.preamble)  # maybe half a frame went: the next one starts clean
                return
            self._sent()
            self.counters["tx_bytes"] += len(unit)
            return
        limit = self.settings["write_timeout"]  # None: as long as it takes (pyserial's meaning)
        deadline = None if limit is None else time.monotonic() + limit
        while unit:
            rest = self._write_fd(fd, unit)
            if rest is None or self._live.fd != fd:  # sent, or the port was lost meanwhile (counted there)
                return
            unit = rest
            left = None if deadline is None else deadline - time.monotonic()
            if (left is not None and left <= 0) or not select.select([], [fd], [], left)[1]:
                self._not_taken("tx_timeout")  # flow control or a deaf device held us off: drop the rest
                self._live.fresh = bool(self._live.preamble)  # half a frame went: the next one starts clean
                return

    # -- writing without waiting (the gateway's loop) ------------------------------
    def write_nowait(self, unit: bytes) -> bytes | None:
        """Write what the device takes now, straight to the fd (no select); the rest, for `write`, or None.

        None also when the unit was dropped (the device is gone: counted as in `write`).
        Ports with no fd (socket://...) take nothing here: the whole unit is returned.
        """
        if self._live.device is None and self._device_for_write() is None:
            return None
        fd = self._live.fd
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
            self._lose(str(exc))
            self.counters["tx_dropped"] += 1
            return None
        if written < len(data):
            self.counters["tx_bytes"] += written
            return data[written:]
        self._sent()
        self.counters["tx_bytes"] += written
        return None

    def _with_preamble(self, unit: bytes) -> bytes:
        live = self._live
        if live.fresh:
            live.fresh = False
            return live.preamble + unit
        return unit

    def __enter__(self) -> SerialTransport:
        self.open()
        return self

    def __repr__(self) -> str:
        state = "connected" if self.connected else ("reconnecting" if self._wanted else "closed")
        return f"SerialTransport({self.port!r}, {self.settings['baudrate']}, {state})"
