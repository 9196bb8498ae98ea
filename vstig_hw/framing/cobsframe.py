"""The one serial frame of every UART framing: COBS(payload || CRC-16/MCRF4XX LE) || 0x00.

`encode_frame` builds a frame; `CobsFrameReader` cuts a byte stream into frames,
checks them and hands back the payloads. The reader resynchronises at every 0x00:
garbage, a truncated frame or a corrupted byte costs the frames it touches and
nothing after the next delimiter. Each bad frame is one counted drop:

- `overlong`: more than MAX_ENCODED_FRAME bytes without a delimiter (the bytes are
  discarded as they come, so a noisy line cannot grow the buffer);
- `cobs`: not valid COBS;
- `crc`: the CRC over payload and CRC is not 0;
- `bad_length`: a good frame with another payload length (another framing's frame; cobs8 also
  takes its authenticated frames, `tagged_size`, SPEC.md 10.5).

Empty frames (0x00 0x00) are idle line, not drops: a sender may put a 0x00 before a
frame to cut off whatever partial frame a receiver holds.
"""

from __future__ import annotations

from collections.abc import Callable

from cobs import cobs

from ..counters import Counters
from ..crc import crc16_mcrf4xx, crc16_mcrf4xx_le

__all__ = ["DELIMITER", "MAX_ENCODED_FRAME", "CobsFrameReader", "encode_frame"]

DELIMITER = b"\x00"
MAX_ENCODED_FRAME = 64  # bytes between delimiters; every format's frame is far shorter

_cobs_encode: Callable[[bytes], bytes] = cobs.encode
_cobs_decode: Callable[[bytes], bytes] = cobs.decode
_CobsError = cobs.DecodeError


def encode_frame(payload: bytes) -> bytes:
    """The bytes on the wire for one payload, delimiter included."""
    return _cobs_encode(payload + crc16_mcrf4xx_le(payload)) + DELIMITER


class CobsFrameReader:
    """Stream in, checked payloads of exactly `payload_size` (or `tagged_size`) bytes out; bad frames counted in
    `drops`."""

    def __init__(self, payload_size: int, drops: Counters, max_encoded: int = MAX_ENCODED_FRAME, *,
                 tagged_size: int | None = None) -> None:
        self.payload_size = payload_size
        self.drops = drops
        self.max_encoded = max_encoded
        self._frame_sizes = frozenset(size + 2 for size in (payload_size, tagged_size) if size is not None)
        self._pending = b""
        self._discarding = False  # inside an overlong frame: skip to the next delimiter

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[bytes]:
        """Payloads of the frames that this chunk completes, in order."""
        parts = bytes(chunk).split(DELIMITER)
        tail = parts.pop()  # bytes after the last delimiter: a frame still arriving
        payloads: list[bytes] = []
        if parts:
            head = parts[0]
            if self._discarding:
                self._discarding = False
                parts[0] = b""  # the end of an overlong frame, already counted
            else:
                parts[0] = self._pending + head
            self._pending = b""
            for raw in parts:
                if raw:
                    payload = self._check(raw)
                    if payload is not None:
                        payloads.append(payload)
        self._hold(tail)
        return payloads

    def reset(self) -> None:
        """Forget any partial frame (after a reconnect the old bytes belong to nobody)."""
        self._pending = b""
        self._discarding = False

    def _hold(self, tail: bytes) -> None:
        if self._discarding or not tail:
            return
        pending = self._pending + tail
        if len(pending) > self.max_encoded:
            self.drops["overlong"] += 1
            self._pending = b""
            self._discarding = True
        else:
            self._pending = pending

    def _check(self, raw: bytes) -> bytes | None:
        if len(raw) > self.max_encoded:
            self.drops["overlong"] += 1
            return None
        try:
            frame = _cobs_decode(raw)
        except _CobsError:
            self.drops["cobs"] += 1
            return None
        if crc16_mcrf4xx(frame) != 0:
            self.drops["crc"] += 1
            return None
        if len(frame) not in self._frame_sizes:
            self.drops["bad_length"] += 1
            return None
        return frame[:-2]
