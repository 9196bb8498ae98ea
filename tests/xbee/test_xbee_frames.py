"""The xbee framing as a pure class, checked against Digi's own digi-xbee: what we send, what we read, what we drop.

digi-xbee builds and parses API frames with its own code (packets/common.py); its builders
want frames unescaped and its `output(escaped=True)` escapes them, so a frame of ours must
parse there, and its output must be our bytes exactly, in both API modes.
"""

from __future__ import annotations

import random

import pytest
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.mode import OperatingMode
from digi.xbee.packets.base import XBeePacket
from digi.xbee.packets.common import ReceivePacket, TransmitPacket
from digi.xbee.packets.factory import build_frame
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message, Op, encode
from vstig_hw.counters import Counters
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.xbee import (
    BROADCAST,
    MAX_FRAME_DATA,
    ModuleInfo,
    XBeeFraming,
    XBeeStreamReader,
    api_frame,
    receive_packet,
)

MODES = [("xbee", OperatingMode.API_MODE), ("xbee-api2", OperatingMode.ESCAPED_API_MODE)]
ROBOT = 0x0013A20040A1B2C3
# Every byte API mode 2 escapes, in a key, a value, a timestamp and a robot id.
AWKWARD = Message(Op.PUT, 0x117E, 0x7D13, 0x137E, 0x7D11)
messages_st = st.lists(st.builds(Message, st.sampled_from(list(Op)), st.integers(0, 0x7FFF), st.integers(0, 0xFFFF),
                                 st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)), min_size=1, max_size=70)


def digi(raw: bytes, mode: OperatingMode) -> XBeePacket:
    """digi-xbee's reading of one frame as on the wire (its reader unescapes before it builds)."""
    plain = XBeePacket.unescape_data(bytearray(raw)) if mode is OperatingMode.ESCAPED_API_MODE else bytearray(raw)
    packet = build_frame(plain, mode)
    assert bytes(packet.output(escaped=mode is OperatingMode.ESCAPED_API_MODE)) == raw  # our bytes, exactly
    return packet


@pytest.mark.parametrize(("name", "mode"), MODES)
@settings(max_examples=60, deadline=None)
@given(batch=messages_st, np=st.sampled_from([8, 64, 73, 84, 100, 256]),
       dest=st.sampled_from([BROADCAST, ROBOT, 0]))
def test_every_frame_we_send_is_a_transmit_request_digi_reads_as_sent(name: str, mode: OperatingMode,
                                                                    batch: list[Message], np: int, dest: int) -> None:
    framing = make_serial_framing(name, dest=dest)
    assert isinstance(framing, XBeeFraming)
    framing.use_module(ModuleInfo(max_payload=np))
    frames = framing.encode_batch(batch)
    carried = []
    for number, raw in enumerate(frames):
        packet = digi(raw, mode)
        assert isinstance(packet, TransmitPacket)
        assert packet.x64bit_dest_addr == XBee64BitAddress.from_hex_string(f"{dest:016X}")
        assert packet.x16bit_dest_addr == XBee16BitAddress.from_hex_string("FFFE")
        assert (packet.broadcast_radius, packet.transmit_options) == (0, 0)
        assert packet.frame_id == (1 if number == 0 else 0)  # the period's first frame asks for a report
        assert len(packet.rf_data) <= np and len(packet.rf_data) % 8 == 0
        carried.append(bytes(packet.rf_data))
    assert b"".join(carried) == b"".join(encode(m) for m in batch)  # in order, nothing lost or split
    assert len(frames) == -(-len(batch) // (np // 8))  # as full as NP allows
    assert framing.feed(b"".join(frames)) == batch  # our own tx lines decode too (captures)


@pytest.mark.parametrize(("name", "mode"), MODES)
@settings(max_examples=40, deadline=None)
@given(batch=messages_st, source=st.integers(0, 0xFFFF_FFFF_FFFF_FFFF))
def test_receive_packets_digi_builds_give_their_messages_and_sender(name: str, mode: OperatingMode,
                                                                   batch: list[Message], source: int) -> None:
    packet = ReceivePacket(XBee64BitAddress.from_hex_string(f"{source:016X}"), XBee16BitAddress.from_hex_string("FFFE"),
                           0x02, rf_data=bytearray(b"".join(encode(m) for m in batch)), op_mode=mode)
    raw = bytes(packet.output(escaped=mode is OperatingMode.ESCAPED_API_MODE))
    framing = make_serial_framing(name)
    assert framing.feed(raw) == batch
    assert framing.sender_of(raw) == source  # type: ignore[attr-defined]
    assert framing.sender_of(bytes(raw)) == source  # type: ignore[attr-defined]  # not only the unit just fed
    assert framing.drops == Counters()


def test_the_first_frame_of_each_control_period_asks_for_a_report_with_ids_cycling_1_to_255() -> None:
    framing = XBeeFraming()

    def period() -> list[int]:
        ids = [digi(framing.encode(AWKWARD)[0], OperatingMode.API_MODE).frame_id for _ in range(3)]
        framing.tick()
        return ids

    ids = [period() for _ in range(300)]
    assert ids[0] == [1, 0, 0] and ids[1] == [2, 0, 0] and {tuple(p[1:]) for p in ids} == {(0, 0)}
    assert [p[0] for p in ids[253:257]] == [254, 255, 1, 2]


def test_np_sets_the_batch_and_a_module_below_one_message_still_gets_one_per_frame() -> None:
    framing = XBeeFraming()
    assert framing.per_frame == 8  # 64 bytes until the module says its NP
    framing.use_module(ModuleInfo(max_payload=256))
    assert framing.per_frame == 32
    framing.use_module(ModuleInfo(max_payload=None))  # a module that did not answer NP changes nothing
    assert framing.per_frame == 32
    framing.use_module(ModuleInfo(max_payload=5))
    assert framing.per_frame == 1


def _stream(rng: random.Random, escaped: bool) -> tuple[bytes, list[Message], int]:
    """Good frames among every kind of damage; (stream, the messages of its good frames, good frames)."""
    parts, good, count = [], [], 0
    for _ in range(40):
        batch = [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16), rng.randrange(65536),
                         rng.randrange(65536)) for _ in range(rng.randrange(1, 4))]
        frame = api_frame(receive_packet(ROBOT, b"".join(encode(m) for m in batch)), escaped)
        damage = rng.randrange(6)
        if damage == 0:
            parts.append(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 30))))  # line noise
        elif damage == 1:
            parts.append(frame[:rng.randrange(1, len(frame) - 1)])  # a frame cut short by the next
        elif damage == 2:
            bad = bytearray(frame)
            bad[-1] ^= 0x01 if bad[-1] not in (0x7E, 0x7D, 0x7F, 0x7C, 0x11, 0x13, 0x10, 0x12) else 0x40
            parts.append(bytes(bad))  # a wrong checksum
        parts.append(frame)
        good.extend(batch)
        count += 1
    return b"".join(parts), good, count


