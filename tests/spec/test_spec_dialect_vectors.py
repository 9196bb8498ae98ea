"""Our Buzz and BittyBuzz codecs against the independent vectors in buzz.json and bittybuzz.json."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from conftest import load

from vstig_hw.crc import crc16_mcrf4xx_le
from vstig_hw.dialects.bittybuzz import (
    BBZ_KILOBOT_TYPE,
    BbzOp,
    BbzOther,
    BbzVstig,
    bbzfloat_from_float,
    bbzfloat_to_float,
    decode_bittybuzz,
    encode_bittybuzz,
)
from vstig_hw.dialects.buzz import (
    BuzzDecodeError,
    BuzzObject,
    BuzzOp,
    BuzzOther,
    BuzzVstig,
    buzz_float_from_wire,
    buzz_float_to_wire,
    decode_buzz,
    encode_buzz,
)
from vstig_hw.dialects.buzz_packets import (
    rosbuzz_payload64,
    unpack_frame,
    unpack_rosbuzz_block,
    xbee_word_order,
)
from vstig_hw.dialects.lamport import bbz_is_newer
from vstig_hw.dialects.mapping import BBZ_BASE_STRINGS


def _f32(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


def _obj(spec: dict[str, Any]) -> BuzzObject:
    kind = spec["type"]
    if kind == "nil":
        return None
    if kind == "float":
        return _f32(spec["value"])
    return spec["value"]  # type: ignore[no-any-return]


def _buzz(fields: dict[str, Any]) -> BuzzVstig:
    return BuzzVstig(BuzzOp[fields["op"]], fields["stigmergy"], _obj(fields["key"]), _obj(fields["value"]),
                     fields["timestamp"], fields["robot"])


@pytest.mark.parametrize("vector", load("buzz.json")["messages"], ids=lambda v: v["name"])
def test_buzz_messages(vector: dict[str, Any]) -> None:
    raw, msg = bytes.fromhex(vector["hex"]), _buzz(vector["fields"])
    assert decode_buzz(raw, vector["dialect"]) == msg
    assert encode_buzz(msg, vector["dialect"]) == raw


@pytest.mark.parametrize("vector", load("buzz.json")["floats"], ids=lambda v: str(v["value"]))
def test_buzz_floats(vector: dict[str, Any]) -> None:
    mantissa, exponent = buzz_float_to_wire(vector["value"])
    assert (mantissa & 0xFFFFFFFF, exponent & 0xFFFFFFFF) == (int(vector["mantissa"], 16), int(vector["exponent"], 16))
    assert buzz_float_from_wire(mantissa, exponent) == vector["float32"]


def test_buzz_other_and_invalid() -> None:
    vectors = load("buzz.json")
    for vector in vectors["other"]:
        raw = bytes.fromhex(vector["hex"])
        assert decode_buzz(raw) == BuzzOther(vector["type"], raw), vector["name"]
    for vector in vectors["invalid"]:
        with pytest.raises(BuzzDecodeError) as caught:
            decode_buzz(bytes.fromhex(vector["hex"]))
        assert caught.value.reason == vector["counted_as"], vector["name"]


@pytest.mark.parametrize("vector", load("buzz.json")["frames"], ids=lambda v: v["name"])
def test_buzz_frames(vector: dict[str, Any]) -> None:
    raw = bytes.fromhex(vector["hex"])
    transport = vector["transport"]
    if transport in ("kh4", "argos"):
        frame = unpack_frame(raw, "little" if transport == "kh4" else "big")
    else:
        frame = unpack_rosbuzz_block(raw if transport == "rosbuzz" else xbee_word_order(raw))
    assert (frame.sender, [m.hex() for m in frame.messages], frame.overrun) == (vector["sender"], vector["messages"], 0)
    if "payload64" in vector:
        assert [f"{w:016x}" for w in rosbuzz_payload64(raw)[5:]] == vector["payload64"]


@pytest.mark.parametrize("vector", load("buzz.json")["xbeemav"], ids=lambda v: v["name"])
def test_xbeemav_packets(vector: dict[str, Any]) -> None:
    """What a drone's XbeeMav sends, as its module hands it to us: the framing finds the same Buzz messages."""
    from vstig_hw.dialects.framing import XbeeMavFraming
    from vstig_hw.dialects.mapping import parse_deployment

    framing = XbeeMavFraming(parse_deployment('[buzz]\nstigmergy = 1\n[keys]\nx = { key = 1, type = "int16" }\n'))
    units = [bytes.fromhex(u) for u in vector.get("api1_frames", [vector.get("api1")])]
    heard = [(m, framing.sender_of(unit)) for unit in units for m in framing.feed(unit)]
    buzz = [decode_buzz(bytes.fromhex(m)) for m in vector["messages"]]
    assert heard == [(framing.rosbuzz.translator.to_ours(b), int(vector["sender"], 16)) for b in buzz]  # type: ignore[arg-type]
    assert {name for name, n in framing.drops.items() if n} <= {"xbeemav_control"}  # the ping, when there is one


@pytest.mark.parametrize("vector", load("bittybuzz.json")["messages"], ids=lambda v: v["name"])
def test_bittybuzz_messages(vector: dict[str, Any]) -> None:
    raw, fields = bytes.fromhex(vector["hex"]), vector["fields"]
    msg = BbzVstig(BbzOp(fields["type"]), fields["robot"], fields["key"], fields["mdata"], fields["value"],
                   fields["lamport"])
    assert decode_bittybuzz(raw) == msg and encode_bittybuzz(msg) == raw
    assert msg.value_type == vector["value_type"]
    message_t = raw + bytes((BBZ_KILOBOT_TYPE,))
    assert (message_t + crc16_mcrf4xx_le(message_t)).hex() == vector["kilobot_message_t"]


def test_bittybuzz_other_floats_lamports_ids() -> None:
    vectors = load("bittybuzz.json")
    for vector in vectors["other"]:
        raw = bytes.fromhex(vector["hex"])
        assert decode_bittybuzz(raw) == BbzOther(vector["type"], raw)
    for vector in vectors["floats"]:
        assert f"{bbzfloat_from_float(vector['value']):04x}" == vector["bbzfloat"]
        assert bbzfloat_to_float(int(vector["bbzfloat"], 16)) == vector["value"]
    lamport = vectors["lamport"]
    for case in lamport["cases"]:
        assert bbz_is_newer(case["lamport"], case["local"], lamport["threshold"]) is case["newer"], case
    for name, string_id in vectors["string_ids"].items():
        if name != "source":
            assert BBZ_BASE_STRINGS.index(name) == string_id
