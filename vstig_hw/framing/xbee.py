"""`xbee`: Digi XBee modules in API mode, our 8-byte messages in the RF data of their frames.

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).

An API frame on the module's UART (Digi's "API frame format"; firmware_spec/SPEC.md 6.9)::

    0x7E | length (u16 big-endian) | frame data (frame type, its fields) | checksum

where `length` counts the frame data and checksum = 0xFF - (sum of the frame data & 0xFF).
In API mode 2 (the module's AP=2) every byte after the 0x7E that is 0x7E, 0x7D, 0x11 or
0x13 travels as 0x7D followed by the byte XOR 0x20; length and checksum count the bytes
unescaped. So a 0x7E always starts a frame in mode 2, while in mode 1 (AP=1, what MISTLab's
XbeeMav uses) it may also be data.

What a link sends is a Transmit Request (0x10) broadcast to 000000000000FFFF, or to the
64-bit address given, whose RF data is N of our messages back to back, as many as the
module's maximum payload (AT NP) holds: a batch per frame, as CAN FD carries them. What
it hears is the Receive Packet (0x90): the 64-bit source address, which is the sender the
guard, sniff and captures see, then RF data of whole 8-byte messages.

`XBeeStreamReader` cuts a byte stream into checked frames and resynchronises at the next
0x7E after anything that is not one. Each bad unit is one counted drop, by reason:

- `noise`: bytes outside any frame (a run of them counts once);
- `escape`: mode 2 only, a 0x7D followed by a byte that is not an escaped 0x7E, 0x7D,
  0x11 or 0x13 (a 0x7E too), or a 0x11 or 0x13 left raw, met before the frame's end;
- `frame_length`: a length of 0 or above `MAX_FRAME_DATA` (no module sends one: a corrupted
  header);
- `truncated`: a frame cut short: another frame began (mode 2), or the line went quiet,
  before its length was in;
- `checksum`: the checksum does not match.

`XBeeFraming` takes frames one unit each (the XBee transport cuts them; a unit holding
anything else is read with the same reader, so nothing raises) and adds its own reasons:
`unknown_type` (a frame type a link does not use: set the module's AO=0 so it sends 0x90)
and `bad_length` (RF data that is not a whole number of messages, or a frame too short
for its header). Everything here is pure: no device, no clock.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from ..auth import RECORD_SIZE, Tagged, decode_batch, encode_batch
from ..counters import Counters
from ..wire import MESSAGE_SIZE, DecodeError, Message, decode_many, encode
from .base import SerialFraming

__all__ = [
    "AT_COMMAND",
    "AT_RESPONSE",
    "BROADCAST",
    "DEFAULT_MAX_PAYLOAD",
    "MAX_FRAME_DATA",
    "MAX_PER_FRAME",
    "MODEM_STATUS",
    "RECEIVE_PACKET",
    "START",
    "TRANSMIT_REQUEST",
    "TX_STATUS",
    "ModuleInfo",
    "Sending",
    "XBeeApi2Framing",
    "XBeeFraming",
    "XBeeStreamReader",
    "api_frame",
    "at_command",
    "checksum",
    "escape",
    "frame_type_of",
    "receive_packet",
    "rf_data_of",
    "transmit_request",
]

START = 0x7E
ESCAPE = 0x7D
_SPECIAL = frozenset((0x7E, 0x7D, 0x11, 0x13))  # what API mode 2 escapes
_FLIP = 0x20

TRANSMIT_REQUEST = 0x10
RECEIVE_PACKET = 0x90
TX_STATUS = 0x8B
AT_COMMAND = 0x08
AT_RESPONSE = 0x88
MODEM_STATUS = 0x8A

BROADCAST = 0x000000000000FFFF  # the 64-bit broadcast address
UNKNOWN_16 = 0xFFFE  # "16-bit address unknown": the module finds its way by the 64-bit one
# Frame data longer than this is a corrupted length: the largest frame a swarm radio sends is a 0x90
# carrying 256 bytes of RF data (900HP, SX), 268 bytes of frame data. (A bound, not 65535: a reader
# waits for as many bytes as a length says before its checksum can refuse it.)
MAX_FRAME_DATA = 512
# Messages per frame until the module says its NP: 64 bytes fit every XBee's RF payload (Zigbee with
# APS encryption and source routing leaves 66; DigiMesh 2.4 73; 802.15.4 100; 900HP and SX 256).
DEFAULT_MAX_PAYLOAD = 64
_RX_HEADER = 12  # 0x90, source64, source16, options
_TX_HEADER = 14  # 0x10, frame id, dest64, dest16, radius, options
# Messages a frame carries at most, whatever NP a module claims: its frame data stay within MAX_FRAME_DATA.
MAX_PER_FRAME = (MAX_FRAME_DATA - _TX_HEADER) // MESSAGE_SIZE
MAX_RECORDS_PER_FRAME = (MAX_FRAME_DATA - _TX_HEADER - 1) // RECORD_SIZE  # a tagged batch: its marker, then records
Heard = TypeVar("Heard", Message, tuple[Message, Tagged | None])  # what `feed` or `feed_tagged` gives per message


def checksum(frame_data: bytes | bytearray) -> int:
    return 0xFF - (sum(frame_data) & 0xFF)


def escape(data: bytes) -> bytes:
    """API mode 2's byte stuffing (of everything after the 0x7E)."""
    if not any(byte in _SPECIAL for byte in data):
        return data
    out = bytearray()
    for byte in data:
        if byte in _SPECIAL:
            out += bytes((ESCAPE, byte ^ _FLIP))
        else:
            out.append(byte)
    return bytes(out)


