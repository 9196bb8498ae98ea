"""XBeeTransport: a serial port with a Digi XBee module in API mode behind it.

C twin: vstig_hw/_cext/path.c (its read and cutting into frames); held equal by tests/native (index:
vstig_hw/_vstig.pyi).

The module is the device, as an slcan adapter is for python-can: it speaks frames (API
mode 1, or 2 with escaping), answers AT commands and reports on what it sent. So this
transport, over the serial port's bytes:

- at every open (reconnects too) asks the module, by local AT commands, its API mode (AP),
  its maximum RF payload (NP) and its 64-bit address (SH, SL), waiting `at_timeout` seconds
  at most. A module that answers nothing is a clear error naming the port, the baud rate and
  the API mode to check (the silent link XbeeMav's users meet); one that runs the other API
  mode says which. What it said goes to `module` and to `on_module` (the framing sizes its
  batches by NP);
- cuts the byte stream into API frames (framing/xbee.py's reader): each unit it reads is one
  frame exactly as on the wire, so captures record whole frames and the framing knows each
  frame's sender. What is not a frame is counted under `drop_<reason>` (`drop_checksum`,
  `drop_escape`, `drop_truncated`, `drop_frame_length`, `drop_noise`) and never handed on;
  a frame that stops arriving for `QUIET` seconds is `truncated`;
- keeps the module's own reports: Transmit Status (0x8B) counted per delivery status
  (`tx_delivered`, `tx_failed_<status>`), Modem Status (0x8A) per event (`modem_reset`...),
  AT responses used at open. The framing gets Receive Packets and anything else.

Opening waits for the module, so a write never reopens the port (`reopen_on_write`): the
reader thread does, with backoff, and the gateway's loop never waits for a handshake.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import serial

from ..framing.xbee import (
    AT_RESPONSE,
    MODEM_STATUS,
    TX_STATUS,
    ModuleInfo,
    XBeeStreamReader,
    api_frame,
    at_command,
)
from .base import TransportError
from .serial import SerialTransport

__all__ = ["AT_TIMEOUT", "QUIET", "XBeeTransport"]

log = logging.getLogger(__name__)

AT_TIMEOUT = 1.0  # seconds a module has to answer the AT commands at open (a module answers in milliseconds)
QUIET = 0.1  # seconds without a byte after which a frame still arriving is cut short (a UART never pauses mid-frame)
_ASKED = ("AP", "NP", "SH", "SL")  # in this order; frame ids 1..4
_DELIVERY = {0x01: "no_ack", 0x02: "cca_failure", 0x03: "purged", 0x21: "network_ack_failure",
             0x22: "not_joined", 0x23: "self_addressed", 0x24: "address_not_found", 0x25: "route_not_found",
             0x26: "broadcast_failed", 0x74: "payload_too_large"}
_REPORTS = (TX_STATUS, MODEM_STATUS, AT_RESPONSE)  # the module's own frames: kept here, not units
_MODEM = {0x00: "modem_reset", 0x01: "modem_watchdog_reset", 0x02: "modem_joined", 0x03: "modem_left"}


def delivery_counter(status: int) -> str:
    """The counter a Transmit Status's delivery status adds to."""
    return "tx_delivered" if status == 0 else f"tx_failed_{_DELIVERY.get(status, f'0x{status:02x}')}"


def modem_counter(status: int) -> str:
    return _MODEM.get(status, f"modem_status_0x{status:02x}")