@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(1, 400), max_size=40))
def test_the_reader_finds_the_same_frames_and_drops_however_the_stream_is_cut(escaped: bool, seed: int,
                                                                              cuts: list[int]) -> None:
    stream, _good, _count = _stream(random.Random(seed), escaped)
    whole = Counters()
    reader = XBeeStreamReader(escaped, whole)
    expected = reader.feed(stream) + reader.flush()
    pieces = Counters()
    reader = XBeeStreamReader(escaped, pieces)
    got, pos = [], 0
    for cut in cuts:
        got += reader.feed(stream[pos:pos + cut])
        pos += cut
    got += reader.feed(stream[pos:]) + reader.flush()
    assert got == expected and pieces == whole


@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@pytest.mark.parametrize("seed", range(5))
def test_every_good_frame_after_damage_is_read_resynchronising_at_the_next_0x7e(escaped: bool, seed: int) -> None:
    stream, good, count = _stream(random.Random(seed), escaped)
    drops = Counters()
    reader = XBeeStreamReader(escaped, drops)
    frames = reader.feed(stream) + reader.flush()
    framing = make_serial_framing("xbee-api2" if escaped else "xbee")
    heard = [m for wire, _data in frames for m in framing.feed(wire)]
    # In mode 1 a 0x7E inside damage can start a false frame that swallows a good one; mode 2 never loses one.
    if escaped:
        assert heard == good and len(frames) == count
    else:
        assert len(frames) >= count - 2 and set(heard) <= set(good)
    assert sum(drops.values()) > 0 and set(drops) <= {"noise", "escape", "frame_length", "truncated", "checksum"}


@pytest.mark.parametrize(("escaped", "damaged", "reason"), [
    (False, b"\x7e\x00\x05\x90\x01\x02\x03\x04\x00", "checksum"),
    (True, b"\x7e\x00\x05\x90\x01\x02\x03\x04\x00", "checksum"),
    (True, b"\x7e\x00\x05\x90\x7d\x41\x02\x03\x04\x00", "escape"),  # 0x7D escapes 0x61: never
    (False, b"\x7e\x00\x00\xff", "frame_length"),
    (False, b"\x7e" + (MAX_FRAME_DATA + 1).to_bytes(2, "big"), "frame_length"),
    (True, b"\x7e\x00\x10\x90\x01", "truncated"),  # the next frame starts before this one ended
    (False, b"hello", "noise"),
    (True, b"\x11\x13hello", "noise"),
], ids=["checksum-api1", "checksum-api2", "escape", "zero-length", "too-long", "truncated", "noise", "noise-api2"])
def test_each_kind_of_damage_is_one_drop_under_its_reason_and_the_next_frame_is_read(escaped: bool, damaged: bytes,
                                                                                       reason: str) -> None:
    good = api_frame(receive_packet(ROBOT, encode(AWKWARD)), escaped)
    drops = Counters()
    reader = XBeeStreamReader(escaped, drops, prefix="drop_")
    frames = reader.feed(damaged + good)
    assert [wire for wire, _ in frames] == [good]
    assert drops == Counters({f"drop_{reason}": 1})