def api_frame(frame_data: bytes, escaped: bool = False) -> bytes:
    """The bytes on the UART for one frame's data (mode 2 when `escaped`)."""
    body = len(frame_data).to_bytes(2, "big") + frame_data + bytes((checksum(frame_data),))
    return b"\x7e" + (escape(body) if escaped else body)


def transmit_request(frame_id: int, rf_data: bytes, dest: int = BROADCAST) -> bytes:
    """A Transmit Request's frame data: `frame_id` 0 asks for no TX Status; radius 0 (the maximum); options 0."""
    return (bytes((TRANSMIT_REQUEST, frame_id)) + dest.to_bytes(8, "big") + UNKNOWN_16.to_bytes(2, "big")
            + b"\x00\x00" + rf_data)


def receive_packet(source: int, rf_data: bytes, options: int = 0x02) -> bytes:
    """A Receive Packet's frame data (what a module hands its host; options 0x02: it was a broadcast)."""
    return bytes((RECEIVE_PACKET,)) + source.to_bytes(8, "big") + UNKNOWN_16.to_bytes(2, "big") + \
        bytes((options,)) + rf_data


def at_command(frame_id: int, command: str, parameter: bytes = b"") -> bytes:
    """A local AT Command's frame data: no parameter reads the setting."""
    return bytes((AT_COMMAND, frame_id)) + command.encode("ascii") + parameter


def frame_type_of(frame_data: bytes) -> int:
    return frame_data[0]


def rf_data_of(frame_data: bytes) -> tuple[int | None, bytes] | None:
    """(sender, RF data) of a Receive Packet (sender: its 64-bit source) or of a Transmit Request (sender None:
    our own); None for a frame too short for its header or of another type."""
    kind = frame_data[0]
    if kind == RECEIVE_PACKET and len(frame_data) >= _RX_HEADER:
        return int.from_bytes(frame_data[1:9], "big"), frame_data[_RX_HEADER:]
    if kind == TRANSMIT_REQUEST and len(frame_data) >= _TX_HEADER:
        return None, frame_data[_TX_HEADER:]
    return None


@dataclass(frozen=True, slots=True)
class ModuleInfo:
    """What a module told its host at open: its 64-bit address, maximum RF payload (NP) and API mode (AP)."""

    address: int | None = None
    max_payload: int | None = None
    api_mode: int | None = None


