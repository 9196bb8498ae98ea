"""Vectors for the Buzz and BittyBuzz dialects: buzz.json and bittybuzz.json (called by make_vectors.py).

THIS FILE MUST NEVER IMPORT vstig_hw. Every hex string below was written out by hand
from the C source the vector cites (repository@commit path:lines); a plain packer in
this file, written from the same source, must agree with each before anything is
written. Commits: Buzz a50ce6f (MISTLab/Buzz), BittyBuzz d093626 (buzz-lang/BittyBuzz),
BuzzKH4 b720e81, ROSBuzz ce38cb6, XbeeMav a360a8d.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

BZ = "MISTLab/Buzz@a50ce6f"
BB = "buzz-lang/BittyBuzz@d093626"
SRC_BUZZ_MSG = (f"{BZ} src/buzz/buzzoutmsg.c:393-415 (type, stigmergy id), src/buzz/buzzvstig.c:117-124 "
                "(key, value, timestamp, robot), src/buzz/buzztype.c:523-546 (objects), src/buzz/buzzmsg.c:35-66 "
                "(big-endian u16/u32)")
SRC_BUZZ_FLOAT = f"{BZ} src/buzz/buzzmsg.c:87-124 (buzzmsg_serialize_float), 129-163 (deserialize)"
SRC_BUZZ_STRING = f"{BZ} src/buzz/buzzmsg.c:168-180 (u16 length, then the bytes), 185-203"
SRC_BUZZ_PRE2017 = f"{BZ} a854c5c^ src/buzz/buzztype.c:469-492 (u16 tag, u32 table count)"
SRC_BUZZ_DESERIALIZE = f"{BZ} src/buzz/buzztype.c:574-628 (buzzobj_deserialize), src/buzz/buzzvm.c:276-296"
SRC_KH4 = "MISTLab/BuzzKH4@b720e81 src/buzz/buzz_utility.c:479-511 (send), 413-439 (receive)"
SRC_ARGOS = f"{BZ} src/buzz/argos/buzz_controller.cpp (ProcessOutMsgs, ProcessInMsgs), CByteArray u16 htons"
SRC_ROSBUZZ = ("MISTLab/ROSBuzz@ce38cb6 src/buzz_utility.cpp:112-169 (obt_out_msg), "
               "src/roscontroller.cpp:712-772 (payload64 header words)")
SRC_XBEE = "MISTLab/XbeeMav@a360a8d src/PacketsHandler.cpp:339-347 (bytes[7 - i] = word >> 8i: big-endian words)"
SRC_XBEEMAV = ("MISTLab/XbeeMav@a360a8d src/PacketsHandler.cpp:82-115 (S under 250 bytes, else F fragments of 250), "
               "336-369 (serialized: sysid, msgid, words; the F header), 658-686 (the 0x10 frame), "
               "src/SerialDevice.cpp:188-226 (0x90 read at fixed offsets); ROSBuzz@ce38cb6 roscontroller.cpp:712-772")
SRC_BBZ_MSG = (f"{BB} src/bittybuzz/bbzoutmsg.c:96-118 (type, rid, key, obj, lamport), "
               "src/bittybuzz/bbzmsg.c:50-53 (obj = mdata + u16), src/bittybuzz/bbzmsg.h:13-14 (htons = identity)")
SRC_BBZ_IN = f"{BB} src/bittybuzz/bbzinmsg.c:7-54 (bbzinmsg_queue_append: other types dropped)"
SRC_BBZ_FLOAT = f"{BB} src/bittybuzz/bbzfloat.c:54-83 (fromfloat), 88-118 (tofloat)"
SRC_BBZ_KILOBOT = (f"{BB} src/kilobot/lib/bbzkilobot.c:157-170 (data[9], type BBZMSG = 2, CRC), "
                   "src/kilobot/lib/bbzmessage.h:11-14")
SRC_BBZ_LAMPORT = f"{BB} src/bittybuzz/bbzmsg.c:110-115 (bbzlamport_isnewer), src/cmake/BittyBuzzConfig.cmake:20"
SRC_BBZ_IDS = f"{BB} src/bittybuzz/util/BittyBuzzStrings.bst (line n is id n-1: x = 41, y = 42)"


def h(spaced: str) -> bytes:
    return bytes.fromhex(spaced.replace(" ", "").replace("|", ""))


# --------------------------------------------------------------------------
# Buzz: a plain packer from the C source
# --------------------------------------------------------------------------


def buzz_float_pair(value: float) -> tuple[int, int]:
    """frexpf, then ((|f| - 0.5) * 2 * 2147483648.0f) truncated, + 1, signed: buzzmsg.c:87-125."""
    single = struct.unpack(">f", struct.pack(">f", value))[0]
    if single == 0:
        return 0, 0
    fraction, exponent = math.frexp(single)
    mantissa = math.floor((abs(fraction) - 0.5) * 2 * 2**31) + 1
    return (-mantissa if single < 0 else mantissa), exponent


def buzz_object(obj: dict[str, object], tag_size: int = 1) -> bytes:
    kind = obj["type"]
    tags = {"nil": 0, "int": 1, "float": 2, "string": 3}
    out = tags[str(kind)].to_bytes(tag_size, "big")
    if kind == "int":
        out += int(obj["value"]).to_bytes(4, "big", signed=True)  # type: ignore[call-overload]
    elif kind == "float":
        mantissa, exponent = buzz_float_pair(float(obj["value"]))  # type: ignore[arg-type]
        out += mantissa.to_bytes(4, "big", signed=True) + exponent.to_bytes(4, "big", signed=True)
    elif kind == "string":
        text = str(obj["value"]).encode()
        out += len(text).to_bytes(2, "big") + text
    return out


def buzz_message(op: str, stig: int, key: dict[str, object], value: dict[str, object], ts: int, robot: int,
                 tag_size: int = 1) -> bytes:
    return (bytes([{"PUT": 2, "QUERY": 3}[op]]) + stig.to_bytes(2, "big") + buzz_object(key, tag_size)
            + buzz_object(value, tag_size) + ts.to_bytes(2, "big") + robot.to_bytes(2, "big"))


def S(text: str) -> dict[str, object]:  # S, N, F: short, so the tables below read as the wire does
    return {"type": "string", "value": text}


def N(number: int) -> dict[str, object]:
    return {"type": "int", "value": number}


def F(number: float) -> dict[str, object]:
    return {"type": "float", "value": number}


NIL: dict[str, object] = {"type": "nil"}

# (name, dialect, hex by hand, (op, stig, key, value, ts, robot))
BUZZ_BY_HAND = [
    ("PUT stig 1, key \"x\" = int 42, ts 1, robot 5", "current",
     "02 | 0001 | 03 0001 78 | 01 0000002A | 0001 | 0005", ("PUT", 1, S("x"), N(42), 1, 5)),
    ("QUERY for a key the sender does not hold: nil, ts 0, robot 7", "current",
     "03 | 0001 | 03 0001 78 | 00 | 0000 | 0007", ("QUERY", 1, S("x"), NIL, 0, 7)),
    ("PUT tombstone (put(nil)): stig 1, key \"x\", ts 4, robot 3", "current",
     "02 | 0001 | 03 0001 78 | 00 | 0004 | 0003", ("PUT", 1, S("x"), NIL, 4, 3)),
    ("PUT stig 0, int key 7, float 1.0, ts 300, robot 258", "current",
     "02 | 0000 | 01 00000007 | 02 00000001 00000001 | 012C | 0102", ("PUT", 0, N(7), F(1.0), 300, 258)),
    ("PUT stig 10, key \"pos\" = string \"ab\", ts 2, robot 1", "current",
     "02 | 000A | 03 0003 706F73 | 03 0002 6162 | 0002 | 0001", ("PUT", 10, S("pos"), S("ab"), 2, 1)),
    ("QUERY stig 1, key \"x\" = int -1, ts 65535, robot 65535", "current",
     "03 | 0001 | 03 0001 78 | 01 FFFFFFFF | FFFF | FFFF", ("QUERY", 1, S("x"), N(-1), 65535, 65535)),
    ("PUT stig 2, key \"k\" = float -2.5, ts 9, robot 4", "current",
     "02 | 0002 | 03 0001 6B | 02 DFFFFFFF 00000002 | 0009 | 0004", ("PUT", 2, S("k"), F(-2.5), 9, 4)),
    ("PUT stig 2, key \"k\" = float 0.0, ts 10, robot 4", "current",
     "02 | 0002 | 03 0001 6B | 02 00000000 00000000 | 000A | 0004", ("PUT", 2, S("k"), F(0.0), 10, 4)),
    ("PUT key \"x\" = int 42 in the pre-July-2017 dialect (two-byte tags)", "pre2017",
     "02 | 0001 | 0003 0001 78 | 0001 0000002A | 0001 | 0005", ("PUT", 1, S("x"), N(42), 1, 5)),
]

BUZZ_FLOATS_BY_HAND = [  # value, mantissa, exponent (signed int32, big-endian on the wire)
    (1.0, "00000001", "00000001"),
    (-2.5, "DFFFFFFF", "00000002"),
    (0.0, "00000000", "00000000"),
    (0.1, "4CCCCD01", "FFFFFFFD"),
    (3.14159, "490FD001", "00000002"),
    (-1024.0, "FFFFFFFF", "0000000B"),
]

BUZZ_INVALID = [
    ("empty", "", "buzz_empty"),
    ("ends inside the key string", "02 0001 03 0005 78", "buzz_truncated"),
    ("ends before the robot id", "02 0001 03 0001 78 00 0001", "buzz_truncated"),
    ("userdata value (type 6) cannot be deserialized", "02 0001 03 0001 78 06 0001 0001", "buzz_bad_type"),
    ("bytes after the robot id", "02 0001 03 0001 78 00 0001 0001 00", "buzz_trailing"),
    ("a pre-2017 message read as current: key nil (00), value string \"x\" (03 0001 78), ts 1, robot 0, "
     "then 6 bytes too many", "02 0001 0003 0001 78 0001 0000002A 0001 0005", "buzz_trailing"),
]

BUZZ_OTHER = [  # not vstig: kept whole for relaying (buzzoutmsg.c:366-377 BROADCAST)
    ("BROADCAST topic \"x\" = int 10", "00 | 03 0001 78 | 01 0000000A", 0),
    ("SWARM_LIST of 2 swarms", "01 | 0002 | 0001 0002", 1),
]


def _fields(op: str, stig: int, key: dict[str, object], value: dict[str, object], ts: int, robot: int,
            ) -> dict[str, object]:
    return {"op": op, "stigmergy": stig, "key": key, "value": value, "timestamp": ts, "robot": robot}


def buzz_vectors() -> dict[str, object]:
    messages = []
    for name, dialect, spaced, fields in BUZZ_BY_HAND:
        raw = h(spaced)
        assert buzz_message(*fields, tag_size=1 if dialect == "current" else 2) == raw, name
        messages.append({"name": name, "source": SRC_BUZZ_PRE2017 if dialect == "pre2017" else SRC_BUZZ_MSG,
                         "dialect": dialect, "hex": raw.hex(), "fields": _fields(*fields)})
    floats = []
    for value, mantissa, exponent in BUZZ_FLOATS_BY_HAND:
        pair = buzz_float_pair(value)
        assert (pair[0] & 0xFFFFFFFF, pair[1] & 0xFFFFFFFF) == (int(mantissa, 16), int(exponent, 16)), value
        single = struct.unpack(">f", struct.pack(">f", value))[0]
        floats.append({"value": value, "float32": single, "mantissa": mantissa.lower(), "exponent": exponent.lower(),
                       "source": SRC_BUZZ_FLOAT})
    invalid = [{"name": name, "hex": h(spaced).hex(), "outcome": "drop", "counted_as": reason,
                "source": SRC_BUZZ_DESERIALIZE} for name, spaced, reason in BUZZ_INVALID]
    other = [{"name": name, "hex": h(spaced).hex(), "type": kind, "source": f"{BZ} src/buzz/buzzmsg.h:14-22"}
             for name, spaced, kind in BUZZ_OTHER]
    return {
        "description": "Buzz vstig messages (firmware_spec/dialects.md). `hex` decodes to `fields` in its "
                       "`dialect`, and `fields` encode to `hex`. Objects are {type, value}; a float's value is "
                       "what the receiver rebuilds (a float32). `other` messages are not vstig: a decoder keeps "
                       "them whole. `invalid` ones are dropped and counted as `counted_as` (a decoder "
                       "counter, not a SPEC.md 6.6 reason).",
        "messages": messages,
        "floats": floats,
        "other": other,
        "invalid": invalid,
        "frames": buzz_frames(),
        "xbeemav": xbeemav_vectors(),
    }


def _frame(sender: int, messages: list[bytes], size: int, order: str) -> bytes:
    out = sender.to_bytes(2, order)  # type: ignore[arg-type]
    for message in messages:
        out += len(message).to_bytes(2, order) + message  # type: ignore[arg-type]
    return out + bytes(size - len(out))


def buzz_frames() -> list[dict[str, object]]:
    b1 = buzz_message("PUT", 1, S("x"), N(42), 1, 5)
    b2 = buzz_message("QUERY", 1, S("x"), NIL, 0, 7)
    kh4 = h("0500 1000") + b1 + bytes(12)
    argos = h("0005 0010") + b1 + bytes(10)
    argos2 = h("0007 0010") + b1 + h("000C") + b2
    rosbuzz = h("0300 0500 1000 0200 | 0103 0001 7801 0000 | 002A 0001 0005 0000")
    xbee = h("0002 0010 0005 0003 | 0000 0178 0100 0301 | 0000 0500 0100 2A00")
    assert kh4 == _frame(5, [b1], 32, "little") and argos == _frame(5, [b1], 30, "big")
    assert argos2 == _frame(7, [b1, b2], len(argos2), "big")
    words = (len(b1) + 6 + 7) // 8
    assert rosbuzz == (words.to_bytes(2, "little") + _frame(5, [b1], words * 8 - 2, "little"))
    assert xbee == b"".join(rosbuzz[i:i + 8][::-1] for i in range(0, len(rosbuzz), 8))
    payload64 = [int.from_bytes(rosbuzz[i:i + 8], "little") for i in range(0, len(rosbuzz), 8)]
    assert payload64 == [0x0002001000050003, 0x0000017801000301, 0x0000050001002A00]
    return [
        {"name": "BuzzKH4 frame, msg_size 32, robot 5, one PUT", "transport": "kh4", "size": 32,
         "hex": kh4.hex(), "sender": 5, "messages": [b1.hex()], "source": SRC_KH4},
        {"name": "ARGoS RAB buffer, rab_data_size 30, robot 5, one PUT", "transport": "argos", "size": 30,
         "hex": argos.hex(), "sender": 5, "messages": [b1.hex()], "source": SRC_ARGOS},
        {"name": "ARGoS RAB buffer, robot 7, a PUT then a QUERY", "transport": "argos", "size": len(argos2),
         "hex": argos2.hex(), "sender": 7, "messages": [b1.hex(), b2.hex()], "source": SRC_ARGOS},
        {"name": "ROSBuzz Buzz block, robot 5, one PUT (payload64 words 5..7)", "transport": "rosbuzz",
         "hex": rosbuzz.hex(), "sender": 5, "messages": [b1.hex()], "payload64": [f"{w:016x}" for w in payload64],
         "source": SRC_ROSBUZZ},
        {"name": "the same block as XbeeMav sends it: each 64-bit word big-endian", "transport": "xbee",
         "hex": xbee.hex(), "sender": 5, "messages": [b1.hex()], "source": SRC_XBEE},
    ]


def _api_frame(frame_data: bytes) -> bytes:
    """An XBee API mode 1 frame (what XbeeMav runs): 0x7E, u16 length, frame data, 0xFF - sum."""
    return b"\x7e" + len(frame_data).to_bytes(2, "big") + frame_data + bytes([0xFF - (sum(frame_data) & 0xFF)])


def xbeemav_vectors() -> list[dict[str, object]]:
    """ROSBuzz's block F4 from drone 5 as its XbeeMav sends it, and what our module hands us: 0x90 frames."""
    b1 = buzz_message("PUT", 1, S("x"), N(42), 1, 5)
    rosbuzz = h("0300 0500 1000 0200 | 0103 0001 7801 0000 | 002A 0001 0005 0000")
    # payload64: header (type 2, message number 3, time 0), ROS time 0, latitude, longitude, altitude 0, the block
    words = [2 | 3 << 16, 0, 0, 0, 0] + [int.from_bytes(rosbuzz[i:i + 8], "little") for i in range(0, 24, 8)]
    serialized = bytes([5, 3]) + b"".join(w.to_bytes(8, "big") for w in words)
    assert serialized[2 + 5 * 8:] == h("0002 0010 0005 0003 | 0000 0178 0100 0301 | 0000 0500 0100 2A00")  # F5
    source = 0x0013A20040000005
    header = bytes([0x90]) + source.to_bytes(8, "big") + h("FFFE 02")
    single = _api_frame(header + b"S" + serialized)
    padded = serialized + bytes(8 * 31)  # 314 bytes: XbeeMav sends two fragments, then a ping
    fragments = [b"F" + bytes([3, 5, i]) + (250 * i).to_bytes(2, "big") + padded[250 * i:250 * i + 250]
                 for i in range(2)]
    assert [len(f) for f in fragments] == [256, 70]
    ping = b"P" + bytes([3, 5, 2])
    return [
        {"name": "drone 5's S packet (sysid 5, msgid 3) in a Receive Packet from its module", "api1": single.hex(),
         "sender": f"{source:016x}", "serialized": serialized.hex(), "messages": [b1.hex()], "source": SRC_XBEEMAV},
        {"name": "the same message padded to 314 bytes: two F fragments and a P ping",
         "api1_frames": [_api_frame(header + rf).hex() for rf in (*fragments, ping)], "sender": f"{source:016x}",
         "serialized": padded.hex(), "messages": [b1.hex()], "source": SRC_XBEEMAV},
    ]


