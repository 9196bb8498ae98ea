"""What sniff shows per key: newest entry, counts, conflicts, and senders with a stale view."""

from __future__ import annotations

import pytest

from vstig_hw import Message, Op
from vstig_hw.engine import Stigmergy, larger_value_wins
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard


def heard(op: Op, value: int, ts: int, robot: int, sender: int | None, t: float = 1.0) -> Heard:
    return Heard(Message(op, 5, value, ts, robot), "can0", t, sender)


def test_newest_entry_counts_conflicts_and_stale_senders() -> None:
    view = SwarmView()
    view.add(heard(Op.PUT, 10, 1, 1, sender=1))
    view.add(heard(Op.PUT, 20, 2, 2, sender=2))
    view.add(heard(Op.PUT, 30, 2, 3, sender=3))  # same timestamp, other robot: a conflict robot 3 wins
    view.add(heard(Op.GET, 0, 0, 4, sender=4))  # an empty GET: says nothing about the entry
    view.add(heard(Op.GET, 10, 1, 1, sender=5, t=2.0))  # robot 5 still believes timestamp 1
    key = view.keys[5]
    assert (key.value, key.timestamp, key.robot) == (30, 2, 3)
    assert (key.puts, key.gets, key.conflicts) == (3, 2, 1)
    assert key.stale_senders() == [1, 4, 5] and key.last_seen == 2.0
    view.add(heard(Op.PUT, 30, 2, 3, sender=5))  # robot 5 catches up
    assert view.keys[5].stale_senders() == [1, 4]


def test_links_that_do_not_name_senders_show_no_stale_senders() -> None:
    view = SwarmView()
    view.add(heard(Op.PUT, 1, 3, 1, sender=None))
    view.add(heard(Op.PUT, 1, 1, 2, sender=None))
    assert view.keys[5].stale_senders() == [] and view.messages == 2


@pytest.mark.parametrize("rule", [None, larger_value_wins])
def test_a_conflict_is_settled_by_the_engines_rule_and_counted_once(rule: object) -> None:
    view = SwarmView() if rule is None else SwarmView(onconflict=larger_value_wins)
    engine = Stigmergy(0xFFFF) if rule is None else Stigmergy(0xFFFF, onconflict=larger_value_wins)
    messages = [heard(Op.PUT, 100, 1, 7, sender=7)] + [heard(Op.PUT, 200, 1, 8, sender=s) for s in (8, 9, 10)]
    messages += [heard(Op.PUT, 100, 1, 7, sender=11)]  # a late relay of the loser: the same conflict
    for message in messages:
        view.add(message)
        engine.receive(message.message)
    key = view.keys[5]
    assert (key.value, key.timestamp, key.robot) == tuple(engine.entry(5) or ()) == (200, 1, 8)
    assert key.conflicts == 1
    view.add(heard(Op.PUT, 50, 1, 9, sender=9))  # a third robot wrote timestamp 1: a second conflict
    engine.receive(Message(Op.PUT, 5, 50, 1, 9))
    assert (key.value, key.robot) == tuple((engine.entry(5) or (0, 0, 0))[0::2]) and key.conflicts == 2
