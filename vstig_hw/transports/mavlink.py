"""MAVLink transports: a telemetry radio's UART, or UDP as the MAVLink world routes it (udpin, udpout).

C twin: vstig_hw/_cext/path.c vstig_hw/_cext/outlet.c vstig_hw/_cext/peers.c (the compiled delivery reads a UDP
link's socket itself, its outlet sends to it, and a udpin link's peers are a `UdpPeers` in C; held equal by
tests/native/test_native_mavlink_udp.py).

Whatever the device, a unit is one MAVLink frame exactly as on the wire (framing/mavlink.py's reader cuts the
bytes), so captures hold whole frames and the framing knows each frame's sender. What is not a frame is counted
under `drop_<reason>` (`drop_noise`, `drop_crc`, `drop_incompat_flags`, `drop_truncated`) and never handed on.

Both kinds also
- announce the gateway: `heartbeat` (the framing's HEARTBEAT) goes out once a second from the reader thread, so
  MAVLink tools list the component (none while listen-only, or while a udpin link has heard no peer);
- write in signing order: every write (a TUNNEL unit, a HEARTBEAT) passes `stamp` (the framing's `in_order`)
  under one lock as the device takes it, so signed frames leave in timestamp order whichever thread made them
  and however long the air budget held them; a HEARTBEAT never goes between the parts of a unit the port took
  in part (it waits for the next read);
- pace what they send to `air_rate` (bits a second on the air; a SiK radio's AIR_SPEED): at most half of it,
  `AIR_SHARE`, is ours, the rest the ground station's and the other vehicles'. A unit the budget has no room
  for is not taken by `write_nowait` (the link's writer waits for room in `write`), so what waits stays in the
  gateway's outlet, shared fairly among its sources, as on any slow device.

`udpin` binds the address it is given (a loopback one unless asked otherwise) and sends to every address a
datagram came from in the last `PEER_TIMEOUT` seconds, at most `MAX_PEERS` (the most recently heard: `UdpPeers`):
MAVLink's own udpin answers the last sender alone, which one stray datagram would divert. `udpout` sends to the
router's address and hears only it (a connected socket). Neither routes: what it hears goes to the gateway alone.
Its `CompiledHandle` holds the socket's fd and the peers, so the compiled delivery can read and send in C; its
HEARTBEATs then go out when the delivery's timer calls `beat`.
"""

from __future__ import annotations

import errno
import select
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from ..framing.mavlink import MAX_FRAME, MavlinkStreamReader
from .base import CompiledHandle, DeviceTransport, TransportError
from .serial import SerialTransport

__all__ = ["AIR_SHARE", "HEARTBEAT_PERIOD", "MAX_PEERS", "PEER_TIMEOUT", "AirBudget", "MavlinkSerialTransport",
           "MavlinkUdpTransport", "UdpPeers"]

HEARTBEAT_PERIOD = 1.0  # seconds between HEARTBEATs, MAVLink's usual rate
AIR_SHARE = 0.5  # of a radio's air rate a link uses at most
MAX_PEERS = 8  # addresses a udpin link sends to at most
PEER_TIMEOUT = 10.0  # seconds a udpin link keeps sending to an address it no longer hears from
_DATAGRAM = 65535  # bytes a datagram read takes at most
_DATAGRAMS_PER_READ = 64  # datagrams one read takes at most
Address = tuple[Any, ...]  # a socket address as the socket module gives it: (host, port[, flowinfo, scope_id])


