"""The dialect framings, pure: Kilobot message_t frames, overhead-controller packets, BuzzKH4 frames."""

from __future__ import annotations

from functools import reduce
from operator import xor

import pytest
from cobs import cobs
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.crc import crc16_mcrf4xx_le
from vstig_hw.dialects.buzz import BuzzOp, BuzzVstig, encode_buzz
from vstig_hw.dialects.buzz_packets import pack_frame, rosbuzz_payload64, unpack_frame, xbee_packet
from vstig_hw.dialects.framing import (
    BittyBuzzKilobotFraming,
    BittyBuzzOhcFraming,
    BuzzKh4Framing,
    RosBuzzDecoder,
    make_dialect_framing,
)
from vstig_hw.dialects.mapping import parse_deployment
from vstig_hw.framing import TransmitOnlyError
from vstig_hw.wire import Message, Op

DEPLOYMENT = parse_deployment('[buzz]\nstigmergy = 1\n[keys]\nx = { key = 1, type = "int16" }\n')
K1 = bytes.fromhex("010700290001 2a0001".replace(" ", ""))  # PUT rid 7, "x", int 42, lamport 1


def _uart(message_t: bytes) -> bytes:
    return cobs.encode(message_t + crc16_mcrf4xx_le(message_t)) + b"\0"


def test_kilobot_frames_both_ways() -> None:
    framing = BittyBuzzKilobotFraming(DEPLOYMENT)
    heard = framing.feed(_uart(K1 + b"\x02") + _uart(K1 + b"\x56") + _uart(bytes.fromhex("000500290001 0a0000"
                                                                                         .replace(" ", "")) + b"\x02"))
    assert heard == [Message(Op.PUT, 1, 42, 1, 7)]
    assert framing.drops["foreign_type"] == 1 and framing.drops["bbz_other"] == 1
    (frame,) = framing.encode(Message(Op.PUT, 1, 43, 2, 200))
    assert frame == _uart(bytes.fromhex("01c8002900012b0002") + b"\x02")  # one step past lamport 1


def test_overhead_controller_packet_is_o1() -> None:
    framing = BittyBuzzOhcFraming(DEPLOYMENT)
    (packet,) = framing.encode(Message(Op.PUT, 1, 42, 1, 7))
    assert packet[:12] == bytes.fromhex("55060107002900012a000102") and packet[12:131] == bytes(119)
    assert packet[131] == 0x54 and reduce(xor, packet) == 0  # DIALECTS.md O1
    with pytest.raises(TransmitOnlyError):
        framing.feed(packet)


def test_kh4_frames_pack_several_messages_and_refuse_oversize() -> None:
    framing = BuzzKh4Framing(DEPLOYMENT, robot_id=200, frame_size=32)
    frames = framing.encode_batch([Message(Op.PUT, 1, 42, 1, 7), Message(Op.GET, 1, 42, 1, 7),
                                   Message(Op.PUT, 9, 1, 1, 1)])
    put = encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "x", 42, 1, 7))
    query = encode_buzz(BuzzVstig(BuzzOp.QUERY, 1, "x", 42, 1, 7))
    assert frames == [pack_frame(200, [put], 32)[0], pack_frame(200, [query], 32)[0]]  # 2 x 18 bytes > 30
    assert framing.drops["unmapped"] == 1
    tiny = BuzzKh4Framing(DEPLOYMENT, robot_id=200, frame_size=16)
    assert tiny.encode(Message(Op.PUT, 1, 42, 1, 7)) == [] and tiny.drops["oversize"] == 1
    heard = framing.feed(pack_frame(5, [put, b"\x00\x03", b"\x02\x00"], 64)[0])
    assert heard == [Message(Op.PUT, 1, 42, 1, 7)]
    assert framing.drops["buzz_other"] == 1 and framing.drops["buzz_truncated"] == 1
    assert framing.sender_of(pack_frame(5, [put], 64)[0]) == 5
    assert unpack_frame(frames[0]).sender == 200


def test_dialect_framings_by_capture_name() -> None:
    assert isinstance(make_dialect_framing("blabbermouth", DEPLOYMENT), BuzzKh4Framing)
    assert isinstance(make_dialect_framing("bittybuzz-kilobot", DEPLOYMENT), BittyBuzzKilobotFraming)
    with pytest.raises(ValueError, match="unknown dialect framing"):
        make_dialect_framing("cobs8", DEPLOYMENT)


@given(st.binary(max_size=200))
def test_any_bytes_fed_never_crash(data: bytes) -> None:
    for framing in (BittyBuzzKilobotFraming(DEPLOYMENT), BuzzKh4Framing(DEPLOYMENT)):
        for msg in framing.feed(data):
            assert isinstance(msg, Message) and msg.key == 1


@given(st.lists(st.binary(min_size=1, max_size=30), max_size=4))
def test_any_buzz_messages_in_a_frame_never_crash(messages: list[bytes]) -> None:
    framing = BuzzKh4Framing(DEPLOYMENT)
    frame, _ = pack_frame(3, messages, 128)
    assert all(isinstance(m, Message) for m in framing.feed(frame))


def test_rosbuzz_blocks_payload64_and_xbee_packets() -> None:
    rosbuzz = RosBuzzDecoder(DEPLOYMENT, robot_id=3)
    sent = [Message(Op.PUT, 1, n, n, 3) for n in range(1, 14)]  # 13 x 18 bytes: more than one block
    blocks = rosbuzz.encode_batch(sent)
    assert len(blocks) == 2 and all(len(b) <= 192 and len(b) % 8 == 0 for b in blocks)
    heard = [m for b in blocks for m in rosbuzz.feed_xbee(xbee_packet(3, 0, rosbuzz_payload64(b)))]
    assert heard == sent
    assert rosbuzz.feed_payload64([1, 0, 0, 0, 0, 0]) == []  # a code update, not a Buzz block
