"""What sniff shows per key: newest entry, counts, conflicts, and senders with a stale view."""

from __future__ import annotations

from vstig_hw import Message, Op
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard


def heard(op: Op, value: int, ts: int, robot: int, sender: int | None, t: float = 1.0) -> Heard:
    return Heard(Message(op, 5, value, ts, robot), "can0", t, sender)


def test_newest_entry_counts_conflicts_and_stale_senders() -> None:
    view = SwarmView()
    view.add(heard(Op.PUT, 10, 1, 1, sender=1))
    view.add(heard(Op.PUT, 20, 2, 2, sender=2))
    view.add(heard(Op.PUT, 30, 2, 3, sender=3))  # same timestamp, other robot: a conflict
    view.add(heard(Op.GET, 0, 0, 4, sender=4))  # an empty GET: says nothing about the entry
    view.add(heard(Op.GET, 10, 1, 1, sender=5, t=2.0))  # robot 5 still believes timestamp 1
    key = view.keys[5]
    assert (key.value, key.timestamp, key.robot) == (20, 2, 2)
    assert (key.puts, key.gets, key.conflicts) == (3, 2, 1)
    assert key.stale_senders() == [1, 4, 5] and key.last_seen == 2.0
    view.add(heard(Op.PUT, 20, 2, 2, sender=5))  # robot 5 catches up
    assert view.keys[5].stale_senders() == [1, 4]


def test_links_that_do_not_name_senders_show_no_stale_senders() -> None:
    view = SwarmView()
    view.add(heard(Op.PUT, 1, 3, 1, sender=None))
    view.add(heard(Op.PUT, 1, 1, 2, sender=None))
    assert view.keys[5].stale_senders() == [] and view.messages == 2
