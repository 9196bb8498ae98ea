#!/usr/bin/env python3
"""Writes firmware_spec/vectors/*.json from SPEC.md alone.

THIS SCRIPT MUST NEVER IMPORT vstig_hw (nor anything else from this repository).
The vectors check our implementations; vectors produced by the code they check
would prove nothing. Everything here is re-implemented from the spec text in the
plainest form: CRCs bit by bit (and checked against the published catalogue
values before anything is written), COBS by hand, fields packed with shifts.
Expected outcomes of the protocol and reassembly cases are written out by hand in
the tables below; the small models in this file only confirm them.

Usage: python firmware_spec/tools/make_vectors.py [OUTDIR]   (default: ../vectors)
Only the standard library is used (Python 3.10+).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

# --------------------------------------------------------------------------
# CRCs, bit by bit, from their catalogue parameters
# --------------------------------------------------------------------------


def crc16_mcrf4xx(data: bytes) -> int:
    """CRC-16/MCRF4XX: poly 0x1021 reflected (0x8408), init 0xFFFF, refin/refout, xorout 0."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def crc16_avr_ccitt_update(crc: int, byte: int) -> int:
    """The byte-wise shift/xor form documented for avr-libc's _crc_ccitt_update.

    A second, differently derived formula for the same CRC: the generator
    insists that both agree before using either.
    """
    data = (byte ^ crc) & 0xFF
    data = (data ^ (data << 4)) & 0xFF
    return ((data << 8) | (crc >> 8)) ^ (data >> 4) ^ (data << 3) & 0xFFFF


