"""CAN framing: the arbitration-ID scheme and payloads (normative text: firmware_spec/SPEC.md section 6.5).

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).

This module is the one owner of the CAN ID scheme::

    11-bit:  id = base | op << 8  | sender            base in {0x000, 0x200, 0x400, 0x600}
    29-bit:  id = base | stigmergy << 17 | op << 16 | sender    base uses bits 28..25 only

op 0 is PUT and 1 is GET, so on the wire a PUT's lower ID wins arbitration over
every GET. Each node transmits only under its own sender field, so two nodes
never send the same ID with different data (CAN arbitration needs that).

A classic frame carries one 8-byte wire message (DLC 8). A CAN FD frame carries
1, 2, 3, 4, 6 or 8 messages back to back (8..64 bytes, no padding), all of the
frame's op, or one authenticated message (a 20-byte record, DLC 11; SPEC.md 10.5).
Anything else is dropped and counted, never raised.

Batching (for the gateway): per control period, hand the whole drained outbox to
`encode_batch(messages)` (or `Link.send_many`), which packs FD frames as full as
the allowed sizes permit and falls back to one classic frame per message.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import can

from ..auth import RECORD_SIZE, Tagged, decode_record, encode_record
from ..counters import Counters
from ..wire import GET_BIT, MESSAGE_SIZE, Message, Op, decode_many, encode
from .base import Framing

__all__ = [
    "BASES_11BIT",
    "CAPTURE_NAME",
    "DEFAULT_BASE_11BIT",
    "DEFAULT_BASE_29BIT",
    "FD_BATCH_SIZES",
    "LISTENER_ID",
    "CanFraming",
    "CanIdScheme",
    "can_framing",
    "can_framing_for",
]

CAPTURE_NAME = "can"  # the framing name CAN records carry, classic or FD (capture.records.CAN_FRAMING)
BASES_11BIT = (0x000, 0x200, 0x400, 0x600)
DEFAULT_BASE_11BIT = 0x600
DEFAULT_BASE_29BIT = 0x18000000
BASE_MASK_29BIT = 0x1E000000  # bits 28..25
FD_BATCH_SIZES = (1, 2, 3, 4, 6, 8)  # messages per CAN FD frame: the FD lengths 8..64 that are multiples of 8
_FD_LENGTHS = frozenset(n * MESSAGE_SIZE for n in FD_BATCH_SIZES)
LISTENER_ID = 0  # the sender field of a node that never transmits (sniff, record)


@dataclass(frozen=True)
class CanIdScheme:
    """Which arbitration IDs carry one stigmergy on one bus, and how to read them.

    11-bit IDs tell stigmergies apart by `base` alone (so `stigmergy` must be 0);
    29-bit IDs carry an 8-bit `stigmergy` field below the base.
    """

    extended: bool = False
    base: int | None = None  # None: the default for the width
    stigmergy: int = 0
    # Derived once so `parse` stays a few integer operations per frame.
    _match_mask: int = field(init=False, repr=False, compare=False)
    _match_value: int = field(init=False, repr=False, compare=False)
    _op_shift: int = field(init=False, repr=False, compare=False)
    _sender_mask: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.extended:
            base = DEFAULT_BASE_29BIT if self.base is None else self.base
            _require(isinstance(base, int) and base == base & BASE_MASK_29BIT,
                     "a 29-bit id_base may use bits 28..25 only "
                     f"(0x00000000..0x1E000000 in steps of 0x02000000), got {_shown(self.base)}")
            _require(isinstance(self.stigmergy, int) and 0 <= self.stigmergy <= 0xFF,
                     f"stigmergy must be 0..255 for 29-bit IDs, got {self.stigmergy!r}")
            derived = (base, 0x1FFE0000, base | self.stigmergy << 17, 16, 0xFFFF)
        else:
            base = DEFAULT_BASE_11BIT if self.base is None else self.base
            _require(base in BASES_11BIT,
                     f"an 11-bit id_base must be one of 0x000, 0x200, 0x400, 0x600, got {_shown(self.base)}")
            _require(self.stigmergy == 0,
                     "11-bit IDs have no stigmergy field: give each stigmergy its own id_base "
                     f"(0x000, 0x200, 0x400, 0x600), got stigmergy={self.stigmergy!r}")
            derived = (base, 0x600, base, 8, 0xFF)
        for name, value in zip(("base", "_match_mask", "_match_value", "_op_shift", "_sender_mask"), derived,
                               strict=True):
            object.__setattr__(self, name, value)

    @property
    def max_sender(self) -> int:
        return self._sender_mask

    def can_id(self, op: Op, sender: int) -> int:
        """The arbitration ID node `sender` transmits `op` messages under."""
        if isinstance(sender, bool) or not isinstance(sender, int) or not 0 <= sender <= self._sender_mask:
            raise ValueError(f"a sender on {'a 29' if self.extended else 'an 11'}-bit CAN bus must be a node id "
                             f"in 0..{self._sender_mask}, got {sender!r}")
        return self._match_value | int(op) << self._op_shift | sender

    def parse(self, arbitration_id: int, is_extended_id: bool) -> tuple[Op, int] | None:
        """(op, sender) of an ID in this scheme, or None for any other ID."""
        if is_extended_id != self.extended or arbitration_id & self._match_mask != self._match_value:
            return None
        return (Op.GET if arbitration_id >> self._op_shift & 1 else Op.PUT), arbitration_id & self._sender_mask

    def can_filters(self) -> list[dict[str, Any]]:
        """python-can `can_filters` that pass exactly this scheme's IDs (both ops, every sender)."""
        return [{"can_id": self._match_value, "can_mask": self._match_mask, "extended": self.extended}]


