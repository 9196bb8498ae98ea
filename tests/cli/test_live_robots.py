"""The live view's `/vstig/robots`, watched with Foxglove's own client (tests/live, as test_live_view.py):
12 real pty robots and 2 CAN robots on an slcan adapter; 3 pty robots go silent mid-run and one keeps sending
an old write of a key. Quiet, gone and behind reach the viewer within the documented times
(docs/how-to/robots.md: the threshold, a control period, and the channel's second)."""

from __future__ import annotations

import json
import time
from typing import Any

from peers import SlcanAdapter, start_vstig, stop
from robots import PtyRobot
from roster_steps import KEY, RosterSteps
from test_live_view import _URL, Lines, SharedBusRobot, Viewer

from vstig_hw.wire import Message

SILENT = (9, 10, 11)
LAGGING = 12
CAN_IDS = (20, 21)  # named by the CAN ID's sender field
STEP = 0.1  # the robots' control step, as the gateway's period
QUIET_AFTER, GONE_AFTER = 0.3, 2.0
SLACK = 1.0  # a loaded machine (two CPUs, several suites), the two pumps between roster and viewer


class TimedViewer(Viewer):
    """Foxglove's client, each event stamped with when it reached this process."""

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.events.put({**json.loads(line), "at": time.monotonic()})

    def first(self, robot: int, since: float, state: str) -> float | None:
        """When the first /vstig/robots message after `since` showing `robot` in `state` arrived."""
        return next((m["at"] for m in self.messages("/vstig/robots") if m["at"] >= since
                     for row in m["data"]["rows"] if row["robot"] == robot and row["state"] == state), None)

    def latest(self) -> dict[str, Any]:
        data: dict[str, Any] = self.messages("/vstig/robots")[-1]["data"]
        return data


def test_quiet_gone_and_behind_reach_foxglove_within_the_documented_time() -> None:
    robots = [PtyRobot(n) for n in range(1, 13)]
    adapter = SlcanAdapter()
    bus: list[tuple[int, Message]] = []
    can_robots = [SharedBusRobot(n, adapter, bus) for n in CAN_IDS]
    sniff = start_vstig("sniff", f"can:slcan:{adapter.path}", *(robot.spec for robot in robots), "--jsonl",
                        "--foxglove", "0", "--quiet-after", str(QUIET_AFTER), "--gone-after", str(GONE_AFTER))
    assert sniff.stderr is not None and sniff.stdout is not None
    err, _out = Lines(sniff.stderr), Lines(sniff.stdout)
    viewer: TimedViewer | None = None

    def can_steps() -> None:
        for can_robot in can_robots:
            can_robot.step()

    run_step = RosterSteps(robots, LAGGING, STEP, also=can_steps)

    try:
        viewer = TimedViewer(err.first(_URL).group(1))
        everyone = set(range(1, 13)) | set(CAN_IDS)
        viewer.until(lambda: bool(viewer.messages("/vstig/robots"))
                     and {r["robot"] for r in viewer.latest()["rows"]} >= everyone, 30, run_step)
        latest = viewer.latest()
        rows = {r["robot"]: r for r in latest["rows"]}
        assert {n: rows[n]["named_by"] for n in everyone} == {n: "sender" if n in CAN_IDS else "writer"
                                                              for n in everyone}
        assert all(rows[n]["state"] == "alive" for n in everyone) and latest["untracked"] == 0, rows
        assert rows[CAN_IDS[0]]["sender"] == CAN_IDS[0] and rows[1]["sender"] is None

        since = time.monotonic()
        run_step.silent.update(SILENT)
        viewer.until(lambda: all(viewer.first(n, since, "gone") for n in SILENT), 20, run_step)
        for n in SILENT:  # their last write was a step before
            quiet, gone = viewer.first(n, since, "quiet"), viewer.first(n, since, "gone")
            assert quiet is not None and quiet - since <= QUIET_AFTER + STEP + 1.0 + SLACK, (n, quiet, since)
            assert gone is not None
            assert GONE_AFTER - STEP <= gone - since <= GONE_AFTER + STEP + 1.0 + SLACK, gone - since
        viewer.until(lambda: viewer.messages("/vstig/robots")[-1]["at"] > since + GONE_AFTER + 1.0, 10,
                     run_step)
        latest = viewer.latest()
        rows = {r["robot"]: r for r in latest["rows"]}
        assert {n for n, r in rows.items() if r["state"] == "alive"} == everyone - set(SILENT)
        assert (latest["alive"], latest["quiet"], latest["gone"], latest["robots_total"]) == (11, 0, 3, 14)
        assert [r["robot"] for r in latest["rows"]][-3:] == list(SILENT)  # sorted by state, then id
        assert rows[LAGGING]["behind"] == [KEY] and rows[1]["behind"] == [], rows[LAGGING]
        assert rows[1]["writes"] > rows[2]["writes"] and rows[2]["rate"] > 3, rows
        assert rows[CAN_IDS[0]]["gets"] > 0 and rows[CAN_IDS[0]]["links"] != rows[1]["links"]
    finally:
        if viewer is not None and viewer.process.poll() is None:
            viewer.leave()
        stop(sniff)
        err.join()  # its stderr, read by `err`
        for robot in robots:
            robot.close()
        adapter.close()
    assert sniff.returncode == 0 and not any("Traceback" in line for line in err.lines), "".join(err.lines)