# --------------------------------------------------------------------------
# BittyBuzz
# --------------------------------------------------------------------------


def bbz_pack(kind: int, rid: int, key: int, mdata: int, value: int, lamport: int) -> bytes:
    """type, rid, key, mdata, value, lamport: u16 little-endian (htons is the identity)."""
    return (bytes([kind]) + rid.to_bytes(2, "little") + key.to_bytes(2, "little") + bytes([mdata])
            + value.to_bytes(2, "little") + bytes([lamport]))


# (name, hex by hand, (type, rid, key, mdata, value, lamport))
BBZ_BY_HAND = [
    ("PUT rid 7, key \"x\" (41), int 42, lamport 1, plain tag", "01 0700 2900 01 2A00 01", (1, 7, 41, 0x01, 42, 1)),
    ("the same with the heap flags a put() may leak (valid, permanent, GC mark): still int",
     "01 0700 2900 39 2A00 01", (1, 7, 41, 0x39, 42, 1)),
    ("QUERY from rid 3 for a key it does not hold: nil, lamport 0", "02 0300 2900 00 0000 00", (2, 3, 41, 0, 0, 0)),
    ("PUT rid 258, key \"y\" (42), float 1.0 (bbzfloat 0x3E00), lamport 200", "01 0201 2A00 02 003E C8",
     (1, 258, 42, 0x02, 0x3E00, 200)),
    ("PUT rid 1, key id 46, int -1, lamport 255", "01 0100 2E00 01 FFFF FF", (1, 1, 46, 0x01, 0xFFFF, 255)),
    ("PUT rid 9, key id 50, string id 47, lamport 2", "01 0900 3200 03 2F00 02", (1, 9, 50, 0x03, 47, 2)),
    ("PUT of nil (an ordinary write in BittyBuzz), rid 7, key \"x\", lamport 3", "01 0700 2900 00 0000 03",
     (1, 7, 41, 0, 0, 3)),
    ("QUERY rid 7, key \"x\", int 42, lamport 1", "02 0700 2900 01 2A00 01", (2, 7, 41, 0x01, 42, 1)),
]
BBZ_OTHER = [("BROADCAST rid 5, topic \"x\", int 10 (the 9th byte is left over)", "00 0500 2900 01 0A00 00", 0)]
BBZ_FLOATS_BY_HAND = [(1.0, 0x3E00), (2.0, 0x4000), (0.5, 0x3C00), (-1.0, 0xBE00), (1.5, 0x3F00), (3.25, 0x4140),
                      (0.0, 0x0000)]
