"""XbeeMav's packets, pure: 'S' packets of ROSBuzz blocks both ways, 'F' fragments reassembled, 'P', 'A', 'L' counted.

The fragments here are built the way PacketsHandler::Handle_Mavlink_Message builds them
(written out below, not with our `fragment_packets`, which is checked against them).
"""

from __future__ import annotations

import struct

import pytest

from vstig_hw.counters import Counters
from vstig_hw.dialects.buzz import BuzzOp, BuzzVstig, encode_buzz
from vstig_hw.dialects.buzz_packets import pack_rosbuzz_block, rosbuzz_payload64, xbee_packet
from vstig_hw.dialects.framing import XbeeMavApi2Framing, XbeeMavFraming, make_dialect_framing
from vstig_hw.dialects.mapping import parse_deployment
from vstig_hw.dialects.xbeemav import MAX_PARTIALS, XbeeMavReassembler, fragment_packets
from vstig_hw.framing.xbee import ModuleInfo, api_frame, receive_packet, transmit_request
from vstig_hw.wire import Message, Op

DEPLOYMENT = parse_deployment('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\n')
DRONE = 0x0013A20040A1B2C3
B1 = encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "leader", 42, 1, 5))  # PUT "leader" = 42, ts 1, robot 5


def serialized(sysid: int, msgid: int, words: list[int]) -> bytes:
    """PacketsHandler::Serialize_Mavlink_Message: u8 sysid, u8 msgid, then bytes[7 - i] = word >> 8i."""
    out = bytes((sysid, msgid))
    for word in words:
        out += bytes((word >> (8 * (7 - i))) & 0xFF for i in range(8))
    return out


def xbeemav_fragments(message: bytes, msgid: int, node: int) -> list[bytes]:
    """Handle_Mavlink_Message's loop: ceil(size / 250) fragments, each 'F', msgid, node, i, offset >> 8, offset."""
    out = []
    for i in range(-(-len(message) // 250)):
        offset = i * 250
        out.append(b"F" + bytes((msgid, node, i, offset >> 8 & 0xFF, offset & 0xFF)) + message[offset:offset + 250])
    return out


def drone_words(*buzz: bytes, robot: int = 5, padding: int = 0) -> list[int]:
    block, packed = pack_rosbuzz_block(robot, list(buzz))
    assert packed == len(buzz)
    return rosbuzz_payload64(block, message_number=3) + [0] * padding


def heard(framing: XbeeMavFraming, rf: bytes, source: int = DRONE) -> list[Message]:
    unit = api_frame(receive_packet(source, rf), framing.escaped)
    messages = framing.feed(unit)
    assert not messages or framing.sender_of(unit) == source
    return messages


def test_our_fragments_are_xbeemavs() -> None:
    message = bytes(range(256)) * 3
    assert fragment_packets(message, 7, 3) == xbeemav_fragments(message, 7, 3)
    assert [len(f) for f in fragment_packets(message, 7, 3)] == [256, 256, 256, 24]


@pytest.mark.parametrize("framing_class", [XbeeMavFraming, XbeeMavApi2Framing])
def test_an_s_packet_of_a_drone_gives_its_messages_from_its_module(framing_class: type[XbeeMavFraming]) -> None:
    framing = framing_class(DEPLOYMENT)
    rf = b"S" + serialized(5, 3, drone_words(B1))
    assert rf == xbee_packet(5, 3, drone_words(B1))
    assert heard(framing, rf) == [Message(Op.PUT, 1, 42, 1, 5)]
    assert framing.drops == Counters()


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 0, 1), (1, 2, 0)])
def test_fragments_in_any_order_complete_the_packet_at_the_last_one(order: tuple[int, ...]) -> None:
    framing = XbeeMavFraming(DEPLOYMENT)
    message = serialized(5, 9, drone_words(B1, padding=60))  # 2 + 8 * 68 = 546 bytes: three fragments
    fragments = xbeemav_fragments(message, 9, 4)
    got = [heard(framing, fragments[i]) for i in order]
    assert got[:-1] == [[], []] and got[-1] == [Message(Op.PUT, 1, 42, 1, 5)]
    assert heard(framing, fragments[order[0]]) == []  # a retransmission of a finished packet
    assert framing.drops == Counters({"fragment_repeat": 1}) and framing.reassembler.pending == 0