class Sending:
    """What a link's frames carry from one to the next: the last frame id given (1..255), whether the next frame asks
    for a report, messages a frame, records a tagged batch. The compiled data path's Encoder has the same fields; a
    link whose outlet sends through one shares them with it (`XBeeFraming.share_sending`), so frame ids go on
    whichever side sends."""

    __slots__ = ("frame_id", "per_frame", "records_per_frame", "report")

    def __init__(self) -> None:
        self.frame_id = 0
        self.report = True
        self.per_frame = DEFAULT_MAX_PAYLOAD // MESSAGE_SIZE
        self.records_per_frame = (DEFAULT_MAX_PAYLOAD - 1) // RECORD_SIZE


def _stuffed(wire: bytes) -> bool:
    """Whether a mode-2 frame's bytes after its 0x7E hold an escape (or a byte that should have been one)."""
    return any(wire.find(special, 1) >= 0 for special in (b"\x7d", b"\x7e", b"\x11", b"\x13"))


class XBeeStreamReader:
    """A UART byte stream in, checked frames out as (bytes on the wire, frame data); bad units counted.

    `feed` returns the frames a chunk completes; a frame still arriving waits for the next chunk.
    `flush` ends the stream there (the line went quiet): a frame still arriving is counted `truncated`
    and the frames after its start are returned. Drops go to `drops` under `prefix` + reason. The
    buffer holds at most one frame's bytes and some noise: a noisy line cannot grow it.
    """

    def __init__(self, escaped: bool, drops: Counters, prefix: str = "") -> None:
        self.escaped = escaped
        self.drops = drops
        self._names = {reason: prefix + reason
                       for reason in ("noise", "escape", "frame_length", "truncated", "checksum")}
        self._buf = bytearray()
        self._junk = 0  # bytes at the head of _buf already known not to be a frame
        self._counted = False  # the bytes being skipped are already counted (noise, or what is left of a bad frame)

    @property
    def holding(self) -> bool:
        """Something came since the last frame: part of one, or bytes skipped (a run of noise, a bad frame's remains,
        which the line going quiet ends: `flush`)."""
        return bool(self._buf) or self._counted

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[tuple[bytes, bytes]]:
        self._buf += chunk
        return self._cut(final=False)

    def flush(self) -> list[tuple[bytes, bytes]]:
        """The line went quiet: a frame still arriving never will (`truncated`), but frames may follow its
        start (it claimed more bytes than came); they are returned."""
        frames = self._cut(final=True)
        self.reset()
        return frames

    def _cut(self, final: bool) -> list[tuple[bytes, bytes]]:
        buf = self._buf
        frames: list[tuple[bytes, bytes]] = []
        while True:
            start = buf.find(START, self._junk)
            if (len(buf) if start < 0 else start) > self._junk and not self._counted:
                self._drop("noise")  # bytes no frame claims: one drop per run
            if start < 0:
                self._junk = len(buf)
                break
            self._junk = start
            verdict = self._frame_at(buf, start)
            if verdict is None:  # still arriving
                if not final:
                    break
                verdict = "truncated"
            if isinstance(verdict, str):
                self._drop(verdict)  # what follows it up to the next 0x7E is its remains, not more noise
                self._junk = start + 1  # resynchronise at the next 0x7E
                continue
            end, data = verdict
            frames.append((bytes(buf[start:end]), data))
            del buf[:end]
            self._junk = 0
            self._counted = False
        if self._junk > MAX_FRAME_DATA:  # noise: keep no more of it than one frame's worth
            del buf[:self._junk]
            self._junk = 0
        return frames

    def reset(self) -> None:
        """Forget everything held (a reopened port: the old bytes belong to nobody)."""
        self._buf.clear()
        self._junk = 0
        self._counted = False

    def _drop(self, reason: str) -> None:
        self.drops[self._names[reason]] += 1
        self._counted = True

    def _frame_at(self, buf: bytearray, start: int) -> tuple[int, bytes] | str | None:
        """(end, frame data) of the frame at `start`, a drop reason, or None while it is still arriving."""
        if self.escaped:
            return self._escaped_frame_at(buf, start)
        if len(buf) - start < 3:
            return None
        length = buf[start + 1] << 8 | buf[start + 2]
        if not 0 < length <= MAX_FRAME_DATA:
            return "frame_length"
        end = start + length + 4
        if len(buf) < end:
            return None
        if sum(memoryview(buf)[start + 3:end]) & 0xFF != 0xFF:
            return "checksum"
        return end, bytes(buf[start + 3:end - 1])

    def _escaped_frame_at(self, buf: bytearray, start: int) -> tuple[int, bytes] | str | None:
        # Mode 2: the frame runs at most to the next 0x7E; unescape as far as its length says, no further
        # (what follows a whole frame is the next unit's business, noise or not). SPEC.md 6.6's order: a bad
        # escape met before the frame's end is `escape`, even if the frame is cut short or its length impossible.
        stop = buf.find(START, start + 1)
        cut = stop >= 0
        raw = bytes(buf[start + 1:] if stop < 0 else buf[start + 1:stop])
        head = _unescape_prefix(raw, 2, cut)
        if isinstance(head, str):
            return head
        if len(head[0]) < 2:
            return "truncated" if cut else None
        length = head[0][0] << 8 | head[0][1]
        if not 0 < length <= MAX_FRAME_DATA:
            return "frame_length"
        found = _unescape_prefix(raw, length + 3, cut)
        if isinstance(found, str):
            return found
        frame, used = found
        if len(frame) < length + 3:
            return "truncated" if cut else None
        if sum(frame[2:]) & 0xFF != 0xFF:
            return "checksum"
        return start + 1 + used, frame[2:-1]


