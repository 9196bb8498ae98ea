"""The protocol engine, one test per rule (paper §3, Buzz semantics, our decisions)."""

from __future__ import annotations

import pytest

from vstig_hw import Entry, Message, Op, Outcome, Stigmergy
from vstig_hw.engine import larger_value_wins, sum_merge
from vstig_hw.outqueue import OutQueue
from vstig_hw.timestamps import is_newer, next_timestamp

PUT, GET = Op.PUT, Op.GET


def test_put_new_key_starts_at_one_and_queues_put() -> None:
    s = Stigmergy(7)
    s.put(3, 100)
    assert s.entry(3) == Entry(100, 1, 7)
    assert s.drain() == [Message(PUT, 3, 100, 1, 7)]


def test_put_existing_key_increments_and_takes_ownership() -> None:
    s = Stigmergy(7)
    s.receive(Message(PUT, 3, 5, 41, 2))
    s.drain()
    s.put(3, 6)
    assert s.entry(3) == Entry(6, 42, 7)
    assert s.drain() == [Message(PUT, 3, 6, 42, 7)]


def test_get_returns_local_and_queues_get_with_local_view() -> None:
    s = Stigmergy(7)
    s.receive(Message(PUT, 3, 5, 9, 2))
    s.drain()
    assert s.get(3) == 5
    assert s.drain() == [Message(GET, 3, 5, 9, 2)]


def test_get_unknown_returns_none_and_queues_empty_view() -> None:
    s = Stigmergy(7)
    assert s.get(3) is None
    assert s.drain() == [Message(GET, 3, 0, 0, 7)]
    assert not s.has(3) and s.size() == 0


def test_has_size_entries() -> None:
    s = Stigmergy(1)
    s.put(1, 10)
    s.put(2, 20)
    assert s.has(1) and not s.has(3) and s.size() == 2
    assert dict(s.entries()) == {1: Entry(10, 1, 1), 2: Entry(20, 1, 1)}
    for key, _ in s.entries():  # a snapshot: writing while iterating is safe
        s.put(key + 10, 0)
    assert s.size() == 4


def test_receive_newer_put_stores_and_rebroadcasts() -> None:
    s = Stigmergy(1)
    msg = Message(PUT, 4, 9, 3, 2)
    assert s.receive(msg) is Outcome.STORED
    assert s.entry(4) == Entry(9, 3, 2)
    assert s.drain() == [msg]


def test_receive_older_put_is_ignored() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(PUT, 4, 1, 2, 5)) is Outcome.STALE
    assert s.entry(4) == Entry(9, 3, 2)
    assert s.drain() == []


def test_receive_same_put_does_nothing() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(PUT, 4, 9, 3, 2)) is Outcome.SAME
    assert s.drain() == []


def test_receive_put_same_ts_other_robot_is_conflict_higher_robot_wins() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(PUT, 4, 1, 3, 5)) is Outcome.CONFLICT
    assert s.entry(4) == Entry(1, 3, 5)
    assert s.drain() == [Message(PUT, 4, 1, 3, 5)]
    assert s.receive(Message(PUT, 4, 8, 3, 3)) is Outcome.CONFLICT  # lower robot loses
    assert s.entry(4) == Entry(1, 3, 5)
    assert s.drain() == [Message(PUT, 4, 1, 3, 5)]


def test_receive_get_older_than_local_answers_with_put() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(GET, 4, 0, 1, 8)) is Outcome.ANSWERED
    assert s.drain() == [Message(PUT, 4, 9, 3, 2)]


def test_receive_get_empty_view_is_answered_when_we_hold_key() -> None:
    s = Stigmergy(1)
    s.put(4, 9)
    s.drain()
    assert s.receive(Message(GET, 4, 0, 0, 8)) is Outcome.ANSWERED
    assert s.drain() == [Message(PUT, 4, 9, 1, 1)]


def test_receive_get_newer_than_local_stores_and_queues_put() -> None:
    s = Stigmergy(1)
    s.put(4, 9)
    s.drain()
    assert s.receive(Message(GET, 4, 77, 5, 8)) is Outcome.STORED
    assert s.entry(4) == Entry(77, 5, 8)
    assert s.drain() == [Message(PUT, 4, 77, 5, 8)]