class AirBudget:
    """Bytes a link may send: `rate` a second, at most `burst` saved up (a token bucket)."""

    def __init__(self, air_rate: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.rate = air_rate * AIR_SHARE / 8
        self.burst = max(self.rate / 4, 2.0 * MAX_FRAME)
        self.clock = clock
        self._tokens = self.burst
        self._at = clock()

    def _refill(self) -> float:
        now = self.clock()
        self._tokens = min(self.burst, self._tokens + (now - self._at) * self.rate)
        self._at = now
        return self._tokens

    def take(self, size: int) -> bool:
        """Spend `size` bytes if there is room for them now."""
        if self._refill() < min(size, self.burst):
            return False
        self._tokens -= size
        return True

    def charge(self, size: int) -> None:
        """Spend `size` bytes that go out anyway (a HEARTBEAT)."""
        self._refill()
        self._tokens -= size

    def wait(self, size: int) -> float:
        """Seconds until `size` bytes fit."""
        return max(0.0, (min(size, self.burst) - self._refill()) / self.rate)


class UdpPeers:
    """The addresses a udpin link sends to: each heard from within `timeout` seconds, at most `most` of them (the
    least recently heard is forgotten first), in the order last heard."""

    def __init__(self, most: int = MAX_PEERS, timeout: float = PEER_TIMEOUT) -> None:
        self.most, self.timeout = most, timeout
        self._until: dict[Address, float] = {}  # kept in the order last heard

    def __len__(self) -> int:
        """Addresses held, those past their time too until `live` lets them go."""
        return len(self._until)

    def heard(self, address: Address, now: float) -> None:
        until = self._until
        until.pop(address, None)
        until[address] = now + self.timeout  # re-inserted: the order is the order last heard
        if len(until) > self.most:
            del until[next(iter(until))]

    def live(self, now: float) -> list[Address]:
        """The addresses heard from within `timeout` of `now` (the others let go), the least recently heard first."""
        until = self._until
        for address in [address for address, deadline in until.items() if deadline < now]:
            del until[address]
        return list(until)


def _one_frame(data: bytes) -> bool:
    """Whether `data` is exactly one MAVLink 2 frame by its header (its crc not checked)."""
    return len(data) > 12 and data[0] == 0xFD and not data[2] & 0xFE and \
        len(data) == 12 + data[1] + (13 if data[2] else 0)


class _Mavlink:
    """What both MAVLink transports add to their device: cutting, heartbeats, pacing."""

    counters: Any
    heartbeat: Callable[[], bytes] | None
    budget: AirBudget | None
    _live: CompiledHandle[Any]  # the device transport's

    def _mavlink_init(self, heartbeat: Callable[[], bytes] | None, air_rate: int | None,
                      stamp: Callable[[bytes], bytes] | None) -> None:
        self.heartbeat = heartbeat
        self.budget = None if air_rate is None else AirBudget(air_rate)
        self._next_beat = 0.0
        self._reader = MavlinkStreamReader(self.counters, prefix="drop_")
        self._stamp = stamp or (lambda unit: unit)
        self._writing = threading.Lock()  # one write at a time, each unit stamped as it goes (see the module)
        if stamp is not None:  # signed: the compiled outlet's own writes hold the lock too
            self._live.writing = self._writing
        self._tail: bytes | None = None  # what a write left of a unit the port took in part: it goes next, as is

    def _in_order(self, unit: bytes) -> bytes:
        """`unit` ready for the device (under `_writing`): stamped, unless it is the rest of one already begun."""
        if unit is self._tail:
            self._tail = None
            return unit
        self._tail = None
        return self._stamp(unit)

    def _beat(self, send: Callable[[bytes], object]) -> None:
        """Send the HEARTBEAT if one is due and no write is under way (else it goes at a later read)."""
        if self.heartbeat is None or time.monotonic() < self._next_beat or not self._writing.acquire(blocking=False):
            return
        try:
            if self._tail is None:
                beat = self._beat_due()
                if beat is not None:
                    send(self._stamp(beat))
        finally:
            self._writing.release()

    def cut(self, data: bytes) -> list[bytes]:
        """The frames this whole chunk holds (a datagram, or what a read took: see `flush_after`)."""
        return self._reader.feed(data)

    def _beat_due(self) -> bytes | None:
        """The HEARTBEAT to send now, if one is due."""
        if self.heartbeat is None:
            return None
        now = time.monotonic()
        if now < self._next_beat:
            return None
        self._next_beat = now + HEARTBEAT_PERIOD
        beat = self.heartbeat()
        if self.budget is not None:
            self.budget.charge(len(beat))
        self.counters["heartbeats"] += 1
        return beat

    def _room(self, unit: bytes) -> bool:
        return self.budget is None or self.budget.take(len(unit))

    def _pace(self, unit: bytes, closed: Any) -> None:
        """Wait until the air budget has room for `unit` (the writer thread's blocking write)."""
        budget = self.budget
        while budget is not None and not budget.take(len(unit)):
            if closed.wait(budget.wait(len(unit))):
                return


class MavlinkSerialTransport(_Mavlink, SerialTransport):
    """A telemetry radio (SiK, RFD900, a mesh radio) on a UART: Transport[bytes] of whole MAVLink frames."""

    quiet_after = 0.1  # seconds without a byte after which a frame still arriving is cut short

    def __init__(self, port: str, baudrate: int = 57600, *, heartbeat: Callable[[], bytes] | None = None,
                 air_rate: int | None = None, stamp: Callable[[bytes], bytes] | None = None,
                 **options: Any) -> None:
        super().__init__(port, baudrate, **options)
        self._mavlink_init(heartbeat, air_rate, stamp)
        self._last_byte = 0.0

    def _open_device(self) -> Any:
        port = super()._open_device()
        self._reader.reset()
        return port

    def _read_device(self, device: Any, timeout: float) -> list[bytes]:
        self._beat(lambda beat: SerialTransport.write(self, beat))
        chunks = super()._read_device(device, min(timeout, HEARTBEAT_PERIOD))
        if chunks:
            self._last_byte = time.monotonic()
            return self.cut(chunks[0])
        if self._reader.holding and time.monotonic() - self._last_byte > self.quiet_after:
            return self._reader.flush()
        return []

    def write_nowait(self, unit: bytes) -> bytes | None:
        if not self._room(unit):
            return unit
        with self._writing:
            self._tail = super().write_nowait(self._in_order(unit))  # the rest goes next, as it is (`write`)
            return self._tail

    def write(self, unit: bytes) -> None:
        self._pace(unit, self._closed)
        with self._writing:
            super().write(self._in_order(unit))


class MavlinkUdpTransport(_Mavlink, DeviceTransport[bytes, socket.socket]):
    """MAVLink over UDP: `udpin` (bind `address`, answer the last sender) or `udpout` (send to `address`)."""

    device_word = "UDP socket"
    lost_counter = "disconnects"

    def __init__(self, mode: str, address: tuple[str, int], *, heartbeat: Callable[[], bytes] | None = None,
                 air_rate: int | None = None, stamp: Callable[[bytes], bytes] | None = None,
                 name: str | None = None) -> None:
        if mode not in ("udpin", "udpout"):
            raise ValueError(f"a MAVLink UDP link is udpin or udpout, got {mode!r}")
        super().__init__(name or f"{mode}:{address[0]}:{address[1]}", (0.1, 2.0))
        self.mode, self.address = mode, address
        self._live.peers = UdpPeers() if mode == "udpin" else None  # udpout: the connected socket's one address
        self.listening = (f"udp/{address[0]}:{address[1]}",) if mode == "udpin" else ()
        self._mavlink_init(heartbeat, air_rate, stamp)

    @property
    def about(self) -> str:
        if self.mode == "udpin":
            return f"listening on udp {self.address[0]}:{self.address[1]}"
        return f"sending to udp {self.address[0]}:{self.address[1]}"

    def _open_device(self) -> socket.socket:
        try:
            family = socket.getaddrinfo(self.address[0], self.address[1], type=socket.SOCK_DGRAM)[0][0]
            sock = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as exc:
            raise TransportError(f"MAVLink {self.mode}:{self.address[0]}:{self.address[1]}: {exc}") from None
        try:
            if self.mode == "udpin":
                sock.bind(self.address)
            else:
                sock.connect(self.address)  # hears the router alone
        except OSError as exc:
            sock.close()
            raise TransportError(f"MAVLink {self.mode}:{self.address[0]}:{self.address[1]}: "
                                 f"{exc.strerror or exc}") from None
        sock.setblocking(False)
        self._live.fd = sock.fileno()
        return sock

    def _close_device(self, device: socket.socket) -> None:
        self._live.fd = None
        device.close()

    @property
    def peers(self) -> UdpPeers | None:
        """Whom a udpin link sends to (the compiled path's own table, once it reads the link); None: udpout."""
        peers: UdpPeers | None = self._live.peers
        return peers

    @property
    def writes_as_made(self) -> bool:
        """A unit may go to the socket as it was made, by whoever holds the write lock (the compiled outlet, holding
        `CompiledHandle.writing` where the link signs): no air budget to charge on this link."""
        return self.budget is None

    def _heard_any(self) -> bool:
        peers = self._live.peers
        return peers is None or len(peers) > 0

    def beat(self) -> float:
        """Send the HEARTBEAT if one is due, as a read does (a udpin link once it heard a peer); the seconds until the
        next is due. The compiled delivery reads the socket itself and calls this when its timer says so."""
        device = self._live.device
        if self.heartbeat is None:
            return HEARTBEAT_PERIOD
        if device is not None and self._heard_any():
            self._beat(lambda beat: self._send(device, beat))
        return max(0.0, self._next_beat - time.monotonic())

    def _read_device(self, device: socket.socket, timeout: float) -> list[bytes]:
        if self._heard_any():
            self._beat(lambda beat: self._send(device, beat))
        if not select.select([device], [], [], min(timeout, HEARTBEAT_PERIOD))[0]:
            return []
        frames: list[bytes] = []
        peers = self._live.peers
        for _ in range(_DATAGRAMS_PER_READ):  # what has come, a bounded number of datagrams per read
            try:
                data, source = device.recvfrom(_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # an ICMP answer to an earlier send: nobody at the router's address yet
                self.counters["tx_refused"] += 1
                continue
            self.counters["rx_bytes"] += len(data)
            self.counters["rx_datagrams"] += 1
            if peers is not None:
                peers.heard(source, time.monotonic())
            if _one_frame(data):
                frames.append(data)  # the common datagram: one whole frame (its crc is the framing's to check)
            else:
                frames += self._reader.feed(data) + self._reader.flush()  # a datagram is whole
        return frames

    def _write_device(self, device: socket.socket, unit: bytes) -> None:
        self._send(device, unit)

    def _send(self, device: socket.socket, unit: bytes) -> None:
        peers = self._live.peers
        targets: list[Address | None] = [None] if peers is None else list(peers.live(time.monotonic()))
        if not targets:
            self.counters["tx_no_peer"] += 1  # udpin: nobody has spoken to us lately
            return
        sent = False
        for peer in targets:
            try:
                if peer is None:  # udpout: the connected socket's address
                    device.send(unit)
                else:
                    device.sendto(unit, peer)
            except ConnectionRefusedError:  # nobody there (an ICMP answer): the others still get it
                self.counters["tx_refused"] += 1
                continue
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.ENOBUFS):
                    raise
                self._not_taken("tx_busy")
                continue
            sent = True
            self.counters["tx_bytes"] += len(unit)
        if sent:
            self._sent()

    def write_nowait(self, unit: bytes) -> bytes | None:
        if not self._room(unit):
            return unit
        with self._writing:
            DeviceTransport.write(self, self._in_order(unit))  # a datagram goes whole or not at all
        return None

    def write(self, unit: bytes) -> None:
        self._pace(unit, self._closed)
        with self._writing:
            super().write(self._in_order(unit))