def crc32_iso_hdlc(data: bytes) -> int:
    """CRC-32/ISO-HDLC: poly 0x04C11DB7 reflected (0xEDB88320), init/xorout 0xFFFFFFFF."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


CHECK = b"123456789"
assert crc16_mcrf4xx(CHECK) == 0x6F91, "CRC-16/MCRF4XX catalogue check value"
assert crc32_iso_hdlc(CHECK) == 0xCBF43926, "CRC-32/ISO-HDLC catalogue check value"
_acc = 0xFFFF
for _b in CHECK:
    _acc = crc16_avr_ccitt_update(_acc, _b)
assert _acc == 0x6F91, "avr-libc formula disagrees with the catalogue"

# --------------------------------------------------------------------------
# COBS by hand (0x00 delimiter, blocks of at most 254 data bytes)
# --------------------------------------------------------------------------


def cobs_encode(data: bytes) -> bytes:
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(byte)
            if len(block) == 254:
                out += b"\xff" + block
                block = bytearray()
    out += bytes([len(block) + 1]) + block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes | None:
    """None when the bytes are not valid COBS."""
    out = bytearray()
    i = 0
    while i < len(data):
        code = data[i]
        if code == 0 or i + code > len(data):
            return None
        out += data[i + 1 : i + code]
        i += code
        if code != 0xFF and i < len(data):
            out.append(0)
    return bytes(out)


assert cobs_encode(b"\x11\x22\x00\x33") == bytes.fromhex("0311220233")  # the classic worked example
assert cobs_encode(b"\x00") == bytes.fromhex("0101")
assert cobs_decode(bytes.fromhex("0311220233")) == b"\x11\x22\x00\x33"


def serial_frame(payload: bytes) -> bytes:
    crc = crc16_mcrf4xx(payload)
    return cobs_encode(payload + bytes([crc & 0xFF, crc >> 8])) + b"\x00"


# --------------------------------------------------------------------------
# The 8-byte message, with shifts
# --------------------------------------------------------------------------
OPS = ("PUT", "GET")


def pack(op: str, key: int, value: int, ts: int, robot: int) -> bytes:
    head = (OPS.index(op) << 15) | key
    return bytes([head >> 8, head & 0xFF, value >> 8, value & 0xFF, ts >> 8, ts & 0xFF, robot >> 8, robot & 0xFF])


def fields(raw: bytes) -> dict[str, object]:
    return {
        "op": OPS[raw[0] >> 7],
        "key": ((raw[0] & 0x7F) << 8) | raw[1],
        "value": (raw[2] << 8) | raw[3],
        "timestamp": (raw[4] << 8) | raw[5],
        "robot": (raw[6] << 8) | raw[7],
    }


# --------------------------------------------------------------------------
# Timestamps: serial-number arithmetic as SPEC.md words it
# --------------------------------------------------------------------------


def is_newer(a: int, b: int) -> bool:
    if b == 0:
        return a != 0
    if a == 0:
        return False
    d = (a - b) % 65536
    return 0 < d < 32768 or (d == 32768 and a > b)


def next_ts(ts: int) -> int:
    return 1 if ts == 65535 else ts + 1


# --------------------------------------------------------------------------
# wire.json
# --------------------------------------------------------------------------
# Hand-worked: (name, hex written out by hand, the fields it must decode to).
WIRE_BY_HAND = [
    ("all zero: PUT key 0 (ts 0 is reserved, but the codec still carries it)", "0000000000000000",
     ("PUT", 0, 0, 0, 0)),
    ("GET bit alone", "8000000000000000", ("GET", 0, 0, 0, 0)),
    ("PUT, every other field at its maximum", "7fffffffffffffff", ("PUT", 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF)),
    ("all ones: GET key 0x7FFF", "ffffffffffffffff", ("GET", 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF)),
    ("key 1 value 0x1234 ts 1 robot 42", "000112340001002a", ("PUT", 1, 0x1234, 1, 42)),
    ("key high byte and GET bit share byte 0", "8102abcd800000ff", ("GET", 0x0102, 0xABCD, 0x8000, 0x00FF)),
    ("key 0x7FFF PUT value 0", "7fff000000010001", ("PUT", 0x7FFF, 0, 1, 1)),
    ("key 0 GET value 0xFFFF", "8000ffff00020003", ("GET", 0, 0xFFFF, 2, 3)),
    ("timestamp at the wrap: 0xFFFF", "00050007ffff0009", ("PUT", 5, 7, 0xFFFF, 9)),
    ("timestamp just after the wrap: 1", "0005000700010009", ("PUT", 5, 7, 1, 9)),
    ("key 0x4000: the bit right below the op bit", "4000000100010001", ("PUT", 0x4000, 1, 1, 1)),
    ("key 0x0080: bit 7 of byte 1, not the op bit", "0080000100010001", ("PUT", 0x80, 1, 1, 1)),
    ("robot 0xFFFF", "000a000a000affff", ("PUT", 10, 10, 10, 0xFFFF)),
    ("empty GET as an unknown key is asked for", "8007000000000011", ("GET", 7, 0, 0, 0x11)),
]


def wire_vectors() -> dict[str, object]:
    valid = []
    for name, hexbytes, (op, key, value, ts, robot) in WIRE_BY_HAND:
        raw = bytes.fromhex(hexbytes)
        assert pack(op, key, value, ts, robot) == raw, name  # shifts agree with the hand-worked hex
        names = ("op", "key", "value", "timestamp", "robot")
        assert fields(raw) == dict(zip(names, (op, key, value, ts, robot), strict=True))
        valid.append({"name": name, "hex": hexbytes, "fields": fields(raw)})
    invalid = [
        {"name": "empty buffer", "hex": "", "outcome": "drop", "reason": "bad_length"},
        {"name": "7 bytes", "hex": "00010002000300", "outcome": "drop", "reason": "bad_length"},
        {"name": "9 bytes", "hex": "000100020003000400", "outcome": "drop", "reason": "bad_length"},
        {"name": "16 bytes: two messages are not one", "hex": "0001000200030004" * 2,
         "outcome": "drop", "reason": "bad_length"},
    ]
    return {
        "description": "The 8-byte message (SPEC.md section 2). `hex` decodes to `fields`, and `fields` "
                       "encode to `hex`. Any 8 bytes are a message; only the length can be wrong.",
        "valid": valid,
        "invalid": invalid,
    }


# --------------------------------------------------------------------------
# timestamps.json
# --------------------------------------------------------------------------
# (a, b, is a strictly newer than b?) decided by hand from SPEC.md section 3.
COMPARE_BY_HAND = [
    (2, 1, True, "one step"),
    (1, 2, False, "one step back"),
    (7, 7, False, "equal is not newer"),
    (1, 65535, True, "across the wrap: 65535 -> 1 is one step (0 is skipped)"),
    (65535, 1, False, "across the wrap, backwards"),
    (3, 65530, True, "a few steps across the wrap"),
    (65530, 3, False, "a few steps across the wrap, backwards"),
    (32768, 1, True, "32767 ahead: the farthest that still counts as newer"),
    (32769, 1, True, "exactly half-way (32768 apart): the larger number is newer"),
    (1, 32769, False, "exactly half-way, other way round: the smaller number is not newer"),
    (40000, 10, False, "more than half the space ahead is behind"),
    (10, 40000, True, "more than half the space behind is ahead"),
    (1, 0, True, "anything is newer than the reserved 0"),
    (65535, 0, True, "0 is not 65535 + 1"),
    (0, 1, False, "0 is never newer"),
    (0, 65535, False, "0 is never newer, even after 65535"),
    (0, 0, False, "0 against 0"),
    (32768, 0, True, "0 is reserved, not a position on the circle"),
]

NEXT_BY_HAND = [(1, 2), (0x7FFF, 0x8000), (0xFFFE, 0xFFFF), (0xFFFF, 1)]


def timestamp_vectors() -> dict[str, object]:
    compare = []
    for a, b, newer, why in COMPARE_BY_HAND:
        assert is_newer(a, b) is newer, (a, b, why)
        compare.append({"a": a, "b": b, "a_is_newer": newer, "why": why})
    nexts = []
    for ts, nxt in NEXT_BY_HAND:
        assert next_ts(ts) == nxt
        nexts.append({"timestamp": ts, "next": nxt})
    return {
        "description": "16-bit Lamport timestamps (SPEC.md section 3): is `a` strictly newer than `b` "
                       "by serial-number arithmetic, and the timestamp a local put gives after `timestamp`.",
        "compare": compare,
        "next": nexts,
    }


# --------------------------------------------------------------------------
# receive.json: the receive rules (one case per row of SPEC.md's table), the queue, onconflictlost
# --------------------------------------------------------------------------
# (name, self id, local entry (value, ts, robot) or None, incoming (op, key, value, ts, robot),
#  outcome, entry after, queued messages). Written by hand; key 4 throughout. Conflicts use the
#  default rule (higher robot id wins; the winner keeps the local timestamp) unless a case says
#  otherwise (`Case` below); `before` lists the robot's own calls after its entry was set.
RECEIVE_BY_HAND = [
    ("PUT for an unknown key: store, relay", 1, None, ("PUT", 4, 9, 3, 2),
     "STORED", (9, 3, 2), [("PUT", 4, 9, 3, 2)]),
    ("newer PUT: store, relay", 1, (5, 2, 7), ("PUT", 4, 9, 3, 2),
     "STORED", (9, 3, 2), [("PUT", 4, 9, 3, 2)]),
    ("older PUT: ignore, no answer", 1, (9, 3, 2), ("PUT", 4, 1, 2, 5),
     "STALE", (9, 3, 2), []),
    ("same PUT again: nothing", 1, (9, 3, 2), ("PUT", 4, 9, 3, 2),
     "SAME", (9, 3, 2), []),
    ("same ts and robot, other value: still nothing", 1, (9, 3, 2), ("PUT", 4, 8, 3, 2),
     "SAME", (9, 3, 2), []),
    ("PUT conflict, remote robot higher: remote wins", 1, (9, 3, 2), ("PUT", 4, 1, 3, 5),
     "CONFLICT", (1, 3, 5), [("PUT", 4, 1, 3, 5)]),
    ("PUT conflict, remote robot lower: local wins and is re-sent", 1, (9, 3, 5), ("PUT", 4, 8, 3, 3),
     "CONFLICT", (9, 3, 5), [("PUT", 4, 9, 3, 5)]),
    ("PUT with reserved ts 0: malformed", 1, None, ("PUT", 4, 9, 0, 2),
     "INVALID", None, []),
    ("PUT with reserved ts 0 over a held key: malformed", 1, (9, 3, 2), ("PUT", 4, 1, 0, 2),
     "INVALID", (9, 3, 2), []),
    ("newer PUT across the wrap (1 after 65535)", 1, (9, 65535, 2), ("PUT", 4, 10, 1, 2),
     "STORED", (10, 1, 2), [("PUT", 4, 10, 1, 2)]),
    ("older PUT across the wrap (65535 before 1)", 1, (10, 1, 2), ("PUT", 4, 9, 65535, 2),
     "STALE", (10, 1, 2), []),
    ("GET older than ours: answer with a PUT of ours", 1, (9, 3, 2), ("GET", 4, 0, 1, 8),
     "ANSWERED", (9, 3, 2), [("PUT", 4, 9, 3, 2)]),
    ("empty GET (ts 0) for a key we hold: answer", 1, (9, 1, 1), ("GET", 4, 0, 0, 8),
     "ANSWERED", (9, 1, 1), [("PUT", 4, 9, 1, 1)]),
    ("empty GET for a key we lack: drop, do not relay", 1, None, ("GET", 4, 0, 0, 8),
     "UNKNOWN", None, []),
    ("GET newer than ours: store its view, relay as PUT", 1, (9, 1, 1), ("GET", 4, 77, 5, 8),
     "STORED", (77, 5, 8), [("PUT", 4, 77, 5, 8)]),
    ("GET with data for a key we lack: store, relay as PUT", 1, None, ("GET", 4, 77, 5, 8),
     "STORED", (77, 5, 8), [("PUT", 4, 77, 5, 8)]),
    ("GET with our very view: nothing", 1, (9, 3, 2), ("GET", 4, 9, 3, 2),
     "SAME", (9, 3, 2), []),
    ("GET conflict, remote robot higher: remote wins, sent as PUT", 1, (9, 3, 2), ("GET", 4, 5, 3, 6),
     "CONFLICT", (5, 3, 6), [("PUT", 4, 5, 3, 6)]),
]


class Case:
    """A case beyond the table's rows: the robot's own calls first, a named resolver, onconflictlost."""

    def __init__(self, row: tuple[object, ...], before: tuple[str, ...] = (), resolver: str = "higher_robot",
                 lost: tuple[int, int, int] | None = None) -> None:
        self.row, self.before, self.resolver, self.lost = row, before, resolver, lost


# The outgoing queue (SPEC.md section 5) after the robot's own `get`, and onconflictlost (section 4).
RECEIVE_MORE_BY_HAND = [
    Case(("pending GET of our view, older GET heard: the GET stays (a newer neighbour answers it)", 1,
          (9, 3, 2), ("GET", 4, 0, 1, 8), "ANSWERED", (9, 3, 2), [("GET", 4, 9, 3, 2)]), before=("get",)),
    Case(("pending GET of our view, empty GET heard: the GET stays", 1,
          (1, 1, 1), ("GET", 4, 0, 0, 8), "ANSWERED", (1, 1, 1), [("GET", 4, 1, 1, 1)]), before=("get",)),
    Case(("pending GET, conflict won by the entry it carries: the GET stays", 1,
          (9, 3, 5), ("PUT", 4, 8, 3, 3), "CONFLICT", (9, 3, 5), [("GET", 4, 9, 3, 5)]), before=("get",)),
    Case(("pending GET, conflict lost: the winner replaces it", 1,
          (9, 3, 2), ("PUT", 4, 1, 3, 5), "CONFLICT", (1, 3, 5), [("PUT", 4, 1, 3, 5)]), before=("get",)),
    Case(("our write loses a conflict: onconflictlost", 1,
          (9, 1, 1), ("PUT", 4, 3, 1, 5), "CONFLICT", (3, 1, 5), [("PUT", 4, 3, 1, 5)]), lost=(9, 1, 1)),
    Case(("the echo of our lost write: no second onconflictlost", 1,
          (3, 1, 5), ("PUT", 4, 9, 1, 1), "CONFLICT", (3, 1, 5), [("PUT", 4, 3, 1, 5)])),
    Case(("our write wins a conflict: no onconflictlost", 5,
          (9, 1, 5), ("GET", 4, 3, 1, 1), "CONFLICT", (9, 1, 5), [("PUT", 4, 9, 1, 5)])),
    Case(("merge named for the other writer: keep its entry, our write is lost", 1,
          (100, 1, 1), ("PUT", 4, 200, 1, 2), "CONFLICT", (200, 1, 2), [("PUT", 4, 200, 1, 2)]),
         resolver="sum_merge", lost=(100, 1, 1)),
    Case(("merge named for us: a new write at the next timestamp", 2,
          (200, 1, 2), ("PUT", 4, 100, 1, 1), "CONFLICT", (300, 2, 2), [("PUT", 4, 300, 2, 2)]),
         resolver="sum_merge"),
    Case(("merge named for us at the wrap: next(65535) = 1", 2,
          (200, 65535, 2), ("GET", 4, 100, 65535, 1), "CONFLICT", (300, 1, 2), [("PUT", 4, 300, 1, 2)]),
         resolver="sum_merge"),
    Case(("merge between two other robots: keep the named robot's entry", 9,
          (200, 1, 2), ("PUT", 4, 100, 1, 1), "CONFLICT", (200, 1, 2), [("PUT", 4, 200, 1, 2)]),
         resolver="sum_merge"),
]

RESOLVERS = {
    "higher_robot": "keep the entry with the higher robot id (the default rule)",
    "sum_merge": "a new value: the sum of both values mod 65536, named for the higher robot id",
}
ENTRY = ("value", "timestamp", "robot")


def receive_vectors() -> dict[str, object]:
    cases = []
    for case in [Case(row) for row in RECEIVE_BY_HAND] + RECEIVE_MORE_BY_HAND:
        name, me, local, (op, key, value, ts, robot), outcome, after, queued = case.row
        model = _receive_model(me, local, case.before, case.resolver, (op, value, ts, robot))
        assert model == (outcome, after, [q[:1] + q[2:] for q in queued], case.lost), (name, model)
        cases.append({
            "name": name,
            "self": me,
            "local": None if local is None else dict(zip(ENTRY, local, strict=True)),
            "before": list(case.before),
            "resolver": case.resolver,
            "incoming": pack(op, key, value, ts, robot).hex(),
            "outcome": outcome,
            "entry_after": None if after is None else dict(zip(ENTRY, after, strict=True)),
            "queued": [pack(*q).hex() for q in queued],
            "conflict_lost": None if case.lost is None else dict(zip(ENTRY, case.lost, strict=True)),
        })
    return {
        "description": "Receive rules (SPEC.md sections 4 and 5): a robot `self` holding `local` for the key "
                       "(or nothing), with an empty outgoing queue, makes the calls in `before` (`get`: read the "
                       "key) and then hears `incoming`. It must reach `outcome`, hold `entry_after`, queue "
                       "exactly `queued` (wire hex, in drain order), and call onconflictlost with "
                       "`conflict_lost` (null: not at all). Conflicts use the rule named by `resolver` "
                       "(see `resolvers`).",
        "key": 4,
        "resolvers": RESOLVERS,
        "cases": cases,
    }


def _receive_model(me: int, local: tuple[int, int, int] | None, before: tuple[str, ...], resolver: str,
                   incoming: tuple[str, int, int, int]) -> tuple[object, ...]:
    """SPEC.md's receive table and queue rules in the plainest form: confirms the hand-written columns."""
    op, value, ts, robot = incoming
    queue: list[tuple[str, int, int, int]] = []  # one pending (op, value, ts, robot) at most: a single key

    def push(msg: tuple[str, int, int, int]) -> None:
        if queue:
            pending = queue[0]
            if msg[2] == pending[2] and msg[1::2] == pending[1::2]:
                return  # equal ts, same entry: the pending message stays
            if msg[2] != pending[2] and not is_newer(msg[2], pending[2]):
                return
            queue.clear()
        queue.append(msg)

    for call in before:
        assert call == "get" and local is not None, call
        push(("GET", *local))
    lost = None
    if ts == 0 and op == "PUT":
        outcome = "INVALID"
    elif ts == 0 and local is None:
        outcome = "UNKNOWN"
    elif local is None or is_newer(ts, local[1]):
        outcome, local = "STORED", (value, ts, robot)
        push(("PUT", *local))
    elif ts != local[1]:
        outcome = "ANSWERED" if op == "GET" else "STALE"
        if op == "GET":
            push(("PUT", *local))
    elif robot == local[2]:
        outcome = "SAME"
    else:
        outcome, held, remote = "CONFLICT", local, (value, ts, robot)
        named = max(held[2], robot)
        chosen = (held[0] + value) % 65536 if resolver == "sum_merge" else None
        if chosen is not None and named == me:
            local = (chosen, next_ts(ts), me)  # a merge: a new write of the robot it names
        else:
            local = held if named == held[2] else remote
        push(("PUT", *local))
        if held[2] == me and local[2] != me:
            lost = held
    return outcome, local, queue, lost


