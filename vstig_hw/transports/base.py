"""The transport contract, and the one base that keeps a device alive.

A transport owns one device (a pyserial port, a python-can bus, a Zenoh
session). It never interprets payloads. It survives the device vanishing:
`read` and `write` reconnect with backoff and report the loss once, instead of
raising into the caller's loop.

`DeviceTransport` does that policy once (python-can's `BusABC` is the model:
the base owns open/read/write, the outage, the backoff and the counters; a
transport implements only its device calls, `_open_device`, `_read_device`,
`_write_device` and `_close_device`).
"""

from __future__ import annotations

import abc
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypeVar

from ..counters import Counters

if TYPE_CHECKING:
    from ..clocks import ClockOffset

Unit = TypeVar("Unit")
Device = TypeVar("Device")


def errno_of(exc: BaseException) -> int | None:
    """The OS error number behind a pyserial/python-can exception: in `.errno`, `.error_code` or a cause."""
    seen: BaseException | None = exc
    while seen is not None:
        for attr in ("errno", "error_code"):
            code = getattr(seen, attr, None)
            if isinstance(code, int):
                return code
        seen = seen.__cause__ or seen.__context__
    return None


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (its type name when it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


class TransportError(Exception):
    """A device problem the user must fix; the message is one clear line naming the device."""


class DeviceUnreachable(TransportError):
    """The device cannot be opened yet but may come (a router not up): `open` returns and `read` retries it."""


class Transport(abc.ABC, Generic[Unit]):
    """One device: what every transport does, and the optional calls with the default a device without them gets.

    The gateway calls the optional ones unconditionally (python-can's `BusABC`
    declares `fileno` so), and mypy checks a new device against them:

    * `write_nowait`: write without waiting, where the device can say it is full
      (a non-blocking fd, `send(timeout=0)`); default: it takes nothing at once, so
      the link's writer thread writes the unit with the blocking `write`;
    * `deliver_to`: hand what is heard to a callback on the device's own thread
      (Zenoh's subscriber); default: nothing calls back, the reader thread reads;
    * `listening`: the endpoints others reach it by (a Zenoh link's listeners);
      default: none; `about`: one line on where it listens and connects, for a start line;
    * `unreached`: why nothing can be heard, where it was told to reach someone and reaches nobody
      (a Zenoh link's connect=); default: None;
    * `compiled_handle`: the `CompiledHandle` the compiled data path reads and writes the device by (a
      serial port's fd, a SocketCAN bus); default: None, the device is the transport's own to call;
    * `clock`: the `PeerClock` measuring the peers' clocks over the device (a Zenoh session's round trips);
      default: None, nothing measured.
    """

    name: str  # how the user named the device, for messages and counters
    counters: Counters  # rx/tx units, reconnects, bus errors...
    listening: tuple[str, ...] = ()  # the endpoints it listens on, where others reach it
    clock: PeerClock | None = None  # measures the peers' clocks over the device, where it can

    @abc.abstractmethod
    def open(self) -> None:
        """Open the device; raise TransportError with a one-line reason if it cannot be."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the device (it may be gone already: this does not raise)."""

    @abc.abstractmethod
    def read(self, timeout: float) -> list[Unit]:
        """Units received within `timeout` seconds (maybe none). Reconnects quietly when the device is gone."""

    @abc.abstractmethod
    def write(self, unit: Unit) -> None:
        """Send one unit; while the device is gone the unit is dropped and counted, not raised."""

    @property
    @abc.abstractmethod
    def connected(self) -> bool:
        """Whether the device is there now."""

    def write_nowait(self, unit: Unit) -> Unit | None:
        """Write what the device takes now, never waiting: None when it took all, else what it did not take."""
        return unit

    def deliver_to(self, deliver: Callable[[list[Unit]], None] | None) -> None:
        """Hand what the device hears to `deliver` on its own thread instead of `read` (None: back to `read`)."""

    @property
    def about(self) -> str:
        """Where it listens and connects, in one line for a start line ("": nothing to say)."""
        return ""

    @property
    def unreached(self) -> str | None:
        """Where it was told to connect and reaches nobody now, in words that follow its name; None if not so."""
        return None

    def compiled_handle(self) -> CompiledHandle[Any] | None:
        """The live state the compiled data path reads the device by (vstig_hw/_cext), or None: it does not."""
        return None


class PeerClock(Protocol):
    """The peers' clocks as a transport measures them (round trips over its device: transports.zenoh_clock)."""

    def estimates(self) -> list[ClockOffset]:
        """The tightest offset now known per peer clock (the metrics page)."""
        ...

    def take(self) -> list[ClockOffset]:
        """The round trips measured since the last take (a recorder notes them in its capture)."""
        ...


class CompiledHandle(Generic[Device]):
    """A device transport's live state that the compiled data path (vstig_hw/_cext: path.c, outlet.c) reads, and
    the one field it writes (`fresh`): the transport keeps its state here, so both see the same values, and the C
    reaches them by these declared names only (`vstig_hw._vstig.DECLARED`, checked by tests/native).

    * `device`: the open device (None: none now); `outage`: from a loss until the device is back;
    * `fd`: a serial port's (or a MAVLink UDP socket's) non-blocking file descriptor, where it has one (None:
      pyserial's own calls);
    * `fresh`: the port was (re)opened and nothing written since: `preamble` goes ahead of the next write;
    * `peers`: a udpin socket's peers, the addresses its sends go to (transports.mavlink.UdpPeers, or its C twin
      once the compiled path reads the link); None elsewhere;
    * `writing`: the lock every write of the device holds while it is under way, where frames must leave in the
      order they were made (a signed MAVLink link's); None elsewhere.
    """

    __slots__ = ("device", "fd", "fresh", "outage", "peers", "preamble", "writing")

    device: Device | None
    outage: bool
    fd: int | None
    fresh: bool
    preamble: bytes
    peers: Any
    writing: Any

    def __init__(self, preamble: bytes = b"") -> None:
        self.device = None
        self.outage = False
        self.fd = None
        self.fresh = False
        self.preamble = preamble
        self.peers = None
        self.writing = None


class Backoff:
    """When to try a lost device again: after `initial` seconds, doubling per failed try up to `maximum`."""

    def __init__(self, initial: float, maximum: float) -> None:
        self.initial, self.maximum = initial, maximum
        self.delay = initial
        self.next_at = 0.0  # monotonic time of the next try

    def start(self, now: float, *, at_once: bool = False) -> None:
        """The device was just lost: the first try comes `initial` seconds from now (`at_once`: now, then so)."""
        self.delay = self.initial / 2 if at_once else self.initial
        self.next_at = now if at_once else now + self.delay

    def failed(self, now: float) -> None:
        """A try failed: wait twice as long (at most `maximum`) before the next."""
        self.delay = min(self.delay * 2, self.maximum)
        self.next_at = now + self.delay


class DeviceTransport(Transport[Unit], Generic[Unit, Device]):
    """A Transport over one device that may vanish: the outage, backoff and counters, once.

    An outage starts when a device call fails (the transport calls `_lose`, or its
    `_read_device`/`_write_device` raises one of `device_errors`): it is logged once
    and counted (`lost_counter`); the device is reopened with backoff from `read`
    (which waits, up to its timeout) and `write` (which never waits; the unit is
    dropped and counted `tx_dropped` meanwhile). The outage ends, counted as
    `reconnects` and logged once, when the device reopens, or where opening proves
    nothing (`back_on_open = False`: a SocketCAN bus binds to an interface that is
    down) when a call on the reopened device has worked (`_sent`, or a read).
    """

    device_word: ClassVar[str] = "device"  # what the device is called in the lost/back lines
    lost_counter: ClassVar[str] = "lost"  # the counter an outage adds to
    back_on_open: ClassVar[bool] = True
    reopen_on_write: ClassVar[bool] = True  # False: a write never tries the device (opening it may take long)
    device_errors: ClassVar[tuple[type[BaseException], ...]] = (OSError,)  # a device call failing this way: lost

    def __init__(self, name: str, backoff: tuple[float, float]) -> None:
        self.name = name
        self.counters = Counters()
        self.last_error: str | None = None  # why the device is away, while it is
        self._log = logging.getLogger(type(self).__module__)
        self._live: CompiledHandle[Device] = CompiledHandle()  # the device and its outage, shared with the C
        self._wanted = False  # open() was called and close() was not
        self._was_opened = False
        self._lost_at = 0.0
        self._backoff = Backoff(*backoff)
        self._retrying = threading.Lock()  # one thread reopens at a time (the reader and a writer may both try)
        self._closed = threading.Event()  # set by close(): a device call still waiting (an open's wait) gives up
        self._slow_drops = 0  # units not taken in time since the device last took one: a slow episode, said once

    @property
    def _device(self) -> Device | None:
        """The open device (None: none now), for a transport's own calls."""
        return self._live.device

    def compiled_handle(self) -> CompiledHandle[Device]:
        return self._live

    # -- the device calls: all a transport implements ----------------------------
    def _open_device(self) -> Device:
        """Open the device, or raise TransportError (DeviceUnreachable: not yet) with one line naming it."""
        raise NotImplementedError

    def _close_device(self, device: Device) -> None:
        """Release the device; it may be gone already, so this does not raise."""
        raise NotImplementedError

    def _read_device(self, device: Device, timeout: float) -> list[Unit]:
        """Units that arrived within `timeout` (maybe none)."""
        raise NotImplementedError

    def _write_device(self, device: Device, unit: Unit) -> None:
        """Send one unit; call `_sent` once it went (a transport counts its own partial or busy cases)."""
        raise NotImplementedError

    # -- the contract ------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._live.device is not None

    def open(self) -> None:
        """Open the device now; TransportError (one line naming it) if it cannot be. Unreachable: retried later."""
        self._closed.clear()
        try:
            self._live.device = self._open_device()
        except DeviceUnreachable as exc:
            self._wanted = self._was_opened = True
            self._begin_outage(str(exc), "unreachable")
            return
        self._wanted = self._was_opened = True
        self.last_error = None

    def close(self) -> None:
        self._wanted = False
        self._closed.set()
        self._drop_device()

    def read(self, timeout: float) -> list[Unit]:
        device = self._live.device
        if device is None:
            device = self._reconnect(timeout)
            if device is None:
                return []
        try:
            units = self._read_device(device, timeout)
        except self.device_errors as exc:
            self._lose(one_line(exc))
            return []
        if units:
            self.counters["rx"] += len(units)
        if self._live.outage and self._live.device is device:  # the reopened device worked
            self._recovered()
        return units

    def write(self, unit: Unit) -> None:
        device = self._live.device
        if device is None:
            device = self._device_for_write()
            if device is None:
                return
        try:
            self._write_device(device, unit)
        except self.device_errors as exc:
            self._lose(one_line(exc))
            self.counters["tx_dropped"] += 1

    def __enter__(self) -> DeviceTransport[Unit, Device]:
        self.open()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- for the device calls ------------------------------------------------------
    def _sent(self, units: int = 1) -> None:
        """`units` went out: counted, and proof that a reopened device works (or that a slow one takes data again)."""
        self.counters["tx"] += units
        if self._slow_drops:
            self._log.warning("%s: %s takes what we send again (%d not taken in time meanwhile)", self.name,
                              self.device_word, self._slow_drops)
            self._slow_drops = 0
        if self._live.outage and self._live.device is not None:
            self._recovered()

    def _not_taken(self, counter: str, units: int = 1) -> None:
        """The device did not take a write in time (slow, deaf or flow-controlled): counted under `counter`, and
        the device kept: slow is not gone. Said once when such an episode starts; `_sent` says when it ends."""
        self.counters[counter] += units
        if not self._slow_drops:
            self._log.warning("%s: %s is not taking what we send in time; what it does not take is dropped (%s) "
                              "and the link stays up", self.name, self.device_word, counter)
        self._slow_drops += units

    def failed(self, reason: str) -> None:
        """A call on the device made outside this transport failed with `reason` (the compiled data path reads a
        SocketCAN socket itself, and a socket tells its error once): the outage starts as if this transport's own
        call had failed."""
        self._lose(reason)

    def _lose(self, reason: str) -> None:
        """The device failed: drop it; report the outage once, then reopen it with backoff from read/write."""
        self._drop_device()
        if not self._wanted:  # a call that failed because close() took the device away: no outage
            return
        if self._live.outage:  # the reopened device failed at once: still the same outage
            self.last_error = reason
            self._retry_later(reason)
            return
        self._begin_outage(reason, self.lost_counter)

    def _device_for_write(self) -> Device | None:
        """The device, or None (the unit dropped and counted) while it stays away; a write never waits."""
        device = self._live.device
        if device is None and (self.reopen_on_write or not self._was_opened):
            device = self._reconnect(0.0)
        if device is None:
            self.counters["tx_dropped"] += 1
        return device

    # -- the state machine -------------------------------------------------------
    def _begin_outage(self, reason: str, counter: str) -> None:
        self._live.outage = True
        self.last_error = reason
        self._lost_at = now = time.monotonic()
        self._backoff.start(now)
        self.counters[counter] += 1
        if counter == "unreachable":  # never opened yet: the reason says it all ("no Zenoh router reachable...")
            self._log.warning("%s: %s; retrying with backoff", self.name, reason)
        else:
            self._log.warning("%s: %s lost (%s); reconnecting with backoff", self.name, self.device_word, reason)

    def _retry_later(self, reason: str) -> None:
        self._backoff.failed(time.monotonic())
        self._log.debug("%s: still lost (%s); next try in %.1f s", self.name, reason, self._backoff.delay)

    def _recovered(self) -> None:
        self._live.outage = False
        self.last_error = None
        self.counters["reconnects"] += 1
        self._log.warning("%s: %s back after %.1f s", self.name, self.device_word, time.monotonic() - self._lost_at)

    def _drop_device(self) -> None:
        live = self._live
        device, live.device = live.device, None
        if device is not None:
            self._close_device(device)

    def _reconnect(self, timeout: float) -> Device | None:
        """Reopen the device when the backoff allows, within `timeout` seconds (sleeping, not spinning)."""
        if not self._wanted:
            if not self._was_opened:
                raise TransportError(f"{self.device_word} {self.name}: not open (call open() first)")
            time.sleep(max(timeout, 0.0))  # closed: nothing will arrive
            return None
        deadline = time.monotonic() + timeout
        while True:
            now = time.monotonic()
            wait = self._backoff.next_at - now
            if wait > deadline - now:
                time.sleep(max(deadline - now, 0.0))
                return None
            if wait > 0:
                time.sleep(wait)
            if self._try_reopen(deadline - time.monotonic()):
                return self._live.device
            if time.monotonic() >= deadline:
                return None

    def _try_reopen(self, patience: float) -> bool:
        """One try to reopen the device; `patience` seconds to wait while another thread is trying."""
        if not self._retrying.acquire(timeout=patience) if patience > 0 else not self._retrying.acquire(False):
            return False
        try:
            if self._live.device is not None:  # the other thread got it back
                return True
            try:
                self._live.device = self._open_device()
            except TransportError as exc:
                self.last_error = str(exc)
                self._retry_later(str(exc))
                return False
            if self.back_on_open:
                self._recovered()
            return True
        finally:
            self._retrying.release()