class XBeeTransport(SerialTransport):
    """Transport[bytes] whose units are whole XBee API frames (see the module docstring)."""

    reopen_on_write = False  # opening asks the module and waits for its answers: the reader thread does it
    quiet_after = QUIET  # (the compiled data path, which may read the module's bytes itself, cuts short as we do)
    api: int  # 1 or 2 (escaped); declared: the compiled data path reads it too

    def __init__(self, port: str, baudrate: int = 9600, *, api: int = 1, at_timeout: float = AT_TIMEOUT,
                 on_module: Callable[[ModuleInfo], None] | None = None, **options: Any) -> None:
        if api not in (1, 2):
            raise ValueError(f"XBee api must be 1 or 2, got {api!r}")
        super().__init__(port, baudrate, **options)
        self.api = api
        self.at_timeout = at_timeout
        self.on_module = on_module
        self.module: ModuleInfo | None = None
        self._reader = XBeeStreamReader(api == 2, self.counters, prefix="drop_")
        self._held: list[bytes] = []  # frames that came with the AT answers, for the first read
        self._last_byte = 0.0

    # -- the device calls ------------------------------------------------------
    def _open_device(self) -> serial.Serial:
        port = super()._open_device()
        self._reader.reset()
        self._held = []
        try:
            module = self._ask(port)
        except BaseException:
            self._close_device(port)
            raise
        self.module = module
        if self.on_module is not None:
            self.on_module(module)
        address = "unknown address" if module.address is None else f"{module.address:016X}"
        payload = "NP unknown" if module.max_payload is None else f"NP {module.max_payload} bytes"
        log.info("%s: XBee %s, %s, API mode %d at %d baud", self.name, address, payload, self.api,
                 self.settings["baudrate"])
        return port

    def _read_device(self, device: serial.Serial, timeout: float) -> list[bytes]:
        if self._held:
            held, self._held = self._held, []
            return held
        chunks = super()._read_device(device, timeout)
        if chunks:
            self._last_byte = time.monotonic()
            return self.cut(chunks[0])
        if self._reader.holding and time.monotonic() - self._last_byte > self.quiet_after:
            return self.quiet()
        return []

    # -- the module's stream (pure: `read` calls these; the spec's vectors too) ---------
    def cut(self, chunk: bytes) -> list[bytes]:
        """The units (whole frames for the framing) that this chunk of the module's bytes completes."""
        if not self._reader.holding and self.api == 1 and len(chunk) > 4 and chunk[0] == 0x7E \
                and (chunk[1] << 8 | chunk[2]) + 4 == len(chunk) and sum(memoryview(chunk)[3:]) & 0xFF == 0xFF:
            # the common read: one whole frame and nothing held, checked in place
            return [chunk] if chunk[3] not in _REPORTS else self._units([(chunk, chunk[3:-1])])
        return self._units(self._reader.feed(chunk))

    def quiet(self) -> list[bytes]:
        """The line went quiet: a frame still arriving is cut short; the units its bytes held after all."""
        return self._units(self._reader.flush())

    # -- the module ------------------------------------------------------------
    def _ask(self, port: serial.Serial) -> ModuleInfo:
        """AP, NP, SH and SL, asked at once; their answers awaited up to `at_timeout` (other frames kept)."""
        escaped = self.api == 2
        try:
            port.write(b"".join(api_frame(at_command(number, command), escaped)
                                for number, command in enumerate(_ASKED, 1)))
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"XBee module on {self.port}: cannot send AT commands ({exc})") from None
        answers: dict[str, bytes | None] = {}
        deadline = time.monotonic() + self.at_timeout
        left = self.at_timeout
        while len(answers) < len(_ASKED) and _number(answers.get("AP")) in (None, self.api) and left >= 0:
            # what came is read even when the wait is over (a process slowed down may get there late)
            left = deadline - time.monotonic()
            for chunk in SerialTransport._read_device(self, port, min(max(left, 0.0), 0.05)):
                for wire, data in self._reader.feed(chunk):
                    if data[0] == AT_RESPONSE and len(data) >= 5:
                        command = data[2:4].decode("ascii", "replace")
                        answers[command] = data[5:] if data[4] == 0 else None  # status 0: OK
                    else:
                        self._held.extend(self._units([(wire, data)]))
        if not answers:
            raise TransportError(
                f"XBee module on {self.port}: no answer to AT commands within {self.at_timeout:g} s at "
                f"{self.settings['baudrate']} baud: the module must run API mode {self.api} (AP={self.api}) at "
                f"that speed (BD); set it with XCTU, or give baud= and api= to match it (docs/how-to/xbee.md)")
        mode = _number(answers.get("AP"))
        if mode is not None and mode != self.api:
            raise TransportError(f"XBee module on {self.port}: it runs API mode {mode} (AP={mode}) and the link "
                                 f"speaks api={self.api}: give api={mode}, or set the module's AP to {self.api}")
        high, low = _number(answers.get("SH")), _number(answers.get("SL"))
        address = None if high is None or low is None else high << 32 | low
        return ModuleInfo(address=address, max_payload=_number(answers.get("NP")), api_mode=mode)

    def holds(self) -> bool:
        """What this transport's reads took is not all handed on: frames that came with the answers at open, or
        part of a frame (the compiled data path, which may read the module's bytes itself, waits for none)."""
        return bool(self._held) or self._reader.holding

    def note_report(self, data: bytes) -> bool:
        """Count the module's own report whose frame data are `data` (Transmit Status per delivery status, Modem
        Status per event; an AT answer after open: nothing asked it); False for any other frame (a unit)."""
        kind = data[0]
        if kind == TX_STATUS and len(data) >= 6:
            self.counters[delivery_counter(data[5])] += 1
        elif kind == MODEM_STATUS and len(data) >= 2:
            self.counters[modem_counter(data[1])] += 1
        return kind in _REPORTS

    def _units(self, frames: list[tuple[bytes, bytes]]) -> list[bytes]:
        """The frames the framing gets; the module's own reports counted here."""
        return [wire for wire, data in frames if not self.note_report(data)]


def _number(value: bytes | None) -> int | None:
    """An AT register's value (big-endian), or None when it was refused or never came."""
    return int.from_bytes(value, "big") if value else None