# --------------------------------------------------------------------------
# cobs8.json
# --------------------------------------------------------------------------
SAMPLE = pack("PUT", 1, 0x1234, 1, 42)  # 00 01 12 34 00 01 00 2a: three zero bytes to stuff


def crc_catalogue() -> list[dict[str, object]]:
    return [
        {"algorithm": "CRC-16/MCRF4XX", "ascii": "123456789", "hex": CHECK.hex(), "crc": "6f91",
         "source": "reveng CRC catalogue check value"},
        {"algorithm": "CRC-32/ISO-HDLC", "ascii": "123456789", "hex": CHECK.hex(), "crc": "cbf43926",
         "source": "reveng CRC catalogue check value"},
        {"algorithm": "CRC-16/MCRF4XX", "ascii": "", "hex": "", "crc": "ffff", "source": "init, no input"},
        {"algorithm": "CRC-32/ISO-HDLC", "ascii": "", "hex": "", "crc": "00000000",
         "source": "init xor xorout, no input"},
    ]


def stream_case(name: str, stream: bytes, messages: list[bytes], drops: dict[str, int]) -> dict[str, object]:
    return {"name": name, "stream": stream.hex(), "messages": [m.hex() for m in messages], "drops": drops}


def cobs8_vectors() -> dict[str, object]:
    frames = []
    for name, hexbytes, _ in WIRE_BY_HAND:
        raw = bytes.fromhex(hexbytes)
        crc = crc16_mcrf4xx(raw)
        frames.append({"name": name, "message": hexbytes, "fields": fields(raw), "crc": f"{crc:04x}",
                       "frame": serial_frame(raw).hex()})
    good = serial_frame(SAMPLE)
    bad_crc = bytearray(good)
    bad_crc[3] ^= 0x01  # a payload bit flipped on the line, COBS still valid
    swapped_crc = SAMPLE + bytes([crc16_mcrf4xx(SAMPLE) >> 8, crc16_mcrf4xx(SAMPLE) & 0xFF])  # big-endian CRC
    epuck_word = serial_frame(bytes.fromhex("12345678"))
    kilobot_payload = serial_frame(SAMPLE + b"\x01\x56")
    streams = [
        stream_case("one frame", good, [SAMPLE], {}),
        stream_case("idle zeros around a frame are not drops", b"\x00\x00" + good + b"\x00", [SAMPLE], {}),
        stream_case("two frames back to back", good + serial_frame(pack("GET", 0x7FFF, 0, 0, 1)),
                    [SAMPLE, pack("GET", 0x7FFF, 0, 0, 1)], {}),
        stream_case("joined mid-frame: the tail before the first delimiter is garbage", good[5:] + good,
                    [SAMPLE], {"crc": 1}),
        stream_case("a flipped bit fails the CRC", bytes(bad_crc), [], {"crc": 1}),
        stream_case("CRC stored big-endian is wrong", cobs_encode(swapped_crc) + b"\x00", [], {"crc": 1}),
        stream_case("code byte runs past the delimiter", bytes.fromhex("05112200"), [], {"cobs": 1}),
        stream_case("an epuck4 word (4-byte payload) is not a cobs8 frame", epuck_word, [], {"bad_length": 1}),
        stream_case("a kilobot payload (10 bytes) is not a cobs8 frame", kilobot_payload, [], {"bad_length": 1}),
        stream_case("1 decoded byte: too short to hold a CRC fails it", bytes.fromhex("024200"), [], {"crc": 1}),
        stream_case("0 decoded bytes fail the CRC", bytes.fromhex("0100"), [], {"crc": 1}),
        stream_case("CRC-valid empty payload", serial_frame(b""), [], {"bad_length": 1}),
        stream_case("64 non-zero bytes then a delimiter: a (bad) frame, not overlong",
                    b"\x41" * 64 + b"\x00", [], {"cobs": 1}),
        stream_case("65 non-zero bytes: overlong, counted once, resync at the next 0x00",
                    b"\x41" * 65 + b"\x41" * 100 + b"\x00" + good, [SAMPLE], {"overlong": 1}),
    ]
    for case in streams:
        assert _deframe_model(bytes.fromhex(case["stream"]), 8) == (
            [bytes.fromhex(m) for m in case["messages"]], case["drops"]), case["name"]
    return {
        "description": "cobs8 (SPEC.md section 6.1): frame = COBS(message || CRC-16/MCRF4XX little-endian) "
                       "|| 0x00. `frames`: message -> frame. `streams`: bytes fed to a fresh receiver -> "
                       "messages delivered in order, and drops counted by reason.",
        "crc_check_values": crc_catalogue(),
        "max_frame": 64,
        "frames": frames,
        "streams": streams,
    }


