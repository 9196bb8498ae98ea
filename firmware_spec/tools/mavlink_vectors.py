"""mavlink.json (SPEC.md section 6.10): vstig messages in MAVLink 2 TUNNEL messages, from mavlink.io alone.

Usage: python firmware_spec/tools/mavlink_vectors.py [OUTDIR]   (default: ../vectors)

Uses make_vectors.py's bit-by-bit CRC-16/MCRF4XX and the standard library only (hashlib for
SHA-256). Never imports the code it checks. Outcomes of the receive streams are written out by hand.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

Crc = Callable[[bytes], int]

TUNNEL, HEARTBEAT, PARAM_REQUEST_LIST = 385, 0, 21
CRC_EXTRA = {TUNNEL: 147, HEARTBEAT: 50, PARAM_REQUEST_LIST: 159}  # from MAVLink's common.xml (mavgen)
PAYLOAD_TYPE = 0xB571
PAYLOAD_TYPE_TAGGED = 0xB572  # authenticated messages, 20-byte records (SPEC.md 10.5)
KEY = hashlib.sha256(b"vstig swarm").digest()  # a passphrase's SHA-256, as MAVProxy and QGroundControl make a key
A = bytes.fromhex("0001123400010007")  # PUT key 1 = 0x1234, timestamp 1, robot 7
B = bytes.fromhex("8002000000020007")  # GET key 2, value 0, timestamp 2, robot 7
C = bytes.fromhex("0003000000000000")  # PUT key 3, all zero after the key: a TUNNEL's trailing zeros are cut
R = bytes.fromhex("0102abcd8000002a0000000064f6ab19de24cfe6")  # SPEC.md 10.3's record (robot 42's PUT, epoch 0)
E = bytes.fromhex("810200000000002a") + bytes(12)  # a GET showing no entry: epoch and tag all zero (SPEC.md 10.2)


def crc_x25(crc16: Crc, data: bytes, extra: int) -> int:
    return crc16(data + bytes([extra]))


def mavlink2(crc16: Crc, msgid: int, payload: bytes, seq: int, sysid: int, compid: int,
             key: bytes | None = None, link_id: int = 0, timestamp: int = 0) -> bytes:
    """A MAVLink 2 frame: trailing zero bytes of the payload cut (one byte kept), signed when `key` is given."""
    end = len(payload)
    while end > 1 and payload[end - 1] == 0:
        end -= 1
    body = payload[:end]
    header = bytes([0xFD, len(body), 0x01 if key is not None else 0x00, 0x00, seq, sysid, compid,
                    msgid & 0xFF, (msgid >> 8) & 0xFF, msgid >> 16])
    crc = crc_x25(crc16, header[1:] + body, CRC_EXTRA[msgid])
    frame = header + body + bytes([crc & 0xFF, crc >> 8])
    if key is None:
        return frame
    stamp = bytes((timestamp >> (8 * i)) & 0xFF for i in range(6))
    return frame + bytes([link_id]) + stamp + hashlib.sha256(key + frame + bytes([link_id]) + stamp).digest()[:6]


def tunnel_payload(data: bytes, target_system: int = 0, target_component: int = 0,
                   payload_type: int = PAYLOAD_TYPE) -> bytes:
    return bytes([payload_type & 0xFF, payload_type >> 8, target_system, target_component, len(data)]) + data + \
        bytes(128 - len(data))


def mavlink1_heartbeat(crc16: Crc) -> bytes:
    payload = bytes([0, 0, 0, 0, 2, 3, 0, 4, 3])
    header = bytes([0xFE, len(payload), 0, 9, 1, HEARTBEAT])
    crc = crc_x25(crc16, header[1:] + payload, CRC_EXTRA[HEARTBEAT])
    return header + payload + bytes([crc & 0xFF, crc >> 8])


def _stream(name: str, stream: bytes, frames: list[tuple[str, list[bytes]]], drops: dict[str, int],
            key: bool = False) -> dict[str, object]:
    """A receive case; a frame's 20-byte units are records: its messages are their first 8 bytes."""
    return {"name": name, "key": KEY.hex() if key else None, "stream": stream.hex(),
            "frames": [{"sender": sender, "messages": [m[:8].hex() for m in units]}
                       | ({"records": [r.hex() for r in units]} if len(units[0]) == 20 else {})
                       for sender, units in frames],
            "drops": drops}


