"""CRC-16/MCRF4XX, CRC-32 and the shared COBS serial frame."""

from __future__ import annotations

import os
import zlib

import pytest
from crccheck.crc import Crc16Mcrf4XX

from vstig_hw.counters import Counters
from vstig_hw.crc import CRC16_CHECK, crc16_mcrf4xx, crc16_mcrf4xx_le, crc32
from vstig_hw.framing.cobsframe import MAX_ENCODED_FRAME, CobsFrameReader, encode_frame


def avr_crc_ccitt_update(crc: int, byte: int) -> int:
    """avr-libc's documented C equivalent of `_crc_ccitt_update`, the routine kilolib calls."""
    byte ^= crc & 0xFF
    byte = (byte ^ (byte << 4)) & 0xFF
    return (((byte << 8) | (crc >> 8)) ^ (byte >> 4) ^ (byte << 3)) & 0xFFFF


def kilolib_message_crc(first_ten: bytes) -> int:
    crc = 0xFFFF
    for byte in first_ten:
        crc = avr_crc_ccitt_update(crc, byte)
    return crc


def test_crc16_check_value_is_the_catalogue_one() -> None:
    assert crc16_mcrf4xx(b"123456789") == CRC16_CHECK == 0x6F91
    assert kilolib_message_crc(b"123456789") == 0x6F91


@pytest.mark.parametrize("length", [0, 1, 2, 4, 8, 10, 33])
def test_crc16_matches_two_independent_implementations(length: int) -> None:
    for _ in range(50):
        data = os.urandom(length)
        assert crc16_mcrf4xx(data) == Crc16Mcrf4XX.calc(data) == kilolib_message_crc(data)


def test_crc16_chains_and_a_frame_with_its_crc_checks_to_zero() -> None:
    data = os.urandom(20)
    assert crc16_mcrf4xx(data[7:], crc16_mcrf4xx(data[:7])) == crc16_mcrf4xx(data)
    assert crc16_mcrf4xx_le(data) == crc16_mcrf4xx(data).to_bytes(2, "little")
    assert crc16_mcrf4xx(data + crc16_mcrf4xx_le(data)) == 0


def test_crc32_is_zlibs_unsigned() -> None:
    assert crc32(b"123456789") == 0xCBF43926 == zlib.crc32(b"123456789")


def test_frame_vector() -> None:
    payload = bytes([0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07])
    crc = crc16_mcrf4xx(payload)
    assert encode_frame(payload) == bytes([0x01, 0x0A, 1, 2, 3, 4, 5, 6, 7]) + crc.to_bytes(2, "little") + b"\x00"
    assert len(encode_frame(bytes(range(1, 9)))) == 12


def test_reader_byte_by_byte_and_all_at_once() -> None:
    payloads = [os.urandom(8) for _ in range(30)]
    stream = b"".join(encode_frame(p) for p in payloads)
    whole = CobsFrameReader(8, Counters())
    assert whole.feed(stream) == payloads
    drops = Counters()
    trickle = CobsFrameReader(8, drops)
    got = [p for i in range(len(stream)) for p in trickle.feed(stream[i:i + 1])]
    assert got == payloads and not +drops


def test_each_bad_frame_is_one_counted_drop_by_reason() -> None:
    drops = Counters()
    reader = CobsFrameReader(8, drops)
    good = encode_frame(b"ABCDEFGH")
    corrupted = bytearray(good)
    corrupted[3] ^= 0x40
    stream = (b"\x05\x00"  # COBS code pointing past the end: cobs
              + bytes(corrupted)  # crc
              + encode_frame(b"ABCD")  # another framing's length: bad_length
              + b"\x01" * (MAX_ENCODED_FRAME + 10) + b"\x00"  # no delimiter in time: overlong
              + b"\x00\x00\x00"  # idle line: not a drop
              + good)
    assert reader.feed(stream) == [b"ABCDEFGH"]
    assert drops == Counters(cobs=1, crc=1, bad_length=1, overlong=1)


def test_overlong_garbage_is_counted_once_and_never_buffered() -> None:
    drops = Counters()
    reader = CobsFrameReader(8, drops)
    for _ in range(1000):
        assert reader.feed(b"\x07" * 50) == []
    assert drops == Counters(overlong=1)
    assert len(reader._pending) == 0  # a noisy line cannot grow memory
    assert reader.feed(b"\x00" + encode_frame(b"12345678")) == [b"12345678"]
    assert drops == Counters(overlong=1)


def test_truncated_frame_costs_itself_and_the_frame_it_runs_into_only() -> None:
    drops = Counters()
    reader = CobsFrameReader(8, drops)
    a, b, c = (encode_frame(bytes([i]) * 8) for i in (1, 2, 3))
    assert reader.feed(a[:5] + b + c) == [bytes([3]) * 8]
    assert sum(drops.values()) == 1
    assert reader.feed(a[:5] + b"\x00" + b) == [bytes([2]) * 8]  # a leading 0x00 saves the next frame


def test_reset_forgets_a_partial_frame() -> None:
    reader = CobsFrameReader(8, Counters())
    frame = encode_frame(b"abcdefgh")
    reader.feed(frame[:6])
    reader.reset()
    assert reader.feed(frame) == [b"abcdefgh"]
