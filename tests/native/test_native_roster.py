"""The roster's C tally (RosterTally) against the Python Roster's own `take`, `refuse` and `sweep`, on random traffic.

Two Rosters with the same thresholds: one fed through its own `take`/`refuse` and sweeping in Python, one through a
RosterTally that keeps the rates and judges the states (`due`: a sweep runs Python only when a state changes), folded
in at such a sweep and at each read. From random senders (named by the medium or not), on a few links, with
timestamps that meet (stale, equal, the wrap), refusals and sweeps between, into a roster small enough to fill:
after every step they must show the same robots, states, rates, tallies, behind keys, counts and state changes.
Times are whole eighths of a second, so both sides compute the same floats.
"""

from __future__ import annotations

import os
import time
import tty
from types import ModuleType
from typing import Any

import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from traffic import EXAMPLES

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.gateway import Mode, Node
from vstig_hw.gateway.kept_roster import keep_roster
from vstig_hw.gateway.roster import RobotState, Roster, StateChange
from vstig_hw.links import parse
from vstig_hw.links.link import Heard

LINKS = ("radio0", "can0", "zenoh0")

message_st = st.builds(lambda get, key, ts, writer: Message(Op.GET if get else Op.PUT, key, 1, ts, writer),
                       st.booleans(), st.integers(0, 4), st.sampled_from([0, 1, 2, 3, 0x7FFF, 0x8001, 0xFFFF]),
                       st.integers(1, 6))
sender_st = st.none() | st.integers(1, 6) | st.just(0x0013A20040A10001)
step_st = st.one_of(
    st.tuples(st.just("take"), st.integers(0, 2), st.integers(0, 4), sender_st, st.lists(message_st, max_size=5)),
    st.tuples(st.just("refuse"), st.integers(0, 2), st.integers(0, 4), sender_st, message_st),
    st.tuples(st.just("sweep"), st.just(0), st.integers(0, 12), st.none(), st.none()),
    st.tuples(st.just("look"), st.just(0), st.just(0), st.none(), st.none()),  # a view reads (and so folds)
)

# one robot lagging on three keys at once, a full roster evicting its gone robot, and one coming back
LAGGING: list[tuple[Any, ...]] = [("take", 0, 1, 1, [Message(Op.PUT, k, 1, 3, 1) for k in range(4)]),
                                  ("take", 0, 1, 2, [Message(Op.GET, k, 0, 1, 1) for k in range(4)]),
                                  ("sweep", 0, 4, None, None), ("take", 1, 12, None, [Message(Op.PUT, 0, 1, 2, 3)]),
                                  ("sweep", 0, 12, None, None), ("take", 2, 1, 4, []),
                                  ("refuse", 0, 1, None, Message(Op.PUT, 1, 1, 9, 1)),
                                  ("take", 0, 2, 1, [Message(Op.GET, 2, 0, 3, 1)]), ("sweep", 0, 2, None, None)]

# a robot whose usual gap grows (quiet at 1.25 s of silence only by the gap's own weighting)
SLOWING: list[tuple[Any, ...]] = [("take", 0, 0, 1, []), ("take", 0, 1, 1, []), ("take", 0, 1, 1, []),
                                  ("take", 0, 8, 1, []), ("sweep", 0, 10, None, None)]
# the same robot swept sooner: silent for 2.2 of its usual gaps (0.34 s) and past quiet_after, still alive
GAPPED: list[tuple[Any, ...]] = [*SLOWING[:4], ("sweep", 0, 6, None, None)]
# two robots heard in one unit, gone alike: a newcomer takes the place of the first added
EVICTING: list[tuple[Any, ...]] = [("take", 0, 0, None, [Message(Op.PUT, 0, 1, 1, 1), Message(Op.PUT, 1, 1, 1, 2)]),
                                   ("sweep", 0, 13, None, None), ("take", 1, 0, 3, []), ("sweep", 0, 1, None, None)]

# a robot heard again once, long enough before the next sweep to be quiet again by then: that sweep must still run
# (the Python tells its return and its going quiet again), though no state it judges differs from the last one told
RETURNING: list[tuple[Any, ...]] = [("take", 0, 0, 1, []), ("take", 0, 1, 1, []), ("take", 0, 1, 1, []),
                                    ("take", 0, 1, 1, []), ("sweep", 0, 6, None, None), ("take", 0, 1, 1, []),
                                    ("sweep", 0, 8, None, None)]


