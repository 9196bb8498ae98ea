"""`mavlink`: our 8-byte messages in MAVLink 2 TUNNEL (#385) messages, optionally signed (SPEC.md 6.10).

C twin: vstig_hw/_cext/framing.c vstig_hw/_cext/mavlink.c (the compiled Receiver and Encoder of a mavlink link,
libvstig's vstig_mavlink and the replay table; held equal by tests/native/test_native_mavlink.py).

A MAVLink 2 frame (mavlink.io, "Serialization")::

    0xFD | len | incompat | compat | seq | sysid | compid | msgid (u24 LE) | payload (len) | crc (u16 LE)
         [| link id | timestamp (u48 LE) | signature (6)]   when incompat has bit 0x01 (signed)

crc is CRC-16/MCRF4XX (X.25) over everything after the 0xFD up to the payload's end, then the message's
CRC_EXTRA byte (147 for TUNNEL, 50 for HEARTBEAT). A payload's trailing zero bytes are not sent (at least one
byte is). TUNNEL's payload, in wire order: payload_type (u16 LE), target_system, target_component,
payload_length, payload[128]. Ours: payload_type `PAYLOAD_TYPE`, payload = up to 16 messages back to back; or
payload_type `PAYLOAD_TYPE_TAGGED`, payload = up to 6 authenticated messages (20-byte records, SPEC.md 10.5).
`feed` takes a tagged TUNNEL's messages without their tags (a link with auth off), and so does the compiled twin
(libvstig's vstig_mavlink_messages); `feed_tagged` gives their records.

The signature is the first 6 bytes of SHA-256(key | the frame from the 0xFD through the crc | link id |
timestamp); the timestamp counts 10 microseconds since 2015-01-01 00:00 UTC. With a key, a frame that is not
signed is `unsigned`, a wrong signature `signature`, and a timestamp not newer than the last one accepted from
the same (sysid, compid, link id) `replay`; all are dropped and counted.

`MavlinkStreamReader` cuts a byte stream (a telemetry radio's UART, a UDP datagram) into frames; what a receiver
does with each frame (SPEC.md 6.10.3) is `MavlinkFraming.feed`'s. Every reason a frame gives no message is a
counted drop, never raised. Everything here is pure but the signer's clock, which a caller may replace.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, ClassVar, TypeVar

from ..auth import RECORD_SIZE, Tagged, decode_record, encode_record
from ..counters import Counters
from ..crc import crc16_mcrf4xx
from ..wire import MESSAGE_SIZE, Message, decode_many, encode
from .base import SerialFraming

__all__ = [
    "BROADCAST",
    "COMP_ID",
    "HEARTBEAT",
    "KEY_SIZE",
    "MAX_PER_TUNNEL",
    "MAX_RECORDS_PER_TUNNEL",
    "PAYLOAD_TYPE",
    "PAYLOAD_TYPE_TAGGED",
    "STREAMS_KEPT",
    "TUNNEL",
    "MavlinkFraming",
    "MavlinkStreamReader",
    "Signing",
    "frame",
    "heartbeat_payload",
    "sender_name",
    "signing_timestamp",
    "tunnel_payload",
]

STX = 0xFD  # MAVLink 2
STX_V1 = 0xFE  # MAVLink 1: counted, never taken
SIGNED = 0x01  # incompat_flags: a signature follows the crc
HEADER = 10  # 0xFD through msgid
SIGNATURE = 13  # link id, timestamp (6), signature (6)
TUNNEL = 385
HEARTBEAT = 0
CRC_EXTRA = {TUNNEL: 147, HEARTBEAT: 50}  # the messages a link sends and checks; others' crc cannot be checked
PAYLOAD_TYPE = 0xB571  # ours, in the range MAVLink leaves for local use (32768..65535); SPEC.md 6.10.1
PAYLOAD_TYPE_TAGGED = 0xB572  # ours too: authenticated messages (SPEC.md 10.5)
BROADCAST = 0  # target_system 0: every system
COMP_ID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER: a companion computer's component id
MAX_PER_TUNNEL = 16  # TUNNEL's payload holds 128 bytes
MAX_RECORDS_PER_TUNNEL = 6  # 120 of its 128 bytes
KEY_SIZE = 32
STREAMS_KEPT = 1024  # (sysid, compid, link id) streams whose last timestamp is kept; SPEC.md 6.10.4
NEW_STREAM_WINDOW = 6_000_000  # 60 s in 10 us units: a new stream's first timestamp may be this much behind
Heard = TypeVar("Heard", Message, tuple[Message, Tagged | None])  # what `feed` or `feed_tagged` gives per message
_EPOCH_2015 = 1420070400  # 2015-01-01 00:00:00 UTC in Unix seconds
_TUNNEL_HEAD = struct.Struct("<HBBB")  # payload_type, target_system, target_component, payload_length
_TUNNEL_SIZE = _TUNNEL_HEAD.size + MAX_PER_TUNNEL * MESSAGE_SIZE  # 133: the payload before truncation
MAX_FRAME = HEADER + 255 + 2 + SIGNATURE
# HEARTBEAT (#0): custom_mode 0, type MAV_TYPE_ONBOARD_CONTROLLER (18), autopilot MAV_AUTOPILOT_INVALID (8),
# base_mode 0, system_status MAV_STATE_ACTIVE (4), mavlink_version 3: a component MAVLink tools list, no vehicle.
_HEARTBEAT = struct.pack("<IBBBBB", 0, 18, 8, 0, 4, 3)


def heartbeat_payload() -> bytes:
    return _HEARTBEAT


def signing_timestamp(now: float) -> int:
    """A signing timestamp: 10 microsecond units since 2015-01-01 00:00 UTC."""
    return int((now - _EPOCH_2015) * 100_000)


def sender_name(sender: int) -> str:
    """`sysid/compid` of a sender id (sysid << 8 | compid), as a log line shows it."""
    return f"{sender >> 8}/{sender & 0xFF}"


def tunnel_payload(data: bytes, target_system: int = BROADCAST, target_component: int = 0,
                   payload_type: int = PAYLOAD_TYPE) -> bytes:
    """A TUNNEL's payload carrying `data` (at most 128 bytes), before truncation."""
    return _TUNNEL_HEAD.pack(payload_type, target_system, target_component, len(data)) + data + \
        bytes(MAX_PER_TUNNEL * MESSAGE_SIZE - len(data))


