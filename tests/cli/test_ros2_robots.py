"""A ros2: link's `robots` topic (vstig_msgs/Robots, transient local), read by a plain rclpy node
(tests/cli/ros2_robots_peer.py) in a lo-only namespace, as test_ros2.py's: 6 pty robots heard by a sniff,
2 go silent, one keeps sending an old write; published on change and at most once a second; a late
subscriber gets the latest."""

from __future__ import annotations

import itertools
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import dds
import pytest
from dds import Host
from peers import VSTIG, wait_for
from robots import PtyRobot
from roster_steps import KEY, RosterSteps
from test_ros2 import NAMESPACE, Process, host, ros2_env

pytestmark = pytest.mark.slow
__all__ = ["host", "ros2_env"]  # fixtures, used by name

PEER = str(Path(__file__).with_name("ros2_robots_peer.py"))
SILENT = (5, 6)
LAGGING = 4
STEP = 0.1
QUIET_AFTER, GONE_AFTER = 0.3, 2.0
SLACK = 1.0  # a loaded machine; and the node process between the roster and the peer


class Watcher(Process):
    def messages(self) -> list[dict[str, Any]]:
        return [{**record["robots"], "at": record["t"]} for record in map(_json, list(self.lines))
                if "robots" in record]

    def first(self, robot: int, state: str, since: float) -> float | None:
        return next((m["at"] for m in self.messages() if m["at"] >= since
                     for row in m["rows"] if row["robot"] == robot and row["state"] == state), None)


def _json(line: str) -> dict[str, Any]:
    record: dict[str, Any] = json.loads(line)
    return record


@pytest.fixture
def robots() -> Iterator[list[PtyRobot]]:
    made = [PtyRobot(n) for n in range(1, 7)]
    yield made
    for robot in made:
        robot.close()


def test_the_robots_topic_shows_quiet_gone_and_behind_on_change_latched(host: Host, ros2_env: dict[str, str],
                                                                        robots: list[PtyRobot]) -> None:
    sniff = Process([*host.command(), VSTIG, "sniff", *(r.spec for r in robots), "ros2:lab", "--jsonl",
                     "--quiet-after", str(QUIET_AFTER), "--gone-after", str(GONE_AFTER)], dds.vstig_environment())
    watchers: list[Watcher] = []
    run_step = RosterSteps(robots, LAGGING, STEP)

    def watcher() -> Watcher:
        made = Watcher([*host.command(), sys.executable, PEER, NAMESPACE], ros2_env, stdin=True)
        watchers.append(made)
        wait_for(lambda: any('"ready"' in line for line in made.lines) or made.process.poll() is not None, 60,
                 run_step)
        assert any('"ready": true' in line for line in made.lines), f"{made.lines} {''.join(made.errors)[-2000:]}"
        return made

    try:
        wait_for(lambda: sniff.said("ros2-lab: ROS 2 domain") or sniff.process.poll() is not None, 60)
        peer = watcher()
        everyone = set(range(1, 7))
        wait_for(lambda: any({r["robot"] for r in m["rows"]} == everyone and m["alive"] == 6
                             for m in peer.messages()), 30, run_step)
        # Steady: nobody joins, leaves or lags anew, so nothing more is published, though the counts grow.
        steady = len(peer.messages())
        for _ in range(20):
            run_step()
        assert len(peer.messages()) <= steady + 1, peer.messages()[steady:]  # (the lag noticed, if it was not)

        since = time.time()
        run_step.silent.update(SILENT)
        wait_for(lambda: all(peer.first(n, "gone", since) for n in SILENT), 20, run_step)
        for n in SILENT:
            quiet, gone = peer.first(n, "quiet", since), peer.first(n, "gone", since)
            assert quiet is not None and quiet - since <= QUIET_AFTER + STEP + 1.0 + SLACK, (n, quiet, since)
            assert gone is not None
            assert GONE_AFTER - STEP <= gone - since <= GONE_AFTER + STEP + 1.0 + SLACK, gone - since
        sent = peer.messages()
        assert all(b["t"] - a["t"] >= 0.8 for a, b in itertools.pairwise(sent)), \
            [m["t"] for m in sent]  # at most once a second (the snapshots' times, made on a request thread)
        last = sent[-1]
        rows = {r["robot"]: r for r in last["rows"]}
        assert (last["alive"], last["quiet"], last["gone"], last["robots_total"]) == (4, 0, 2, 6)
        assert [r["robot"] for r in last["rows"]] == [1, 2, 3, 4, 5, 6]
        assert rows[LAGGING]["behind"] == [KEY] and rows[1]["behind"] == []
        assert all(r["named_by"] == "writer" and r["quality"] == -1 for r in rows.values())
        assert rows[1]["writes"] > rows[2]["writes"] > 0

        late = watcher()  # joins after: transient local hands it the latest at once
        wait_for(lambda: bool(late.messages()), 10, run_step)
        got = late.messages()[0]
        assert [(r["robot"], r["state"]) for r in got["rows"]] == [(r["robot"], r["state"]) for r in last["rows"]]
    finally:
        for each in watchers:
            each.stop()
        stderr = sniff.stop()
    assert "Traceback" not in stderr, stderr[-3000:]