def test_a_packet_of_whole_fragments_completes_at_the_ping_and_acks_and_loss_reports_are_counted() -> None:
    framing = XbeeMavFraming(DEPLOYMENT)
    words = drone_words(B1)
    words += [0] * ((500 - 2) // 8 - len(words))  # 2 + 8 * 62 = 498 bytes...
    message = serialized(5, 9, words) + b"\0\0"  # ...padded by hand to 500: the last fragment is a full 250
    first, second = xbeemav_fragments(message, 9, 4)
    assert heard(framing, first) == [] and heard(framing, second) == []  # no short fragment: not known to be whole
    assert heard(framing, b"P" + bytes((9, 4, 2))) == []  # 500 bytes are no whole words: malformed
    assert framing.drops == Counters({"xbeemav_control": 1, "xbeemav_malformed": 1})
    framing = XbeeMavFraming(DEPLOYMENT)
    message = serialized(5, 9, words + [0] * 31)  # 2 + 8 * 93 = 746: fragments of 250, 250 and 246
    fragments = xbeemav_fragments(message, 9, 4)
    assert [heard(framing, f) for f in fragments[:2]] == [[], []]
    assert heard(framing, b"P" + bytes((9, 4, 3))) == []  # the ping says 3: one is missing
    assert heard(framing, fragments[2]) == [Message(Op.PUT, 1, 42, 1, 5)]
    assert heard(framing, b"A" + bytes((9, 4))) == [] and heard(framing, b"L" + bytes((4, 0, 12, 1))) == []
    assert framing.drops == Counters({"xbeemav_control": 3})


def test_two_modules_sending_the_same_packet_id_are_kept_apart() -> None:
    framing = XbeeMavFraming(DEPLOYMENT)
    a = xbeemav_fragments(serialized(5, 9, drone_words(B1, padding=40)), 9, 4)
    b = xbeemav_fragments(serialized(6, 9, drone_words(encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "leader", 7, 2, 6)),
                                                        robot=6, padding=40)), 9, 4)
    assert heard(framing, a[0], DRONE) == [] and heard(framing, b[0], DRONE + 1) == []
    assert heard(framing, b[1], DRONE + 1) == [Message(Op.PUT, 1, 7, 2, 6)]
    assert heard(framing, a[1], DRONE) == [Message(Op.PUT, 1, 42, 1, 5)]


def test_reassembly_is_bounded_and_timed_out() -> None:
    drops = Counters()
    reassembler = XbeeMavReassembler(drops, expiry_ticks=3)
    head = b"F" + bytes((0, 4, 0, 0, 0)) + bytes(250)
    for packet_id in range(MAX_PARTIALS + 2):
        reassembler.fragment(DRONE, b"F" + bytes((packet_id,)) + head[2:])
    assert reassembler.pending == MAX_PARTIALS and drops["fragment_evicted"] == 2
    for _ in range(4):
        reassembler.tick()
    assert reassembler.pending == 0 and drops["fragment_stale"] == MAX_PARTIALS
    assert reassembler.fragment(DRONE, b"F\x00\x04\x00\xff\xff" + bytes(250)) is None  # past 64,000 bytes
    assert reassembler.fragment(DRONE, b"F\x00\x04") is None  # no room for a header
    assert drops["fragment_bad"] == 2 and reassembler.pending == 0


def test_what_carries_no_buzz_block_is_counted() -> None:
    framing = XbeeMavFraming(DEPLOYMENT)
    code_update = serialized(5, 1, [1, 0x1234, 0])  # ROSBuzz's UPDATER_MESSAGE: word 0 is 1
    assert heard(framing, b"S" + code_update) == []
    assert heard(framing, b"S\x05\x03\x00") == []  # not whole words
    assert heard(framing, b"Q" + code_update) == []
    assert framing.drops == Counters({"rosbuzz_other": 1, "xbeemav_malformed": 1, "xbeemav_unknown": 1})


def test_we_send_s_packets_of_rosbuzz_blocks_under_our_id_as_large_as_np_allows() -> None:
    framing = XbeeMavFraming(DEPLOYMENT, robot_id=200)
    ours = [Message(Op.PUT, 1, v, v, 200) for v in range(1, 40)]
    frames = framing.encode_batch(ours)
    rfs = []
    for number, frame in enumerate(frames, 1):
        data = frame[3:-1]
        assert data[:2] == transmit_request(data[1], b"")[:2] and frame == api_frame(data)
        rf = data[14:]
        assert rf[:3] == bytes((ord("S"), 200, number)) and len(rf) <= 256  # sysid, msgid = message number
        words = list(struct.unpack(f">{(len(rf) - 3) // 8}Q", rf[3:]))
        assert words[0] & 0xFFFF == 2 and words[0] >> 16 & 0xFFFF == number  # BUZZ_MESSAGE, message number
        assert words[1:5] == [0, 0, 0, 0]  # no ROS time, position 0
        block = struct.pack(f"<{len(words) - 5}Q", *words[5:])
        assert struct.unpack_from("<HH", block) == (len(words) - 5, 200) and len(block) <= 192
        rfs.append(rf)
    back = XbeeMavFraming(DEPLOYMENT)
    assert [m for rf in rfs for m in heard(back, rf)] == ours
    small = XbeeMavFraming(DEPLOYMENT, robot_id=200)
    small.use_module(ModuleInfo(max_payload=84))  # a Zigbee module: blocks shrink to fit
    assert all(len(frame) - 18 <= 84 for frame in small.encode_batch(ours))


def test_rosbuzz_robot_ids_are_one_byte() -> None:
    with pytest.raises(ValueError, match=r"0\.\.255"):
        XbeeMavFraming(DEPLOYMENT, robot_id=256)
    assert isinstance(make_dialect_framing("xbeemav-api2", DEPLOYMENT), XbeeMavApi2Framing)
