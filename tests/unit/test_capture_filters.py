"""The capture filter: its numpy mask equals its definition; units are kept, dropped or re-encoded as promised."""

from __future__ import annotations

import can
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.capture.decoded import RecordFilter, filter_records
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.records import CAN_FRAMING, Record
from vstig_hw.framing import make_serial_framing
from vstig_hw.wire import Message, Op, encode

LINKS = ["can0", "can1", "radio"]
small = st.integers(0, 3)
subset = st.one_of(st.none(), st.frozensets(small, min_size=1))
filters = st.builds(Filter, keys=subset, robots=subset, senders=subset,
                    ops=st.one_of(st.none(), st.frozensets(st.sampled_from(list(Op)), min_size=1)),
                    links=st.one_of(st.none(), st.frozensets(st.sampled_from(LINKS), min_size=1)),
                    since=st.one_of(st.none(), st.floats(0, 2)), until=st.one_of(st.none(), st.floats(0, 3)))
rows = st.lists(st.tuples(st.floats(0, 3), st.integers(0, 2), st.integers(-1, 3), st.sampled_from(list(Op)),
                          small, small), min_size=1, max_size=40)


Row = tuple[float, int, int, Op, int, int]


@settings(max_examples=200, deadline=None)
@given(filters, rows)
def test_mask_is_the_definition_over_columns(keep: Filter, messages: list[Row]) -> None:
    t, link, sender, op, key, robot = (np.array(c) for c in zip(*messages, strict=True))
    mask = keep.mask(t.astype(np.float64), link, LINKS, sender, op.astype(np.int64), key, robot)
    expected = [keep.accepts(tt, LINKS[ll], None if ss < 0 else ss, Message(oo, kk, 0, 1, rr))
                for tt, ll, ss, oo, kk, rr in messages]
    assert mask.tolist() == expected


def _frame(t: float, sender: int, msg: Message, link: str = "can0") -> Record:
    frame = can.Message(timestamp=t, arbitration_id=0x600 | msg.op << 8 | sender, data=encode(msg),
                        is_extended_id=False)
    return Record(t, link, CAN_FRAMING, frame)


def test_can_frames_are_kept_or_dropped_whole() -> None:
    records = [_frame(0.0, 1, Message(Op.PUT, 3, 7, 1, 1)), _frame(0.5, 2, Message(Op.GET, 4, 7, 1, 1)),
               _frame(1.0, 2, Message(Op.PUT, 3, 8, 2, 2), "can1"), _frame(2.0, 1, Message(Op.PUT, 3, 9, 3, 1))]
    assert list(filter_records(records, Filter())) == records
    assert list(filter_records(records, Filter(keys=frozenset({3}), senders=frozenset({1})))) == \
        [records[0], records[3]]
    assert list(filter_records(records, Filter(links=frozenset({"can1"})))) == [records[2]]
    assert list(filter_records(records, Filter(since=0.5, until=2.0))) == records[1:3]  # seconds after the first
    assert list(filter_records(records, Filter(ops=frozenset({Op.GET})))) == [records[1]]


def test_a_serial_chunk_cut_by_message_is_re_encoded_in_its_framing() -> None:
    framing = make_serial_framing("epuck4")
    wanted, other = Message(Op.PUT, 3, 7, 1, 1), Message(Op.PUT, 4, 8, 1, 2)
    chunk = b"".join(framing.encode(other)) + b"".join(framing.encode(wanted))
    (kept,) = RecordFilter(Filter(keys=frozenset({3}))).units(Record(1.0, "radio", "epuck4", chunk))
    assert (kept.t, kept.link, kept.framing, kept.unit) == (1.0, "radio", "epuck4", b"".join(framing.encode(wanted)))
    assert make_serial_framing("epuck4").feed(kept.unit) == [wanted]
