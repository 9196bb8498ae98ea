"""Buzz transport frames: KH4 (little-endian), ARGoS (big-endian), ROSBuzz blocks and XbeeMav's word order."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.dialects.buzz_packets import (
    pack_frame,
    pack_rosbuzz_block,
    rosbuzz_block_from_payload64,
    rosbuzz_payload64,
    unpack_frame,
    unpack_rosbuzz_block,
    xbee_packet,
    xbee_payload64,
    xbee_word_order,
)

B1 = bytes.fromhex("02000103000178010000002a00010005")  # PUT stig 1 "x" = 42, ts 1, robot 5
B2 = bytes.fromhex("030001030001780000000007")  # QUERY stig 1 "x" nil, ts 0, robot 7


def test_kh4_frame_by_hand() -> None:
    frame, packed = pack_frame(5, [B1], 32, "little")
    assert frame == bytes.fromhex("05001000") + B1 + bytes(12) and packed == 1
    assert unpack_frame(frame, "little").messages == [B1]


def test_argos_frame_by_hand() -> None:
    frame, packed = pack_frame(7, [B1, B2], 40, "big")
    assert frame == bytes.fromhex("00070010") + B1 + bytes.fromhex("000c") + B2 + bytes(6) and packed == 2
    unpacked = unpack_frame(frame, "big")
    assert (unpacked.sender, unpacked.messages) == (7, [B1, B2])


def test_a_message_that_does_not_fit_waits() -> None:
    frame, packed = pack_frame(5, [B1, B2], 30, "little")
    assert packed == 1 and unpack_frame(frame).messages == [B1]
    with pytest.raises(ValueError):
        pack_frame(5, [b""], 30)


def test_overrunning_length_is_counted() -> None:
    frame = bytes.fromhex("0500ff00") + bytes(10)
    unpacked = unpack_frame(frame)
    assert (unpacked.messages, unpacked.overrun) == ([], 1)


def test_rosbuzz_block_words_and_xbee_order() -> None:
    block, packed = pack_rosbuzz_block(5, [B1])
    assert block.hex() == "03000500100002000103000178010000002a000100050000" and packed == 1
    words = rosbuzz_payload64(block)
    assert words[5:] == [0x0002001000050003, 0x0000017801000301, 0x0000050001002A00]
    assert rosbuzz_block_from_payload64(words) == block
    assert xbee_word_order(block).hex() == "000200100005000300000178010003010000050001002a00"
    assert unpack_rosbuzz_block(xbee_word_order(xbee_word_order(block))).messages == [B1]
    assert rosbuzz_block_from_payload64([1, 0, 0, 0, 0, 7]) is None  # an UPDATER message, not Buzz


@given(st.binary(max_size=80), st.sampled_from(["little", "big"]))
def test_any_frame_unpacks_without_crashing(raw: bytes, order: str) -> None:
    unpacked = unpack_frame(raw, order)  # type: ignore[arg-type]
    assert sum(len(m) + 2 for m in unpacked.messages) <= max(len(raw) - 2, 0)
    assert all(unpacked.messages)
    rosbuzz = unpack_rosbuzz_block(raw)
    assert sum(len(m) + 2 for m in rosbuzz.messages) <= max(len(raw) - 4, 0)


@given(st.lists(st.binary(min_size=1, max_size=20), max_size=6), st.integers(0, 0xFFFF))
def test_packed_messages_come_back_in_order(messages: list[bytes], robot: int) -> None:
    frame, packed = pack_frame(robot, messages, 64)
    assert len(frame) == 64
    unpacked = unpack_frame(frame)
    assert (unpacked.sender, unpacked.messages) == (robot, messages[:packed])
    block, in_block = pack_rosbuzz_block(robot, messages)
    assert len(block) % 8 == 0 and len(block) <= 192
    assert unpack_rosbuzz_block(block).messages == messages[:in_block]


def test_an_xbee_packet_carries_the_block_byte_reversed() -> None:
    block, _ = pack_rosbuzz_block(5, [B1])
    words = rosbuzz_payload64(block, message_number=3)
    packet = xbee_packet(5, 3, words)
    assert packet[:3] == b"S\x05\x03" and packet[3 + 5 * 8:] == xbee_word_order(block)  # after 5 header words
    sysid, msgid, back = xbee_payload64(packet)
    assert (sysid, msgid, back) == (5, 3, words)
    block_back = rosbuzz_block_from_payload64(back)
    assert block_back is not None and unpack_rosbuzz_block(block_back).messages == [B1]
    with pytest.raises(ValueError):
        xbee_payload64(b"F\x00\x00")
    with pytest.raises(ValueError):
        xbee_packet(1, 1, [0] * 31)  # 250 bytes: XbeeMav fragments it