def rosters(compiled: ModuleType, max_robots: int) -> tuple[Roster, Roster, list[StateChange], list[StateChange]]:
    python, c = (Roster(0.125, quiet_after=0.5, gone_after=1.5, behind_after=0.25, max_robots=max_robots)
                 for _ in range(2))
    c.use_tally(compiled.RosterTally)
    told_python: list[StateChange] = []
    told_c: list[StateChange] = []
    python.on_change.append(told_python.append)
    c.on_change.append(told_c.append)
    return python, c, told_python, told_c


def seen(roster: Roster, now: float) -> tuple[Any, ...]:
    return (roster.snapshot(now), len(roster), roster.untracked, roster.behind_untracked, roster.unattributed,
            dict(roster.changes), roster.counts())


@EXAMPLES
@example(max_robots=2, steps=LAGGING)
@example(max_robots=1, steps=SLOWING)
@example(max_robots=2, steps=EVICTING)
@example(max_robots=1, steps=RETURNING)
@example(max_robots=1, steps=GAPPED)
@given(max_robots=st.integers(1, 4), steps=st.lists(step_st, max_size=40))
def test_the_tally_folded_in_equals_the_python_roster(compiled: ModuleType, max_robots: int,
                                                      steps: list[tuple[Any, ...]]) -> None:
    python, c, told_python, told_c = rosters(compiled, max_robots)
    take, refuse = c.listeners()
    now = 100.0
    for kind, link, dt, sender, what in steps:
        now += dt / 8
        if kind == "take":
            python.take(LINKS[link], now, sender, what)
            take(LINKS[link], now, sender, what)
        elif kind == "refuse":
            heard = Heard(what, LINKS[link], now, sender)
            python.refuse(heard, "drop_jump")
            refuse(heard, "drop_jump")
        elif kind == "sweep":
            python.sweep(now)
            c.sweep(now)
            # a fold tells a robot's return at the time it was heard, after the others it folds in
            assert sorted(told_c, key=str) == sorted(told_python, key=str)
        else:  # only here and at the end: a read folds, which would tell a return before the sweep must
            look(python, c, now)
    look(python, c, now)
    assert sorted(told_c, key=str) == sorted(told_python, key=str)


def look(python: Roster, c: Roster, now: float) -> None:
    assert seen(c, now) == seen(python, now)
    for robot in range(1, 7):
        assert c.last_heard(robot) == python.last_heard(robot)


def test_a_flood_of_fresh_ids_keeps_the_tally_bounded(compiled: ModuleType) -> None:
    """Into a roster of two live robots, 10,000 fresh senders are counted, never stored."""
    _, c, _, _ = rosters(compiled, 2)
    take, _refuse = c.listeners()
    for who in range(10_000):
        take("radio0", 100.0, who, [Message(Op.PUT, 1, 1, 1, 1)])
    assert len(c) == 2
    assert c.untracked == 9_998
    assert [view.robot for view in c.snapshot(100.0)] == [0, 1]


def test_a_tick_sweeps_only_when_a_state_would_change(compiled: ModuleType) -> None:
    """The tally's tick (a Node's tick listener) reads the wall clock and calls the roster's sweep only when a robot
    would change state: a tick of robots heard just now calls nothing."""
    swept: list[float] = []
    tally = compiled.RosterTally(4, 0.3, 10.0, swept.append)
    now = time.time()
    tally.take("radio0", now, 1, [Message(Op.PUT, 1, 1, 1, 1)])
    tally.tick(None)
    assert swept == []
    tally.take("radio0", now - 1.0, 2, [])  # robot 2 last heard a second ago: quiet
    tally.tick(None)
    assert len(swept) == 1 and now <= swept[0] <= time.time()
    assert not tally.due(now - 0.8)  # 0.2 s after robot 2 was heard it was still alive


def test_a_tally_refuses_thresholds_out_of_order_by_name(compiled: ModuleType) -> None:
    with pytest.raises(ValueError, match=r"quiet_after .* gone_after"):
        compiled.RosterTally(4, 3.0, 1.0, print)


