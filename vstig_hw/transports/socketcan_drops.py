"""What the kernel drops on SocketCAN, which python-can cannot see: `kernel_dropped`, `interface_dropped`.

When a socket's receive queue is full the kernel drops the frame and counts it
(sk_drops). With SO_RXQ_OVFL set, each frame received afterwards carries that
running count as ancillary data (as candump -d reads it). python-can's socketcan
bus makes room for one ancillary record only (the timestamp), so the count never
reaches it. Drops at the end of a burst have no later frame to carry them, so
the count is also read directly (SO_MEMINFO) every second and at close.
`count_kernel_drops` wraps such a bus: receiving goes through python-can's own
`capture_message` (same frames, same timestamps) on a socket view that asks
for both records and keeps the count. It also enlarges the receive queue, so a
saturated bus fills it less often (what candump's `-r` does), and lets CAN FD
frames through to a classic link, which decodes them rather than never seeing them.

A frame can also be dropped before any socket sees it: when the kernel's input
backlog (net.core.netdev_max_backlog) is full, as on a slow machine under a
burst. The interface counts those (`rx_dropped`, what `ip -s link` shows);
`interface_dropped` is how much that count grew while the bus was open
(every receiver on the interface missed those frames, not only us).
"""

from __future__ import annotations

import errno
import select
import socket
import struct
import time
from pathlib import Path
from typing import Any

import can

from ..counters import Counters

__all__ = ["RCVBUF", "count_kernel_drops"]

SO_RXQ_OVFL = 40  # linux/socket.h (asm-generic); Python's socket module does not name it
SO_RCVBUFFORCE = 33  # as SO_RCVBUF, past net.core.rmem_max (needs CAP_NET_ADMIN)
SO_MEMINFO = 55  # u32[SK_MEMINFO_VARS]: the socket's memory use, and its drop count at SK_MEMINFO_DROPS
_SK_MEMINFO_DROPS = 8
RCVBUF = 8 << 20  # bytes of receive queue asked for: ~8,000 queued frames (an skb takes ~1 KiB)
_CANFD_MTU = 72  # bytes of the largest SocketCAN frame (struct canfd_frame)
_INTERFACE_POLL_S = 1.0  # how often to read the interface's drop count (a sysfs read)
_DROPS = struct.Struct("=I")
_DROPS_SPACE = socket.CMSG_SPACE(_DROPS.size)