def test_receive_get_for_unknown_key_with_data_is_stored() -> None:
    s = Stigmergy(1)
    assert s.receive(Message(GET, 4, 77, 5, 8)) is Outcome.STORED
    assert s.drain() == [Message(PUT, 4, 77, 5, 8)]


def test_receive_empty_get_for_unknown_key_is_dropped_not_relayed() -> None:
    s = Stigmergy(1)
    assert s.receive(Message(GET, 4, 0, 0, 8)) is Outcome.UNKNOWN
    assert s.drain() == [] and not s.has(4)


def test_receive_get_same_view_does_nothing() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(GET, 4, 9, 3, 2)) is Outcome.SAME
    assert s.drain() == []


def test_receive_get_conflict_resolved_and_winner_queued() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    assert s.receive(Message(GET, 4, 5, 3, 6)) is Outcome.CONFLICT
    assert s.entry(4) == Entry(5, 3, 6)
    assert s.drain() == [Message(PUT, 4, 5, 3, 6)]


def test_put_with_reserved_timestamp_zero_is_invalid() -> None:
    s = Stigmergy(1)
    assert s.receive(Message(PUT, 4, 9, 0, 2)) is Outcome.INVALID
    assert not s.has(4) and s.drain() == []


def test_onconflict_chooses_and_keeps_local_timestamp() -> None:
    seen = []

    def pick_remote_value_with_other_ts(key: int, local: Entry, remote: Entry) -> Entry:
        seen.append((key, local, remote))
        return Entry(remote.value, 999, remote.robot)  # a resolver that tampers with ts

    s = Stigmergy(1, onconflict=pick_remote_value_with_other_ts)
    s.receive(Message(PUT, 4, 9, 3, 8))
    assert s.receive(Message(PUT, 4, 5, 3, 2)) is Outcome.CONFLICT
    assert seen == [(4, Entry(9, 3, 8), Entry(5, 3, 2))]
    assert s.entry(4) == Entry(5, 3, 2)  # local timestamp kept


def test_onconflictlost_fires_only_when_own_write_discarded() -> None:
    lost: list[tuple[int, Entry]] = []
    s = Stigmergy(1, onconflictlost=lambda key, entry: lost.append((key, entry)))
    s.put(4, 9)  # ours, ts 1
    s.receive(Message(PUT, 4, 3, 1, 5))  # robot 5 > 1 wins by default
    assert lost == [(4, Entry(9, 1, 1))]
    s.put(6, 9)
    s.receive(Message(PUT, 6, 3, 1, 0))  # we win against robot 0: not lost
    s.receive(Message(PUT, 7, 3, 1, 2))
    s.receive(Message(PUT, 7, 3, 1, 4))  # a conflict between two others
    assert lost == [(4, Entry(9, 1, 1))]


def test_conflict_winner_replaces_pending_same_timestamp_loser() -> None:
    # Buzz keeps the first pending message of a timestamp and would send the
    # stale loser; we send the winner.
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))  # pending: PUT ts3 robot 2
    s.receive(Message(PUT, 4, 1, 3, 5))  # conflict: robot 5 wins
    assert s.drain() == [Message(PUT, 4, 1, 3, 5)]


def test_onconflictlost_fires_once_when_the_lost_write_echoes_back() -> None:
    # Issue 14.3: the echo of our own losing write conflicts again, but it is
    # the remote then, not the entry we held: Buzz does not report it twice.
    lost: list[tuple[int, Entry]] = []
    s = Stigmergy(1, onconflictlost=lambda key, entry: lost.append((key, entry)))
    s.put(4, 9)
    assert s.receive(Message(PUT, 4, 3, 1, 5)) is Outcome.CONFLICT
    assert s.receive(Message(PUT, 4, 9, 1, 1)) is Outcome.CONFLICT  # our write, relayed back
    assert s.receive(Message(GET, 4, 9, 1, 1)) is Outcome.CONFLICT  # and as someone's view
    assert lost == [(4, Entry(9, 1, 1))]
    assert s.entry(4) == Entry(3, 1, 5)