def _shown(base: object) -> str:
    """An id_base as the user wrote it: in hex."""
    return f"{base:#05x}" if isinstance(base, int) and not isinstance(base, bool) else repr(base)


def _require(ok: bool, complaint: str) -> None:
    if not ok:
        raise ValueError(complaint)


class CanFraming(Framing[can.Message]):
    """One stigmergy message per classic frame, or FD batches; decodes what any sender put on the bus.

    `sender` is this node's id: the ID field it transmits under. Drops (counted
    per frame, `op_mismatch` per message): `error_frame`, `unknown_id`,
    `remote_frame`, `bad_dlc`, `op_mismatch` (a message whose op bit differs
    from its frame ID's op).
    """

    names_senders = True  # the frame ID carries the sender's id
    capture_medium = "can"  # python-can's log formats

    def __init__(self, scheme: CanIdScheme, sender: int, *, fd: bool = False, bitrate_switch: bool = True) -> None:
        self.scheme = scheme
        self.sender = sender
        self.fd = fd
        self.bitrate_switch = bitrate_switch and fd
        self.name = "canfd" if fd else "can"
        self.carries_tags = fd  # a classic frame's 8 bytes have no room
        self.drops = Counters()
        self._ids = (scheme.can_id(Op.PUT, sender), scheme.can_id(Op.GET, sender))
        self._parse = scheme.parse

    # -- sending ---------------------------------------------------------------
    def _frame(self, op: int, payload: bytes) -> can.Message:
        return can.Message(arbitration_id=self._ids[op], is_extended_id=self.scheme.extended, data=payload,
                           is_fd=self.fd, bitrate_switch=self.bitrate_switch)

    def encode(self, msg: Message) -> list[can.Message]:
        return [self._frame(msg[0] >> 15, encode(msg))]

    def encode_batch(self, messages: Iterable[Message]) -> list[can.Message]:
        """Frames carrying `messages`: one each on classic CAN; FD frames packed full, PUTs first.

        A frame's ID carries one op, so PUTs and GETs travel in separate frames.
        A run of n messages goes out as the fewest frames of allowed sizes
        (greedy: 7 = 6 + 1, 5 = 4 + 1).
        """
        if not self.fd:
            return [frame for msg in messages for frame in self.encode(msg)]
        by_op: tuple[list[bytes], list[bytes]] = ([], [])
        for msg in messages:
            by_op[msg[0] >> 15].append(encode(msg))
        frames = []
        for op, payloads in enumerate(by_op):
            start = 0
            while start < len(payloads):
                size = max(n for n in FD_BATCH_SIZES if n <= len(payloads) - start)
                frames.append(self._frame(op, b"".join(payloads[start:start + size])))
                start += size
        return frames

    def encode_tagged(self, records: Sequence[Tagged]) -> list[can.Message]:
        """One FD frame of 20 data bytes per record, under its message's op (classic CAN: no room)."""
        if not self.fd:
            return super().encode_tagged(records)
        return [self._frame(record.message[0] >> 15, encode_record(record)) for record in records]

    # -- receiving -------------------------------------------------------------
    def feed(self, frame: can.Message) -> list[Message]:
        want_get = self._op_of(frame)
        if want_get is None:
            return []
        data = frame.data
        if frame.is_fd and len(data) == RECORD_SIZE:
            return [msg for msg, _ in self._record(data, want_get)]
        if not (len(data) in _FD_LENGTHS if frame.is_fd else len(data) == MESSAGE_SIZE):
            self.drops["bad_dlc"] += 1
            return []
        messages = list(decode_many(data))
        kept = [m for m in messages if bool(m[0] & GET_BIT) == want_get]
        if len(kept) != len(messages):
            self.drops["op_mismatch"] += len(messages) - len(kept)
        return kept

    def feed_tagged(self, frame: can.Message) -> list[tuple[Message, Tagged | None]]:
        if frame.is_fd and len(frame.data) == RECORD_SIZE:
            want_get = self._op_of(frame)
            return [] if want_get is None else self._record(frame.data, want_get)
        return [(msg, None) for msg in self.feed(frame)]

    def _op_of(self, frame: can.Message) -> bool | None:
        """True for a frame under a GET ID of ours, False for a PUT's, None (counted) for any other frame."""
        if frame.is_error_frame:
            self.drops["error_frame"] += 1
            return None
        parsed = self._parse(frame.arbitration_id, frame.is_extended_id)
        if parsed is None:
            self.drops["unknown_id"] += 1
            return None
        if frame.is_remote_frame:
            self.drops["remote_frame"] += 1
            return None
        return parsed[0] is Op.GET

    def _record(self, data: bytes | bytearray, want_get: bool) -> list[tuple[Message, Tagged | None]]:
        record = decode_record(bytes(data))
        if bool(record.message[0] & GET_BIT) != want_get:
            self.drops["op_mismatch"] += 1
            return []
        return [(record.message, record)]

    @property
    def capture_name(self) -> str:
        return CAPTURE_NAME

    def replay_unit(self, unit: can.Message, recorded_as: str, direction: str) -> can.Message | None:
        """A copy of the recorded frame (no recorded timestamp or channel), where this link's IDs are those a CAN
        capture is read with (11-bit, base 0x600, stigmergy 0); else None: its messages go in this link's IDs."""
        scheme = self.scheme
        if recorded_as != CAPTURE_NAME or scheme.extended or scheme.base not in (None, DEFAULT_BASE_11BIT) \
                or scheme.stigmergy:
            return None
        return can.Message(arbitration_id=unit.arbitration_id, is_extended_id=unit.is_extended_id, data=unit.data,
                           is_fd=unit.is_fd, bitrate_switch=unit.bitrate_switch, is_remote_frame=unit.is_remote_frame,
                           dlc=unit.dlc, check=False)

    def can_id(self, op: Op, sender: int) -> int | None:
        return self.scheme.can_id(op, sender)

    def sender_of(self, frame: can.Message) -> int | None:
        """The transmitting node's id (from the frame's ID), or None if the ID is not ours."""
        if frame.is_error_frame:
            return None
        parsed = self._parse(frame.arbitration_id, frame.is_extended_id)
        return None if parsed is None else parsed[1]

    def tick(self) -> None:
        """Nothing to expire: every CAN frame is complete in itself."""


def can_framing_for(robot_id: int, id_base: int | None = None, extended: bool = False,
                    stigmergy: int = 0) -> CanFraming:
    """The CAN framing a node with this id transmits under (and decodes every sender with)."""
    return CanFraming(CanIdScheme(extended=extended, base=id_base, stigmergy=stigmergy), sender=robot_id)


def can_framing(id_base: int | None = None, extended: bool = False, stigmergy: int = 0) -> CanFraming:
    """A CAN framing that decodes what any sender put on a bus with this ID scheme."""
    return can_framing_for(LISTENER_ID, id_base, extended, stigmergy)
