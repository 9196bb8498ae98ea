"""XbeeMav's packets: how ROSBuzz drones put their Mavlink messages into XBee RF data.

MISTLab/XbeeMav (src/PacketsHandler.cpp, src/SerialDevice.cpp; 'L' on its network_status
branch) serializes a `mavros_msgs/Mavlink` as u8 sysid, u8 msgid, then each `payload64`
word big-endian, and sends it in Transmit Requests (0x10, broadcast, API mode 1) as:

- `S` (single): 'S', then the serialized message, when it is under 250 bytes;
- `F` (fragment), for messages of 251 to 64,000 bytes: 'F', u8 packet id (the msgid), u8
  node address (the 8-bit id XbeeMav's database.xml gives the module), u8 fragment id,
  u16 offset (big-endian), then up to 250 bytes of the serialized message;
- `P` (ping, after the fragments): 'P', packet id, node address, u8 number of fragments;
- `A` (acknowledgement of a ping): 'A', packet id, node address, then the missing fragment ids;
- `L` (packet-loss report, unicast): 'L', node address, u16 packets received, u8 report id.

A serialized message of exactly 250 bytes matches neither branch and is never sent.
ROSBuzz's Buzz messages are always `S` packets (a block of at most 190 bytes, 234 bytes
serialized). `dialects.framing.XbeeMavFraming` reads all five: `S` and reassembled `F` packets carry Buzz
blocks (`RosBuzzDecoder`), `P` may complete a packet, `A` and `L` are counted
(`xbeemav_control`). It sends `S` packets only, under the gateway's robot id, and never
acknowledges: a sender waits for the acknowledgements of the nodes it has heard from, and
a gateway that never sends fragments or acknowledgements is never one of them.

Reassembly (`XbeeMavReassembler`) is keyed by the module's 64-bit source address and the
packet id, bounded and timed out: at most `MAX_PARTIALS` packets in progress (a new one
evicts the oldest: `fragment_evicted`), each at most 64,000 bytes (`fragment_bad` beyond,
or for a header too short); fragments older than `expiry_ticks` control periods are
dropped (`fragment_stale`); a fragment seen before, or one of a packet just completed, is
`fragment_repeat` (senders retransmit until every node acknowledged). A packet completes
when its fragments cover it from offset 0 with no gap and either the last is shorter than
250 bytes or a ping gave the number of fragments and all are in.
"""

from __future__ import annotations

from collections import deque

from ..counters import Counters

__all__ = ["DEFAULT_EXPIRY_TICKS", "FRAGMENT_HEADER", "MAX_PACKET", "MAX_PARTIALS", "MTU", "XbeeMavReassembler",
           "fragment_packets"]

MTU = 250  # bytes of a message per fragment (PacketsHandler XBEE_NETWORK_MTU)
MAX_PACKET = 64000  # the largest message XbeeMav fragments (MAX_PACEKT_SIZE)
FRAGMENT_HEADER = 6  # 'F', packet id, node, fragment id, u16 offset
MAX_PARTIALS = 8  # packets reassembled at once; 8 x 64,000 bytes at most held
DEFAULT_EXPIRY_TICKS = 50  # control periods a packet's fragments may take (5 s at 0.1 s; XbeeMav retries ~seconds)
_RECENT = 16  # completed packets remembered, so their retransmitted fragments are not a new packet


def fragment_packets(serialized: bytes, packet_id: int, node: int) -> list[bytes]:
    """The `F` packets XbeeMav sends for one serialized message (Handle_Mavlink_Message)."""
    return [b"F" + bytes((packet_id & 0xFF, node & 0xFF, number & 0xFF)) + offset.to_bytes(2, "big")
            + serialized[offset:offset + MTU] for number, offset in enumerate(range(0, len(serialized), MTU))]


class _Partial:
    __slots__ = ("born", "fragments", "total")

    def __init__(self, born: int) -> None:
        self.born = born  # reassembler tick of the first fragment
        self.fragments: dict[int, tuple[int, bytes]] = {}  # fragment id -> (offset, bytes)
        self.total: int | None = None  # fragments the sender's ping announced


class XbeeMavReassembler:
    """`F` and `P` packets from any number of modules -> whole serialized messages (see the module docstring)."""

    def __init__(self, drops: Counters | None = None, expiry_ticks: int = DEFAULT_EXPIRY_TICKS) -> None:
        if isinstance(expiry_ticks, bool) or not isinstance(expiry_ticks, int) or expiry_ticks < 1:
            raise ValueError(f"xbeemav expiry_ticks must be a positive integer, got {expiry_ticks!r}")
        self.drops = drops if drops is not None else Counters()
        self.expiry_ticks = expiry_ticks
        self._partials: dict[tuple[int | None, int], _Partial] = {}
        self._recent: deque[tuple[int | None, int]] = deque(maxlen=_RECENT)
        self._now = 0

    @property
    def pending(self) -> int:
        return len(self._partials)

    def fragment(self, source: int | None, packet: bytes) -> bytes | None:
        """The message this `F` packet completes, if any."""
        if len(packet) <= FRAGMENT_HEADER:
            self.drops["fragment_bad"] += 1
            return None
        packet_id, number = packet[1], packet[3]
        offset = packet[4] << 8 | packet[5]
        data = packet[FRAGMENT_HEADER:]
        if offset + len(data) > MAX_PACKET:
            self.drops["fragment_bad"] += 1
            return None
        key = (source, packet_id)
        if key in self._recent:
            self.drops["fragment_repeat"] += 1
            return None
        partial = self._partials.get(key)
        if partial is None:
            partial = self._start(key)
        elif number in partial.fragments:
            self.drops["fragment_repeat"] += 1
            return None
        partial.fragments[number] = (offset, data)
        return self._complete(key, partial)

    def ping(self, source: int | None, packet: bytes) -> bytes | None:
        """The message a `P` packet completes (it says how many fragments there were), if any."""
        if len(packet) < 4:
            return None
        partial = self._partials.get((source, packet[1]))
        if partial is None:
            return None
        partial.total = packet[3]
        return self._complete((source, packet[1]), partial)

    def tick(self) -> None:
        """One control period: packets whose first fragment came `expiry_ticks` periods ago are dropped."""
        self._now += 1
        horizon = self._now - self.expiry_ticks
        for key, partial in list(self._partials.items()):
            if partial.born < horizon:
                self.drops["fragment_stale"] += 1
                del self._partials[key]

    def _start(self, key: tuple[int | None, int]) -> _Partial:
        if len(self._partials) >= MAX_PARTIALS:
            oldest = min(self._partials, key=lambda k: self._partials[k].born)
            del self._partials[oldest]
            self.drops["fragment_evicted"] += 1
        partial = self._partials[key] = _Partial(self._now)
        return partial

    def _complete(self, key: tuple[int | None, int], partial: _Partial) -> bytes | None:
        pieces = sorted(partial.fragments.values())
        end = 0
        for offset, data in pieces:
            if offset != end:
                return None  # a gap (or an overlap: not XbeeMav's)
            end += len(data)
        last_short = len(pieces[-1][1]) < MTU
        if not (last_short or (partial.total is not None and len(pieces) == partial.total)):
            return None
        del self._partials[key]
        self._recent.append(key)
        return b"".join(data for _offset, data in pieces)
