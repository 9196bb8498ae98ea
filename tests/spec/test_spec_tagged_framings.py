"""Framings that carry tags (SPEC.md 10.5): records in, the same messages with their records out; untagged units
beside them unchanged; framings without room say so and refuse to carry records; broken tagged units counted."""

from __future__ import annotations

from typing import Any

import can
import pytest
from conftest import load

from vstig_hw.auth import SwarmKeys, Tagged, encode_batch
from vstig_hw.dialects.framing import XbeeMavFraming
from vstig_hw.dialects.mapping import parse_deployment
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.base import Framing, NoRoomForTags
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.framing.ros2 import Ros2Framing
from vstig_hw.framing.xbee import api_frame, receive_packet
from vstig_hw.framing.zenoh import ZenohFraming, ZenohKeySpace, ZenohSample
from vstig_hw.wire import Message, Op

VECTORS = load("auth.json")
KEYS = SwarmKeys(bytes.fromhex(VECTORS["master"]))
RECORDS = [KEYS.tag(Message(Op.GET if i % 3 == 2 else Op.PUT, 0x100 + i, 1000 + i, 1 + i, 40 + i % 4), i % 2)
           for i in range(7)]


def _with_tags() -> list[Framing[Any]]:
    return [make_serial_framing("cobs8"), make_serial_framing("xbee"), make_serial_framing("xbee-api2"),
            make_serial_framing("mavlink"), CanFraming(CanIdScheme(), 7, fd=True),
            ZenohFraming(ZenohKeySpace("lab"), 7), Ros2Framing(7)]


def _without_room() -> list[Framing[Any]]:
    deployment = parse_deployment('[buzz]\nstigmergy = 1\n[keys]\nx = { key = 1, type = "int16" }\n')
    return [make_serial_framing(name) for name in ("epuck4", "kilobot", "kilobot-ohc")] + \
        [CanFraming(CanIdScheme(), 7), XbeeMavFraming(deployment)]


def _fed(framing: Framing[Any], units: list[Any]) -> list[tuple[Message, Tagged | None]]:
    return [heard for unit in units for heard in framing.feed_tagged(unit)]


@pytest.mark.parametrize("framing", _with_tags(), ids=lambda f: f.name)
def test_records_travel_whole_and_untagged_units_stay_untagged(framing: Framing[Any]) -> None:
    assert framing.carries_tags
    units = framing.encode_tagged(RECORDS)
    heard = _fed(framing, units)
    assert sorted(heard) == sorted((record.message, record) for record in RECORDS)  # CAN FD sends PUTs first
    assert all(KEYS.verify(record) for _, record in heard if record is not None)
    plain = [msg for unit in units for msg in framing.feed(unit)]  # a link with auth off: the messages, no tags
    assert sorted(plain) == sorted(record.message for record in RECORDS)
    messages = [record.message for record in RECORDS]
    assert sorted(_fed(framing, framing.encode_batch(messages))) == sorted((msg, None) for msg in messages)
    assert not framing.drops


def test_xbee_packs_as_many_records_as_its_payload_holds() -> None:
    framing = make_serial_framing("xbee")
    assert len(framing.encode_tagged(RECORDS)) == 3  # 3 records in 64 bytes of RF data (1 + 3 * 20)


def test_the_cobs8_vector_frame_decodes_to_its_record() -> None:
    framed = VECTORS["framed"]["cobs8"]
    framing = make_serial_framing("cobs8")
    heard = framing.feed_tagged(bytes.fromhex(framed["frame"]))
    assert [(msg.robot, record is not None and record.tag.hex()) for msg, record in heard] == \
        [(42, framed["record"][-16:])]
    assert framing.encode_tagged([record for _, record in heard if record]) == [bytes.fromhex(framed["frame"])]


@pytest.mark.parametrize("framing", _without_room(), ids=lambda f: f.name)
def test_framings_without_room_refuse_records(framing: Framing[Any]) -> None:
    assert not framing.carries_tags
    with pytest.raises(NoRoomForTags, match=f"{framing.name} has no room for tags"):
        framing.encode_tagged(RECORDS[:1])


def test_broken_tagged_batches_are_bad_length() -> None:
    batch = VECTORS["framed"]["batch"]["data"]
    zenoh = ZenohFraming(ZenohKeySpace("lab"), 7)
    assert zenoh.feed_tagged(ZenohSample("vstig/lab/0/9", bytes.fromhex(batch)[:-2])) == []
    assert zenoh.feed(ZenohSample("vstig/lab/0/9", b"\xa0" + bytes.fromhex(batch)[1:])) == []
    assert zenoh.drops["bad_length"] == 2
    xbee = make_serial_framing("xbee")
    source = 0x0013A200_0000_0001
    whole = xbee.feed_tagged(api_frame(receive_packet(source, encode_batch(RECORDS[:2]))))
    assert [record for _, record in whole] == RECORDS[:2] and xbee.sender_of(b"") is None
    short = api_frame(receive_packet(source, encode_batch(RECORDS[:1])[:-1]))  # a record one byte short
    assert xbee.feed_tagged(short) == [] and xbee.feed(short) == [] and xbee.drops["bad_length"] == 2


def test_a_can_fd_record_under_the_other_ops_id_is_an_op_mismatch() -> None:
    framing = CanFraming(CanIdScheme(), 7, fd=True)
    put = framing.encode_tagged(RECORDS[:1])[0]
    under_get = can.Message(arbitration_id=CanIdScheme().can_id(Op.GET, 9), data=put.data, is_fd=True,
                            is_extended_id=False)
    assert framing.feed_tagged(under_get) == [] and framing.feed(under_get) == []
    assert framing.drops["op_mismatch"] == 2
    heard = framing.feed_tagged(can.Message(arbitration_id=CanIdScheme().can_id(Op.PUT, 9), data=put.data,
                                            is_fd=True, is_extended_id=False))
    assert [record for _, record in heard] == RECORDS[:1]
