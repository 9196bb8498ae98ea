"""The serial framings as pure classes: layouts, registry, Kilobot, OHC, epuck4 reassembly and loss."""

from __future__ import annotations

import math
import random
import zlib
from functools import reduce
from operator import xor
from pathlib import Path

import pytest

from vstig_hw import Message, Op, encode
from vstig_hw.crc import crc16_mcrf4xx
from vstig_hw.framing import SERIAL_FRAMINGS, TransmitOnlyError, make_serial_framing
from vstig_hw.framing.cobsframe import encode_frame
from vstig_hw.framing.epuck4 import Epuck4Framing, EpuckFragmenter, EpuckReassembler
from vstig_hw.framing.kilobot import KilobotFraming, kilobot_payload
from vstig_hw.framing.kilobot_ohc import OHC_FORWARDMSG, OHC_FORWARDMSGSINGLE, KilobotOhcFraming

MSG = Message(Op.PUT, 0x1234, 0xBEEF, 7, 42)


def messages(n: int, seed: int, senders: int = 50) -> list[Message]:
    rng = random.Random(seed)
    return [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16), rng.randrange(1, 65536),
                    rng.randrange(senders)) for _ in range(n)]


# --- registry -------------------------------------------------------------------------------------------

def test_registry_builds_each_framing_by_name_with_its_line_defaults() -> None:
    assert set(SERIAL_FRAMINGS) == {"cobs8", "epuck4", "kilobot", "kilobot-ohc", "xbee", "xbee-api2", "mavlink"}
    for name, cls in SERIAL_FRAMINGS.items():
        framing = make_serial_framing(name)
        assert isinstance(framing, cls) and framing.name == name
    assert SERIAL_FRAMINGS["kilobot-ohc"].default_baud == 38400 and SERIAL_FRAMINGS["cobs8"].default_baud == 115200
    assert make_serial_framing("epuck4", expiry_ticks=9).reassembler.expiry_ticks == 9  # type: ignore[attr-defined]


@pytest.mark.parametrize(("name", "options", "complaint"), [
    ("cobs9", {}, "unknown serial framing 'cobs9'; choose one of cobs8"),
    ("cobs8", {"expiry_ticks": 3}, "'cobs8' has no option 'expiry_ticks'"),
    ("kilobot", {"msg_type": 0x80}, "user type in 0..127"),
    ("epuck4", {"expiry_ticks": 0}, "expiry_ticks must be a positive integer"),
    ("kilobot-ohc", {"mode": "forever"}, "mode must be 'single' or 'repeat'"),
])
def test_bad_framing_choices_name_themselves(name: str, options: dict[str, object], complaint: str) -> None:
    with pytest.raises(ValueError, match=complaint):
        make_serial_framing(name, **options)


@pytest.mark.parametrize("name", ["cobs8", "epuck4", "kilobot"])
def test_round_trip_in_any_chunking(name: str) -> None:
    framing = make_serial_framing(name)
    sent = messages(200, seed=1)
    stream = b"".join(unit for m in sent for unit in framing.encode(m))
    rng = random.Random(2)
    got, at = [], 0
    while at < len(stream):
        step = rng.randint(1, 40)
        got += framing.feed(stream[at:at + step])
        at += step
    assert got == sent and not +framing.drops


# --- cobs8 and kilobot ----------------------------------------------------------------------------------

def test_cobs8_is_twelve_bytes_per_message() -> None:
    (unit,) = make_serial_framing("cobs8").encode(MSG)
    assert unit == encode_frame(encode(MSG)) and len(unit) == 12


def test_kilobot_payload_is_message_t_and_the_frame_crc_is_kilolibs() -> None:
    framing = KilobotFraming()
    (unit,) = framing.encode(MSG)
    data_and_type = kilobot_payload(MSG)
    assert data_and_type == encode(MSG) + b"\x01\x56"
    assert unit == encode_frame(data_and_type)  # COBS(data[9] type crc_lo crc_hi) 0x00
    crc = crc16_mcrf4xx(data_and_type)
    assert crc16_mcrf4xx(b"123456789") == 0x6F91
    assert (data_and_type + crc.to_bytes(2, "little"))[10:] == crc.to_bytes(2, "little")


def test_kilobot_ignores_other_types_and_versions_and_counts_them() -> None:
    framing = KilobotFraming(msg_type=0x42)
    other_type = encode_frame(encode(MSG) + b"\x01\x56")
    other_version = encode_frame(encode(MSG) + b"\x02\x42")
    ours = framing.encode(MSG)[0]
    assert framing.feed(other_type + other_version + ours) == [MSG]
    assert framing.drops == {"foreign_type": 1, "bad_version": 1}


