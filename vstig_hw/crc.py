"""The two CRCs of the serial formats: CRC-16/MCRF4XX (every UART frame, Kilobot) and CRC-32 (epuck4).

CRC-16/MCRF4XX: poly 0x1021 reflected (0x8408), init 0xFFFF, refin and refout,
xorout 0x0000, check("123456789") = 0x6F91. It is avr-libc's `_crc_ccitt_update`
from 0xFFFF, which kilolib uses for every Kilobot message.

Fast path: a reflected CRC equals the bit-reversal of the unreflected CRC of the
bit-reversed bytes. `binascii.crc_hqx` is the unreflected CRC-16 with poly 0x1021
in C, and `bytes.translate` reverses every byte through a 256-entry table in C, so
one frame costs three C calls instead of a Python loop per byte.
"""

from __future__ import annotations

import zlib
from binascii import crc_hqx

__all__ = ["CRC16_CHECK", "CRC16_INIT", "crc16_mcrf4xx", "crc16_mcrf4xx_le", "crc32"]

CRC16_INIT = 0xFFFF
CRC16_CHECK = 0x6F91  # crc16_mcrf4xx(b"123456789"), the catalogue check value

_REVERSED_BYTE = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))


def crc16_mcrf4xx(data: bytes | bytearray | memoryview, crc: int = CRC16_INIT) -> int:
    """CRC-16/MCRF4XX of `data`, continuing from `crc` (pass a previous result to chain).

    Over a frame followed by its own CRC stored little-endian the result is 0.
    """
    start = (_REVERSED_BYTE[crc & 0xFF] << 8) | _REVERSED_BYTE[crc >> 8]
    plain = crc_hqx(bytes(data).translate(_REVERSED_BYTE), start)
    return (_REVERSED_BYTE[plain & 0xFF] << 8) | _REVERSED_BYTE[plain >> 8]


def crc16_mcrf4xx_le(data: bytes | bytearray | memoryview) -> bytes:
    """The two CRC bytes as they follow `data` on the wire (little-endian)."""
    return crc16_mcrf4xx(data).to_bytes(2, "little")


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32/ISO-HDLC (zlib's), as an unsigned 32-bit integer."""
    return zlib.crc32(data) & 0xFFFFFFFF