_STUFFING = re.compile(b"[\x7d\x11\x13]")  # an escape, or a byte a mode-2 module never sends raw


def _unescape_prefix(data: bytes, want: int, cut: bool) -> tuple[bytes, int] | str:
    """The first `want` bytes of `data` unescaped (fewer if it ends first) and the raw bytes they took; "escape"
    for a 0x7D before a byte it never escapes, or a 0x11 or 0x13 left raw. A 0x7D at the very end waits for its
    byte, unless `cut` (a 0x7E follows: 0x7D 0x7E is a bad escape too)."""
    out = bytearray()
    i, end = 0, len(data)
    while len(out) < want and i < end:
        found = _STUFFING.search(data, i)
        j = end if found is None else found.start()
        if j - i >= want - len(out):
            take = min(want - len(out), end - i)
            out += data[i:i + take]
            i += take
            break
        out += data[i:j]
        if j == end:
            i = j
            break
        if data[j] != ESCAPE:
            return "escape"
        if j + 1 >= end:
            if cut:
                return "escape"
            i = j
            break
        byte = data[j + 1] ^ _FLIP
        if byte not in _SPECIAL:
            return "escape"
        out.append(byte)
        i = j + 2
    return bytes(out), i


class XBeeFraming(SerialFraming):
    """Our messages in XBee API frames (mode 1); `XBeeApi2Framing` for mode 2.

    A unit is one frame as on the wire (the XBee transport cuts them). Receive Packets (0x90)
    give messages from their 64-bit source (`sender_of`); Transmit Requests (0x10: our own, in a
    capture's tx lines) decode too. `use_module` sets how many messages a frame carries from the
    module's NP.
    """

    name = "xbee"
    escaped = False
    names_senders = True  # a Receive Packet carries its 64-bit source
    default_baud = 9600  # Digi's factory setting (BD=3)
    transmit_only = False
    preamble = b""  # a 0x7E starts every frame: nothing to cut off
    replays_received = False  # a 0x90 a module handed us cannot be written back: replay re-encodes it
    narrows = True  # a cut frame keeps its header (a 0x90 its sender's address)
    carries_tags = True  # RF data of 0xA1 and records (SPEC.md 10.5)

    default_max_payload = DEFAULT_MAX_PAYLOAD  # the RF payload assumed until the module says its NP

    def __init__(self, dest: int = BROADCAST) -> None:
        if isinstance(dest, bool) or not isinstance(dest, int) or not 0 <= dest <= 0xFFFF_FFFF_FFFF_FFFF:
            raise ValueError(f"xbee dest must be a 64-bit address, got {dest!r}")
        self.drops = Counters()
        self.dest = dest
        self.max_payload = self.default_max_payload
        self.sending: Sending | Any = Sending()  # or the compiled Encoder's fields (`share_sending`)
        self._use_max_payload(self.max_payload)
        self._head = bytes((TRANSMIT_REQUEST, 0)) + dest.to_bytes(8, "big") + UNKNOWN_16.to_bytes(2, "big") + \
            b"\x00\x00"  # a Transmit Request's fields, frame id 0 (byte 1)
        self._reader = XBeeStreamReader(self.escaped, self.drops)
        self._last: tuple[bytes | None, int | None] = (None, None)

    @property
    def per_frame(self) -> int:
        return int(self.sending.per_frame)

    def _use_max_payload(self, max_payload: int) -> None:
        """Messages a frame and records a tagged batch (after its marker) as the RF payload holds: at least one, and
        the frame data within MAX_FRAME_DATA."""
        self.max_payload = max_payload
        self.sending.per_frame = max(1, min(max_payload // MESSAGE_SIZE, MAX_PER_FRAME))
        self.sending.records_per_frame = max(1, min((max_payload - 1) // RECORD_SIZE, MAX_RECORDS_PER_FRAME))

    def use_module(self, module: ModuleInfo) -> None:
        """What the module said at open: as many messages per frame as its NP holds (at least one, at most
        MAX_PER_FRAME)."""
        if module.max_payload is not None:
            self._use_max_payload(module.max_payload)

    def share_sending(self, twin: Any) -> None:
        """Send with `twin`'s frame ids, reports and NP from now on (the compiled Encoder of this link's outlet:
        what either sends goes on the other's count). It takes ours as they are."""
        ours = self.sending
        twin.frame_id, twin.report, twin.per_frame = ours.frame_id, ours.report, ours.per_frame
        twin.records_per_frame = ours.records_per_frame
        self.sending = twin

    # -- sending -------------------------------------------------------------------
    def encode(self, msg: Message) -> list[bytes]:
        return self.encode_batch([msg])  # through `_payloads`, which a dialect's framing (XbeeMav) replaces

    def encode_batch(self, messages: Sequence[Message]) -> list[bytes]:
        """As few Transmit Requests as hold the messages, in order, each as full as NP allows."""
        return [self._transmit(rf) for rf in self._payloads(messages)]

    def _payloads(self, messages: Sequence[Message]) -> list[bytes]:
        """The RF data that carry `messages`: here up to `per_frame` messages back to back in each."""
        step = self.per_frame
        if len(messages) <= step:  # one flush, one frame: the common case, without slicing
            return [b"".join(map(encode, messages))] if messages else []
        return [b"".join(map(encode, messages[i:i + step])) for i in range(0, len(messages), step)]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[bytes]:
        """Transmit Requests of tagged batches, as many records in each as NP allows (3 in 64 bytes)."""
        step = int(self.sending.records_per_frame)
        return [self._transmit(encode_batch(list(records[i:i + step]))) for i in range(0, len(records), step)]

    def _transmit(self, rf_data: bytes) -> bytes:
        """A Transmit Request. The first frame of each control period has a frame id (1..255), so the module
        reports its delivery (0x8B); the others have 0. A report per frame would cost the host's UART 11 bytes
        and the gateway a read for each: a sample shows the same channel, NP and network faults."""
        head = self._head
        sending = self.sending
        if sending.report:
            sending.report = False
            sending.frame_id = sending.frame_id % 255 + 1
            head = head[:1] + bytes((sending.frame_id,)) + head[2:]
        data = head + rf_data
        body = len(data).to_bytes(2, "big") + data + bytes((0xFF - (sum(data) & 0xFF),))
        return b"\x7e" + (escape(body) if self.escaped else body)

    # -- receiving -----------------------------------------------------------------
    def feed(self, unit: bytes) -> list[Message]:
        return self._heard(unit, self._messages)

    def feed_tagged(self, unit: bytes) -> list[tuple[Message, Tagged | None]]:
        return self._heard(unit, self._records)

    def _heard(self, unit: bytes, read: Callable[[bytes, int | None], list[Heard]]) -> list[Heard]:
        """What `read` makes of the RF data of each frame in `unit`."""
        heard: list[Heard] = []
        sender = None
        for _wire, data in self._frames(unit):
            carried = rf_data_of(data)
            if carried is None:
                kind = data[0]
                self.drops["bad_length" if kind in (RECEIVE_PACKET, TRANSMIT_REQUEST) else "unknown_type"] += 1
                continue
            source, rf = carried
            got = read(rf, source)
            if got:
                heard.extend(got)
                sender = source if sender is None else sender
        self._last = (unit, sender)  # the gateway asks `sender_of` the unit it just fed
        return heard

    def _messages(self, rf_data: bytes, source: int | None) -> list[Message]:
        """The messages in one frame's RF data: whole 8-byte messages (a tagged batch's without their tags), or
        a `bad_length` drop."""
        if rf_data and not len(rf_data) % MESSAGE_SIZE:
            return decode_many(rf_data)
        return [msg for msg, _ in self._records(rf_data, source)]

    def _records(self, rf_data: bytes, source: int | None) -> list[tuple[Message, Tagged | None]]:
        """Each message of one frame's RF data with its record (SPEC.md 10.5: a tagged batch is never 8*N
        bytes), or a `bad_length` drop."""
        if rf_data and not len(rf_data) % MESSAGE_SIZE:
            return [(msg, None) for msg in decode_many(rf_data)]
        try:
            return [(record.message, record) for record in decode_batch(rf_data)]
        except DecodeError:
            self.drops["bad_length"] += 1
            return []

    def sender_of(self, unit: bytes) -> int | None:
        """The 64-bit source address of the Receive Packet that is this unit; None for anything else."""
        last_unit, sender = self._last
        if unit is last_unit:
            return sender
        frames = self._frames(unit, count=False)
        carried = rf_data_of(frames[0][1]) if frames else None
        return None if carried is None else carried[0]

    def narrow(self, unit: bytes, messages: Iterable[Message]) -> bytes | None:
        """The same frame carrying only `messages` (a filtered capture keeps who sent what); None for none."""
        frames = self._frames(unit, count=False)
        if not frames:
            return None
        data = frames[0][1]
        head = data[:_RX_HEADER] if data[0] == RECEIVE_PACKET else data[:_TX_HEADER]
        rf = b"".join(encode(m) for m in messages)
        return api_frame(head + rf, self.escaped) if rf else None

    def _frames(self, unit: bytes, count: bool = True) -> list[tuple[bytes, bytes]]:
        # The common case, one whole frame with nothing escaped: checked in place, without the reader's buffer.
        if len(unit) > 4 and unit[0] == START and (unit[1] << 8 | unit[2]) + 4 == len(unit) \
                and sum(memoryview(unit)[3:]) & 0xFF == 0xFF and not (self.escaped and _stuffed(unit)):
            return [(unit, unit[3:-1])]
        reader = self._reader if count else XBeeStreamReader(self.escaped, Counters())
        return reader.feed(unit) + reader.flush()  # a unit is whole: what it did not complete never will

    def tick(self) -> None:
        """A control period passed: the next frame asks for a report. (Units are whole frames: nothing ages.)"""
        self.sending.report = True

    def reset(self) -> None:
        """No partial state between units."""


class XBeeApi2Framing(XBeeFraming):
    """XBee API mode 2 (AP=2): escaped frames."""

    name = "xbee-api2"
    escaped = True