# --- kilobot-ohc ----------------------------------------------------------------------------------------

@pytest.mark.parametrize(("mode", "packet_type"), [("single", OHC_FORWARDMSGSINGLE), ("repeat", OHC_FORWARDMSG)])
def test_ohc_packet_layout_and_xor_to_zero(mode: str, packet_type: int) -> None:
    for msg in messages(100, seed=3):
        (packet,) = KilobotOhcFraming(msg_type=0x21, mode=mode).encode(msg)  # type: ignore[arg-type]
        assert len(packet) == 132 and packet[0] == 0x55 and packet[1] == packet_type
        assert packet[2:10] == encode(msg) and packet[10] == 0x01 and packet[11] == 0x21
        assert packet[12:131] == bytes(119)
        assert reduce(xor, packet) == 0
    assert (OHC_FORWARDMSG, OHC_FORWARDMSGSINGLE) == (2, 6)  # kilolib ohc.h packet type enum


def test_ohc_refuses_to_receive_clearly() -> None:
    framing = make_serial_framing("kilobot-ohc")
    assert framing.transmit_only
    with pytest.raises(TransmitOnlyError, match="kilobot-ohc is transmit-only"):
        framing.feed(b"\x55" * 132)


# --- epuck4 ---------------------------------------------------------------------------------------------

def test_epuck_word_layout() -> None:
    words = EpuckFragmenter().fragment(MSG)
    raw = encode(MSG)
    c = zlib.crc32(raw)
    assert len(words) == 3 and all(len(w) == 4 for w in words)
    values = [int.from_bytes(w, "big") for w in words]
    assert [v >> 30 for v in values] == [0, 1, 2]
    assert {(v >> 26) & 0xF for v in values} == {c >> 28}
    p78 = 0
    for v in values:
        p78 = (p78 << 26) | (v & 0x3FFFFFF)
    assert p78 >> 14 == int.from_bytes(raw, "big") and p78 & 0x3FFF == (c >> 14) & 0x3FFF


def test_epuck_uart_carriage_is_eight_bytes_a_word() -> None:
    units = Epuck4Framing().encode(MSG)
    assert units == [encode_frame(w) for w in EpuckFragmenter().fragment(MSG)]
    assert [len(u) for u in units] == [8, 8, 8]


def test_epuck_reorder_and_duplicates() -> None:
    w0, w1, w2 = EpuckFragmenter().fragment(MSG)
    r = EpuckReassembler()
    assert [r.feed(w) for w in (w2, w0, w0, w1)] == [None, None, None, MSG]
    assert r.drops == {"duplicate": 1} and r.pending == 0
    late_duplicate = r.feed(w2)  # after delivery, a late copy is just a new partial that will expire
    assert late_duplicate is None and r.pending == 1


def test_epuck_reserved_index_and_wrong_word_size() -> None:
    r = EpuckReassembler()
    assert r.feed(b"\xc0\x00\x00\x01") is None and r.feed(b"\x00\x00") is None
    assert r.drops == {"bad_index": 1, "bad_length": 1}


def test_epuck_stale_partials_expire_after_the_configured_ticks() -> None:
    w0, w1, w2 = EpuckFragmenter().fragment(MSG)
    r = EpuckReassembler(expiry_ticks=2)
    r.feed(w0)
    r.tick()
    r.tick()
    assert r.pending == 1 and not r.drops
    r.tick()
    assert r.pending == 0 and r.drops == {"stale": 1}
    assert [r.feed(w) for w in (w1, w2)] == [None, None]


def _same_group_pair() -> tuple[Message, Message]:
    """Two messages whose fragments carry the same group (1 in 16 pairs do)."""
    base = EpuckFragmenter().fragment(MSG)[0][0] >> 2 & 0xF
    for value in range(1, 1000):
        other = MSG.replace(value=value)
        if EpuckFragmenter().fragment(other)[0][0] >> 2 & 0xF == base:
            return MSG, other
    raise AssertionError("no same-group message found")