def _signature(key: bytes, signed_part: bytes) -> bytes:
    return hashlib.sha256(key + signed_part).digest()[:6]


def frame(msgid: int, payload: bytes, *, seq: int, sysid: int, compid: int, key: bytes | None = None,
          link_id: int = 0, timestamp: int = 0, crc_extra: int | None = None) -> bytes:
    """One MAVLink 2 frame as on the wire: the payload's trailing zeros cut, signed when `key` is given."""
    body = payload.rstrip(b"\x00") or b"\x00"
    head = struct.pack("<BBBBBBB", STX, len(body), SIGNED if key is not None else 0, 0, seq & 0xFF, sysid,
                       compid) + msgid.to_bytes(3, "little")
    extra = CRC_EXTRA[msgid] if crc_extra is None else crc_extra
    crc = crc16_mcrf4xx(bytes((extra,)), crc16_mcrf4xx(head[1:] + body))
    wire = head + body + crc.to_bytes(2, "little")
    if key is None:
        return wire
    tail = bytes((link_id,)) + timestamp.to_bytes(6, "little")
    return wire + tail + _signature(key, wire + tail)


class Signing:
    """One key's two sides: the timestamps a link signs with, and the last one accepted per stream.

    Sent timestamps never go backwards and never repeat (one more than the last when the clock has not moved).
    Received ones are kept per (sysid, compid, link id), at most `STREAMS_KEPT` of them (the least recently
    heard is forgotten first); a stream not seen before must not start more than 60 s behind the newest
    timestamp accepted on the link, so a forgotten stream's old frames stay refused.
    """

    def __init__(self, key: bytes, link_id: int = 0, clock: Callable[[], float] = time.time) -> None:
        if len(key) != KEY_SIZE:
            raise ValueError(f"a MAVLink signing key is {KEY_SIZE} bytes, got {len(key)}")
        if not 0 <= link_id <= 0xFF:
            raise ValueError(f"a MAVLink link id is 0..255, got {link_id}")
        self.key = key
        self.link_id = link_id
        self.clock = clock
        self._sent = 0
        self._heard: dict[tuple[int, int, int], int] = {}
        self._newest = 0

    def next_timestamp(self) -> int:
        self._sent = max(self._sent + 1, signing_timestamp(self.clock()))
        return self._sent

    def check(self, wire: bytes | memoryview) -> str | None:
        """The drop reason for this whole frame (None: accepted, and its timestamp remembered)."""
        if not wire[2] & SIGNED:
            return "unsigned"
        end = len(wire) - 6
        if not hmac.compare_digest(_signature(self.key, bytes(wire[:end])), bytes(wire[end:])):
            return "signature"
        stream = (wire[5], wire[6], wire[end - 7])
        stamp = int.from_bytes(wire[end - 6:end], "little")
        last = self._heard.get(stream)
        if stamp <= (self._newest - NEW_STREAM_WINDOW if last is None else last):
            return "replay"
        self._heard.pop(stream, None)
        self._heard[stream] = stamp  # re-inserted: the dict's order is the order streams were last heard
        if len(self._heard) > STREAMS_KEPT:
            del self._heard[next(iter(self._heard))]
        self._newest = max(self._newest, stamp)
        return None