def test_a_frame_the_line_stops_sending_is_truncated_and_the_frames_behind_its_start_are_kept() -> None:
    good = api_frame(receive_packet(ROBOT, encode(AWKWARD)))
    drops = Counters()
    reader = XBeeStreamReader(False, drops)
    # Mode 1: a length hit by noise claims 300 bytes, a good frame follows inside that span, then the line is quiet.
    assert reader.feed(b"\x7e\x01\x2c\x90" + good) == [] and reader.holding
    assert [wire for wire, _ in reader.flush()] == [good]
    assert drops == Counters({"truncated": 1}) and not reader.holding
    # Mode 2 needs no wait: the good frame's 0x7E ends the bad one at once.
    escaped = api_frame(receive_packet(ROBOT, encode(AWKWARD)), True)
    reader = XBeeStreamReader(True, drops)
    assert [wire for wire, _ in reader.feed(b"\x7e\x01\x2c\x90" + escaped)] == [escaped] and not reader.holding
    assert drops == Counters({"truncated": 2})


def test_a_noisy_line_cannot_grow_the_buffer() -> None:
    reader = XBeeStreamReader(False, Counters())
    rng = random.Random(3)
    for _ in range(200):
        reader.feed(bytes(rng.choice(b"abcdefghij") for _ in range(1000)))
        assert len(reader._buf) <= MAX_FRAME_DATA + 1000
    assert reader.drops["noise"] >= 1


@pytest.mark.parametrize(("unit", "reason"), [
    (api_frame(bytes.fromhex("95") + bytes(20)), "unknown_type"),  # node identification: AO must be 0
    (api_frame(receive_packet(ROBOT, b"\x00" * 7)), "bad_length"),
    (api_frame(receive_packet(ROBOT, b"")), "bad_length"),
    (api_frame(bytes.fromhex("90") + bytes(5)), "bad_length"),  # shorter than a receive packet's header
])
def test_frames_that_carry_no_messages_are_dropped_by_reason(unit: bytes, reason: str) -> None:
    framing = XBeeFraming()
    assert framing.feed(unit) == [] and framing.drops == Counters({reason: 1})
    assert framing.sender_of(unit) is None


def test_a_unit_that_is_not_one_frame_is_still_read_frame_by_frame() -> None:
    framing = XBeeFraming()
    one = api_frame(receive_packet(ROBOT, encode(AWKWARD)))
    two = api_frame(receive_packet(ROBOT + 1, encode(Message(Op.GET, 1, 2, 3, 4))))
    assert framing.feed(b"junk" + one + two[:-1]) == [AWKWARD]
    assert framing.drops == Counters({"noise": 1, "truncated": 1})
    assert framing.sender_of(one + two) == ROBOT


@pytest.mark.parametrize("name", ["xbee", "xbee-api2"])
def test_a_filtered_frame_keeps_its_header_and_sender(name: str) -> None:
    framing = make_serial_framing(name)
    kept = Message(Op.GET, 1, 2, 3, 4)
    unit = api_frame(receive_packet(ROBOT, encode(AWKWARD) + encode(kept)), framing.escaped)  # type: ignore[attr-defined]
    narrowed = framing.narrow(unit, [kept])  # type: ignore[attr-defined]
    assert framing.feed(narrowed) == [kept] and framing.sender_of(narrowed) == ROBOT  # type: ignore[attr-defined]
    assert framing.narrow(unit, []) is None  # type: ignore[attr-defined]


def test_dest_must_be_a_64_bit_address() -> None:
    for bad in (-1, 1 << 64, True, "FFFF"):
        with pytest.raises(ValueError, match="64-bit address"):
            XBeeFraming(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("escaped", [False, True])
def test_a_quiet_line_ends_a_run_of_noise_however_long(escaped: bool) -> None:
    """The transport flushes its reader when the line goes quiet while it holds anything, a run of skipped bytes
    included: noise after the pause is a new run (the compiled path's cutting does the same)."""
    reader = XBeeStreamReader(escaped, Counters())
    for length in (7, 2 * MAX_FRAME_DATA):  # a run its buffer keeps, and one it has let go of
        reader.feed(b"\x00" * length)
        assert reader.holding
        assert reader.flush() == [] and not reader.holding
    assert reader.drops == Counters({"noise": 2})