def test_merged_winner_of_another_robot_reports_our_lost_write() -> None:
    # Issue 14.1: robot 2's merge discards our write; we keep robot 2's entry
    # until its merged write arrives, and are told our write was lost.
    lost: list[tuple[int, Entry]] = []
    s = Stigmergy(1, onconflict=sum_merge, onconflictlost=lambda key, entry: lost.append((key, entry)))
    s.put(5, 100)
    assert s.receive(Message(PUT, 5, 200, 1, 2)) is Outcome.CONFLICT
    assert lost == [(5, Entry(100, 1, 1))]
    assert s.entry(5) == Entry(200, 1, 2)
    assert s.drain() == [Message(PUT, 5, 200, 1, 2)]  # our loser is never sent
    assert s.receive(Message(PUT, 5, 300, 2, 2)) is Outcome.STORED


def test_merged_winner_is_a_new_write_of_the_robot_it_names() -> None:
    # Issue 14.4: the merge goes out at the next timestamp, newer than both inputs.
    lost: list[tuple[int, Entry]] = []
    s = Stigmergy(2, onconflict=sum_merge, onconflictlost=lambda key, entry: lost.append((key, entry)))
    s.put(5, 200)
    assert s.receive(Message(GET, 5, 100, 1, 1)) is Outcome.CONFLICT
    assert s.entry(5) == Entry(300, 2, 2)
    assert s.drain() == [Message(PUT, 5, 300, 2, 2)]
    assert lost == []  # our value lives on in our own new write
    assert s.receive(Message(PUT, 5, 100, 1, 1)) is Outcome.STALE  # the inputs are now older


def test_merged_winner_between_two_other_robots_keeps_the_named_entry() -> None:
    s = Stigmergy(9, onconflict=sum_merge)
    s.receive(Message(PUT, 5, 200, 1, 2))
    assert s.receive(Message(PUT, 5, 100, 1, 1)) is Outcome.CONFLICT
    assert s.entry(5) == Entry(200, 1, 2)


def test_merged_winner_naming_a_third_robot_is_refused_by_name() -> None:
    s = Stigmergy(9, onconflict=lambda key, local, remote: Entry(1, local.timestamp, 77))
    s.receive(Message(PUT, 5, 200, 1, 2))
    with pytest.raises(ValueError, match=r"onconflict returned .*robot=77"):
        s.receive(Message(PUT, 5, 100, 1, 1))


def test_pending_get_is_not_replaced_by_an_answer_of_the_same_timestamp() -> None:
    # Issue 14.2: a PUT of our view says less than a GET of it: a neighbour with
    # newer data ignores the PUT but answers the GET.
    s = Stigmergy(1)
    s.put(4, 1)
    s.drain()
    s.get(4)
    assert s.receive(Message(GET, 4, 0, 0, 8)) is Outcome.ANSWERED
    assert s.drain() == [Message(GET, 4, 1, 1, 1)]


def test_three_robots_stale_robot_is_repaired_in_the_round_it_answers() -> None:
    # Issue 14.2 reproducer: A holds (1, ts 1) with a GET queued, C holds (9, ts 2);
    # A answers B's empty GET. If that answer replaced A's GET, C would ignore it
    # as stale and A would stay behind for the round.
    a, b, c = Stigmergy(1), Stigmergy(2), Stigmergy(3)
    a.put(4, 1)
    c.put(4, 8)
    c.put(4, 9)
    for robot in (a, c):
        robot.drain()
    a.get(4)
    b.get(4)
    for msg in b.drain():
        a.receive(msg)
    for msg in a.drain():
        b.receive(msg)
        c.receive(msg)
    for msg in c.drain():
        a.receive(msg)
        b.receive(msg)
    assert a.entry(4) == b.entry(4) == c.entry(4) == Entry(9, 2, 3)


def test_conflict_winner_equal_to_pending_get_keeps_the_get() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 5))
    s.drain()
    s.get(4)
    assert s.receive(Message(PUT, 4, 8, 3, 3)) is Outcome.CONFLICT  # robot 5's entry wins: nothing changed
    assert s.drain() == [Message(GET, 4, 9, 3, 5)]


def test_conflict_winner_replaces_pending_get_of_the_loser() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.drain()
    s.get(4)
    assert s.receive(Message(PUT, 4, 1, 3, 5)) is Outcome.CONFLICT
    assert s.drain() == [Message(PUT, 4, 1, 3, 5)]


def test_a_queue_fed_from_drains_sends_the_winner_not_the_loser() -> None:
    # A gateway copies each drain into every link's own queue; a loser that
    # waits there for bandwidth must give way to the winner drained after it.
    link_queue = OutQueue()
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    for msg in s.drain():
        link_queue.push(msg)
    s.receive(Message(PUT, 4, 1, 3, 5))  # robot 5 wins the conflict
    for msg in s.drain():
        link_queue.push(msg)
    assert link_queue.drain() == [Message(PUT, 4, 1, 3, 5)]


