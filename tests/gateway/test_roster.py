"""The roster: who is heard where, alive / quiet / gone, behind on a key, bounded: data in, data out."""

from __future__ import annotations

import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message, Op
from vstig_hw.gateway.roster import MAX_BEHIND_KEYS, RobotState, RobotView, Roster, StateChange
from vstig_hw.links import Heard

PERIOD = 0.1


def put(key: int, ts: int, robot: int, value: int = 1) -> Message:
    return Message(Op.PUT, key, value, ts, robot)


def get(key: int, ts: int, robot: int = 0) -> Message:
    return Message(Op.GET, key, 0, ts, robot)


def by_id(roster: Roster, now: float) -> dict[int, RobotView]:
    return {view.robot: view for view in roster.snapshot(now)}


def test_a_named_sender_is_who_whatever_it_carries() -> None:
    roster = Roster(PERIOD)
    roster.take("can0", 1.0, 7, [put(1, 3, 2), get(2, 0, 9)])
    roster.take("can1", 1.05, 7, [get(1, 3, 2)])
    [view] = roster.snapshot(1.1)
    assert (view.robot, view.named_by, view.links) == (7, "sender", ("can0", "can1"))
    assert (view.messages, view.writes, view.gets) == (3, 1, 2)
    assert view.first_heard == 1.0 and view.last_heard == 1.05
    assert view.as_json()["sender"] == 7 and view.as_json()["state"] == "alive"


def test_without_a_sender_the_writer_of_puts_is_who_and_gets_name_nobody() -> None:
    roster = Roster(PERIOD)
    roster.take("radio", 1.0, None, [put(1, 3, 4), put(2, 1, 5), get(1, 3, 4)])
    views = by_id(roster, 1.0)
    assert set(views) == {4, 5}
    assert all(v.named_by == "writer" and v.writes == 1 and v.gets == 0 for v in views.values())
    assert roster.unattributed == 1
    assert views[4].as_json()["sender"] is None


def test_quiet_then_gone_then_alive_each_change_told_and_counted_once() -> None:
    roster = Roster(PERIOD, gone_after=1.0)
    told: list[StateChange] = []
    roster.on_change.append(told.append)
    t = 0.0
    for _ in range(10):  # talks every period
        roster.take("can0", t, 3, [put(1, 1, 3)])
        roster.sweep(t)
        t += PERIOD
    assert roster.snapshot(t)[0].state is RobotState.ALIVE
    for step in range(15):  # silent: quiet after 3 periods, gone after 1 s
        roster.sweep(t + step * PERIOD)
    assert [(c.old, c.new) for c in told] == [(RobotState.ALIVE, RobotState.QUIET),
                                              (RobotState.QUIET, RobotState.GONE)]
    assert told[0].t - 0.9 == pytest.approx(0.4)  # first sweep with silence > 0.3 s
    roster.take("can0", t + 2, 3, [put(1, 2, 3)])
    assert told[-1].new is RobotState.ALIVE and roster.changes == {"alive->quiet": 1, "quiet->gone": 1,
                                                                   "gone->alive": 1}


def test_a_robot_that_talks_rarely_is_not_quiet_between_its_messages() -> None:
    roster = Roster(PERIOD)
    for second in range(5):  # once a second: its usual gap is 1 s
        roster.take("can0", float(second), 1, [put(1, second + 1, 1)])
    roster.sweep(4.9)
    assert roster.snapshot(4.9)[0].state is RobotState.ALIVE
    roster.sweep(7.5)  # silent for three of its gaps and more
    assert roster.snapshot(7.5)[0].state is RobotState.QUIET


def test_behind_once_an_older_entry_lasts_behind_after_and_cleared_by_the_newest() -> None:
    roster = Roster(PERIOD)  # behind after 0.3 s
    roster.take("can0", 1.0, 1, [put(9, 5, 1)])
    roster.take("can0", 1.0, 2, [get(9, 4)])  # robot 2 still holds timestamp 4
    assert by_id(roster, 1.2)[2].behind == ()
    roster.take("can0", 1.2, 2, [get(9, 4)])
    assert by_id(roster, 1.31)[2].behind == (9,)
    assert by_id(roster, 1.31)[1].behind == ()
    roster.take("can0", 1.4, 2, [get(9, 5)])  # caught up
    assert by_id(roster, 2.0)[2].behind == ()


def test_an_empty_get_from_a_named_sender_holds_nothing_and_lags_a_held_key() -> None:
    roster = Roster(PERIOD)
    roster.take("can0", 0.0, 2, [get(9, 0)])  # nothing held anywhere yet: not behind
    roster.take("can0", 0.0, 1, [put(9, 1, 1)])
    roster.take("can0", 0.1, 2, [get(9, 0)])
    assert by_id(roster, 0.5)[2].behind == (9,)


