"""`epuck4`: one 8-byte message as three 4-byte e-puck range-and-bearing words.

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).

Word (32 bits, big-endian on the air and on the UART)::

     31 30 29    26 25                                   0
    +-----+--------+--------------------------------------+
    |index| group  |                chunk                 |
    +-----+--------+--------------------------------------+
       2      4                      26

C = CRC-32 of the 8 message bytes; group = C[31..28] in all three words; the 78
bits P = message (64) || C[27..14] (14) are cut into three 26-bit chunks from the
top. Index 3 is reserved. 4 + 14 = 18 check bits: a set of fragments mixed up
from different messages is accepted with probability 2^-18.

Reassembly (firmware_spec/SPEC.md 6.2.3 is normative): partials keyed by group; each
fragment remembers when it came. A clash on a filled slot evicts that fragment
and everything older in the partial; a complete set whose check fails loses its
oldest fragment; fragments older than `expiry_ticks` ticks are dropped as stale.
Older fragments are the ones that go because they are the leftovers of an
earlier message that lost a fragment.

On a UART each word travels as its own serial frame (cobsframe), 8 bytes a word.
"""

from __future__ import annotations

from ..counters import Counters
from ..crc import crc32
from ..wire import Message, decode, encode
from .base import SerialFraming
from .cobsframe import DELIMITER, CobsFrameReader, encode_frame

__all__ = ["WORDS_PER_MESSAGE", "WORD_SIZE", "Epuck4Framing", "EpuckFragmenter", "EpuckReassembler"]

WORD_SIZE = 4
WORDS_PER_MESSAGE = 3
_CHUNK_BITS = 26
_CHUNK_MASK = (1 << _CHUNK_BITS) - 1
_CHECK_BITS = 14
_CHECK_MASK = (1 << _CHECK_BITS) - 1
_RESERVED_INDEX = 3


def _group_and_check(message_bytes: bytes) -> tuple[int, int]:
    c = crc32(message_bytes)
    return c >> 28, (c >> 14) & _CHECK_MASK


class EpuckFragmenter:
    """Message -> its three radio words, in index order."""

    def fragment(self, msg: Message) -> list[bytes]:
        raw = encode(msg)
        group, check = _group_and_check(raw)
        bits = (int.from_bytes(raw, "big") << _CHECK_BITS) | check
        tag = group << _CHUNK_BITS
        return [((index << 30) | tag | ((bits >> (_CHUNK_BITS * (2 - index))) & _CHUNK_MASK)).to_bytes(4, "big")
                for index in range(WORDS_PER_MESSAGE)]


class _Partial:
    __slots__ = ("chunks", "order", "ticks")

    def __init__(self) -> None:
        self.chunks: list[int | None] = [None, None, None]
        self.order = [0, 0, 0]  # arrival sequence number of each filled slot
        self.ticks = [0, 0, 0]  # reassembler clock when each slot was filled

    def evict(self, slot: int) -> None:
        self.chunks[slot] = None

    def filled(self) -> list[int]:
        return [slot for slot in range(3) if self.chunks[slot] is not None]


class EpuckReassembler:
    """Radio words from any number of senders -> complete, checked messages."""

    def __init__(self, drops: Counters | None = None, expiry_ticks: int = 3) -> None:
        if isinstance(expiry_ticks, bool) or not isinstance(expiry_ticks, int) or expiry_ticks < 1:
            raise ValueError(f"epuck4 expiry_ticks must be a positive integer, got {expiry_ticks!r}")
        self.drops = drops if drops is not None else Counters()
        self.expiry_ticks = expiry_ticks
        self._partials: dict[int, _Partial] = {}
        self._now = 0
        self._arrivals = 0

    @property
    def pending(self) -> int:
        """Partials waiting for fragments."""
        return len(self._partials)

    def feed(self, word: bytes) -> Message | None:
        """The message this word completes, if any."""
        if len(word) != WORD_SIZE:
            self.drops["bad_length"] += 1
            return None
        value = int.from_bytes(word, "big")
        index = value >> 30
        if index == _RESERVED_INDEX:
            self.drops["bad_index"] += 1
            return None
        group = (value >> _CHUNK_BITS) & 0xF
        chunk = value & _CHUNK_MASK
        partial = self._partials.get(group)
        if partial is None:
            partial = self._partials[group] = _Partial()
        else:
            held = partial.chunks[index]
            if held == chunk:
                self.drops["duplicate"] += 1
                return None
            if held is not None:
                self.drops["collision"] += 1
                cut = partial.order[index]
                for slot in partial.filled():
                    if partial.order[slot] <= cut:
                        partial.evict(slot)
        self._arrivals += 1
        partial.chunks[index] = chunk
        partial.order[index] = self._arrivals
        partial.ticks[index] = self._now
        if None in partial.chunks:
            return None
        return self._complete(group, partial)

    def _complete(self, group: int, partial: _Partial) -> Message | None:
        c0, c1, c2 = partial.chunks
        assert c0 is not None and c1 is not None and c2 is not None
        bits = (c0 << 52) | (c1 << 26) | c2
        raw = (bits >> _CHECK_BITS).to_bytes(8, "big")
        if _group_and_check(raw) != (group, bits & _CHECK_MASK):
            self.drops["check"] += 1
            partial.evict(min(range(3), key=partial.order.__getitem__))
            return None
        del self._partials[group]
        return decode(raw)

    def tick(self) -> None:
        """One control period: fragments older than `expiry_ticks` periods are dropped (`stale`)."""
        self._now += 1
        horizon = self._now - self.expiry_ticks
        for group, partial in list(self._partials.items()):
            old = [slot for slot in partial.filled() if partial.ticks[slot] < horizon]
            if old:
                self.drops["stale"] += 1
                for slot in old:
                    partial.evict(slot)
                if not partial.filled():
                    del self._partials[group]


class Epuck4Framing(SerialFraming):
    """epuck4 over a UART: each radio word is one serial frame."""

    name = "epuck4"
    default_baud = 115200
    transmit_only = False
    preamble = DELIMITER  # sent before the first frame after the port opens (SPEC 6.0.3)

    def __init__(self, expiry_ticks: int = 3) -> None:
        self.drops = Counters()
        self.fragmenter = EpuckFragmenter()
        self.reassembler = EpuckReassembler(self.drops, expiry_ticks)
        self._reader = CobsFrameReader(WORD_SIZE, self.drops)

    def encode(self, msg: Message) -> list[bytes]:
        return [encode_frame(word) for word in self.fragmenter.fragment(msg)]

    def feed(self, unit: bytes) -> list[Message]:
        messages = []
        for word in self._reader.feed(unit):
            msg = self.reassembler.feed(word)
            if msg is not None:
                messages.append(msg)
        return messages

    def tick(self) -> None:
        self.reassembler.tick()

    def reset(self) -> None:
        self._reader.reset()
