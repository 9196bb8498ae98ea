"""The guard, pure: each policy by example, then properties (hypothesis) against small independent models."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.counters import Counters
from vstig_hw.gateway.guard import DEFAULT_MAX_JUMP, MAX_SENDERS, Guard, IdSet, LinkPolicy
from vstig_hw.timestamps import TS_NONE, is_newer, next_timestamp, steps_ahead

PUT, GET = Op.PUT, Op.GET


def put(key: int, ts: int, robot: int = 1, value: int = 7) -> Message:
    return Message(PUT, key, value, ts, robot)


def get(key: int, ts: int, robot: int = 1, value: int = 7) -> Message:
    return Message(GET, key, value, ts, robot)


# -- max jump ------------------------------------------------------------------------
def test_a_key_we_do_not_hold_passes_at_any_timestamp() -> None:
    guard = Guard()
    assert guard.check("can", 3, put(1, 40000), 0.0) is None
    assert guard.check("can", 3, get(2, 65535), 0.0) is None


def test_a_put_or_get_more_than_max_jump_ahead_is_refused_and_not_remembered() -> None:
    guard = Guard(max_jump=10)
    assert guard.check("can", 1, put(5, 100), 0.0) is None
    assert guard.check("can", 1, put(5, 111), 0.1) == "drop_jump"
    assert guard.check("can", 1, get(5, 111), 0.2) == "drop_jump"
    assert guard.check("can", 1, put(5, 110), 0.3) is None  # exactly max_jump ahead of our 100 still passes
    assert guard.check("can", 1, put(5, 120), 1.3) is None  # our entry is now 110, and a second refilled the skips


def test_a_climb_in_steps_of_max_jump_gains_at_most_max_jump_a_second() -> None:
    guard = Guard()  # 5 -> 260 -> 515 ...: each step is within 255 of the last
    assert guard.check("can", 1, put(5, 5), 0.0) is None
    verdicts = [guard.check("can", 9, put(5, 5 + 255 * n, robot=9), 0.01 * n) for n in range(1, 20)]
    assert verdicts[0] is None and set(verdicts[1:]) == {"drop_jump"}
    assert guard.check("can", 9, put(5, 5 + 255 * 2, robot=9), 1.02) is None  # a second later: one more step
    assert guard.check("can", 1, put(5, 516), 1.03) is None  # an honest robot stepping by one is never held back


def test_honest_steps_of_one_pass_at_any_rate_and_missed_updates_within_the_budget_pass() -> None:
    guard = Guard(max_jump=10)
    assert all(guard.check("can", 1, put(5, ts), ts * 1e-4) is None for ts in range(1, 5000))
    assert guard.check("can", 1, put(5, 5005), 1.0) is None  # 5 missed: within the budget
    assert guard.check("can", 1, put(5, 5012), 1.0) == "drop_jump"  # 6 more would be 11 missed within a second
    assert guard.check("can", 1, put(5, 5006), 1.0) is None


def test_after_learning_a_key_we_do_not_hold_is_measured_from_zero() -> None:
    guard = Guard(learn=10.0)
    assert guard.check("can", 1, put(1, 40000), 0.0) is None  # still learning: the swarm's keys as they are
    assert guard.check("can", 1, put(2, 32767), 9.9) is None
    assert guard.check("can", 9, put(3, 32767, robot=9), 10.0) == "drop_jump"  # a first write at 32767
    assert guard.check("can", 9, get(4, 256, robot=9), 10.0) == "drop_jump"
    assert guard.check("can", 2, put(3, 1, robot=2), 10.0) is None  # an honest first write of the key
    assert guard.check("can", 2, put(4, 255, robot=2), 12.0) is None  # at most max_jump from 0
    assert guard.check("can", 1, put(1, 40001), 10.5) is None  # keys learnt in time go on as before


def test_the_default_refuses_one_flipped_bit_in_the_high_byte() -> None:
    guard = Guard()
    assert guard.max_jump == DEFAULT_MAX_JUMP
    guard.check("can", 1, put(5, 0x0003), 0.0)
    assert all(guard.check("can", 1, put(5, 0x0003 | 1 << bit), 0.0) == "drop_jump" for bit in range(8, 15))
    assert guard.check("can", 1, put(5, 0x0003 + DEFAULT_MAX_JUMP), 0.0) is None


def test_the_jump_is_counted_in_steps_across_the_wrap() -> None:
    guard = Guard(max_jump=10)
    guard.check("can", 1, put(5, 65530), 0.0)
    assert guard.check("can", 1, put(5, 5), 0.0) is None  # 65530 -> 65535 -> 1..5: 10 steps (0 is skipped)
    guard2 = Guard(max_jump=10)
    guard2.check("can", 1, put(5, 65530), 0.0)
    assert guard2.check("can", 1, put(5, 6), 0.0) == "drop_jump"


def test_older_messages_and_empty_gets_are_never_jumps() -> None:
    guard = Guard(max_jump=1)
    guard.check("can", 1, put(5, 30000), 0.0)
    assert guard.check("can", 1, put(5, 2), 0.0) is None  # far behind: the engine ignores or answers it
    assert guard.check("can", 1, get(5, TS_NONE, value=0), 0.0) is None


def test_max_jump_none_lets_every_jump_through() -> None:
    guard = Guard(max_jump=None)
    guard.check("can", 1, put(5, 1), 0.0)
    assert guard.check("can", 1, put(5, 30000), 0.0) is None


def test_a_robot_repeating_a_jump_it_stored_is_refused_every_time() -> None:
    guard = Guard(max_jump=10)
    guard.check("can", 2, put(5, 100), 0.0)
    for second in range(1, 120):
        assert guard.check("can", 9, get(5, 30000), float(second)) == "drop_jump"
        assert guard.check("can", 2, get(5, 100), second + 0.5) is None


# -- rate ---------------------------------------------------------------------------------
def test_a_flooding_sender_is_held_to_its_rate_and_the_others_pass() -> None:
    guard = Guard(rate=10)
    counters = Counters()
    flood = [put(100 + i % 50, 1, robot=9) for i in range(1000)]
    passed = guard.filter("can", 9, flood, 0.5, counters)
    assert len(passed) == 10 and counters["drop_rate"] == 990  # one second's burst, then nothing
    assert all(guard.check("can", sender, put(sender, 1, robot=sender), 0.5) is None for sender in range(1, 9))
    assert guard.check("can", 9, put(1, 2, robot=9), 0.5) == "drop_rate"
    assert guard.check("can", 9, put(1, 2, robot=9), 0.65) is None  # 0.15 s refills one token


def test_where_the_medium_names_nobody_the_link_is_the_sender() -> None:
    guard = Guard(rate=2)
    assert [guard.check("radio", None, put(k, 1), 0.0) for k in range(3)] == [None, None, "drop_rate"]
    assert guard.check("radio-2", None, put(9, 1), 0.0) is None  # another link has its own bucket


def test_a_source_changing_its_claimed_sender_per_message_is_held_to_the_source_rate() -> None:
    guard = Guard(rate=10, source_rate=100)
    counters = Counters()
    passed = sum(len(guard.filter("zenoh", sender, [put(1, 1, robot=sender)], 0.5, counters, source="peer-a"))
                 for sender in range(1000))
    assert passed == 100 and counters["drop_source_rate"] == 900 and not counters["drop_rate"]
    assert guard.check("zenoh", 5000, put(1, 1), 0.5, source="peer-b") is None  # another source: its own bucket
    assert guard.check("zenoh", 5001, put(1, 1), 0.5) is None  # no source named: the link's bucket
    assert guard.check("can", 1, put(1, 1), 0.5, source="peer-a") is None  # buckets are per link


def test_a_rate_below_one_still_lets_one_message_through() -> None:
    guard = Guard(rate=0.5)
    assert guard.check("can", 1, put(1, 1), 0.0) is None
    assert guard.check("can", 1, put(1, 2), 1.0) == "drop_rate"
    assert guard.check("can", 1, put(1, 2), 2.1) is None


def test_a_clock_stepping_back_refills_nothing() -> None:
    guard = Guard(rate=1)
    assert guard.check("can", 1, put(1, 1), 100.0) is None
    assert guard.check("can", 1, put(1, 2), 50.0) == "drop_rate"


def test_token_buckets_stay_bounded_as_senders_come_and_go() -> None:
    guard = Guard(rate=100)
    for i in range(3 * MAX_SENDERS):
        guard.check("can", i, get(1, TS_NONE, value=0), i * 0.001)
    assert len(guard._buckets) <= MAX_SENDERS + 1
    sources = Guard(source_rate=100)
    for i in range(3 * MAX_SENDERS):
        sources.check("zenoh", None, get(1, TS_NONE, value=0), i * 0.001, source=f"peer-{i}")
    assert len(sources._source_buckets) <= MAX_SENDERS + 1


# -- trust, deny, keys ----------------------------------------------------------------------
def test_trust_and_deny_lists_per_link() -> None:
    guard = Guard(links={"can": LinkPolicy(trust=IdSet.parse("1-3", 255)),
                         "bus": LinkPolicy(deny=IdSet.parse("7", 255))})
    assert guard.check("can", 2, put(1, 1), 0.0) is None
    assert guard.check("can", 4, put(1, 2), 0.0) == "drop_untrusted"
    assert guard.check("can", None, put(1, 2), 0.0) == "drop_untrusted"  # a medium naming nobody: nobody trusted
    assert guard.check("bus", 7, put(2, 1), 0.0) == "drop_untrusted"
    assert guard.check("bus", 8, put(2, 1, robot=7), 0.0) == "drop_untrusted"  # robot 8 relaying robot 7's write
    assert guard.check("bus", 8, put(2, 1), 0.0) is None
    assert guard.check("radio", 7, put(3, 1), 0.0) is None  # the lists are per link


def test_a_link_may_write_only_its_keys_but_may_read_any() -> None:
    guard = Guard(links={"class": LinkPolicy(keys=IdSet.parse("100-199", 0x7FFF))})
    assert guard.check("class", 1, put(150, 1), 0.0) is None
    assert guard.check("class", 1, put(5, 1), 0.0) == "drop_key"
    assert guard.check("class", 1, get(5, TS_NONE, value=0), 0.0) is None  # asking is reading
    assert guard.check("class", 1, get(5, 3), 0.0) == "drop_key"  # a view of a key we lack would be stored
    guard.check("lab", 1, put(5, 10, robot=4, value=99), 0.0)
    assert guard.check("class", 1, get(5, 9), 0.0) is None  # older: we answer it
    assert guard.check("class", 1, get(5, 10, robot=4, value=99), 0.0) is None  # the same entry
    assert guard.check("class", 1, get(5, 10, robot=5), 0.0) == "drop_key"  # a conflict would write
    assert guard.check("class", 1, get(5, 11), 0.0) == "drop_key"
    assert guard.check("lab", 1, put(5, 11), 0.0) is None


def test_checks_run_in_order_and_each_refusal_is_counted_once() -> None:
    guard = Guard(max_jump=5, rate=1, links={"can": LinkPolicy(deny=IdSet.parse("9", 255),
                                                                 keys=IdSet.parse("0-9", 0x7FFF))})
    counters = Counters()
    guard.filter("can", 1, [put(1, 1)], 0.0, counters)
    heard = [put(1, 100, robot=9), put(1, 100), put(50, 1), put(1, 100)]
    assert guard.filter("can", 9, heard[:1], 0.0, counters) == []
    assert guard.filter("can", 1, heard[1:], 0.0, counters) == []
    assert counters == Counters(drop_untrusted=1, drop_rate=3)
    assert guard.filter("can", 2, [put(50, 1)], 0.0, counters) == [] and counters["drop_key"] == 1
    assert guard.filter("can", 3, [put(1, 100)], 0.0, counters) == [] and counters["drop_jump"] == 1


# -- read-only ------------------------------------------------------------------------------------
def test_entries_a_read_only_link_wrote_are_confined_to_it() -> None:
    guard = Guard(links={"class": LinkPolicy(read_only=True)})
    assert guard.read_only("class") and not guard.read_only("lab") and guard.confines
    assert guard.check("class", None, put(5, 3, robot=8), 0.0) is None  # it passes: our table learns it
    assert guard.confined_to(put(5, 3, robot=8)) == "class"
    guard.check("class", None, get(5, 2, robot=8), 0.1)  # an older view from it changes nothing
    assert guard.confined_to(put(5, 3, robot=8)) == "class"
    guard.check("lab", None, put(5, 4, robot=2), 0.2)
    assert guard.confined_to(put(5, 4, robot=2)) is None  # a newer entry from elsewhere goes everywhere
    assert not Guard().confines


def test_a_conflict_won_by_a_read_only_robot_stays_confined() -> None:
    guard = Guard(links={"class": LinkPolicy(read_only=True)})
    guard.check("lab", None, put(5, 3, robot=2), 0.0)
    guard.check("class", None, put(5, 3, robot=8), 0.0)
    assert guard.confined_to(put(5, 3, robot=8)) == "class"
    assert guard.confined_to(put(5, 3, robot=2)) is None


# -- flapping --------------------------------------------------------------------------------------
def test_a_flapping_key_is_reported_once_naming_the_key_and_both_robots() -> None:
    guard = Guard(flap=3)
    t = 0.0
    for ts in range(1, 40):
        for robot in (4, 6):
            guard.check("can", robot, put(12, ts, robot=robot), t)
            guard.check("can", robot, put(12, ts, robot=robot), t)  # heard again: the same conflict
        t += 0.1
    assert len(guard.warnings) == 1
    assert "key 12" in guard.warnings[0] and "robots 4 and 6" in guard.warnings[0]


def test_conflicts_slower_than_the_limit_are_not_reported() -> None:
    guard = Guard(flap=3)
    for ts in range(1, 40):
        for robot in (4, 6):
            guard.check("can", robot, put(12, ts, robot=robot), float(ts))  # one a second
    assert guard.warnings == []
    assert Guard().flap is None  # off by default


def test_two_robots_sharing_an_id_show_as_one_id_with_two_values() -> None:
    guard = Guard(flap=2)
    for ts in range(1, 10):
        guard.check("can", 1, put(3, ts, robot=5, value=1), ts * 0.05)
        guard.check("can", 2, put(3, ts, robot=5, value=2), ts * 0.05)
    assert len(guard.warnings) == 1 and "sharing id 5" in guard.warnings[0]


# -- arguments ---------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs", [{"max_jump": 0}, {"max_jump": 40000}, {"rate": 0}, {"rate": -1.0},
                                    {"flap": 0}, {"rate": float("nan")},
                                    {"source_rate": 0}, {"learn": -1.0}])
def test_bad_arguments_are_value_errors_naming_them(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        Guard(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("text", ["", "1-", "x", "5-3", "1,,2", "70000", "-1", "0x"])
def test_a_bad_id_set_names_itself(text: str) -> None:
    with pytest.raises(ValueError, match="bad ids"):
        IdSet.parse(text, 0xFFFF)


def test_id_sets() -> None:
    ids = IdSet.parse("9, 1-3,0x10-0x11,2-4", 255)
    assert str(ids) == "1-4,9,16-17"
    assert [n for n in range(20) if n in ids] == [1, 2, 3, 4, 9, 16, 17]
    assert None not in ids and "1" not in ids
    assert ids == IdSet.parse("1-4,9,16,17", 255)


# -- properties ------------------------------------------------------------------------------
messages = st.builds(Message, st.sampled_from([PUT, GET]), st.integers(0, 3), st.integers(0, 3),
                     st.integers(0, 0xFFFF), st.integers(0, 5))
timestamps = st.integers(1, 0xFFFF)


@settings(max_examples=300, deadline=None)
@given(held=timestamps, ts=timestamps, max_jump=st.integers(1, 0x7FFF))
def test_a_jump_is_refused_exactly_when_it_is_more_than_max_jump_steps_ahead(held: int, ts: int,
                                                                            max_jump: int) -> None:
    guard = Guard(max_jump=max_jump)
    guard.check("can", 1, put(0, held), 0.0)
    steps, t = 0, held  # the model: walk next_timestamp until we reach ts, at most max_jump steps
    while t != ts and steps < max_jump:
        t, steps = next_timestamp(t), steps + 1
    refused = is_newer(ts, held) and t != ts
    assert (guard.check("can", 1, put(0, ts), 0.0) == "drop_jump") == refused


@settings(max_examples=300, deadline=None)
@given(a=timestamps, b=timestamps)
def test_steps_ahead_counts_next_timestamp_steps(a: int, b: int) -> None:
    if not is_newer(a, b):
        return
    steps, t = 0, b
    while t != a:
        t, steps = next_timestamp(t), steps + 1
    assert steps_ahead(a, b) == steps


arrivals = st.lists(st.tuples(st.floats(0, 0.5), st.integers(0, 3), messages), max_size=60)


@settings(max_examples=300, deadline=None)
@given(arrivals=arrivals, rate=st.one_of(st.none(), st.floats(0.5, 50)),
       max_jump=st.one_of(st.none(), st.integers(1, 50)), deny=st.one_of(st.none(), st.just(IdSet.parse("3", 255))),
       keys=st.one_of(st.none(), st.just(IdSet.parse("0-1", 9))), flap=st.one_of(st.none(), st.floats(0.5, 5)))
def test_every_message_passes_or_is_counted_once_and_the_engine_never_jumps(
        arrivals: list[tuple[float, int, Message]], rate: float | None, max_jump: int | None, deny: IdSet | None,
        keys: IdSet | None, flap: float | None) -> None:
    guard = Guard(max_jump=max_jump, rate=rate, flap=flap,
                  links={"can": LinkPolicy(deny=deny, keys=keys)})
    engine = Stigmergy(200)
    counters = Counters()
    now = 0.0
    passed_per_sender: dict[int, int] = {}
    for gap, sender, msg in arrivals:
        now += gap
        before = engine.entry(msg.key)
        kept = guard.filter("can", sender, [msg], now, counters)
        for m in kept:
            engine.receive(m)
            passed_per_sender[sender] = passed_per_sender.get(sender, 0) + 1
            after = engine.entry(m.key)
            moved = before is not None and after is not None and after.timestamp != before.timestamp
            if max_jump is not None and moved:
                assert before is not None and after is not None
                assert steps_ahead(after.timestamp, before.timestamp) <= max_jump
        assert not (deny is not None and sender in deny and kept)
    assert sum(passed_per_sender.values()) + sum(counters.values()) == len(arrivals)
    if rate is not None:
        for count in passed_per_sender.values():
            assert count <= max(rate, 1.0) + rate * now + 1e-9
    assert len(guard.warnings) <= 4  # at most once per key
