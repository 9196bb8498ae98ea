"""A pty radio flooded from its far end, for the tests that stop a loaded gateway (tests/gateway, tests/cli)."""

from __future__ import annotations

import os
import select
import threading
import tty

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing

FRAME = 12  # bytes of one cobs8 frame


class FloodedPty:
    """A pty whose far end writes batches of frames as fast as the gateway reads them, and reads what it sends."""

    def __init__(self, robot: int) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        self.path = os.ttyname(self.slave)
        framing = make_serial_framing("cobs8")
        self.batches = [b"".join(framing.encode(Message(Op.PUT, (base + i) % 30000, i, 1 + base // 30000, robot))[0]
                                 for i in range(64)) for base in range(0, 64 * 200, 64)]
        self.written = 0
        self._running = True
        self._thread = threading.Thread(target=self._flood, daemon=True)
        self._thread.start()

    def _flood(self) -> None:
        n = 0
        while self._running:
            readable, writable, _ = select.select([self.master], [self.master], [], 0.01)
            if readable:
                try:
                    os.read(self.master, 65536)  # what the gateway sends: read, so it never backs up
                except OSError:
                    return
            if writable:
                try:
                    self.written += os.write(self.master, self.batches[n % len(self.batches)])
                except (BlockingIOError, OSError):
                    continue
                n += 1

    def stop(self) -> None:
        self._running = False
        self._thread.join(2)

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)
