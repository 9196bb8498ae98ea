"""8-bit BittyBuzz lamports against our 16-bit timestamps, over long random histories on both sides.

A Kilobot store that follows BittyBuzz's receive rules (bbzmsg.c `bbzmsg_process_vstig`,
HEAD) and our real engine exchange versions through `BittyBuzzTranslator`, with writes
and message loss on both sides. At every crossing:

- toward the Kilobots, a lamport is one step past the last one the bridge saw or
  sent for that key (two when a pending repair was overtaken by a newer version),
  or that very version again: never a jump of 50 or more, never a used lamport
  with another value;
- toward our side, a timestamp is strictly newer than the last one the bridge saw
  or produced for that key: never an equal timestamp with another value.

After the history, a few loss-free rounds of gets must bring both sides to one value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.dialects.bittybuzz import BbzOp, BbzType, BbzVstig
from vstig_hw.dialects.lamport import LamportBridge, Verdict, advance, bbz_is_newer
from vstig_hw.dialects.mapping import parse_deployment
from vstig_hw.dialects.translate import BittyBuzzTranslator
from vstig_hw.engine import Stigmergy
from vstig_hw.timestamps import is_newer
from vstig_hw.wire import Message, Op

DEPLOYMENT = parse_deployment("""
[keys]
x = { key = 1, type = "int16" }
y = { key = 2, type = "int16" }
light = { key = 3, type = "int16", bbz_id = 50 }
""")
IDS = {1: 41, 2: 42, 3: 50}
GATEWAY = 500


@dataclass
class KiloEntry:
    lamport: int
    value: int
    robot: int


@dataclass
class KilobotStore:
    """BittyBuzz's vstig rules for held and new keys; `outbox` is what it broadcasts."""

    threshold: int = 50
    entries: dict[int, KiloEntry] = field(default_factory=dict)
    outbox: list[BbzVstig] = field(default_factory=list)

    def put(self, bbz_key: int, value: int, robot: int) -> None:
        old = self.entries.get(bbz_key)
        lamport = (old.lamport + 1) & 0xFF if old else 1
        self.entries[bbz_key] = KiloEntry(lamport, value, robot)
        self.outbox.append(self._message(BbzOp.PUT, bbz_key))

    def query_all(self, keys: list[int]) -> None:
        """A get() of each key: a QUERY of the entry, or nil at lamport 0 for a key not held."""
        self.outbox.extend(self._message(BbzOp.QUERY, key) if key in self.entries
                           else BbzVstig(BbzOp.QUERY, 1, key, BbzType.NIL, 0, 0) for key in keys)

    def _message(self, op: BbzOp, bbz_key: int) -> BbzVstig:
        entry = self.entries[bbz_key]
        return BbzVstig(op, entry.robot, bbz_key, BbzType.INT, entry.value & 0xFFFF, entry.lamport)

    def receive(self, msg: BbzVstig) -> None:
        local = self.entries.get(msg.key)
        value = msg.value - 0x10000 if msg.value & 0x8000 else msg.value
        if local is None or bbz_is_newer(msg.lamport, local.lamport, self.threshold):
            self.entries[msg.key] = KiloEntry(msg.lamport, value, msg.robot)
            self.outbox.append(self._message(BbzOp.PUT, msg.key))
        elif local.lamport == msg.lamport and local.robot != msg.robot:
            if msg.robot >= local.robot:
                self.entries[msg.key] = KiloEntry(msg.lamport, value, msg.robot)
            self.outbox.append(self._message(BbzOp.PUT, msg.key))


class Crossing:
    """The bridge under test, with the invariants checked at every message it passes."""

    def __init__(self) -> None:
        self.translator = BittyBuzzTranslator(DEPLOYMENT)
        self.engine = Stigmergy(GATEWAY)
        self.kilobots = KilobotStore()
        self.last_lamport: dict[int, tuple[int, int]] = {}
        self.last_timestamp: dict[int, int] = {}

    def _to_kilobots(self, msg: BbzVstig, lost: bool) -> None:
        """1..49 steps past the last lamport seen or sent (one, unless a repair was superseded), or that version."""
        last = self.last_lamport.get(msg.key)
        assert last is None or 1 <= (msg.lamport - last[0]) & 0xFF <= 2 or last == (msg.lamport, msg.value), (last, msg)
        self.last_lamport[msg.key] = (msg.lamport, msg.value)
        if not lost:
            self.kilobots.receive(msg)

    def kilobots_to_ours(self, lost: bool) -> None:
        outbox, self.kilobots.outbox = self.kilobots.outbox, []
        for msg in outbox if not lost else ():
            ours = self.translator.to_ours(msg)
            if msg.value_type != BbzType.NIL:
                self.last_lamport[msg.key] = (msg.lamport, msg.value)
            if ours is not None and ours.timestamp:
                last = self.last_timestamp.get(ours.key)
                assert last is None or is_newer(ours.timestamp, last), (last, ours)
                self.last_timestamp[ours.key] = ours.timestamp
            if ours is not None:
                self.engine.receive(ours)

    def ours_to_kilobots(self, lost: bool) -> None:
        for msg in self.engine.drain():
            out = self.translator.from_ours(msg)
            if out is not None:
                self.last_timestamp[msg.key] = msg.timestamp
                self._to_kilobots(out, lost)

    def settle(self) -> None:
        for _ in range(8):
            self.kilobots.query_all(sorted(IDS.values()))
            for key in IDS:
                self.engine.get(key)
            self.ours_to_kilobots(lost=False)
            self.kilobots_to_ours(lost=False)
            self.ours_to_kilobots(lost=False)