def mavlink_vectors(crc16: Crc) -> dict[str, object]:
    def tunnel(data: bytes, seq: int = 0, sysid: int = 9, compid: int = 1, **kwargs: int) -> bytes:
        target = {k: kwargs.pop(k) for k in ("target_system", "target_component", "payload_type") if k in kwargs}
        return mavlink2(crc16, TUNNEL, tunnel_payload(data, **target), seq, sysid, compid, **kwargs)  # type: ignore[arg-type]

    def signed(data: bytes, timestamp: int, seq: int = 0, link_id: int = 0, key: bytes = KEY) -> bytes:
        return mavlink2(crc16, TUNNEL, tunnel_payload(data), seq, 9, 1, key, link_id, timestamp)

    sixteen = b"".join(bytes([0, k, 0, k, 0, 1, 0, 7]) for k in range(1, 17))
    transmit = []
    for name, data, key, link_id, stamp in (
            ("one message", A, None, 0, 0),
            ("sixteen messages: a full TUNNEL", sixteen, None, 0, 0),
            ("a message ending in zeros: the payload's trailing zeros are cut", C, None, 0, 0),
            ("one message, signed (link id 1)", A, KEY, 1, 0x0123456789AB),
            ("three messages, signed", A + B + C, KEY, 0, 0x000000000001)):
        wire = mavlink2(crc16, TUNNEL, tunnel_payload(data), 0, 1, 191, key, link_id, stamp)
        transmit.append({"name": name, "sysid": 1, "compid": 191, "seq": 0, "target": 0,
                         "messages": [data[i:i + 8].hex() for i in range(0, len(data), 8)],
                         "key": None if key is None else key.hex(), "link_id": link_id, "timestamp": stamp,
                         "wire": wire.hex()})
    transmit_tagged = []
    for name, data, key, stamp in (
            ("two records: SPEC.md 10.3's, and an empty GET's (its zeros cut)", R + E, None, 0),
            ("six records, signed: a full tagged TUNNEL", R * 6, KEY, 0x000000000001)):
        wire = mavlink2(crc16, TUNNEL, tunnel_payload(data, payload_type=PAYLOAD_TYPE_TAGGED), 0, 1, 191, key, 0,
                        stamp)
        transmit_tagged.append({"name": name, "sysid": 1, "compid": 191, "seq": 0, "target": 0,
                                "records": [data[i:i + 20].hex() for i in range(0, len(data), 20)],
                                "key": None if key is None else key.hex(), "link_id": 0, "timestamp": stamp,
                                "wire": wire.hex()})
    heartbeat = mavlink2(crc16, HEARTBEAT, bytes([0, 0, 0, 0, 18, 8, 0, 4, 3]), 0, 1, 191)
    good = tunnel(A + B)
    bad_crc = bytearray(good)
    bad_crc[14] ^= 0x01  # a payload byte: the crc no longer matches
    flags = bytearray(good)
    flags[2] = 0x02  # an incompat flag nobody knows
    sender = "9/1"
    signed_good = signed(A, 10_000_000)
    signed_forged = signed(B, 10_000_001, key=hashlib.sha256(b"a guess").digest())
    tampered = bytearray(signed(B, 10_000_002))
    tampered[-1] ^= 0x01
    streams = [
        _stream("one TUNNEL", good, [(sender, [A, B])], {}),
        _stream("two senders back to back", good + tunnel(C, sysid=12, compid=191), [(sender, [A, B]),
                                                                                     ("12/191", [C])], {}),
        _stream("noise before a frame: one drop per run", b"noise" + good, [(sender, [A, B])], {"noise": 1}),
        _stream("a wrong crc, then the next frame", bytes(bad_crc) + good, [(sender, [A, B])], {"crc": 1}),
        _stream("an incompat flag other than signing", bytes(flags) + good, [(sender, [A, B])],
                {"incompat_flags": 1}),
        _stream("the stream ends inside a frame", good + good[:12], [(sender, [A, B])], {"truncated": 1}),
        _stream("a MAVLink 1 frame: counted, never taken", mavlink1_heartbeat(crc16) + good, [(sender, [A, B])],
                {"mavlink1": 1}),
        _stream("other messages: counted", heartbeat + mavlink2(crc16, PARAM_REQUEST_LIST, bytes([1, 191]), 1, 255,
                                                                 190) + good, [(sender, [A, B])],
                {"other_message": 2}),
        _stream("a TUNNEL of another payload_type", tunnel(A, payload_type=PAYLOAD_TYPE - 1) + good,
                [(sender, [A, B])], {"other_payload_type": 1}),
        _stream("a TUNNEL for another system (the receiver is 4/191)", tunnel(A, target_system=5)
                + tunnel(B, target_system=4), [(sender, [B])], {"not_for_us": 1}),
        _stream("a TUNNEL for another component", tunnel(A, target_system=4, target_component=1), [],
                {"not_for_us": 1}),
        _stream("a payload that is not whole messages", tunnel(A[:7]), [], {"bad_length": 1}),
        _stream("a signed frame, no key: taken", signed_good, [(sender, [A])], {}),
        _stream("a tagged TUNNEL: its records, then an untagged one", tunnel(R + E, payload_type=PAYLOAD_TYPE_TAGGED)
                + good, [(sender, [R, E]), (sender, [A, B])], {}),
        _stream("a tagged TUNNEL that is not whole records", tunnel(R + A, payload_type=PAYLOAD_TYPE_TAGGED)
                + tunnel(R[:8], payload_type=PAYLOAD_TYPE_TAGGED), [], {"bad_length": 2}),
        _stream("with a key: signed, then replayed", signed_good + signed_good, [(sender, [A])], {"replay": 1},
                key=True),
        _stream("with a key: unsigned, forged, tampered", good + signed_forged + bytes(tampered) + signed_good,
                [(sender, [A])], {"unsigned": 1, "signature": 2}, key=True),
        _stream("with a key: an older timestamp on another link id is its own stream", signed_good
                + signed(B, 9_999_999, link_id=1), [(sender, [A]), (sender, [B])], {}, key=True),
        _stream("with a key: a new stream more than 60 s behind the newest is a replay", signed_good
                + signed(B, 10_000_000 - 6_000_001, link_id=2), [(sender, [A])], {"replay": 1}, key=True),
    ]
    return {
        "description": "vstig messages in MAVLink 2 TUNNEL (#385) messages (SPEC.md section 6.10): 0xFD | len | "
                       "incompat_flags | compat_flags | seq | sysid | compid | msgid (u24 LE) | payload | crc "
                       "(CRC-16/MCRF4XX over len..payload, then CRC_EXTRA: TUNNEL 147, HEARTBEAT 50) [| link id "
                       "| timestamp u48 LE | SHA-256(key | frame | link id | timestamp)[:6]]. TUNNEL payload: "
                       f"payload_type u16 LE ({PAYLOAD_TYPE}), target_system, target_component, payload_length, "
                       "payload[128]; trailing zeros cut. `transmit`: what a sender writes. `heartbeat`: the "
                       "gateway's HEARTBEAT. `streams`: bytes a receiver (sysid 4, compid 191; `key` when "
                       "given) reads -> each TUNNEL's sender (sysid/compid) and messages, and drops by reason. "
                       f"A TUNNEL of payload_type {PAYLOAD_TYPE_TAGGED} carries 1..6 authenticated messages "
                       "(SPEC.md 10.5: 20-byte records, message || epoch u32 || tag): `transmit_tagged`, and "
                       "`records` beside a frame's messages (a receiver with auth off takes the messages; tags "
                       "are checked by the gateway's policy, not here).",
        "payload_type": PAYLOAD_TYPE,
        "crc_extra": {"TUNNEL": 147, "HEARTBEAT": 50},
        "receiver": {"sysid": 4, "compid": 191},
        "transmit": transmit,
        "payload_type_tagged": PAYLOAD_TYPE_TAGGED,
        "transmit_tagged": transmit_tagged,
        "heartbeat": {"sysid": 1, "compid": 191, "seq": 0, "wire": heartbeat.hex()},
        "streams": streams,
    }


def main(argv: list[str]) -> int:
    """Write mavlink.json into OUTDIR (default ../vectors), with make_vectors.py's CRC."""
    import json
    import sys
    from pathlib import Path

    here = Path(__file__).resolve().parent
    sys.path.insert(0, str(here))  # -I leaves this folder off sys.path
    from make_vectors import crc16_mcrf4xx

    outdir = Path(argv[1]) if len(argv) > 1 else here.parent / "vectors"
    (outdir / "mavlink.json").write_text(json.dumps(mavlink_vectors(crc16_mcrf4xx), indent=1) + "\n",
                                         encoding="utf-8")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
