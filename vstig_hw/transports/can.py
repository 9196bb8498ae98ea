"""CanTransport: a python-can bus that survives its adapter vanishing.

Any python-can interface works unchanged (socketcan, slcan, pcan, kvaser,
virtual, udp_multicast, socketcand...): interface, channel, bitrate and any other
option go to `can.Bus` as given. Units are `can.Message` frames, passed up as
received (error frames too, so captures keep them; the framing counts them).

Counters: `rx`, `tx`, `tx_dropped` (device gone or TX queue full), `bus_errors`
(error frames and failed bus calls), `bus_off`, `lost` (outages) and `reconnects`
(recoveries), and on SocketCAN `kernel_dropped` (frames the kernel dropped because
our receive queue was full, as candump -d reports), `interface_dropped` (frames the
interface dropped before any socket got them) and `unread_at_close`. An outage is
logged once and its end once; meanwhile the bus is reopened with exponential
backoff (0.1 s doubling to 2 s) from `read`/`write`, which never raise into the
caller's loop. A bus that opens but fails at its first call (SocketCAN binds to an
interface that is down, then reports ENETDOWN) has not come back: the outage goes
on and the backoff keeps growing.
"""

from __future__ import annotations

import errno
import logging
import time
from typing import Any

import can

from ..counters import Counters
from .base import TransportError, errno_of, one_line
from .socketcan_drops import count_kernel_drops

__all__ = ["CanTransport"]

log = logging.getLogger(__name__)

# Linux error-frame class bit for bus-off (linux/can/error.h CAN_ERR_BUSOFF); python-can hands
# SocketCAN error frames up with the kernel's class bits as the arbitration id.
_CAN_ERR_BUSOFF = 0x40
_DRAIN_LIMIT = 512  # frames taken per read() after the first, so one busy bus cannot starve the loop
_STATE_POLL_S = 1.0  # how often to ask interfaces that report it (pcan, kvaser...) for bus-off
# Send failures that mean "the bus is busy", not "the device is gone".
_TRANSIENT_ERRNOS = frozenset({errno.ENOBUFS, errno.EAGAIN})
# Interfaces whose send(timeout=0) returns at once (queue full: an error), so the gateway's loop may call it.
_NONBLOCKING_SEND = frozenset({"socketcan", "virtual"})