def _deframe_model(stream: bytes, want: int) -> tuple[list[bytes], dict[str, int]]:
    """The receive procedure of SPEC.md section 6.0.4, step by step (confirms hand-stated drops)."""
    out: list[bytes] = []
    drops: dict[str, int] = {}
    buf = bytearray()
    discarding = False

    def drop(reason: str) -> None:
        drops[reason] = drops.get(reason, 0) + 1

    for byte in stream:
        if byte != 0:
            if discarding:
                continue
            if len(buf) == 64:
                drop("overlong")
                discarding = True
                buf.clear()
                continue
            buf.append(byte)
            continue
        if discarding:
            discarding = False
            continue
        if not buf:
            continue
        decoded = cobs_decode(bytes(buf))
        buf.clear()
        if decoded is None:
            drop("cobs")
        elif len(decoded) < 2 or crc16_mcrf4xx(decoded) != 0:
            drop("crc")
        elif len(decoded) - 2 != want:
            drop("bad_length")
        else:
            out.append(decoded[:-2])
    return out, drops


# --------------------------------------------------------------------------
# epuck4.json
# --------------------------------------------------------------------------


def epuck_words(msg: bytes) -> list[int]:
    c = crc32_iso_hdlc(msg)
    group = c >> 28
    p = (int.from_bytes(msg, "big") << 14) | ((c >> 14) & 0x3FFF)
    return [(i << 30) | (group << 26) | ((p >> (52 - 26 * i)) & 0x3FFFFFF) for i in range(3)]


def _hex32(word: int) -> str:
    return f"{word:08x}"


def _same_group_pair() -> tuple[bytes, bytes]:
    """Two different messages whose CRC-32 share the top nibble (for collision cases)."""
    a = pack("PUT", 1, 1, 1, 1)
    group = crc32_iso_hdlc(a) >> 28
    for key in range(2, 1000):  # key (word 0) and timestamp (word 1) differ from a
        b = pack("PUT", key, 1, key, 1)
        if crc32_iso_hdlc(b) >> 28 == group:
            return a, b
    raise AssertionError("no pair found")


def epuck4_vectors() -> dict[str, object]:
    messages = []
    for name, hexbytes, _ in WIRE_BY_HAND:
        raw = bytes.fromhex(hexbytes)
        c = crc32_iso_hdlc(raw)
        words = epuck_words(raw)
        messages.append({"name": name, "message": hexbytes, "crc32": f"{c:08x}",
                         "words": [_hex32(w) for w in words],
                         "uart": [serial_frame(w.to_bytes(4, "big")).hex() for w in words]})
    a, b = _same_group_pair()
    wa, wb = epuck_words(a), epuck_words(b)
    other = pack("GET", 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF)
    wo = epuck_words(other)
    bad_check = list(wa)
    bad_check[2] ^= 0x1  # last bit of the 14-bit check (P bit 0)
    bad_body = list(wa)
    bad_body[1] ^= 1 << 20  # a message bit inside word 1
    reserved = (3 << 30) | (wa[0] & 0x3FFFFFFF)

    def w(word: int) -> dict[str, str]:
        return {"word": _hex32(word)}

    tick = {"tick": 1}
    # (name, events, messages delivered, drops): outcomes decided by hand from SPEC.md section 6.2.
    cases = [
        ("in order", [w(wa[0]), w(wa[1]), w(wa[2])], [a], {}),
        ("any order", [w(wa[2]), w(wa[0]), w(wa[1])], [a], {}),
        ("identical duplicates are counted and ignored", [w(wa[0]), w(wa[0]), w(wa[1]), w(wa[1]), w(wa[2])],
         [a], {"duplicate": 2}),
        ("a retransmission after delivery assembles again", [w(x) for x in wa + wa], [a, a], {}),
        ("two messages in different groups interleave", [w(wa[0]), w(wo[0]), w(wo[1]), w(wa[1]), w(wa[2]),
                                                         w(wo[2])], [a, other], {}),
        ("index 3 is reserved", [w(reserved)], [], {"bad_index": 1}),
        ("a flipped check bit fails the check", [w(x) for x in bad_check], [], {"check": 1}),
        ("a flipped message bit fails the check", [w(x) for x in bad_body], [], {"check": 1}),
        ("a clash evicts the older fragment; the newer message completes",
         [w(wa[0]), w(wb[0]), w(wb[1]), w(wb[2])], [b], {"collision": 1}),
        ("a clash evicts everything older than the clashing fragment",
         [w(wa[0]), w(wa[1]), w(wb[1]), w(wb[0]), w(wb[2])], [b], {"collision": 1}),
        ("a clash keeps fragments newer than the clashing one",
         [w(wa[1]), w(wb[0]), w(wb[1]), w(wb[2])], [b], {"collision": 1}),
        ("a failed check evicts only the oldest fragment: the leftover goes, the new message completes",
         [w(wa[0]), w(wb[1]), w(wb[2]), w(wb[0])], [b], {"check": 1}),
        ("a mixed-up set fails the check", [w(wa[0]), w(wb[1]), w(wa[2])], [], {"check": 1}),
        ("a fragment survives expiry_ticks ticks", [w(wa[0]), tick, tick, tick, w(wa[1]), w(wa[2])], [a], {}),
        ("a fragment is stale after expiry_ticks + 1 ticks",
         [w(wa[0]), tick, tick, tick, tick, w(wa[1]), w(wa[2])], [], {"stale": 1}),
        ("fragments age one by one; one stale count per partial per tick",
         [w(wa[0]), tick, tick, w(wa[1]), tick, tick, w(wa[2])], [], {"stale": 1}),
        ("two fragments expiring on the same tick count once",
         [w(wa[0]), w(wa[1]), tick, tick, tick, tick, w(wa[2])], [], {"stale": 1}),
        ("after the stale fragment goes, the rest of a retransmission completes",
         [w(wa[0]), tick, tick, w(wa[1]), tick, tick, w(wa[2]), w(wa[0])], [a], {"stale": 1}),
    ]
    reassembly = []
    for name, events, delivered, drops in cases:
        assert _reassemble_model(events, 3) == (delivered, drops), name
        reassembly.append({"name": name, "events": events, "messages": [m.hex() for m in delivered],
                           "drops": drops})
    return {
        "description": "epuck4 (SPEC.md section 6.2): one message in three 32-bit radio words "
                       "`index:2 | group:4 | chunk:26`; on the UART each word is a serial frame with a "
                       "4-byte big-endian payload. `reassembly`: events fed to a fresh reassembler with "
                       "expiry_ticks = 3 ({\"word\"} or {\"tick\"}), messages delivered in order, drops by "
                       "reason; partials still incomplete at the end are not counted.",
        "expiry_ticks": 3,
        "messages": messages,
        "reassembly": reassembly,
    }


def _reassemble_model(events: list[dict[str, object]], expiry: int) -> tuple[list[bytes], dict[str, int]]:
    """SPEC.md section 6.2's reassembly procedure, step by step (confirms the hand-stated outcomes)."""
    partials: dict[int, dict[int, tuple[int, int, int]]] = {}  # group -> index -> (chunk, arrival, tick)
    out: list[bytes] = []
    drops: dict[str, int] = {}
    now = arrivals = 0

    def drop(reason: str) -> None:
        drops[reason] = drops.get(reason, 0) + 1

    for event in events:
        if "tick" in event:
            now += 1
            for group, held in list(partials.items()):
                old = [i for i, (_, _, born) in held.items() if now - born > expiry]
                if old:
                    drop("stale")
                    for i in old:
                        del held[i]
                if not held:
                    del partials[group]
            continue
        word = int(str(event["word"]), 16)
        index, group, chunk = word >> 30, (word >> 26) & 0xF, word & 0x3FFFFFF
        if index == 3:
            drop("bad_index")
            continue
        held = partials.setdefault(group, {})
        if index in held:
            if held[index][0] == chunk:
                drop("duplicate")
                continue
            drop("collision")
            cut = held[index][1]
            for i in [i for i, (_, arrival, _) in held.items() if arrival <= cut]:
                del held[i]
        arrivals += 1
        held[index] = (chunk, arrivals, now)
        if len(held) < 3:
            continue
        p = (held[0][0] << 52) | (held[1][0] << 26) | held[2][0]
        msg = (p >> 14).to_bytes(8, "big")
        c = crc32_iso_hdlc(msg)
        if c >> 28 == group and (c >> 14) & 0x3FFF == p & 0x3FFF:
            out.append(msg)
            del partials[group]
        else:
            drop("check")
            del held[min(held, key=lambda i: held[i][1])]
    return out, drops


