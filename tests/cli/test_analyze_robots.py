"""`vstig analyze --robots` on a capture `vstig record` made of 5 real pty robots: one goes silent mid-run and comes
back, one goes silent for good, one keeps sending an old write. The roster over the capture's time shows who was
heard when, both silences as gaps (one open until the end), the state changes and the robot behind."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from peers import run_vstig, start_vstig, stop, wait_for
from robots import PtyRobot
from roster_steps import KEY, RosterSteps

STEP = 0.1
BACK, LEAVES, LAGGING = 3, 4, 5  # silent for PAUSE seconds mid-run; silent from then to the end; an old write
PAUSE = 1.0  # quiet, not gone
QUIET_AFTER, GONE_AFTER = 0.3, 2.0


def _record(tmp_path: Path) -> tuple[Path, dict[str, float]]:
    """The capture, and when (wall clock) each robot's silences began and ended."""
    robots = [PtyRobot(n) for n in range(1, 6)]
    capture = tmp_path / "swarm.txt"
    record = start_vstig("record", *(robot.spec for robot in robots), "-o", str(capture))
    marks: dict[str, float] = {}
    run_step = RosterSteps(robots, LAGGING, STEP)

    try:
        wait_for(lambda: capture.exists() and capture.stat().st_size > 2000, 30, run_step)
        for _ in range(10):
            run_step()
        marks["pause"] = time.time()
        run_step.silent.add(BACK)
        for _ in range(int(PAUSE / STEP)):
            run_step()
        marks["back"] = time.time()
        run_step.silent.discard(BACK)
        for _ in range(10):
            run_step()
        marks["leaves"] = time.time()
        run_step.silent.add(LEAVES)
        for _ in range(int((GONE_AFTER + 1.0) / STEP)):
            run_step()
    finally:
        _, stderr = stop(record)
        for robot in robots:
            robot.close()
    assert record.returncode == 0, stderr
    return capture, marks


def test_analyze_robots_shows_who_was_heard_when_and_the_silences(tmp_path: Path) -> None:
    capture, marks = _record(tmp_path)
    done = run_vstig("analyze", str(capture), "--robots", "--json", "--quiet-after", str(QUIET_AFTER),
                     "--gone-after", str(GONE_AFTER))
    assert done.returncode == 0, done.stderr
    roster: dict[str, Any] = json.loads(done.stdout)["robots"]
    assert (roster["quiet_after_s"], roster["gone_after_s"], roster["untracked"]) == (QUIET_AFTER, GONE_AFTER, 0)
    robots = {row["robot"]: row for row in roster["robots"]}
    assert sorted(robots) == [1, 2, 3, 4, 5]
    assert [row["robot"] for row in roster["robots"]] == [1, 2, 3, 5, 4]  # by state at the end, then id
    assert {n: row["state_at_end"] for n, row in robots.items()} == {1: "alive", 2: "alive", 3: "alive",
                                                                     4: "gone", 5: "alive"}
    assert all(row["named_by"] == "writer" and len(row["links"]) == 1 for row in robots.values())
    assert robots[LAGGING]["behind"] == [KEY] and robots[1]["behind"] == []

    # Robot 3's silence: from its last write before the pause until its first after (the capture's own times),
    # within a step or two of when the test paused it; robot 4's is open until the capture ends.
    ((back,), (leaves,)) = robots[BACK]["gaps"], robots[LEAVES]["gaps"]
    assert abs(back["start"] - marks["pause"]) < 2 * STEP + 0.2 and abs(back["end"] - marks["back"]) < 2 * STEP + 0.2
    assert PAUSE - 2 * STEP - 0.2 < back["seconds"] < PAUSE + 2 * STEP + 0.2, back
    assert abs(leaves["start"] - marks["leaves"]) < 2 * STEP + 0.2 and leaves["end"] is None
    assert leaves["seconds"] > GONE_AFTER + 0.5, leaves
    assert all(row["gaps"] == [] for n, row in robots.items() if n not in (BACK, LEAVES))
    assert robots[LEAVES]["last_heard"] == leaves["start"]

    changes = [(c["robot"], c["from"], c["to"]) for c in roster["changes"]]
    assert changes == [(BACK, "alive", "quiet"), (BACK, "quiet", "alive"), (LEAVES, "alive", "quiet"),
                       (LEAVES, "quiet", "gone")], changes
    went_quiet = roster["changes"][0]["t"] - back["start"]
    assert QUIET_AFTER <= went_quiet <= QUIET_AFTER + 2 * STEP, went_quiet  # swept each period of capture time
    went = roster["changes"][3]["t"] - leaves["start"]
    assert GONE_AFTER <= went <= GONE_AFTER + 2 * STEP, went

    text = run_vstig("analyze", str(capture), "--robots", "--quiet-after", str(QUIET_AFTER),
                     "--gone-after", str(GONE_AFTER))
    assert text.returncode == 0, text.stderr
    lines = text.stdout.splitlines()
    assert any(line.startswith("robots: 5 robots at the end (4 alive, 0 quiet, 1 gone)") for line in lines), lines
    gap_rows = [line.split() for line in lines[lines.index(next(x for x in lines if x.startswith("silences"))):]
                if line.split() and line.split()[0] in (str(BACK), str(LEAVES)) and len(line.split()) >= 4]
    assert [row[0] for row in gap_rows] == [str(BACK), str(LEAVES)] and gap_rows[1][2] == "-", gap_rows
    assert "state changes: 4 (alive->quiet 2, quiet->alive 1, quiet->gone 1)" in lines
    assert all(len(line) <= 80 for line in lines[lines.index(next(x for x in lines if x.startswith("robots:"))):])


def test_analyze_refuses_thresholds_without_robots_and_gone_before_quiet(tmp_path: Path) -> None:
    capture = tmp_path / "one.log"
    capture.write_text("(1.0) can0 101#0100010001000100\n")
    alone = run_vstig("analyze", str(capture), "--quiet-after", "1")
    assert alone.returncode == 2 and "give --robots too" in alone.stderr, alone.stderr
    backwards = run_vstig("analyze", str(capture), "--robots", "--quiet-after", "5", "--gone-after", "2")
    assert backwards.returncode == 2 and "--gone-after (2 s) must be longer than --quiet-after (5 s)" in \
        backwards.stderr, backwards.stderr