# (message lamport, local lamport, newer?) with threshold 50; HEAD since 42cd16d (2021-05-24)
LAMPORT_BY_HAND = [(1, 0, True), (0, 255, True), (49, 0, True), (50, 0, False), (5, 5, False), (200, 10, False),
                   (20, 240, True), (4, 210, False)]


def bbzfloat_plain(value: float) -> int:
    """bbzfloat.c:54-83 for values in range: sign, IEEE exponent - 96 in bits 9-14, fraction >> 14."""
    bits = struct.unpack("<I", struct.pack("<f", value))[0]
    exponent = (bits >> 23) & 0xFF
    if exponent == 0:
        return (bits >> 16) & 0x8000
    return ((bits >> 16) & 0x8000) | ((exponent - 96) << 9) | ((bits & 0x7FFFFF) >> 14)


def bittybuzz_vectors(crc16: Callable[[bytes], int]) -> dict[str, object]:
    names = ("type", "robot", "key", "mdata", "value", "lamport")
    messages = []
    for name, spaced, fields in BBZ_BY_HAND:
        raw = h(spaced)
        assert bbz_pack(*fields) == raw, name
        message_t = raw + bytes([2])
        crc = crc16(message_t)
        messages.append({"name": name, "hex": raw.hex(), "fields": dict(zip(names, fields, strict=True)),
                         "value_type": fields[3] & 7,
                         "kilobot_message_t": (message_t + crc.to_bytes(2, "little")).hex(),
                         "source": SRC_BBZ_MSG, "frame_source": SRC_BBZ_KILOBOT})
    other = [{"name": name, "hex": h(spaced).hex(), "type": kind, "source": SRC_BBZ_IN}
             for name, spaced, kind in BBZ_OTHER]
    floats = []
    for value, raw16 in BBZ_FLOATS_BY_HAND:
        assert bbzfloat_plain(value) == raw16, value
        floats.append({"value": value, "bbzfloat": f"{raw16:04x}", "source": SRC_BBZ_FLOAT})
    lamport = []
    for new, old, newer in LAMPORT_BY_HAND:
        assert (new != old and (new - old) % 256 < 50) is newer, (new, old)
        lamport.append({"lamport": new, "local": old, "newer": newer})
    return {
        "description": "BittyBuzz's 9-byte message (firmware_spec/dialects.md). `hex` decodes to `fields` and back; "
                       "the value's type is `mdata & 7`. `kilobot_message_t` is the Kilobot IR message carrying "
                       "it: data[9], type 2 (BBZMSG), CRC-16/MCRF4XX little-endian. `lamport` cases use "
                       "BBZLAMPORT_THRESHOLD 50.",
        "messages": messages,
        "other": other,
        "floats": floats,
        "lamport": {"threshold": 50, "source": SRC_BBZ_LAMPORT, "cases": lamport},
        "string_ids": {"x": 41, "y": 42, "stigmergy": 32, "put": 33, "get": 34, "source": SRC_BBZ_IDS},
    }


def dialect_files(crc16: Callable[[bytes], int]) -> dict[str, object]:
    return {"buzz.json": buzz_vectors(), "bittybuzz.json": bittybuzz_vectors(crc16)}