def test_refusals_are_counted_to_the_robot_they_name() -> None:
    roster = Roster(PERIOD)
    roster.refuse(Heard(put(1, 30000, 4), "radio", 1.0, None), "drop_jump")
    roster.refuse(Heard(get(1, 3, 4), "can0", 1.0, 8), "drop_rate")
    roster.refuse(Heard(get(1, 3, 4), "radio", 1.0, None), "drop_rate")
    views = by_id(roster, 1.0)
    assert views[4].refused == 1 and views[8].refused == 1 and roster.unattributed == 1


def test_a_full_roster_counts_newcomers_and_gives_a_gone_robots_place_to_one() -> None:
    roster = Roster(PERIOD, gone_after=1.0, max_robots=3)
    for who in range(3):
        roster.take("can0", 0.0, who, [put(1, 1, who)])
    roster.take("can0", 0.0, 10, [put(1, 1, 10)])
    assert len(roster) == 3 and roster.untracked == 1
    roster.take("can0", 1.5, 1, [put(1, 2, 1)])
    roster.take("can0", 1.5, 2, [put(1, 2, 2)])
    roster.sweep(1.5)  # robot 0 gone
    roster.take("can0", 1.6, 11, [put(1, 3, 11)])
    assert sorted(by_id(roster, 1.6)) == [1, 2, 11] and roster.untracked == 1


def test_a_flood_of_fresh_sender_ids_keeps_memory_bounded() -> None:
    roster = Roster(PERIOD, max_robots=256)
    for who in range(256):
        roster.take("can0", 0.0, who, [put(who, 1, who)])
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for who in range(256, 200_000):
        roster.take("can0", 0.01, who, [put(who & 0x7FFF, 2, who & 0xFFFF)])
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert len(roster) == 256 and roster.untracked == 200_000 - 256
    assert grown < 50_000  # bytes: nothing per newcomer


def test_one_robot_remembers_a_bounded_number_of_keys_it_lags_on() -> None:
    roster = Roster(PERIOD)
    for key in range(MAX_BEHIND_KEYS + 10):
        roster.take("can0", 0.0, 1, [put(key, 2, 1)])
        roster.take("can0", 0.0, 2, [get(key, 1)])
    assert len(by_id(roster, 1.0)[2].behind) == MAX_BEHIND_KEYS and roster.behind_untracked == 10


def test_counts_are_per_link_and_state() -> None:
    roster = Roster(PERIOD)
    roster.take("can0", 0.0, 1, [put(1, 1, 1)])
    roster.take("can1", 0.0, 1, [put(1, 1, 1)])
    roster.take("can0", 1.0, 2, [put(1, 2, 2)])
    roster.sweep(1.0)
    assert roster.counts() == {("can0", RobotState.QUIET): 1, ("can1", RobotState.QUIET): 1,
                               ("can0", RobotState.ALIVE): 1}


@pytest.mark.parametrize(("field", "value"), [("quiet_after", 0.0), ("gone_after", float("nan")),
                                               ("behind_after", -1.0)])
def test_a_bad_threshold_is_named(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        Roster(PERIOD, **{field: value})  # type: ignore[arg-type]


def test_gone_must_come_after_quiet() -> None:
    with pytest.raises(ValueError, match="gone_after"):
        Roster(PERIOD, quiet_after=2.0, gone_after=1.0)


events = st.lists(st.tuples(st.floats(0, 0.5), st.one_of(st.none(), st.integers(0, 20)), st.booleans(),
                            st.integers(0, 7), st.integers(0, 6), st.integers(0, 20), st.booleans()),
                  max_size=120)


@settings(max_examples=150, deadline=None)
@given(events, st.integers(1, 8))
def test_properties_bounded_counted_consistent(steps: list[tuple[float, int | None, bool, int, int, int, bool]],
                                               max_robots: int) -> None:
    roster = Roster(PERIOD, gone_after=0.6, max_robots=max_robots)
    changes: list[StateChange] = []
    roster.on_change.append(changes.append)
    t = 0.0
    heard: dict[int, int] = {}
    for wait, sender, is_get, key, ts, writer, sweep in steps:
        t += wait
        msg = get(key, ts, writer) if is_get else put(key, max(ts, 1), writer)
        roster.take("l", t, sender, [msg])
        if sender is not None or not is_get:
            who = writer if sender is None else sender
            heard[who] = heard.get(who, 0) + 1
        if sweep:
            roster.sweep(t)
        assert len(roster) <= max_robots
    views = roster.snapshot(t)
    order = [(["alive", "quiet", "gone"].index(v.state.value), v.robot) for v in views]
    assert order == sorted(order)
    for view in views:  # what a tracked robot shows is what was heard of it since it was (last) tracked
        assert view.messages == view.writes + view.gets <= heard[view.robot]
        assert view.first_heard <= view.last_heard <= t
    last: dict[int, RobotState] = {}
    for change in changes:  # each change is a real change from the state told before
        assert change.old is not change.new
        assert last.get(change.robot, change.old) is change.old or change.old is RobotState.ALIVE
        last[change.robot] = change.new
    assert sum(roster.changes.values()) == len(changes)
    if len(heard) <= max_robots:  # never full: everyone heard is tracked
        assert len(roster) == len(heard) and roster.untracked == 0
    else:
        assert len(roster) == max_robots