# --------------------------------------------------------------------------
# kilobot.json and ohc.json
# --------------------------------------------------------------------------
KILO_VERSION = 0x01
KILO_TYPE = 0x56


def kilobot_message_t(msg: bytes, msg_type: int = KILO_TYPE) -> bytes:
    """kilolib message_t: data[9] (our message + version), type, crc (little-endian)."""
    head = msg + bytes([KILO_VERSION, msg_type])
    acc = 0xFFFF
    for byte in head:
        acc = crc16_avr_ccitt_update(acc, byte)
    assert acc == crc16_mcrf4xx(head)
    return head + bytes([acc & 0xFF, acc >> 8])


def kilobot_vectors() -> dict[str, object]:
    messages = []
    for name, hexbytes, _ in WIRE_BY_HAND:
        raw = bytes.fromhex(hexbytes)
        message_t = kilobot_message_t(raw)
        messages.append({"name": name, "message": hexbytes, "type": KILO_TYPE, "message_t": message_t.hex(),
                         "kilobot_crc": message_t[10:].hex(), "uart": serial_frame(message_t[:10]).hex()})
    custom_type = kilobot_message_t(SAMPLE, 0x21)
    wrong_version = SAMPLE + bytes([0x02, KILO_TYPE])
    wrong_type = SAMPLE + bytes([KILO_VERSION, 0x57])
    system_type = SAMPLE + bytes([KILO_VERSION, 0x80])
    streams = [
        stream_case("one message", serial_frame(SAMPLE + b"\x01\x56"), [SAMPLE], {}),
        stream_case("format version 2 is not ours", serial_frame(wrong_version), [], {"bad_version": 1}),
        stream_case("another message type is another program's traffic", serial_frame(wrong_type), [],
                    {"foreign_type": 1}),
        stream_case("a system type (>= 0x80) is never ours", serial_frame(system_type), [], {"foreign_type": 1}),
        stream_case("the type is checked before the version", serial_frame(SAMPLE + bytes([0x02, 0x57])), [],
                    {"foreign_type": 1}),
        stream_case("a cobs8 frame is not a kilobot frame", serial_frame(SAMPLE), [], {"bad_length": 1}),
    ]
    for case in streams:
        payloads, drops = _deframe_model(bytes.fromhex(str(case["stream"])), 10)
        delivered = []
        for payload in payloads:
            reason = "foreign_type" if payload[9] != KILO_TYPE else "bad_version" if payload[8] != 1 else None
            if reason:
                drops[reason] = drops.get(reason, 0) + 1
            else:
                delivered.append(payload[:8])
        assert (delivered, drops) == ([bytes.fromhex(m) for m in case["messages"]], case["drops"]), case["name"]
    return {
        "description": "kilobot (SPEC.md section 6.3): kilolib message_t {data[9], type, crc}; data[0..7] is "
                       "the message, data[8] = 0x01 (format version), type = 0x56 unless configured; crc is "
                       "CRC-16/MCRF4XX over the first 10 bytes, little-endian (kilolib's message_crc). On the "
                       "UART the frame payload is those 10 bytes, so the frame CRC is the Kilobot CRC. "
                       "`streams`: UART bytes to a receiver configured with type 0x56.",
        "version": KILO_VERSION,
        "default_type": KILO_TYPE,
        "crc_check_values": crc_catalogue()[:1],
        "messages": messages,
        "custom_type": {"message": SAMPLE.hex(), "type": 0x21, "message_t": custom_type.hex()},
        "streams": streams,
    }


OHC_TYPES = {"STOP": 0, "LEDTOGGLE": 1, "FORWARDMSG": 2, "FORWARDRAWMSG": 3, "BOOTPAGE": 4, "GPSFRAME": 5,
             "FORWARDMSGSINGLE": 6}


def ohc_packet(packet_type: int, payload: bytes) -> bytes:
    body = bytearray(132)
    body[0] = 0x55
    body[1] = packet_type
    body[2 : 2 + len(payload)] = payload
    x = 0
    for byte in body[:131]:
        x ^= byte
    body[131] = x
    return bytes(body)


def ohc_vectors() -> dict[str, object]:
    packets = []
    for name, hexbytes, _ in WIRE_BY_HAND[:6]:
        raw = bytes.fromhex(hexbytes)
        for kind in ("FORWARDMSGSINGLE", "FORWARDMSG"):
            pkt = ohc_packet(OHC_TYPES[kind], raw + bytes([KILO_VERSION, KILO_TYPE]))
            x = 0
            for byte in pkt:
                x ^= byte
            assert x == 0  # the OHC accepts a packet when the XOR of all 132 bytes is 0
            packets.append({"name": f"{name}, {kind}", "message": hexbytes, "packet_type": kind,
                            "type": KILO_TYPE, "packet": pkt.hex()})
    return {
        "description": "kilobot-ohc (SPEC.md section 6.4): PC -> overhead controller, 38400 8N1, 132-byte "
                       "packets: 0x55, packet type, data[9] (message + version 0x01), message type, zeros, "
                       "XOR of bytes 0..130. Packet types from kilolib ohc.h / kilogui packet.h. The OHC adds "
                       "the Kilobot CRC itself. The link is one-way (the OHC has no IR receiver).",
        "packet_types": OHC_TYPES,
        "packets": packets,
    }


# --------------------------------------------------------------------------
# xbee.json (SPEC.md section 6.9): Digi's API frames, from Digi's published frame format
# --------------------------------------------------------------------------
XBEE_SPECIAL = (0x7E, 0x7D, 0x11, 0x13)  # what API mode 2 escapes
XBEE_MAX_FRAME_DATA = 512
XBEE_SOURCE = 0x0013A20040A1B2C3


def xbee_checksum(frame_data: bytes) -> int:
    total = 0
    for byte in frame_data:
        total = (total + byte) & 0xFF
    return 0xFF - total


def xbee_frame(frame_data: bytes, escaped: bool) -> bytes:
    body = bytes([len(frame_data) >> 8, len(frame_data) & 0xFF]) + frame_data + bytes([xbee_checksum(frame_data)])
    if escaped:
        stuffed = bytearray()
        for byte in body:
            stuffed += bytes([0x7D, byte ^ 0x20]) if byte in XBEE_SPECIAL else bytes([byte])
        body = bytes(stuffed)
    return b"\x7e" + body


# Digi's own worked examples (its XBee user guides): an AT Command NJ, a Transmit Request carrying "TxData0A",
# and the frame its API mode 2 section escapes.
assert xbee_frame(bytes.fromhex("08014e4a"), False) == bytes.fromhex("7e000408014e4a5e")
assert xbee_frame(bytes.fromhex("10010013a200400a0127fffe0000") + b"TxData0A", False) == bytes.fromhex(
    "7e0016100100" "13a200400a0127fffe0000" "5478446174613041" "13")
assert xbee_frame(bytes.fromhex("2311"), True) == bytes.fromhex("7e0002237d31cb")


def xbee_transmit(frame_id: int, rf: bytes, dest: int = 0xFFFF) -> bytes:
    return bytes([0x10, frame_id]) + dest.to_bytes(8, "big") + bytes.fromhex("fffe0000") + rf


def xbee_receive(source: int, rf: bytes) -> bytes:
    return bytes([0x90]) + source.to_bytes(8, "big") + bytes.fromhex("fffe02") + rf


def _xbee_stream(name: str, mode: int, stream: bytes, frames: list[tuple[int, list[bytes]]],
                 drops: dict[str, int]) -> dict[str, object]:
    return {"name": name, "api": mode, "stream": stream.hex(),
            "frames": [{"sender": f"{sender:016x}", "messages": [m.hex() for m in msgs]} for sender, msgs in frames],
            "drops": drops}