def test_epuck_leftovers_of_a_lost_message_do_not_cost_the_next_one() -> None:
    a, b = _same_group_pair()
    fa, fb = EpuckFragmenter().fragment(a), EpuckFragmenter().fragment(b)
    for lost_pattern in ([fa[2]], [fa[1]], [fa[0]], [fa[0], fa[1]], [fa[1], fa[2]], [fa[0], fa[2]]):
        r = EpuckReassembler()
        for word in lost_pattern:  # what survived of a
            assert r.feed(word) is None
        got = [r.feed(w) for w in fb]
        assert got[-1] == b and got[:-1] == [None, None], lost_pattern


def test_epuck_mixed_fragments_are_never_a_wrong_message() -> None:
    a, b = _same_group_pair()
    fa, fb = EpuckFragmenter().fragment(a), EpuckFragmenter().fragment(b)
    r = EpuckReassembler()
    assert [r.feed(w) for w in (fa[0], fb[1], fa[2])] == [None, None, None]
    assert r.drops["check"] == 1


def test_epuck_interleaved_senders_and_word_shuffles_never_deliver_a_wrong_message() -> None:
    rng = random.Random(5)
    fragmenter = EpuckFragmenter()
    r = EpuckReassembler()
    sent: set[Message] = set()
    delivered = 0
    for step in range(3000):
        batch = messages(4, seed=step, senders=4)  # four robots talking in the same control step
        sent.update(batch)
        words = [w for m in batch for w in fragmenter.fragment(m) if rng.random() > 0.1]
        words += rng.sample(words, k=len(words) // 5)  # duplicates
        rng.shuffle(words)  # interleaved and reordered
        for word in words:
            msg = r.feed(word)
            if msg is not None:
                assert msg in sent, f"wrong message delivered: {msg}"
                delivered += 1
        r.tick()
    assert delivered > 0.5 * 12000 and r.drops["collision"] > 0 and r.drops["duplicate"] > 0


@pytest.mark.parametrize(("p", "n"), [(0.0, 20_000), (0.25, 100_000), (0.5, 20_000), (0.75, 20_000)])
def test_epuck_delivery_ratio_is_one_minus_p_cubed(p: float, n: int) -> None:
    """Each word lost with probability p, messages from mixed senders one after another."""
    rng = random.Random(int(p * 100) + 17)
    fragmenter = EpuckFragmenter()
    r = EpuckReassembler()
    sent: set[Message] = set()
    delivered = 0
    for i, msg in enumerate(messages(n, seed=int(p * 100))):
        sent.add(msg)
        for word in fragmenter.fragment(msg):
            if rng.random() >= p:
                got = r.feed(word)
                if got is not None:
                    assert got in sent, f"wrong message delivered: {got}"
                    delivered += 1
        if i % 4 == 3:
            r.tick()
    expected = (1 - p) ** 3
    tolerance = 5 * math.sqrt(expected * (1 - expected) / n) + 1e-9  # five binomial standard deviations
    assert abs(delivered / n - expected) <= tolerance, (delivered / n, expected)


# --- firmware_spec/SPEC.md 6.7: the worked serial example --------------------------------------------

def test_spec_vectors_are_what_the_code_produces() -> None:
    text = (Path(__file__).resolve().parents[2] / "firmware_spec" / "SPEC.md").read_text(encoding="utf-8")
    heading = "### 6.7 Worked example: one message on every serial link"
    assert heading in text, f"SPEC.md lost its section {heading!r}"
    spec = text.split(heading, 1)[1].split("\n## ", 1)[0]  # that section only, up to the next chapter
    spec = " ".join(spec.split())  # vectors may wrap across lines

    def hexed(data: bytes) -> str:
        return data.hex(" ")

    put = Message(Op.PUT, 0x1234, 0xBEEF, 7, 42)
    expected = [
        hexed(encode(put)),
        hexed(make_serial_framing("cobs8").encode(put)[0]),
        *(hexed(w) for w in EpuckFragmenter().fragment(put)),
        *(hexed(u) for u in make_serial_framing("epuck4").encode(put)),
        hexed(make_serial_framing("kilobot").encode(put)[0]),
        hexed(make_serial_framing("kilobot-ohc").encode(put)[0][:12]),
        hexed(make_serial_framing("cobs8").encode(Message(Op.GET, 5, 0, 0, 0x0100))[0]),
    ]
    for vector in expected:
        assert f"`{vector}`" in spec, vector
    packet = make_serial_framing("kilobot-ohc").encode(put)[0]
    assert f"then `{packet[131]:02x}`" in spec
    assert f"0x{crc16_mcrf4xx(encode(put)):04X}" in spec and f"0x{zlib.crc32(encode(put)):08x}" in spec
