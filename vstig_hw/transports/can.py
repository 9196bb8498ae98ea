"""CanTransport: a python-can bus that survives its adapter vanishing, and waits on no adapter.

C twin: vstig_hw/_cext/path.c (its read: a SocketCAN socket's, or any other bus's recv), vstig_hw/_cext/outlet.c
(its write_nowait: a SocketCAN socket's, or the bus's send); held equal by tests/native (index: vstig_hw/_vstig.pyi).

Any python-can interface works unchanged (socketcan, pcan, kvaser, virtual,
udp_multicast, socketcand...): interface, channel, bitrate and any other
option go to `can.Bus` as given. slcan adapters get our own driver of python-can's
slcan interface (`slcan.SlcanBus`: reads in chunks, writes that cannot block, noise
counted as `rx_garbage`). Units are `can.Message` frames, passed up as
received (error frames too, so captures keep them; the framing counts them).

Counters: `rx`, `tx`, `tx_dropped` (device gone), `tx_timeout` (not taken within
`send_timeout`: a full TX queue or a slow adapter, which keeps its link: slow is not
gone), `bus_errors` (error frames and failed bus calls), `bus_off`, `lost` (outages)
and `reconnects` (recoveries), and on SocketCAN `kernel_dropped` (frames the kernel
dropped because our receive queue was full, as candump -d reports),
`interface_dropped` (frames the interface dropped before any socket got them) and
`unread_at_close`. An outage is logged once and its end once, and so is a slow
episode; meanwhile the bus is reopened with exponential
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

from .base import DeviceTransport, TransportError, errno_of, one_line
from .slcan import SlcanBus
from .socketcan_drops import count_kernel_drops

__all__ = ["CanTransport"]

log = logging.getLogger(__name__)

# Linux error-frame class bit for bus-off (linux/can/error.h CAN_ERR_BUSOFF); python-can hands
# SocketCAN error frames up with the kernel's class bits as the arbitration id.
_CAN_ERR_BUSOFF = 0x40
_DRAIN_LIMIT = 512  # frames taken per read() after the first, so one busy bus cannot starve the loop
# A frame read within this long of its arrival (its timestamp) had most likely nothing queued behind it: the read
# ends there rather than ask once more (a python-can recv(0) that finds nothing costs as much as one that finds a
# frame). A frame that waited longer drains the queue; a bus whose timestamps are on another clock drains always
# or never, and either way every frame is read (the next read takes what came since).
_ALONE_S = 0.001
_STATE_POLL_S = 1.0  # how often to ask interfaces that report it (pcan, kvaser...) for bus-off
# Send failures that mean "the bus is busy", not "the device is gone".
_TRANSIENT_ERRNOS = frozenset({errno.ENOBUFS, errno.EAGAIN})
# Interfaces whose send(timeout=0) returns at once (queue full: an error), so the gateway's loop may call it: ours
# and python-can 4.6's own, read from its source for the vendor drivers (PCAN's Write ignores the timeout, Kvaser's
# canWrite waits only for a timeout that is not 0, Vector's xlCanTransmit queues): not tried on their hardware.
_NONBLOCKING_SEND = frozenset({"socketcan", "virtual", "slcan", "pcan", "kvaser", "vector"})


class CanTransport(DeviceTransport[can.Message, can.BusABC]):
    """A python-can bus as a Transport[can.Message]."""

    device_word = "CAN device"
    back_on_open = False  # SocketCAN binds to an interface that is down: back once a call on it works
    device_errors = (can.CanError, OSError)
    channel: str  # declared: the compiled data path reads it too (the can.Messages it makes)

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
        super().__init__(name or f"{interface}:{channel}", backoff)
        self.interface = interface
        self.channel = channel
        self.send_timeout = send_timeout
        self._bus_kwargs: dict[str, Any] = {"interface": interface, "channel": channel, **options}
        if bitrate is not None:
            self._bus_kwargs["bitrate"] = bitrate
        if fd:  # only when asked: some interfaces reject an `fd` keyword they do not support
            self._bus_kwargs["fd"] = True
        if can_filters is not None:
            self._bus_kwargs["can_filters"] = can_filters
        self._next_state_poll = 0.0

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus while connected (for captures and diagnostics)."""
        return self._live.device

    # -- the device calls ------------------------------------------------------
    def _open_device(self) -> can.BusABC:
        try:
            if self.interface == "slcan":  # our own reader and writer of the slcan line protocol (transports/slcan.py)
                options = {k: v for k, v in self._bus_kwargs.items() if k != "interface"}
                return SlcanBus(**options, counters=self.counters, abort=self._closed)
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

    def _close_device(self, device: can.BusABC) -> None:
        try:
            device.shutdown()
        except Exception as exc:  # a half-dead adapter may fail any way while closing
            log.debug("%s: error while closing: %s", self.name, exc)

    def _read_device(self, device: can.BusABC, timeout: float) -> list[can.Message]:
        frames: list[can.Message] = []
        try:
            frame = device.recv(timeout)
            while frame is not None:
                frames.append(frame)
                if frame.is_error_frame:
                    self.note_error_frame(frame)
                if len(frames) > _DRAIN_LIMIT or self._live.device is None or \
                        time.time() - frame.timestamp < _ALONE_S:
                    break
                frame = device.recv(0)
            if self._live.device is not None:
                self._poll_state(device)
        except self.device_errors as exc:  # the frames before the failure are still passed up
            self._lose(one_line(exc))
        return frames

    def _write_device(self, device: can.BusABC, unit: can.Message) -> None:
        """Send, waiting up to `send_timeout` for room in the TX queue; a frame still not taken is dropped."""
        self._send(device, unit, self.send_timeout, drop_when_busy=True)

    @property
    def sends_at_once(self) -> bool:
        """Whether the bus's send(unit, 0.0) returns at once (a full queue raises), so the gateway's loop may call
        it: `write_nowait` does, and so do the compiled outlets while the link's writer is idle (outlet.c)."""
        return self.interface in _NONBLOCKING_SEND

    def write_nowait(self, unit: can.Message) -> can.Message | None:
        """Send only if the TX queue has room now (interfaces whose send cannot block); else the frame, to wait."""
        if not self.sends_at_once:
            return unit
        device = self._live.device
        if device is None:
            device = self._device_for_write()
            if device is None:
                return None
        return None if self._send(device, unit, 0.0, drop_when_busy=False) else unit

    def _send(self, device: can.BusABC, unit: can.Message, timeout: float, *, drop_when_busy: bool) -> bool:
        """False if the bus was busy and the frame is still ours to send; True when sent or dropped (counted)."""
        try:
            device.send(unit, timeout=timeout)
        except self.device_errors as exc:
            busy = errno_of(exc) in _TRANSIENT_ERRNOS or "buffer full" in str(exc).lower()
            if busy:  # a full TX queue or a slow adapter: slow is not gone
                if drop_when_busy:
                    self._not_taken("tx_timeout")
                return drop_when_busy
            self.counters["tx_dropped"] += 1
            self.counters["bus_errors"] += 1
            self._lose(one_line(exc))
            return True
        self._sent()
        return True

    # -- the bus's own reports -----------------------------------------------
    def note_error_frame(self, frame: can.Message) -> None:
        """An error frame the bus delivered (here, or to the compiled data path, which reads a SocketCAN socket
        itself): counted, and a bus-off ends the device as a loss would."""
        self.counters["bus_errors"] += 1
        if self.interface == "socketcan" and frame.arbitration_id & _CAN_ERR_BUSOFF:
            self.counters["bus_off"] += 1
            self._lose("bus-off")

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
            self._lose("bus-off")