def xbee_vectors() -> dict[str, object]:
    a, b, c = (bytes.fromhex(h) for _, h, _ in WIRE_BY_HAND[4:7])
    escapes = pack("PUT", 0x117E, 0x7D13, 0x137E, 0x7D11)  # every byte mode 2 escapes, in every field
    transmit = []
    for name, rf in (("one message", a), ("three messages in one frame", a + b + c),
                     ("bytes mode 2 escapes", escapes)):
        data = xbee_transmit(1, rf)
        transmit.append({"name": name, "frame_id": 1, "dest": "000000000000ffff", "messages": [
            rf[i:i + 8].hex() for i in range(0, len(rf), 8)], "frame_data": data.hex(),
            "api1": xbee_frame(data, False).hex(), "api2": xbee_frame(data, True).hex()})
    rx = xbee_receive(XBEE_SOURCE, a + escapes)
    other = xbee_receive(0x0013A20040000002, b)
    streams = []
    for mode in (1, 2):
        esc = mode == 2
        good, good2 = xbee_frame(rx, esc), xbee_frame(other, esc)
        # Damage is made of `other` (no 0x7E in it: in mode 1 a 0x7E in a bad frame's data may start false frames).
        bad_sum = good2[:-1] + bytes([good2[-1] ^ 0x01])
        assert b"\x7e" not in good2[1:] and bad_sum[-1] not in XBEE_SPECIAL
        streams += [
            _xbee_stream("one receive packet", mode, good, [(XBEE_SOURCE, [a, escapes])], {}),
            _xbee_stream("two senders back to back", mode, good + good2,
                         [(XBEE_SOURCE, [a, escapes]), (0x0013A20040000002, [b])], {}),
            _xbee_stream("noise before a frame: one drop per run", mode, b"noise!" + good,
                         [(XBEE_SOURCE, [a, escapes])], {"noise": 1}),
            _xbee_stream("a wrong checksum, then the next frame", mode, bad_sum + good,
                         [(XBEE_SOURCE, [a, escapes])], {"checksum": 1}),
            _xbee_stream("a length of 0", mode, bytes.fromhex("7e0000ff") + good, [(XBEE_SOURCE, [a, escapes])],
                         {"frame_length": 1}),
            _xbee_stream("a length above 512", mode, bytes.fromhex("7e020190") + good,
                         [(XBEE_SOURCE, [a, escapes])], {"frame_length": 1}),
            _xbee_stream("a frame type a link does not use (0x95)", mode,
                         xbee_frame(bytes.fromhex("95") + bytes(12), esc) + good,
                         [(XBEE_SOURCE, [a, escapes])], {"unknown_type": 1}),
            _xbee_stream("RF data that is not whole messages", mode,
                         xbee_frame(xbee_receive(XBEE_SOURCE, a[:7]), esc), [], {"bad_length": 1}),
            _xbee_stream("a receive packet too short for its header", mode, xbee_frame(bytes(range(0x90, 0x95)), esc),
                         [], {"bad_length": 1}),
            _xbee_stream("the module's own reports (TX status, modem status, AT response) are no drops", mode,
                         xbee_frame(bytes.fromhex("8b01fffe000000"), esc) + xbee_frame(bytes.fromhex("8a00"), esc)
                         + xbee_frame(bytes.fromhex("8801" "4e50" "00" "0100"), esc) + good,
                         [(XBEE_SOURCE, [a, escapes])], {}),
            _xbee_stream("the stream ends inside a frame (the line went quiet)", mode, good + good2[:9],
                         [(XBEE_SOURCE, [a, escapes])], {"truncated": 1}),
            _xbee_stream("bytes after a bad frame are its remains, not noise", mode, bad_sum + b"junk" + good,
                         [(XBEE_SOURCE, [a, escapes])], {"checksum": 1}),
        ]
    good2 = xbee_frame(rx, True)
    streams += [
        _xbee_stream("mode 2: a frame cut short by the next 0x7E", 2, good2[:12] + good2,
                     [(XBEE_SOURCE, [a, escapes])], {"truncated": 1}),
        _xbee_stream("mode 2: 0x7D before a byte it never escapes", 2, bytes.fromhex("7e00057d41") + good2,
                     [(XBEE_SOURCE, [a, escapes])], {"escape": 1}),
        _xbee_stream("mode 2: 0x11 left unescaped", 2, bytes.fromhex("7e0002231174") + good2,
                     [(XBEE_SOURCE, [a, escapes])], {"escape": 1}),
        _xbee_stream("mode 2: 0x7D before the next 0x7E is a bad escape, not a cut", 2,
                     bytes.fromhex("7e00057d") + good2, [(XBEE_SOURCE, [a, escapes])], {"escape": 1}),
        _xbee_stream("mode 2: 0x13 left raw in a frame cut short is a bad escape", 2,
                     bytes.fromhex("7e000590130102") + good2, [(XBEE_SOURCE, [a, escapes])], {"escape": 1}),
        _xbee_stream("mode 1: 0x7E, 0x7D, 0x11, 0x13 inside a frame are data", 1, xbee_frame(rx, False),
                     [(XBEE_SOURCE, [a, escapes])], {}),
        _xbee_stream("mode 1: a corrupted length claims 300 bytes; the frames inside them are still read", 1,
                     bytes.fromhex("7e012c90") + xbee_frame(rx, False), [(XBEE_SOURCE, [a, escapes])],
                     {"truncated": 1}),
    ]
    for case in streams:
        assert _xbee_receive_model(bytes.fromhex(str(case["stream"])), case["api"] == 2) == (
            case["frames"], case["drops"]), case["name"]
    return {
        "description": "XBee API frames (SPEC.md section 6.9): 0x7E | length (u16 BE) | frame data | checksum "
                       "0xFF - (sum of frame data & 0xFF); API mode 2 escapes 0x7E 0x7D 0x11 0x13 after the 0x7E "
                       "as 0x7D, byte ^ 0x20. `checksums`: Digi's worked examples. `transmit`: what a sender "
                       "writes to its module for these messages (a Transmit Request 0x10, frame id 1, broadcast), "
                       "in both modes. `messages_per_frame`: NP (the module's maximum RF payload) -> messages a "
                       "frame carries (at most 62). `streams`: what a module hands its host -> each Receive "
                       "Packet's sender (64-bit source) and messages, in order, and drops by reason.",
        "checksums": [
            {"source": "Digi: AT Command NJ", "frame_data": "08014e4a", "api1": "7e000408014e4a5e"},
            {"source": "Digi: Transmit Request 'TxData0A'", "frame_data": "10010013a200400a0127fffe0000"
             + b"TxData0A".hex(), "api1": xbee_frame(bytes.fromhex("10010013a200400a0127fffe0000") + b"TxData0A",
                                                      False).hex()},
            {"source": "Digi: API mode 2 example", "frame_data": "2311", "api2": "7e0002237d31cb"},
        ],
        "max_frame_data": XBEE_MAX_FRAME_DATA,
        "transmit": transmit,
        # at most 62: a frame's data stay within max_frame_data (14 bytes of header, then the messages)
        "messages_per_frame": [{"np": np, "messages": max(1, min(np // 8, (XBEE_MAX_FRAME_DATA - 14) // 8))}
                               for np in (5, 8, 64, 73, 84, 100, 256, 1000)],
        "streams": streams,
    }


def _xbee_receive_model(stream: bytes, escaped: bool) -> tuple[list[dict[str, object]], dict[str, int]]:
    """SPEC.md 6.9's receive procedure, step by step (confirms the hand-stated outcomes)."""
    frames: list[dict[str, object]] = []
    drops: dict[str, int] = {}
    pos, counted = 0, False

    def drop(reason: str) -> None:
        drops[reason] = drops.get(reason, 0) + 1

    while pos < len(stream):
        start = stream.find(b"\x7e", pos)
        if (len(stream) if start < 0 else start) > pos and not counted:
            drop("noise")
            counted = True
        if start < 0:
            break
        body, i, verdict = bytearray(), start + 1, None
        while verdict is None:
            want = 2 if len(body) < 2 else (body[0] << 8 | body[1]) + 3
            if len(body) == 2 and not 0 < want - 3 <= XBEE_MAX_FRAME_DATA:
                verdict = "frame_length"
            elif len(body) >= want:
                verdict = "ok" if xbee_checksum(bytes(body[2:-1])) == body[-1] else "checksum"
            elif i >= len(stream) or (escaped and stream[i] == 0x7E):
                verdict = "truncated"
            elif escaped and stream[i] == 0x7D:
                if i + 1 >= len(stream):
                    verdict = "truncated"
                elif stream[i + 1] ^ 0x20 not in XBEE_SPECIAL:
                    verdict = "escape"
                else:
                    body.append(stream[i + 1] ^ 0x20)
                    i += 2
            elif escaped and stream[i] in (0x11, 0x13):
                verdict = "escape"
            else:
                body.append(stream[i])
                i += 1
        if verdict != "ok":
            drop(str(verdict))
            counted, pos = True, start + 1
            continue
        counted, pos = False, i
        data = bytes(body[2:-1])
        if data[0] in (0x88, 0x8A, 0x8B):
            continue
        if data[0] != 0x90:
            drop("unknown_type")
        elif len(data) < 12 or len(data) == 12 or (len(data) - 12) % 8:
            drop("bad_length")
        else:
            rf = data[12:]
            frames.append({"sender": data[1:9].hex(), "messages": [rf[k:k + 8].hex() for k in range(0, len(rf), 8)]})
    return frames, drops


# --------------------------------------------------------------------------
# can_frames.json (the ID scheme is SPEC.md section 6.5; can.json from the CAN framing is the
# reference for its drops, this file feeds the DBC and dissector tests)
# --------------------------------------------------------------------------


def can_vectors() -> dict[str, object]:
    frames = []

    def add(name: str, can_id: int, extended: bool, msg: bytes, sender: int, stigmergy: int) -> None:
        f = fields(msg)
        op = 0 if f["op"] == "PUT" else 1
        frames.append({"name": name, "id": f"{can_id:x}", "extended": extended, "data": msg.hex(),
                       "id_op": OPS[op], "sender": sender, "stigmergy": stigmergy, "fields": f})

    for name, hexbytes, (op, *_rest) in WIRE_BY_HAND:
        raw = bytes.fromhex(hexbytes)
        o = OPS.index(op)
        add(f"11-bit base 0x600, sender 0x2a: {name}", 0x600 | o << 8 | 0x2A, False, raw, 0x2A, 0)
        add(f"29-bit base 0x18000000, stigmergy 3, sender 0x1234: {name}",
            0x18000000 | 3 << 17 | o << 16 | 0x1234, True, raw, 0x1234, 3)
    put, get = pack("PUT", 9, 1, 1, 1), pack("GET", 9, 1, 1, 1)
    add("11-bit sender 0", 0x600, False, put, 0, 0)
    add("11-bit sender 0xff", 0x7FF, False, get, 0xFF, 0)
    add("29-bit sender 0, stigmergy 0", 0x18000000, True, put, 0, 0)
    add("29-bit sender 0xffff, stigmergy 255", 0x18000000 | 255 << 17 | 1 << 16 | 0xFFFF, True, get, 0xFFFF, 255)
    add("29-bit sender 0x0500 (above the 11-bit range)", 0x18000500, True, put, 0x500, 0)
    for f in frames:
        can_id = int(str(f["id"]), 16)
        if f["extended"]:
            assert can_id >> 25 == 0xC and (can_id >> 16) & 1 == OPS.index(str(f["id_op"]))
        else:
            assert can_id >> 9 == 3 and (can_id >> 8) & 1 == OPS.index(str(f["id_op"]))
    return {
        "description": "CAN frames in the default bases (SPEC.md section 6.5): 11-bit id = 0x600 | op << 8 | "
                       "sender; 29-bit id = 0x18000000 | stigmergy << 17 | op << 16 | sender. Classic CAN, "
                       "DLC 8, data = one message. Used by the DBC and dissector tests.",
        "frames": frames,
    }


# --------------------------------------------------------------------------
# auth.json (SPEC.md section 10): BLAKE2s written out from RFC 7693 (not hashlib's), checked against the
# RFC's own example and the BLAKE2 team's keyed test vector, and against hashlib (a second implementation)
# --------------------------------------------------------------------------

_B2S_IV = (0x6A09E667, 0xBB67AE85, 0x3C6EF372, 0xA54FF53A, 0x510E527F, 0x9B05688C, 0x1F83D9AB, 0x5BE0CD19)
_B2S_SIGMA = (
    (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15), (14, 10, 4, 8, 9, 15, 13, 6, 1, 12, 0, 2, 11, 7, 5, 3),
    (11, 8, 12, 0, 5, 2, 15, 13, 10, 14, 3, 6, 7, 1, 9, 4), (7, 9, 3, 1, 13, 12, 11, 14, 2, 6, 5, 10, 4, 0, 15, 8),
    (9, 0, 5, 7, 2, 4, 10, 15, 14, 1, 11, 12, 6, 8, 3, 13), (2, 12, 6, 10, 0, 11, 8, 3, 4, 13, 7, 5, 15, 14, 1, 9),
    (12, 5, 1, 15, 14, 13, 4, 10, 0, 7, 6, 3, 9, 2, 8, 11), (13, 11, 7, 14, 12, 1, 3, 9, 5, 0, 15, 4, 8, 6, 2, 10),
    (6, 15, 14, 9, 11, 3, 0, 8, 12, 2, 13, 7, 1, 4, 10, 5), (10, 2, 8, 4, 7, 6, 1, 5, 15, 11, 9, 14, 3, 12, 13, 0),
)


def _rotr32(x: int, n: int) -> int:
    return ((x >> n) | (x << (32 - n))) & 0xFFFFFFFF


def _b2s_compress(h: list[int], block: bytes, count: int, last: bool) -> None:
    m = [int.from_bytes(block[4 * i : 4 * i + 4], "little") for i in range(16)]
    v = h + list(_B2S_IV)
    v[12] ^= count & 0xFFFFFFFF
    v[13] ^= count >> 32
    if last:
        v[14] ^= 0xFFFFFFFF
    for s in _B2S_SIGMA:
        for i, (a, b, c, d) in enumerate(((0, 4, 8, 12), (1, 5, 9, 13), (2, 6, 10, 14), (3, 7, 11, 15),
                                          (0, 5, 10, 15), (1, 6, 11, 12), (2, 7, 8, 13), (3, 4, 9, 14))):
            x, y = m[s[2 * i]], m[s[2 * i + 1]]
            v[a] = (v[a] + v[b] + x) & 0xFFFFFFFF
            v[d] = _rotr32(v[d] ^ v[a], 16)
            v[c] = (v[c] + v[d]) & 0xFFFFFFFF
            v[b] = _rotr32(v[b] ^ v[c], 12)
            v[a] = (v[a] + v[b] + y) & 0xFFFFFFFF
            v[d] = _rotr32(v[d] ^ v[a], 8)
            v[c] = (v[c] + v[d]) & 0xFFFFFFFF
            v[b] = _rotr32(v[b] ^ v[c], 7)
    for i in range(8):
        h[i] ^= v[i] ^ v[i + 8]


def blake2s(data: bytes, key: bytes = b"", outlen: int = 32) -> bytes:
    """BLAKE2s as RFC 7693 section 3.3 writes it (keyed: the key padded to one block comes first)."""
    h = list(_B2S_IV)
    h[0] ^= 0x01010000 ^ (len(key) << 8) ^ outlen
    stream = (key + bytes(64 - len(key)) if key else b"") + data
    blocks = [stream[i : i + 64] for i in range(0, len(stream), 64)] or [b""]
    for n, block in enumerate(blocks):
        last = n == len(blocks) - 1
        count = len(stream) if last else 64 * (n + 1)
        _b2s_compress(h, block + bytes(64 - len(block)), count, last)
    return b"".join(word.to_bytes(4, "little") for word in h)[:outlen]


# RFC 7693 Appendix B, and the first keyed entry of the BLAKE2 reference's blake2s-kat.txt (key 00..1f, no data).
assert blake2s(b"abc").hex() == "508c5e8c327c14e2e1a72ba34eeb452f37458b209ed63a294d999b4c86675982"
assert blake2s(b"", bytes(range(32))).hex() == "48a8997da407876b3d79c0d92325ad3b89cbb754d86ab71aee047ad345fd2c49"

AUTH_MASTER = bytes(range(0xA0, 0xC0))  # the vectors' swarm master secret (a real one is 32 random bytes)
AUTH_MARKER = 0xA1  # first byte of a tagged batch (XBee RF data, zenoh payload)
MAVLINK_TAGGED_TYPE = 0xB572  # TUNNEL payload_type of tagged records (the untagged one is 0xB571)


def robot_key(master: bytes, robot: int) -> bytes:
    return blake2s(b"vstig robot key" + robot.to_bytes(2, "big"), master, 32)


def mac_input(stigmergy: int, msg: bytes, epoch: int) -> bytes:
    entry = bytes([msg[0] & 0x7F]) + msg[1:]  # the op bit is not covered: a GET shows the PUT's entry
    return epoch.to_bytes(4, "big") + stigmergy.to_bytes(2, "big") + entry


def entry_tag(key: bytes, stigmergy: int, msg: bytes, epoch: int) -> bytes:
    return blake2s(mac_input(stigmergy, msg, epoch), key, 8)


def _hashlib_agrees(data: bytes, key: bytes, outlen: int) -> bool:
    import hashlib

    return hashlib.blake2s(data, key=key, digest_size=outlen).digest() == blake2s(data, key, outlen)


def _tagged_newer(a: tuple[int, int], b: tuple[int, int]) -> bool:
    """(epoch, timestamp) against (epoch, timestamp), SPEC.md 10.4: plain order, epoch first."""
    return a > b


def auth_vectors() -> dict[str, object]:
    robots = [0, 1, 7, 9, 42, 0xFFFF]
    keys = {r: robot_key(AUTH_MASTER, r) for r in robots}
    for r in robots:
        assert _hashlib_agrees(b"vstig robot key" + r.to_bytes(2, "big"), AUTH_MASTER, 32)
    put = pack("PUT", 0x0102, 0xABCD, 0x8000, 42)
    get = pack("GET", 0x0102, 0xABCD, 0x8000, 42)
    tags = []

    def tag_case(name: str, stigmergy: int, msg: bytes, epoch: int, signer: int) -> bytes:
        data = mac_input(stigmergy, msg, epoch)
        tag = entry_tag(keys[signer], stigmergy, msg, epoch)
        assert _hashlib_agrees(data, keys[signer], 8)
        tags.append({"name": name, "stigmergy": stigmergy, "message": msg.hex(), "fields": fields(msg),
                     "epoch": epoch, "signer": signer, "mac_input": data.hex(), "tag": tag.hex(),
                     "record": (msg + epoch.to_bytes(4, "big") + tag).hex()})
        return tag

    one = tag_case("PUT written by robot 42", 0, put, 0, 42)
    assert tag_case("GET showing the same entry: the same tag", 0, get, 0, 42) == one
    tag_case("stigmergy 3", 3, put, 0, 42)
    tag_case("epoch 1", 0, put, 1, 42)
    tag_case("epoch 0xFFFFFFFF, every field at its maximum", 0xFFFF, pack("PUT", 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF),
             0xFFFFFFFF, 0xFFFF)
    tag_case("robot 0, smallest entry", 0, pack("PUT", 0, 0, 1, 0), 0, 0)

    good = put + (0).to_bytes(4, "big") + one
    verify = [{"name": "as written", "record": good.hex(), "stigmergy": 0, "verdict": "good"}]

    def forged(name: str, record: bytes, stigmergy: int = 0) -> None:
        msg, epoch, tag = record[:8], int.from_bytes(record[8:12], "big"), record[12:]
        writer = int.from_bytes(msg[6:8], "big")
        ok = writer in keys and entry_tag(keys[writer], stigmergy, msg, epoch) == tag
        assert not ok, name
        verify.append({"name": name, "record": record.hex(), "stigmergy": stigmergy, "verdict": "bad_tag"})

    forged("value changed on the way", pack("PUT", 0x0102, 0xABCE, 0x8000, 42) + good[8:])
    forged("timestamp changed", pack("PUT", 0x0102, 0xABCD, 0x8001, 42) + good[8:])
    forged("key changed", pack("PUT", 0x0103, 0xABCD, 0x8000, 42) + good[8:])
    forged("epoch changed", good[:8] + (1).to_bytes(4, "big") + one)
    forged("another stigmergy", good, stigmergy=1)
    forged("one tag bit flipped", good[:12] + bytes([one[0] ^ 1]) + one[1:])
    claim9 = pack("PUT", 0x0102, 0xABCD, 0x8000, 9)
    forged("robot 7 writes as robot 9 with its own key", claim9 + bytes(4) + entry_tag(keys[7], 0, claim9, 0))
    forged("an outsider's all-zero tag", good[:12] + bytes(8))

    order = []
    for a, b, why in (((0, 2), (0, 1), "same epoch, later timestamp"),
                      ((1, 1), (0, 65535), "across the wrap: the epoch moved on"),
                      ((0, 100), (0, 40000), "a replay within an epoch: 16-bit serial order says newer, it is not"),
                      ((0, 65535), (1, 1), "a write from before the wrap replayed after it"),
                      ((0, 40000), (1, 3), "RFC 1982 half-way trap: an older epoch always loses"),
                      ((2, 1), (1, 60000), "a robot that missed a whole wrap catches up")):
        order.append({"a": list(a), "b": list(b), "a_is_newer": _tagged_newer(a, b), "why": why})
    assert [o["a_is_newer"] for o in order] == [True, True, False, False, False, True]

    epochs = []
    for epoch, old_ts, new_ts, after, why in ((0, 1, 2, 0, "one step"), (0, 0, 1, 0, "a new key starts at epoch 0"),
                                              (4, 65535, 1, 5, "the counter wrapped: 65535 -> 1"),
                                              (4, 65000, 65001, 4, "near the wrap, not across it"),
                                              (0xFFFFFFFE, 65535, 1, 0xFFFFFFFF, "the last epoch")):
        assert after == epoch + (1 if old_ts and new_ts < old_ts else 0)
        epochs.append({"epoch": epoch, "timestamp": old_ts, "next_timestamp": new_ts, "next_epoch": after,
                       "why": why})

    get_empty = pack("GET", 0x0102, 0, 0, 42)
    framed = {
        "cobs8": {"record": good.hex(), "frame": serial_frame(good).hex()},
        "cobs8_get_empty": {"record": (get_empty + bytes(12)).hex(),
                            "frame": serial_frame(get_empty + bytes(12)).hex()},
        "can_fd": {"id_11bit": f"{0x600 | 42:x}", "data": good.hex(), "length": 20},
        "batch": {"marker": f"{AUTH_MARKER:02x}", "data": (bytes([AUTH_MARKER]) + good + good).hex(), "records": 2},
        "mavlink": {"payload_type": f"{MAVLINK_TAGGED_TYPE:04x}", "payload": good.hex()},
    }
    assert len(cobs_decode(bytes.fromhex(str(framed["cobs8"]["frame"]))[:-1]) or b"") == 22
    return {
        "description": "Authenticated messages (SPEC.md section 10). robot key = BLAKE2s-256(key = master, data = "
                       "'vstig robot key' || robot u16); tag = BLAKE2s with an 8-byte digest (key = the writer's robot "
                       "key, data = epoch u32 || stigmergy u16 || the 8 message bytes with the op bit cleared); record "
                       "= message || epoch u32 || tag. BLAKE2s from RFC 7693, written out here and checked against the "
                       "RFC's example, the BLAKE2 keyed test vector and hashlib.",
        "master": AUTH_MASTER.hex(),
        "robot_keys": [{"robot": r, "key": keys[r].hex()} for r in robots],
        "tags": tags,
        "verify": verify,
        "order": order,
        "epochs": epochs,
        "framed": framed,
    }


def main(argv: list[str]) -> int:
    outdir = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parent.parent / "vectors"
    outdir.mkdir(parents=True, exist_ok=True)
    files = {
        "wire.json": wire_vectors(),
        "timestamps.json": timestamp_vectors(),
        "receive.json": receive_vectors(),
        "cobs8.json": cobs8_vectors(),
        "epuck4.json": epuck4_vectors(),
        "kilobot.json": kilobot_vectors(),
        "ohc.json": ohc_vectors(),
        "can_frames.json": can_vectors(),
        "xbee.json": xbee_vectors(),
        "auth.json": auth_vectors(),
    }
    # The dialects' vectors live beside this script; -I leaves its folder off sys.path.
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from dialect_vectors import dialect_files

    files.update(dialect_files(crc16_mcrf4xx))
    for name, content in files.items():
        (outdir / name).write_text(json.dumps(content, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
