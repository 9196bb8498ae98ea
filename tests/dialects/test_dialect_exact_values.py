"""Every robot of every dialect holds its writer's exact bits at the writer's version, or not that version at all.

One gateway joins three dialects: Buzz (int32, float32), BittyBuzz (int16, bbzfloat)
and ours (16 raw bits under int16, uint16, float16 or bbzfloat). A robot writes a
random value in its own dialect; the gateway translates it to ours and from ours to
every dialect, each through the real wire codec, so what a robot holds is what it
decodes. Whoever holds the version must give the writer's bits back when its copy
crosses to the writer's dialect, and robots of the writer's dialect must hold exactly
what the writer's own neighbours heard from it.
"""

from __future__ import annotations

import math
import struct
from typing import TypeAlias

from hypothesis import example, given
from hypothesis import strategies as st

from vstig_hw import Message, Op, decode, encode
from vstig_hw.dialects.bittybuzz import BbzOp, BbzType, BbzVstig, bbzfloat_to_float, decode_bittybuzz, encode_bittybuzz
from vstig_hw.dialects.buzz import BuzzOp, BuzzVstig, decode_buzz, encode_buzz
from vstig_hw.dialects.mapping import DIALECT_VALUE_TYPES, Deployment, parse_deployment
from vstig_hw.dialects.translate import BittyBuzzTranslator, BuzzTranslator

KEY, BBZ_ID, TS, WRITER = 5, 60, 3, 9
Held: TypeAlias = "int | float | tuple[int, int]"  # ours: raw; Buzz: int or float; BittyBuzz: (tag, 16 bits)


def deployment(value_type: str) -> Deployment:
    return parse_deployment(f'[buzz]\nstigmergy = 1\n[keys]\nk = {{ key = {KEY}, type = "{value_type}", '
                            f'bbz_id = {BBZ_ID} }}\n')


def bits(held: Held) -> object:
    """A held value by its bits: 0.1 is not its float16 rounding, -0.0 is not 0.0, an int is no float."""
    return ("float", struct.pack(">f", held).hex()) if isinstance(held, float) else (type(held).__name__, held)


def heard_by_peers(dialect: str, value: Held) -> Held:
    """What the writer's own neighbours hold: its message through its dialect's codec."""
    if dialect == "buzz":
        assert isinstance(value, int | float)
        return decode_buzz(encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "k", value, TS, WRITER))).value  # type: ignore
    return value


def gateway_hears(dialect: str, held: Held, mapping: Deployment) -> Message | None:
    """The robot PUTs what it holds at (TS, WRITER); what the gateway passes to our side (None: dropped)."""
    if dialect == "ours":
        assert isinstance(held, int)
        return decode(encode(Message(Op.PUT, KEY, held, TS, WRITER)))
    if dialect == "buzz":
        assert isinstance(held, int | float)
        wire = encode_buzz(BuzzVstig(BuzzOp.PUT, 1, "k", held, TS, WRITER))
        decoded = decode_buzz(wire)
        assert isinstance(decoded, BuzzVstig)
        return BuzzTranslator(mapping).to_ours(decoded)
    assert isinstance(held, tuple)
    bbz = decode_bittybuzz(encode_bittybuzz(BbzVstig(BbzOp.PUT, WRITER, BBZ_ID, held[0], held[1], TS)))
    assert isinstance(bbz, BbzVstig)
    return BittyBuzzTranslator(mapping).to_ours(bbz)


def robot_holds(dialect: str, msg: Message, mapping: Deployment) -> Held | None:
    """What a robot of `dialect` holds once the gateway sends it `msg` (None: nothing was sent)."""
    if dialect == "ours":
        return decode(encode(msg)).value
    if dialect == "buzz":
        out = BuzzTranslator(mapping).from_ours(msg)
        if out is None:
            return None
        decoded = decode_buzz(encode_buzz(out))
        assert isinstance(decoded, BuzzVstig) and (decoded.timestamp, decoded.robot) == (TS, WRITER)
        assert isinstance(decoded.value, int | float)
        return decoded.value
    bbz_out = BittyBuzzTranslator(mapping).from_ours(msg)
    if bbz_out is None:
        return None
    bbz = decode_bittybuzz(encode_bittybuzz(bbz_out))
    assert isinstance(bbz, BbzVstig) and (bbz.robot, bbz.lamport) == (WRITER, TS)
    return bbz.value_type, bbz.value


