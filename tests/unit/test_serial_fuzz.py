"""Hypothesis: every serial feed() takes arbitrary bytes with counted drops only, never an exception."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.cobsframe import MAX_ENCODED_FRAME
from vstig_hw.framing.epuck4 import EpuckReassembler

FRAME_DROPS = ("cobs", "crc", "bad_length", "overlong")
chunks = st.lists(st.binary(max_size=120), max_size=30)
noisy_chunks = st.lists(st.one_of(st.binary(max_size=120), st.sampled_from([b"\x00", b"\x00\x00", b"\x01" * 70])),
                        max_size=30)
messages = st.builds(Message, st.integers(0, 1), st.integers(0, 0x7FFF), st.integers(0, 0xFFFF),
                     st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))


def frames_to_account_for(stream: bytes) -> int:
    """Complete non-empty frames, plus the unfinished one once it is already too long to be a frame."""
    *complete, unfinished = stream.split(b"\x00")
    return sum(1 for s in complete if s) + (len(unfinished) > MAX_ENCODED_FRAME)


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(["cobs8", "kilobot", "epuck4"]), parts=noisy_chunks)
def test_feed_takes_anything(name: str, parts: list[bytes]) -> None:
    framing = make_serial_framing(name)
    for part in parts:
        for msg in framing.feed(part):
            assert isinstance(msg, Message)
        framing.tick()
    assert all(count > 0 for count in framing.drops.values())


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(["cobs8", "kilobot"]), parts=chunks)
def test_every_frame_is_a_message_or_exactly_one_drop(name: str, parts: list[bytes]) -> None:
    framing = make_serial_framing(name)
    delivered = sum(len(framing.feed(part)) for part in parts)
    stream = b"".join(parts)
    accounted = delivered + sum(framing.drops.values())
    assert accounted == frames_to_account_for(stream), (framing.drops, delivered)


@settings(max_examples=200, deadline=None)
@given(name=st.sampled_from(["cobs8", "kilobot", "epuck4"]), noise=chunks, msgs=st.lists(messages, max_size=10))
def test_any_noise_then_intact_frames_recovers(name: str, noise: list[bytes], msgs: list[Message]) -> None:
    framing = make_serial_framing(name)
    for part in noise:
        framing.feed(part)
    framing.tick()
    framing.tick()
    framing.tick()
    framing.tick()  # older than expiry: leftover epuck4 fragments are gone
    clean = b"\x00" + b"".join(u for m in msgs for u in framing.encode(m))  # one 0x00 ends whatever noise left
    assert framing.feed(clean) == msgs
    assert framing._reader._pending == b"" or len(framing._reader._pending) <= MAX_ENCODED_FRAME  # type: ignore[attr-defined]


@settings(max_examples=300, deadline=None)
@given(words=st.lists(st.one_of(st.binary(min_size=4, max_size=4), st.binary(max_size=8)), max_size=60),
       tick_every=st.integers(1, 10))
def test_reassembler_takes_any_words(words: list[bytes], tick_every: int) -> None:
    r = EpuckReassembler()
    for i, word in enumerate(words):
        msg = r.feed(word)
        assert msg is None or isinstance(msg, Message)
        if i % tick_every == 0:
            r.tick()
    assert r.pending <= 16  # one partial per group at most