def test_resolver_returning_no_entry_is_refused_by_name() -> None:
    s = Stigmergy(1, onconflict=lambda key, local, remote: None)  # type: ignore[arg-type, return-value]
    s.receive(Message(PUT, 4, 9, 3, 2))
    with pytest.raises(TypeError, match=r"onconflict must return .*got None"):
        s.receive(Message(PUT, 4, 1, 3, 5))
    assert s.entry(4) == Entry(9, 3, 2)


def test_outgoing_queue_compares_timestamps_across_the_wrap() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 65535, 2))  # the relay is pending at ts 65535
    s.put(4, 10)  # ts 1 is newer: it replaces the relay (a plain >= would keep the relay)
    assert s.drain() == [Message(PUT, 4, 10, 1, 1)]


def test_outgoing_queue_keeps_only_newest_per_key() -> None:
    s = Stigmergy(1)
    for value in range(5):
        s.put(4, value)
    s.get(4)  # same timestamp as the pending PUT: the PUT stays, ahead of every GET
    assert s.drain() == [Message(PUT, 4, 4, 5, 1)]


def test_outgoing_queue_drains_puts_before_gets_and_respects_budget() -> None:
    s = Stigmergy(1)
    s.get(1)
    s.get(2)
    s.put(3, 30)
    s.put(4, 40)
    assert s.pending() == 4
    assert s.drain(budget=3) == [Message(PUT, 3, 30, 1, 1), Message(PUT, 4, 40, 1, 1), Message(GET, 1, 0, 0, 1)]
    assert s.drain(budget=0) == []
    assert s.drain(budget=5) == [Message(GET, 2, 0, 0, 1)]


def test_replaced_message_keeps_its_place_in_line() -> None:
    s = Stigmergy(1)
    s.put(1, 1)
    s.put(2, 2)
    s.put(1, 3)  # key 1 updated: still first in line, so it cannot starve
    assert [m.key for m in s.drain(budget=1)] == [1]


def test_counts_per_outcome() -> None:
    s = Stigmergy(1)
    s.receive(Message(PUT, 4, 9, 3, 2))
    s.receive(Message(PUT, 4, 9, 2, 2))
    s.receive(Message(PUT, 4, 9, 2, 2))
    assert s.counts[Outcome.STORED] == 1 and s.counts[Outcome.STALE] == 2


def test_timestamp_serial_arithmetic_and_wrap_skips_zero() -> None:
    assert next_timestamp(65535) == 1 and next_timestamp(1) == 2
    assert is_newer(1, 65535) and not is_newer(65535, 1)
    assert is_newer(5, 0) and not is_newer(0, 5) and not is_newer(0, 0)
    assert is_newer(40000, 10) is False  # more than half the space away: older
    assert is_newer(0x8001, 1) != is_newer(1, 0x8001)  # the half-way case stays antisymmetric


def test_bad_arguments_are_named() -> None:
    s = Stigmergy(1)
    for call, text in [(lambda: s.put(0x8000, 1), "key"), (lambda: s.put(1, -1), "value"),
                       (lambda: Stigmergy(70000), "robot_id"), (lambda: s.drain(-1), "budget")]:
        try:
            call()
        except ValueError as error:
            assert text in str(error)
        else:
            raise AssertionError(f"{text} was not rejected")


def test_wraparound_200k_puts_all_accepted_in_order() -> None:
    a, b = Stigmergy(1), Stigmergy(2)
    accepted = 0
    for value in range(200_000):
        a.put(9, value & 0xFFFF)
        (msg,) = a.drain()
        if b.receive(msg) is Outcome.STORED:
            accepted += 1
        assert b.entry(9) == Entry(value & 0xFFFF, msg.timestamp, 1)
    assert accepted == 200_000
    assert a.entry(9) == b.entry(9)


def test_larger_value_wins_rule() -> None:
    s = Stigmergy(1, onconflict=larger_value_wins)
    s.receive(Message(PUT, 1, 10, 1, 9))
    s.receive(Message(PUT, 1, 20, 1, 3))
    assert s.entry(1) == Entry(20, 1, 3)