keys = st.sampled_from(sorted(IDS))
values = st.integers(-30000, 30000)
actions = st.one_of(
    st.tuples(st.just("kput"), keys, values, st.integers(1, 9)),
    st.tuples(st.just("oput"), keys, values),
    st.tuples(st.just("ojump"), keys, values, st.integers(1, 20000), st.integers(1, 900), st.booleans()),
    st.tuples(st.just("k2o"), st.booleans()),
    st.tuples(st.just("o2k"), st.booleans()),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(actions, min_size=1, max_size=400))
def test_long_histories_keep_both_clocks_honest_and_converge(history: list[tuple[object, ...]]) -> None:
    crossing = Crossing()
    for action in history:
        kind = action[0]
        if kind == "kput":
            _, key, value, robot = action
            crossing.kilobots.put(IDS[key], value, robot)  # type: ignore[index, arg-type]
        elif kind == "oput":
            _, key, value = action
            crossing.engine.put(key, value & 0xFFFF)  # type: ignore[arg-type, operator]
        elif kind == "ojump":  # another robot on our side, far ahead in time
            _, key, value, steps, robot, lost = action
            entry = crossing.engine.entry(key)  # type: ignore[arg-type]
            timestamp = advance(entry.timestamp if entry else 1, steps)  # type: ignore[arg-type]
            crossing.engine.receive(Message(Op.PUT, key, value & 0xFFFF, timestamp, robot))  # type: ignore[arg-type, operator]
            crossing.ours_to_kilobots(lost)  # type: ignore[arg-type]
        elif kind == "k2o":
            crossing.kilobots_to_ours(action[1])  # type: ignore[arg-type]
        else:
            crossing.ours_to_kilobots(action[1])  # type: ignore[arg-type]
    crossing.settle()
    for key, bbz_key in IDS.items():
        kilo, ours = crossing.kilobots.entries.get(bbz_key), crossing.engine.entry(key)
        if kilo is not None or ours is not None:
            assert kilo is not None and ours is not None, (key, kilo, ours)
            assert kilo.value & 0xFFFF == ours.value, (key, kilo, ours)


def test_window_cases_by_hand() -> None:
    # "message L against local O" from bbzmsg.c, threshold 50
    assert bbz_is_newer(1, 0) and bbz_is_newer(0, 255) and bbz_is_newer(49, 0)
    assert not bbz_is_newer(50, 0) and not bbz_is_newer(5, 5) and not bbz_is_newer(200, 10)
    clock = LamportBridge()
    assert clock.from_kilobots(7, 1, (1, 42), 3) == (Verdict.NEWER, clock.anchors[7])
    assert clock.anchors[7].timestamp == 1
    assert clock.from_kilobots(7, 5, (1, 43), 3)[1].timestamp == 5  # 4 steps ahead
    assert clock.from_kilobots(7, 5, (1, 43), 9)[0] is Verdict.REPEAT  # a query reply with the replier's id
    verdict, repair = clock.from_kilobots(7, 200, (1, 1), 3)
    assert verdict is Verdict.STALE and (repair.lamport, repair.value) == (201, (1, 43))
    assert clock.to_kilobots(7, 6, (1, 44), GATEWAY) == 202
    assert clock.to_kilobots(7, 6, (1, 44), GATEWAY) is None  # they have it
    assert clock.to_kilobots(7, 60000, (1, 45), GATEWAY) is None  # older in serial arithmetic
    assert clock.to_kilobots(9, 0x1234, (1, 1), GATEWAY) == 0x34  # first contact: equal modulo 256
    assert advance(0xFFFF, 1) == 1 and advance(0xFFF0, 0x20) == 0x11