def test_a_link_past_what_a_gateway_takes_is_refused_by_name(compiled: ModuleType) -> None:
    tally = compiled.RosterTally(4, 0.3, 10.0, print)
    for n in range(64):
        tally.take(f"link{n}", 1.0, 1, [])
    try:
        tally.take("link64", 1.0, 1, [])
    except ValueError as error:
        assert "'link64'" in str(error)
    else:
        raise AssertionError("a 65th link was taken")


def test_a_compiled_relay_feeds_its_roster_in_c(compiled: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """A compiled RAW relay on a real pty keeps its roster with the Python `take` and `refuse` never called."""

    def not_called(*_args: object) -> None:
        raise AssertionError("the Python roster was fed on the compiled path")

    monkeypatch.setattr(Roster, "take", not_called)
    monkeypatch.setattr(Roster, "refuse", not_called)
    (master, slave), (other_master, other_slave) = os.openpty(), os.openpty()
    for fd in (master, slave, other_master, other_slave):
        tty.setraw(fd)
    cobs8 = make_serial_framing("cobs8")
    links = [parse(f"serial:{os.ttyname(fd)}?framing=cobs8").build(name, robot_id=200)
             for name, fd in (("radio", slave), ("radio2", other_slave))]
    try:
        with Node(links, 200, mode=Mode.RAW, period=0.05) as node:
            assert node.compiled
            kept = keep_roster(node)
            assert kept.roster.tallied
            for ts in range(1, 6):
                os.write(master, cobs8.encode(Message(Op.PUT, 6, 1, ts, 40))[0])
                os.write(master, cobs8.encode(Message(Op.PUT, 6, 1, 1, 41))[0])  # 41 keeps sending an old write
                time.sleep(0.05)
            time.sleep(0.2)
            views = {view.robot: view for view in kept.snapshot()}
    finally:
        for fd in (master, slave, other_master, other_slave):
            os.close(fd)
    assert sorted(views) == [40, 41]
    assert (views[40].writes, views[40].links, views[40].behind) == (5, ("radio",), ())
    assert (views[41].writes, views[41].behind) == (5, (6,))


def test_a_compiled_relay_sweeps_in_python_only_when_a_state_changes(compiled: ModuleType,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A compiled RAW relay on a real pty: robots talking every tick and then silent go quiet, told by the Python
    sweep on the tick (or two) where they do; every other tick runs none."""
    sweeps: list[float] = []
    sweep = Roster.sweep

    def counted(roster: Roster, now: float) -> None:
        sweeps.append(now)
        sweep(roster, now)

    monkeypatch.setattr(Roster, "sweep", counted)
    (master, slave), (other_master, other_slave) = os.openpty(), os.openpty()
    fds = (master, slave, other_master, other_slave)
    for fd in fds:
        tty.setraw(fd)
    cobs8 = make_serial_framing("cobs8")
    links = [parse(f"serial:{os.ttyname(fd)}?framing=cobs8").build(name, robot_id=200)
             for name, fd in (("radio", slave), ("radio2", other_slave))]
    changes: list[StateChange] = []
    try:
        with Node(links, 200, mode=Mode.RAW, period=0.05) as node:
            assert node.compiled
            kept = keep_roster(node)
            kept.on_change(changes.append)
            for ts in range(1, 11):
                os.write(master, cobs8.encode(Message(Op.PUT, 6, 1, ts, 40))[0])
                os.write(master, cobs8.encode(Message(Op.PUT, 7, 1, ts, 41))[0])
                time.sleep(0.05)
            time.sleep(0.4)  # silent: quiet after three periods
            states = {view.robot: view.state for view in kept.snapshot()}
            ticks = node.ticks
    finally:
        for fd in fds:
            os.close(fd)
    assert states == {40: RobotState.QUIET, 41: RobotState.QUIET}
    assert sorted((change.robot, change.new) for change in changes) == [(40, RobotState.QUIET),
                                                                        (41, RobotState.QUIET)]
    assert 1 <= len(sweeps) <= 2 and ticks >= 10, (sweeps, ticks)