class MavlinkStreamReader:
    """A byte stream in, whole frames out (bytes as on the wire); bad units counted in `drops` by reason.

    - `noise`: bytes before a 0xFD or 0xFE (one drop per run; none after a bad frame: they are its remains);
    - `incompat_flags`: a MAVLink 2 header with a flag other than signing (no receiver knows its length);
    - `crc`: a TUNNEL or HEARTBEAT whose crc does not match (the only messages whose CRC_EXTRA a link knows);
    - `truncated`: the stream ended (`flush`) inside a frame.
    After a bad frame the search for the next starts at the byte after its start byte. A MAVLink 1 frame, and
    a MAVLink 2 frame of another message, are cut by their length alone and handed on (the framing counts them).
    """

    def __init__(self, drops: Counters, prefix: str = "") -> None:
        self.drops = drops
        self._names = {reason: prefix + reason for reason in ("noise", "incompat_flags", "crc", "truncated")}
        self._buf = bytearray()
        self._counted = False  # the bytes being skipped are already counted

    @property
    def holding(self) -> bool:
        return bool(self._buf)

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[bytes]:
        self._buf += chunk
        return self._cut(final=False)

    def flush(self) -> list[bytes]:
        """The stream ends here: a frame still arriving is `truncated`; frames after its start are returned."""
        frames = self._cut(final=True)
        self.reset()
        return frames

    def reset(self) -> None:
        self._buf.clear()
        self._counted = False

    def _drop(self, reason: str) -> None:
        self.drops[self._names[reason]] += 1
        self._counted = True

    def _cut(self, final: bool) -> list[bytes]:
        buf = self._buf
        frames: list[bytes] = []
        pos = 0
        while True:
            start = _next_start(buf, pos)
            if (len(buf) if start < 0 else start) > pos and not self._counted:
                self._drop("noise")
            if start < 0:
                del buf[:]
                return frames
            verdict = self._frame_at(buf, start)
            if verdict is None:
                if not final:
                    del buf[:start]
                    return frames
                verdict = "truncated"
            if isinstance(verdict, str):
                self._drop(verdict)
                pos = start + 1
                continue
            frames.append(bytes(buf[start:verdict]))
            pos = verdict
            self._counted = False

    @staticmethod
    def _frame_at(buf: bytearray, start: int) -> int | str | None:
        """The end of the frame at `start`, a drop reason, or None while it is still arriving."""
        have = len(buf) - start
        if buf[start] == STX_V1:
            if have < 2:
                return None
            end = start + buf[start + 1] + 8
            return end if len(buf) >= end else None
        if have < 3:
            return None
        flags = buf[start + 2]
        if flags & ~SIGNED:
            return "incompat_flags"
        length = buf[start + 1]
        end = start + HEADER + length + 2 + (SIGNATURE if flags & SIGNED else 0)
        if have < HEADER:
            return None
        extra = CRC_EXTRA.get(int.from_bytes(buf[start + 7:start + 10], "little"))
        if len(buf) < end:
            return None
        if extra is not None:
            crc_at = start + HEADER + length
            crc = crc16_mcrf4xx(bytes((extra,)), crc16_mcrf4xx(memoryview(buf)[start + 1:crc_at]))
            if crc != buf[crc_at] | buf[crc_at + 1] << 8:
                return "crc"
        return end


