"""RosterHistory: the roster fed with capture times, swept each period of capture time, its gaps."""

from __future__ import annotations

import time

import pytest

from vstig_hw import roster_history
from vstig_hw.gateway.roster import RobotState
from vstig_hw.roster_history import RosterHistory
from vstig_hw.wire import Message, Op


def _put(robot: int, key: int = 1, ts: int = 1) -> Message:
    return Message(Op.PUT, key, 0, ts, robot)


def test_an_hour_of_silence_costs_a_few_sweeps_and_is_one_gap_each() -> None:
    history = RosterHistory(quiet_after=0.3, gone_after=2.0)
    sweeps = 0
    sweep = history.roster.sweep

    def counting(now: float) -> None:
        nonlocal sweeps
        sweeps += 1
        sweep(now)

    history.roster.sweep = counting  # type: ignore[method-assign]
    for step in range(10):
        history.take("radio0", 100.0 + step * 0.1, None, _put(1, ts=step + 1))
        history.take("can0", 100.0 + step * 0.1, 7, Message(Op.GET, 1, 0, step + 1, 1))
    started = time.perf_counter()
    history.take("radio0", 3700.0, None, _put(1, ts=20))  # an hour later: robot 1 is back, 7 is not
    assert time.perf_counter() - started < 0.1 and sweeps < 40, sweeps
    report = history.report()
    gaps = {gap.robot: gap for gap in report.gaps}
    assert gaps[1].start == 100.9 and gaps[1].end == 3700.0 and gaps[7].end is None
    assert round(gaps[7].seconds, 6) == round(3700.0 - 100.9, 6)
    assert {view.robot: view.state for view in report.robots} == {1: RobotState.ALIVE, 7: RobotState.GONE}
    assert [(c.robot, c.new.value) for c in report.changes] == [(1, "quiet"), (7, "quiet"), (1, "gone"),
                                                                (7, "gone"), (1, "alive")]
    assert 101.2 <= report.changes[0].t <= 101.3  # quiet after 0.3 s of capture time, to a sweep period


def test_gaps_are_bounded_and_counted(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(roster_history, "MAX_GAPS", 3)
    history = RosterHistory(quiet_after=0.3, gone_after=2.0)
    for t in (0.0, 1.0):  # ten robots heard, silent a second (quiet), heard again: a gap each
        for robot in range(1, 11):
            history.take("radio0", t, None, _put(robot, key=robot, ts=int(t) + 1))
    report = history.report()
    assert len(report.gaps) == 3 and report.gaps_untold == 7
    assert len(report.changes) == 20 and report.changes_untold == 0