class CanTransport:
    """A python-can bus as a Transport[can.Message]."""

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        bitrate: int | None = None,
        fd: bool = False,
        can_filters: list[dict[str, Any]] | None = None,
        name: str | None = None,
        backoff: tuple[float, float] = (0.1, 2.0),
        send_timeout: float = 0.1,
        **options: Any,
    ) -> None:
        self.interface = interface
        self.channel = channel
        self.name = name or f"{interface}:{channel}"
        self.counters = Counters()
        self.last_error: str | None = None
        self.send_timeout = send_timeout
        self._bus_kwargs: dict[str, Any] = {"interface": interface, "channel": channel, **options}
        if bitrate is not None:
            self._bus_kwargs["bitrate"] = bitrate
        if fd:  # only when asked: some interfaces reject an `fd` keyword they do not support
            self._bus_kwargs["fd"] = True
        if can_filters is not None:
            self._bus_kwargs["can_filters"] = can_filters
        self._backoff_min, self._backoff_max = backoff
        self._bus: can.BusABC | None = None
        self._opened = False
        self._outage = False  # from a loss until a reopened bus has worked once
        self._delay = self._backoff_min
        self._next_try = 0.0
        self._next_state_poll = 0.0

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> None:
        self._bus = self._make_bus()
        self._opened = True
        self.last_error = None

    def close(self) -> None:
        self._opened = False
        self._drop_bus()

    @property
    def connected(self) -> bool:
        return self._bus is not None

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus while connected (for captures and diagnostics)."""
        return self._bus

    def _make_bus(self) -> can.BusABC:
        try:
            return count_kernel_drops(can.Bus(**self._bus_kwargs), self.counters)
        except can.CanInterfaceNotImplementedError as exc:
            known = "" if self.interface in can.VALID_INTERFACES else f" (python-can knows: " \
                f"{', '.join(sorted(can.VALID_INTERFACES))})"
            raise TransportError(f"CAN interface {self.interface!r} cannot be used here: {one_line(exc)}{known}") \
                from None
        except (NameError, ImportError, AttributeError) as exc:  # a vendor driver whose library is not installed
            raise TransportError(f"CAN interface {self.interface!r} cannot be used here: its vendor library is "
                                 f"missing or incomplete ({one_line(exc)})") from None
        except (can.CanError, OSError, ValueError, TypeError) as exc:
            raise TransportError(self._explain(exc)) from None

    def _explain(self, exc: BaseException) -> str:
        code = errno_of(exc)
        channel = self.channel
        if code == errno.ENODEV:
            if str(channel).startswith("vcan"):
                return f"no such CAN interface {channel}: create it with `ip link add {channel} type vcan`"
            return f"no such CAN interface {channel}: is the adapter plugged in? (`ip link show` lists CAN interfaces)"
        if code == errno.EAFNOSUPPORT:
            return (f"cannot open {self.interface} channel {channel}: this kernel has no SocketCAN "
                    "(socket(AF_CAN) is not supported); load the `can` modules or use another interface")
        if code == errno.ENETDOWN:
            return f"CAN interface {channel} is down: bring it up with `ip link set up {channel}`"
        return f"cannot open CAN {self.interface} channel {channel}: {one_line(exc)}"

    # -- moving frames -------------------------------------------------------
    def read(self, timeout: float) -> list[can.Message]:
        bus = self._bus or self._reconnect(timeout)
        if bus is None:
            return []
        frames: list[can.Message] = []
        try:
            frame = bus.recv(timeout)
            while frame is not None:
                frames.append(frame)
                if frame.is_error_frame:
                    self._error_frame(frame)
                if len(frames) > _DRAIN_LIMIT or self._bus is None:
                    break
                frame = bus.recv(0)
            if self._bus is not None:
                self._poll_state(bus)
        except (can.CanError, OSError) as exc:
            self._lost(one_line(exc))
        else:
            if self._outage and self._bus is not None:
                self._recovered()
        self.counters["rx"] += len(frames)
        return frames

    def write(self, unit: can.Message) -> None:
        """Send, waiting up to `send_timeout` for room in the TX queue; a frame still not taken is dropped."""
        self._send(unit, self.send_timeout, drop_when_busy=True)

    def write_nowait(self, unit: can.Message) -> can.Message | None:
        """Send only if the TX queue has room now (interfaces whose send cannot block); else the frame, to wait."""
        if self.interface not in _NONBLOCKING_SEND:
            return unit
        return None if self._send(unit, 0.0, drop_when_busy=False) else unit

    def _send(self, unit: can.Message, timeout: float, *, drop_when_busy: bool) -> bool:
        """False if the bus was busy and the frame is still ours to send; True when sent or dropped (counted)."""
        bus = self._bus or self._reconnect(0.0)
        if bus is None:
            self.counters["tx_dropped"] += 1
            return True
        try:
            bus.send(unit, timeout=timeout)
        except (can.CanError, OSError) as exc:
            busy = errno_of(exc) in _TRANSIENT_ERRNOS or "buffer full" in str(exc).lower()
            if busy and not drop_when_busy:
                return False
            self.counters["tx_dropped"] += 1
            self.counters["bus_errors"] += 1
            if not busy:
                self._lost(one_line(exc))
            return True
        if self._outage:
            self._recovered()
        self.counters["tx"] += 1
        return True

    # -- errors and reconnection ---------------------------------------------
    def _error_frame(self, frame: can.Message) -> None:
        self.counters["bus_errors"] += 1
        if self.interface == "socketcan" and frame.arbitration_id & _CAN_ERR_BUSOFF:
            self.counters["bus_off"] += 1
            self._lost("bus-off")

    def _poll_state(self, bus: can.BusABC) -> None:
        now = time.monotonic()
        if now < self._next_state_poll:
            return
        self._next_state_poll = now + _STATE_POLL_S
        try:
            state = bus.state
        except (NotImplementedError, can.CanError, OSError):
            return
        if state is can.BusState.ERROR:
            self.counters["bus_off"] += 1
            self._lost("bus-off")

    def _drop_bus(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception as exc:  # a half-dead adapter may fail any way while closing
                log.debug("%s: error while closing: %s", self.name, exc)

    def _lost(self, reason: str) -> None:
        """The device failed: report once per outage, then reopen it with backoff from read/write."""
        self._drop_bus()
        self.last_error = reason
        if self._outage:  # the reopened bus failed at once: still the same outage
            self._retry_later(reason)
            return
        self._outage = True
        self.counters["lost"] += 1
        log.warning("%s: CAN device lost (%s); reconnecting with backoff", self.name, reason)
        self._delay = self._backoff_min
        self._next_try = time.monotonic() + self._delay

    def _retry_later(self, reason: str) -> None:
        self._delay = min(self._delay * 2, self._backoff_max)
        self._next_try = time.monotonic() + self._delay
        log.debug("%s: still lost (%s); next try in %.1f s", self.name, reason, self._delay)

    def _recovered(self) -> None:
        """A reopened bus worked (a read or a send without error): the outage is over."""
        self._outage = False
        self.counters["reconnects"] += 1
        self.last_error = None
        log.warning("%s: CAN device back", self.name)

    def _reconnect(self, timeout: float) -> can.BusABC | None:
        if not self._opened:
            return None
        wait = self._next_try - time.monotonic()
        if wait > timeout:
            time.sleep(max(timeout, 0.0))  # nothing can arrive while the device is gone
            return None
        if wait > 0:
            time.sleep(wait)
        try:
            self._bus = self._make_bus()
        except TransportError as exc:
            self.last_error = str(exc)
            self._retry_later(str(exc))
            return None
        return self._bus  # not back yet: `_recovered` once a call on it has worked
