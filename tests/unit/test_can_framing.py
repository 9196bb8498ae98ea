"""The CAN ID scheme and payload framing: properties, batching, and fuzzed input."""

from __future__ import annotations

import re

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message, Op
from vstig_hw.framing.can import BASES_11BIT, FD_BATCH_SIZES, CanFraming, CanIdScheme

messages = st.builds(Message, st.sampled_from(Op), st.integers(0, 0x7FFF), st.integers(0, 0xFFFF),
                     st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
schemes = st.one_of(
    st.builds(CanIdScheme, st.just(False), st.sampled_from(BASES_11BIT)),
    st.builds(CanIdScheme, st.just(True), st.integers(1, 15).map(lambda b: b << 25), st.integers(0, 255)),
)


@st.composite
def scheme_and_sender(draw: st.DrawFn) -> tuple[CanIdScheme, int]:
    scheme = draw(schemes)
    return scheme, draw(st.integers(0, scheme.max_sender))


def test_defaults_and_bad_parameters_name_the_input() -> None:
    assert CanIdScheme().base == 0x600 and CanIdScheme(extended=True).base == 0x18000000
    with pytest.raises(ValueError, match="0x000, 0x200, 0x400, 0x600, got 0x100"):
        CanIdScheme(base=0x100)
    with pytest.raises(ValueError, match="no stigmergy field"):
        CanIdScheme(stigmergy=1)
    with pytest.raises(ValueError, match=re.escape("bits 28..25")):
        CanIdScheme(extended=True, base=0x18000001)
    with pytest.raises(ValueError, match=re.escape("stigmergy must be 0..255")):
        CanIdScheme(extended=True, stigmergy=256)
    with pytest.raises(ValueError, match=re.escape("11-bit CAN bus must be a node id in 0..255, got 256")):
        CanFraming(CanIdScheme(), sender=256)
    with pytest.raises(ValueError, match=re.escape("0..65535")):
        CanFraming(CanIdScheme(extended=True), sender=-1)


@given(scheme_and_sender(), st.lists(messages, min_size=1, max_size=20), st.booleans())
def test_round_trip_through_frames_names_the_sender(pair: tuple[CanIdScheme, int], batch: list[Message],
                                                     fd: bool) -> None:
    scheme, sender = pair
    tx, rx = CanFraming(scheme, sender, fd=fd), CanFraming(scheme, sender=0)
    heard = []
    for frame in tx.encode_batch(batch):
        assert rx.sender_of(frame) == sender
        assert frame.is_extended_id == scheme.extended and frame.is_fd == fd
        heard.extend(rx.feed(frame))
    assert not rx.drops
    # Classic frames keep the order; FD batches send PUTs first, each op in order.
    grouped = [m for m in batch if m.op is Op.PUT] + [m for m in batch if m.op is Op.GET]
    assert heard == (grouped if fd else batch)


@given(schemes, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
def test_every_put_outranks_every_get_and_ids_never_collide(scheme: CanIdScheme, a: int, b: int) -> None:
    a, b = a & scheme.max_sender, b & scheme.max_sender
    assert scheme.can_id(Op.PUT, a) < scheme.can_id(Op.GET, b)
    if a != b:
        assert scheme.can_id(Op.PUT, a) != scheme.can_id(Op.PUT, b)
        assert scheme.can_id(Op.GET, a) != scheme.can_id(Op.GET, b)


@given(schemes, schemes, st.integers(0, 255))
def test_distinct_stigmergies_never_share_an_id(one: CanIdScheme, other: CanIdScheme, sender: int) -> None:
    if one != other and one.extended == other.extended:
        assert {one.can_id(op, sender) for op in Op}.isdisjoint({other.can_id(op, sender) for op in Op})


@given(schemes, st.integers(0, 0x1FFFFFFF), st.booleans())
def test_can_filters_pass_exactly_the_ids_the_scheme_parses(scheme: CanIdScheme, ident: int, ext: bool) -> None:
    ident &= 0x1FFFFFFF if ext else 0x7FF
    (flt,) = scheme.can_filters()
    passes = flt["extended"] == ext and ident & flt["can_mask"] == flt["can_id"] & flt["can_mask"]
    assert passes == (scheme.parse(ident, ext) is not None)


@pytest.mark.parametrize(("n", "sizes"), [(1, [1]), (5, [4, 1]), (7, [6, 1]), (8, [8]), (9, [8, 1]), (14, [8, 6])])
def test_fd_batches_use_the_fewest_allowed_frames(n: int, sizes: list[int]) -> None:
    framing = CanFraming(CanIdScheme(), sender=3, fd=True)
    frames = framing.encode_batch([Message(Op.PUT, k, 0, 1, 3) for k in range(n)])
    assert [len(f.data) // 8 for f in frames] == sizes
    assert all(len(f.data) // 8 in FD_BATCH_SIZES and f.bitrate_switch for f in frames)


def test_classic_framing_sends_one_dlc8_frame_per_message() -> None:
    framing = CanFraming(CanIdScheme(), sender=3)
    frames = framing.encode_batch([Message(Op.GET, 1, 2, 3, 4), Message(Op.PUT, 1, 2, 3, 4)])
    assert [(f.arbitration_id, f.dlc, f.is_fd) for f in frames] == [(0x703, 8, False), (0x603, 8, False)]


def test_error_frames_are_counted_not_decoded() -> None:
    framing = CanFraming(CanIdScheme(), sender=3)
    frame = can.Message(arbitration_id=0x605, is_extended_id=False, is_error_frame=True, data=bytes(8))
    assert framing.feed(frame) == [] and framing.drops == {"error_frame": 1}
    assert framing.sender_of(frame) is None


@settings(max_examples=300)
@given(schemes, st.integers(0, 0x1FFFFFFF), st.booleans(), st.booleans(), st.booleans(), st.booleans(),
       st.binary(max_size=64))
def test_fuzzed_frames_are_decoded_or_counted_never_raised(
    scheme: CanIdScheme, ident: int, ext: bool, fd: bool, remote: bool, error: bool, data: bytes
) -> None:
    if not fd:
        data = data[:8]
    frame = can.Message(arbitration_id=ident if ext else ident & 0x7FF, is_extended_id=ext, is_fd=fd,
                        is_remote_frame=remote and not fd, is_error_frame=error, data=data)
    framing = CanFraming(scheme, sender=0, fd=True)
    out = framing.feed(frame)
    mismatched = framing.drops.pop("op_mismatch", 0)
    assert sum(framing.drops.values()) in (0, 1)  # at most one frame-level drop per frame
    if framing.drops:
        assert out == [] and not mismatched
    else:  # a whole number of messages: each one delivered or counted
        assert len(out) + mismatched == len(data) // 8 and len(data) % 8 == 0
