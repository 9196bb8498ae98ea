"""Real peers on ptys for the subprocess tests: an slcan adapter and a serial radio.

`SlcanAdapter` plays a USB-CAN adapter on a pty's master side, so the `vstig`
under test runs python-can's real slcan driver on the slave (FACTS.md, section
4): it acknowledges every command with `\\r` and exchanges `t<id><dlc><data>\\r`
lines. `PtyPeer` is the far end of a serial radio: raw bytes in and out.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can

VSTIG = str(Path(sys.executable).with_name("vstig"))


class PtyPeer:
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        self.path = os.ttyname(self.slave)

    def read(self, timeout: float = 0.05) -> bytes:
        if select.select([self.master], [], [], timeout)[0]:
            try:
                return os.read(self.master, 65536)
            except OSError:
                return b""
        return b""

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


class Listener:
    """The far end of a cobs8 radio that does read: the time each message (by key) first arrived, and how many
    messages arrived in all."""

    def __init__(self, radio: PtyPeer) -> None:
        from vstig_hw.framing import make_serial_framing

        self.radio = radio
        self.arrived: dict[int, float] = {}
        self.heard = 0
        self._framing = make_serial_framing("cobs8")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            data = self.radio.read(0.05)
            stamp = time.perf_counter()
            for msg in self._framing.feed(data) if data else ():
                self.heard += 1
                self.arrived.setdefault(msg.key, stamp)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


class SlcanAdapter(PtyPeer):
    """The adapter side of slcan: frames the driver sends land in `sent`; `inject` puts frames on its bus."""

    def __init__(self) -> None:
        super().__init__()
        self.sent: list[can.Message] = []
        self.commands: list[str] = []
        self.listening = threading.Event()  # cleared: the adapter reads nothing (a hung adapter), still sends
        self.listening.set()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def deafen(self) -> int:
        """Stop reading, and fill the line to us until the host's writes would block, as a hung USB adapter
        leaves it; the bytes written to fill it."""
        self.listening.clear()
        return fill(self.path)

    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            if not self.listening.is_set():
                time.sleep(0.02)
                continue
            buffer += self.read(0.02)
            *lines, buffer = buffer.split(b"\r")
            for raw in lines:
                line = raw.decode("ascii", "replace").strip()
                if line[:1] in ("t", "T"):
                    width = 3 if line[0] == "t" else 8
                    can_id = int(line[1:1 + width], 16)
                    dlc = int(line[1 + width], 16)
                    data = bytes.fromhex(line[2 + width:2 + width + 2 * dlc])
                    self.sent.append(can.Message(arbitration_id=can_id, data=data, is_extended_id=width == 8,
                                                 timestamp=time.time()))
                    self.write(b"z\r" if line[0] == "t" else b"Z\r")
                elif line:
                    self.commands.append(line)
                    self.write(b"\r")

    def inject(self, frame: can.Message) -> None:
        head = f"T{frame.arbitration_id:08X}" if frame.is_extended_id else f"t{frame.arbitration_id:03X}"
        self.write(f"{head}{len(frame.data)}{bytes(frame.data).hex().upper()}\r".encode())

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        super().close()


def fill(path: str) -> int:
    """Write to the terminal at `path` (its slave side) until it takes no more: what the host writes after this
    waits until the far end reads. The bytes written."""
    fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    written = 0
    try:
        while True:
            try:
                written += os.write(fd, b"x" * 4096)
            except BlockingIOError:  # the line discipline moves what it holds on: full only once it stays so
                if not select.select([], [fd], [], 0.3)[1]:
                    return written
    finally:
        os.close(fd)


STARTED: list[subprocess.Popen[str]] = []  # what start_vstig started: conftest kills what a test left running


def kill_what_tests_left_running() -> None:
    """Kill any `vstig` a test started and left running (the conftests call it after every test)."""
    while STARTED:
        process = STARTED.pop()
        if process.poll() is None:
            process.kill()
            process.communicate()


def _as_from_a_terminal() -> None:
    """In the child: SIGHUP, SIGINT and SIGQUIT as a terminal's foreground job has them, even when the tests run
    under nohup (which ignores SIGHUP) or as a background job (`make test &`: SIGINT and SIGQUIT ignored), which
    vstig would rightly keep ignoring."""
    for signum in (signal.SIGHUP, signal.SIGINT, signal.SIGQUIT):
        signal.signal(signum, signal.SIG_DFL)


def start_vstig(*args: str, **kwargs: Any) -> subprocess.Popen[str]:
    kwargs.setdefault("preexec_fn", _as_from_a_terminal)
    process = subprocess.Popen([VSTIG, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)
    STARTED.append(process)
    return process


def run_vstig(*args: str, timeout: float = 60, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    kwargs.setdefault("preexec_fn", _as_from_a_terminal)
    return subprocess.run([VSTIG, *args], capture_output=True, text=True, timeout=timeout, check=False, **kwargs)


def wait_for(done: Callable[[], bool], deadline: float = 20.0, step: Callable[[], None] | None = None) -> None:
    end = time.monotonic() + deadline
    while not done():
        if time.monotonic() > end:
            raise AssertionError("timed out waiting")
        if step:
            step()
        else:
            time.sleep(0.01)


def catches(pid: int, signum: int) -> bool:
    """Whether the process has a handler for `signum` (bit signum-1 of SigCgt in /proc)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    (mask,) = [line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")]
    return bool(int(mask, 16) >> (signum - 1) & 1)


def has_open(pid: int, path: str) -> bool:
    """Whether process `pid` has `path` open (a passive listener shows no other sign of being ready)."""
    fds = Path(f"/proc/{pid}/fd")
    try:
        return any(os.path.realpath(fd) == path for fd in fds.iterdir())
    except OSError:  # a descriptor closed while we looked
        return False


def stop(process: subprocess.Popen[str], timeout: float = 10) -> tuple[str, str]:
    """SIGTERM, as Ctrl-C would, and collect the output; a process that outlives `timeout` is killed and fails the
    test (it must never outlive the test run)."""
    process.terminate()
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        raise AssertionError(f"{process.args} ignored SIGTERM for {timeout} s; killed. stderr: {err[-2000:]}") from None
    return out, err


def run_vstig_on_a_terminal_stderr(*args: str, stdout: Any = subprocess.DEVNULL,
                                   timeout: float = 120) -> tuple[int, bytes]:
    """Run vstig with stderr on a pty (a terminal, as a user sees it); returns (exit code, what the pty showed)."""
    import pty

    primary, secondary = pty.openpty()
    done = subprocess.run([VSTIG, *args], stdout=stdout, stderr=secondary, timeout=timeout, check=False)
    os.close(secondary)
    shown = b""
    while True:
        try:
            chunk = os.read(primary, 65536)
        except OSError:  # EIO: every writer has closed the pty
            break
        if not chunk:
            break
        shown += chunk
    os.close(primary)
    return done.returncode, shown