def finite_bbzfloat(raw: int) -> float:
    number = bbzfloat_to_float(raw)
    return number if math.isfinite(number) else 0.5


buzz_values = st.one_of(
    st.integers(-2**31, 2**31 - 1), st.integers(-70000, 70000),
    st.floats(width=32, allow_nan=False, allow_infinity=False),
    st.floats(width=16, allow_nan=False, allow_infinity=False),  # the values a float16 key can carry
    st.integers(0, 0xFFFF).map(finite_bbzfloat),  # and those a bbzfloat key can
)
written = st.one_of(
    st.tuples(st.just("buzz"), buzz_values),
    st.tuples(st.just("bittybuzz"), st.tuples(st.sampled_from(list(BbzType)), st.integers(0, 0xFFFF))),
    st.tuples(st.just("ours"), st.integers(0, 0xFFFF)),
)


@given(written, st.sampled_from(DIALECT_VALUE_TYPES))
@example(("buzz", 0.1), "float16")  # 0x3dcccccd: float16 holds 0x3dccc000
@example(("buzz", 0.3), "float16")
@example(("buzz", 0.1), "bbzfloat")
@example(("ours", 0x2E67), "float16")  # a float16 with its 10th fraction bit: a bbzfloat has 9
@example(("ours", 0x8000), "float16")  # -0.0: Buzz's float has one zero
@example(("bittybuzz", (BbzType.FLOAT, 0x0001)), "float16")  # 1.002 * 2^-31: below float16
@example(("bittybuzz", (BbzType.INT, 0xFFFF)), "uint16")
def test_every_dialect_holds_the_writers_bits_or_not_that_version(write: tuple[str, Held], value_type: str) -> None:
    writer_dialect, value = write
    mapping = deployment(value_type)
    wrote = bits(heard_by_peers(writer_dialect, value))
    ours = gateway_hears(writer_dialect, value, mapping)
    if ours is None:
        return  # not carried: no robot beyond the writer's own medium holds this version
    assert (ours.timestamp, ours.robot) == (TS, WRITER)
    for dialect in ("ours", "buzz", "bittybuzz"):
        held = robot_holds(dialect, ours, mapping)
        if held is None:
            continue  # the gateway did not send it there: that dialect does not hold the version
        if dialect == writer_dialect:
            assert bits(held) == wrote, (dialect, held)
            continue
        back = gateway_hears(dialect, held, mapping)  # that robot relays its copy
        assert back == ours, (dialect, held, back)
        writer_side = robot_holds(writer_dialect, back, mapping)
        assert writer_side is not None and bits(writer_side) == wrote, (dialect, held, writer_side)


def test_inexact_values_are_counted_unmapped_and_exact_ones_cross() -> None:
    mapping = deployment("float16")
    buzz = BuzzTranslator(mapping)
    assert buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "k", 0.1, TS, WRITER)) is None
    assert buzz.to_ours(BuzzVstig(BuzzOp.QUERY, 1, "k", 0.3, TS, WRITER)) is None
    exact = struct.unpack(">e", bytes.fromhex("2e66"))[0]  # float16(0.1) written as such: 0.0999755859375
    assert buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "k", exact, TS, WRITER)) == Message(Op.PUT, KEY, 0x2E66, TS, WRITER)
    assert buzz.from_ours(Message(Op.PUT, KEY, 0x8000, TS, WRITER)) is None  # -0.0 would reach Buzz as 0.0
    assert buzz.drops["unmapped"] == 3
    kilobots = BittyBuzzTranslator(mapping)
    assert kilobots.from_ours(Message(Op.PUT, KEY, 0x2E67, TS, WRITER)) is None  # 10 fraction bits: bbzfloat has 9
    assert kilobots.from_ours(Message(Op.PUT, KEY, 0x2E66, TS, WRITER)) is not None
    assert kilobots.to_ours(BbzVstig(BbzOp.PUT, 7, BBZ_ID, BbzType.FLOAT, 0x0001, 4)) is None  # below float16
    assert kilobots.drops["unmapped"] == 2