def _next_start(buf: bytearray, pos: int) -> int:
    v2, v1 = buf.find(STX, pos), buf.find(STX_V1, pos)
    if v2 < 0 or v1 < 0:
        return max(v2, v1)
    return min(v2, v1)


class MavlinkFraming(SerialFraming):
    """Our messages in MAVLink 2 TUNNEL messages, from (`sysid`, `compid`), signed when `signing` is given.

    A unit is one frame as on the wire (the link's transport cuts them; a unit holding anything else is read
    with the same reader, so nothing raises). `sender_of` a TUNNEL is sysid << 8 | compid.
    """

    name = "mavlink"
    names_senders = True
    default_baud = 57600  # SiK radios' factory UART rate
    preamble = b""  # a 0xFD starts every frame
    replays_received: ClassVar[bool] = False  # a received frame carries another's sysid (and signature): re-encode
    narrows: ClassVar[bool] = True  # a cut TUNNEL keeps its sender, sequence and target
    carries_tags = True  # TUNNELs of payload_type PAYLOAD_TYPE_TAGGED (SPEC.md 10.5)

    def __init__(self, sysid: int = 1, compid: int = COMP_ID, *, target: int = BROADCAST,
                 signing: Signing | None = None) -> None:
        for what, number, low in (("sysid", sysid, 1), ("compid", compid, 1), ("target", target, 0)):
            if isinstance(number, bool) or not isinstance(number, int) or not low <= number <= 255:
                raise ValueError(f"mavlink {what} must be {low}..255, got {number!r}")
        self.drops = Counters()
        self.sysid, self.compid, self.target = sysid, compid, target
        self.signing = signing
        self._seq = 0
        self._lock = threading.Lock()  # heartbeats go out from the link's reader thread: one sequence for both
        self._reader = MavlinkStreamReader(self.drops)
        self._last: tuple[bytes | None, int | None] = (None, None)
        self._twin: Any = None  # the compiled Encoder this framing sends through, once shared (`share_sending`)
        # the newest signing timestamp the link wrote (`in_order`); once shared, the Encoder's `written`, which the
        # compiled outlet moves on as it sends a signed link's TUNNELs itself (under the link's write lock)
        self.written = 0

    def share_sending(self, twin: Any) -> None:
        """Send through the compiled Encoder `twin` from now on (it goes on from this framing's sequence and last
        signing timestamp): the outlet's TUNNELs and the link's HEARTBEATs then share one sequence and one
        signing clock, so a receiver never sees a timestamp go back (a replay). The Encoder's clock is the
        system's realtime clock, as `Signing`'s default is."""
        with self._lock:
            twin.seq = self._seq
            if self.signing is not None:
                twin.timestamp = self.signing._sent
            twin.written = self.written
            self._twin = twin

    # -- sending -------------------------------------------------------------------
    def _frame(self, msgid: int, payload: bytes) -> bytes:
        with self._lock:
            twin = self._twin
            if twin is None:
                seq, self._seq = self._seq, (self._seq + 1) & 0xFF
            else:  # the Encoder's sequence: one for every frame the link sends
                seq = twin.seq
                twin.seq = (seq + 1) & 0xFF
            signing = self.signing
            if signing is None:
                return frame(msgid, payload, seq=seq, sysid=self.sysid, compid=self.compid)
            return frame(msgid, payload, seq=seq, sysid=self.sysid, compid=self.compid, key=signing.key,
                         link_id=signing.link_id, timestamp=self._next_timestamp(signing))

    def in_order(self, unit: bytes) -> bytes:
        """`unit` (whole frames this framing made) with every signed frame newer than the last one written.

        The link calls this under its write lock as the device takes the unit: a frame is signed when it is
        made, but a TUNNEL the air budget held, or one made on another thread, may go out after a newer
        HEARTBEAT, and a receiver refuses a timestamp not newer than the last it took (SPEC.md 6.10.4). Such a
        frame is signed again with the next timestamp; one in order goes as it is (the usual case: no hashing).
        """
        signing = self.signing
        if signing is None:
            return unit
        fixed: bytearray | None = None
        mark = self if self._twin is None else self._twin  # where the newest timestamp written is kept
        pos = 0
        while pos + HEADER < len(unit) and unit[pos] == STX and unit[pos + 2] & SIGNED:
            end = pos + HEADER + unit[pos + 1] + 2 + SIGNATURE
            if end > len(unit):
                break
            stamp = int.from_bytes(unit[end - 12:end - 6], "little")
            if stamp <= mark.written:
                with self._lock:
                    stamp = max(mark.written + 1, self._next_timestamp(signing))
                fixed = bytearray(unit) if fixed is None else fixed
                tail = bytes((unit[end - 13],)) + stamp.to_bytes(6, "little")
                fixed[end - 13:end] = tail + _signature(signing.key, bytes(fixed[pos:end - 13]) + tail)
            mark.written = stamp
            pos = end
        return unit if fixed is None else bytes(fixed)

    def _next_timestamp(self, signing: Signing) -> int:
        """The next signing timestamp on the one clock this framing and its Encoder share (under `_lock`)."""
        twin = self._twin
        if twin is None:
            return signing.next_timestamp()
        stamp: int = max(twin.timestamp + 1, signing_timestamp(signing.clock()))
        twin.timestamp = stamp
        return stamp

    def encode(self, msg: Message) -> list[bytes]:
        return self.encode_batch((msg,))

    def encode_batch(self, messages: Sequence[Message]) -> list[bytes]:
        """As few TUNNELs as hold the messages, in order, 16 to a TUNNEL (once shared, the Encoder's: one unit,
        the TUNNELs back to back, as `Link.units_of` joins them anyway)."""
        if self._twin is not None:
            units: list[bytes] = self._twin.encode_batch(messages)
            return units
        data = b"".join(map(encode, messages))
        step = MAX_PER_TUNNEL * MESSAGE_SIZE
        return [self._frame(TUNNEL, tunnel_payload(data[i:i + step], self.target)) for i in range(0, len(data), step)]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[bytes]:
        """TUNNELs of payload_type PAYLOAD_TYPE_TAGGED, 6 records to a TUNNEL, in order (SPEC.md 10.5)."""
        step = MAX_RECORDS_PER_TUNNEL
        return [self._frame(TUNNEL, tunnel_payload(b"".join(map(encode_record, records[i:i + step])), self.target,
                                                   payload_type=PAYLOAD_TYPE_TAGGED))
                for i in range(0, len(records), step)]

    def heartbeat(self) -> bytes:
        """The HEARTBEAT that announces this component (once a second, from the link)."""
        if self._twin is not None:
            beat: bytes = self._twin.heartbeat()
            return beat
        return self._frame(HEARTBEAT, _HEARTBEAT)

    # -- receiving -----------------------------------------------------------------
    def feed(self, unit: bytes) -> list[Message]:
        return self._heard(unit, self._messages)

    def feed_tagged(self, unit: bytes) -> list[tuple[Message, Tagged | None]]:
        return self._heard(unit, self._records)

    def _heard(self, unit: bytes, read: Callable[[bytes], list[Heard]]) -> list[Heard]:
        """What `read` makes of each whole frame in `unit`; the sender of the first that gave anything kept."""
        heard: list[Heard] = []
        sender = None
        for wire in self._frames(unit):
            got = read(wire)
            if got:
                heard.extend(got)
                sender = wire[5] << 8 | wire[6] if sender is None else sender
        self._last = (unit, sender)
        return heard

    def _messages(self, wire: bytes) -> list[Message]:
        """The messages of one whole frame (a tagged TUNNEL's without their tags: a link with auth off)."""
        carried = self._carried(wire)
        if carried is None:
            return []
        tagged, data = carried
        if tagged:
            data = b"".join(data[i:i + MESSAGE_SIZE] for i in range(0, len(data), RECORD_SIZE))
        return decode_many(data)

    def _records(self, wire: bytes) -> list[tuple[Message, Tagged | None]]:
        """Each message of one whole frame with its record, None for an untagged TUNNEL's."""
        carried = self._carried(wire)
        if carried is None:
            return []
        tagged, data = carried
        if not tagged:
            return [(msg, None) for msg in decode_many(data)]
        records = [decode_record(data[i:i + RECORD_SIZE]) for i in range(0, len(data), RECORD_SIZE)]
        return [(record.message, record) for record in records]

    def _carried(self, wire: bytes) -> tuple[bool, bytes] | None:
        """(tagged, the records or messages back to back) of one whole frame, or None and the reason counted
        (SPEC.md 6.10.3 and 10.5)."""
        drops = self.drops
        if wire[0] == STX_V1:
            drops["mavlink1"] += 1
            return None
        if self.signing is not None:
            refused = self.signing.check(wire)
            if refused is not None:
                drops[refused] += 1
                return None
        if int.from_bytes(wire[7:10], "little") != TUNNEL:
            drops["other_message"] += 1
            return None
        payload = wire[HEADER:HEADER + wire[1]]
        payload += bytes(_TUNNEL_SIZE - len(payload)) if len(payload) < _TUNNEL_SIZE else b""
        payload_type, target_system, target_component, length = _TUNNEL_HEAD.unpack_from(payload)
        if payload_type != PAYLOAD_TYPE and payload_type != PAYLOAD_TYPE_TAGGED:
            drops["other_payload_type"] += 1
            return None
        if target_system not in (BROADCAST, self.sysid) or target_component not in (0, self.compid):
            drops["not_for_us"] += 1
            return None
        tagged = payload_type == PAYLOAD_TYPE_TAGGED
        size, most = (RECORD_SIZE, MAX_RECORDS_PER_TUNNEL) if tagged else (MESSAGE_SIZE, MAX_PER_TUNNEL)
        if not length or length % size or length > most * size:
            drops["bad_length"] += 1
            return None
        return tagged, payload[_TUNNEL_HEAD.size:_TUNNEL_HEAD.size + length]

    def sender_of(self, unit: bytes) -> int | None:
        """sysid << 8 | compid of the TUNNEL that is this unit; None for anything else."""
        last_unit, sender = self._last
        if unit is last_unit:
            return sender
        frames = self._frames(unit, count=False)
        return frames[0][5] << 8 | frames[0][6] if frames and frames[0][0] == STX else None

    def narrow(self, unit: bytes, messages: Iterable[Message]) -> bytes | None:
        """The same TUNNEL (sender, sequence, target) carrying only `messages`, unsigned; None for none."""
        frames = self._frames(unit, count=False)
        data = b"".join(encode(m) for m in messages)
        if not frames or frames[0][0] != STX or not data:
            return None
        wire = frames[0]
        payload = wire[HEADER:HEADER + wire[1]] + bytes(_TUNNEL_SIZE)
        return frame(TUNNEL, tunnel_payload(data, payload[2], payload[3]), seq=wire[4], sysid=wire[5],
                     compid=wire[6])

    def _frames(self, unit: bytes, count: bool = True) -> list[bytes]:
        # The common case, one whole frame: checked in place, without the reader's buffer.
        if len(unit) > HEADER + 2 and unit[0] == STX and not unit[2] & ~SIGNED \
                and len(unit) == HEADER + unit[1] + 2 + (SIGNATURE if unit[2] & SIGNED else 0) \
                and _crc_ok(unit):
            return [unit]
        reader = self._reader if count else MavlinkStreamReader(Counters())
        return reader.feed(unit) + reader.flush()  # a unit is whole: what it did not complete never will

    def reset(self) -> None:
        """No partial state between units."""


def _crc_ok(wire: bytes) -> bool:
    """A frame's crc matches, where its message's CRC_EXTRA is known (elsewhere it cannot be checked)."""
    extra = CRC_EXTRA.get(int.from_bytes(wire[7:10], "little"))
    if extra is None:
        return True
    crc_at = HEADER + wire[1]
    return crc16_mcrf4xx(bytes((extra,)), crc16_mcrf4xx(memoryview(wire)[1:crc_at])) == \
        wire[crc_at] | wire[crc_at + 1] << 8