class _DropReadingSocket:
    """The bus's socket, as python-can's `capture_message` uses it, with room for the drop count too."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.drops = 0  # the kernel's running count for this socket
        self.flags = 0  # MSG_DONTWAIT while draining: one system call per frame, no select

    def recvmsg(self, bufsize: int, ancbufsize: int = 0,
                flags: int = 0) -> tuple[bytes, list[tuple[int, int, bytes]], int, Any]:
        data, ancillary, msg_flags, address = self.sock.recvmsg(bufsize, ancbufsize + _DROPS_SPACE,
                                                                flags | self.flags)
        kept = []
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL:
                self.drops = _DROPS.unpack_from(payload)[0]
            else:
                kept.append((level, kind, payload))
        return data, kept, msg_flags, address


class KernelDropCountingBus:
    """A python-can socketcan bus whose `recv` also counts what the kernel dropped; all else is the bus's."""

    def __init__(self, bus: Any, counters: Counters, rcvbuf: int = RCVBUF) -> None:
        self.bus = bus
        self.counters = counters
        sock: socket.socket = bus.socket
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        # Hear CAN FD frames too (as candump does): without this the kernel hides them from a classic
        # socket without counting them, so a classic link on an FD bus would miss them in silence.
        sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, rcvbuf)
        except OSError:  # not privileged: as much as net.core.rmem_max allows
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self._socket = _DropReadingSocket(sock)
        self._counted = 0
        self._reading = False  # a link that only sends (replay) never reads: what it hears is not a loss
        self._rx_dropped = Path(f"/sys/class/net/{bus.channel}/statistics/rx_dropped")
        self._interface_base = self._interface_drops()
        self._next_poll = time.monotonic() + _INTERFACE_POLL_S

    def _interface_drops(self) -> int | None:
        try:
            return int(self._rx_dropped.read_text())
        except (OSError, ValueError):  # no such interface file (channel "" or gone): nothing to count
            return None

    def _socket_drops(self) -> int | None:
        try:
            meminfo = self._socket.sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, 4 * (_SK_MEMINFO_DROPS + 1))
        except OSError:  # a kernel before 4.6, or the socket is gone
            return None
        return int(struct.unpack_from(f"={_SK_MEMINFO_DROPS + 1}I", meminfo)[_SK_MEMINFO_DROPS])

    def _count_socket_drops(self) -> None:
        if self._socket.drops != self._counted:  # the count is 32 bits and wraps
            self.counters["kernel_dropped"] += (self._socket.drops - self._counted) % (1 << 32)
            self._counted = self._socket.drops

    def _poll_counts(self) -> None:
        now = time.monotonic()
        if now < self._next_poll:
            return
        self._next_poll = now + _INTERFACE_POLL_S
        latest = self._socket_drops()
        if latest is not None:
            self._socket.drops = latest
            self._count_socket_drops()
        if self._interface_base is None:
            return
        drops = self._interface_drops()
        if drops is not None and drops > self._interface_base:
            self.counters["interface_dropped"] += drops - self._interface_base
            self._interface_base = drops

    # -- for a reader that takes frames from the socket itself (the compiled data path, vstig_hw/_cext/path.c) --
    def fileno(self) -> int:
        """The raw socket's fd, for a reader or writer of it outside python-can."""
        return int(self.bus.socket.fileno())

    def read_elsewhere(self) -> None:
        """Frames are read from this socket by another reader: what it leaves at close is a loss, as after `recv`."""
        self._reading = True

    def poll_counts(self) -> None:
        """Poll the socket's and the interface's drop counts, as `recv` does at most once a second."""
        self._poll_counts()

    def note_kernel_drops(self, count: int) -> None:
        """The kernel's running drop count for this socket, as a frame read elsewhere carried it (SO_RXQ_OVFL)."""
        self._socket.drops = count
        self._count_socket_drops()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        from can.interfaces.socketcan.socketcan import capture_message

        self._reading = True
        self._poll_counts()
        if timeout == 0:  # draining after a frame: try the queue directly instead of asking select first
            self._socket.flags = socket.MSG_DONTWAIT
        else:
            try:
                ready, _, _ = select.select([self._socket.sock], [], [], timeout)
            except OSError as error:  # the interface went away
                raise can.CanOperationError(f"Failed to receive: {error.strerror}", error.errno) from error
            if not ready:
                return None
        channel = self.bus.channel
        try:
            message = capture_message(self._socket, get_channel=not channel)  # type: ignore[arg-type]
        except can.CanOperationError as error:
            if error.error_code in (errno.EAGAIN, errno.EWOULDBLOCK):
                return None  # the queue is empty
            raise
        finally:
            self._socket.flags = 0
        if message is not None and not message.channel and channel:
            message.channel = channel
        self._count_socket_drops()
        return message

    def shutdown(self) -> None:
        """Close the bus; frames still queued for us are lost with the socket, so count them as dropped."""
        self._next_poll = 0.0
        self._poll_counts()  # the last count, before the bus goes
        try:
            while self._reading:
                self._socket.sock.recvmsg(_CANFD_MTU, 0, socket.MSG_DONTWAIT)
                self.counters["unread_at_close"] += 1
        except OSError:  # the queue is empty (or the interface is gone)
            pass
        self.bus.shutdown()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.bus, name)


def count_kernel_drops(bus: can.BusABC, counters: Counters) -> can.BusABC:
    """`bus` itself unless it is a SocketCAN bus, which is wrapped to count kernel drops in `counters`."""
    if not isinstance(getattr(bus, "socket", None), socket.socket) or bus.__class__.__name__ != "SocketcanBus":
        return bus
    wrapped: Any = KernelDropCountingBus(bus, counters)
    return wrapped  # type: ignore[no-any-return]
