"""swarm.record: a capture of what the swarm's links hear, read back by `decode`'s own reader."""

from __future__ import annotations

import io
import json
import threading
import time
from pathlib import Path

import pytest

import vstig_hw
from vstig_hw import Entry, Stigmergy
from vstig_hw.api.virtual import VirtualRobots
from vstig_hw.capture.decoded import decode_file


class Writer:
    """Each robot writes its key three times, once the recording runs (what is sent before, nobody records)."""

    def __init__(self) -> None:
        self.go = threading.Event()
        self.writes: dict[int, int] = {}

    def __call__(self, robot: Stigmergy, step: int) -> None:
        if self.go.is_set() and self.writes.get(robot.robot_id, 0) < 3:
            self.writes[robot.robot_id] = self.writes.get(robot.robot_id, 0) + 1
            robot.put(10 + robot.robot_id, self.writes[robot.robot_id])


def decoded(path: Path) -> list[dict[str, object]]:
    out = io.StringIO()
    decode_file(str(path), out, "jsonl")
    return [json.loads(line) for line in out.getvalue().splitlines()]


def test_a_recording_holds_what_the_bus_carried_until_stopped(tmp_path: Path) -> None:
    writer = Writer()
    with VirtualRobots(can_ids=[1, 2], program=writer) as robots, \
            vstig_hw.join(*robots.links, robot_id=50) as swarm:
        recording = swarm.record(tmp_path / "swarm.log")
        writer.go.set()
        deadline = time.monotonic() + 5
        while [swarm.entry(11), swarm.entry(12)] != [Entry(3, 3, 1), Entry(3, 3, 2)] and time.monotonic() < deadline:
            time.sleep(0.01)
        recording.stop()
        recording.stop()  # twice is fine
        assert recording.records > 0 and recording.files == [str(tmp_path / "swarm.log")]
        after = recording.records
        swarm.put(1, 1)
        assert recording.records == after  # stopped: nothing more written
    rows = decoded(tmp_path / "swarm.log")
    puts = {(row["key"], row["value"], row["robot"]) for row in rows if row["op"] == "PUT"}
    assert {(11, 3, 1), (12, 3, 2)} <= puts


def test_a_recording_never_replaces_a_file_and_refuses_a_format_that_cannot_hold_the_links(tmp_path: Path) -> None:
    existing = tmp_path / "mine.log"
    existing.write_text("keep me")
    with VirtualRobots(can_ids=[1], radio_ids=[2]) as robots, vstig_hw.join(*robots.links, robot_id=50) as swarm:
        with pytest.raises(ValueError, match="links of different media"):
            swarm.record(tmp_path / "both.log")
        with vstig_hw.join(robots.links[0], robot_id=51) as can_only:
            with pytest.raises(FileExistsError, match=r"mine\.log exists: a capture is never replaced"):
                can_only.record(existing)
            with pytest.raises(ValueError, match="a CAN capture is chosen by extension"):
                can_only.record(tmp_path / "x.txt")
            can_only.record(existing, overwrite=True).stop()
    assert existing.read_text() != "keep me"


def test_a_recording_is_never_written_through_a_symbolic_link(tmp_path: Path) -> None:
    target = tmp_path / "notes.txt"
    target.write_text("keep me")
    (tmp_path / "live.log").symlink_to(target)
    (tmp_path / "dangling.log").symlink_to(tmp_path / "nowhere.log")
    with VirtualRobots(can_ids=[1], radio_ids=[]) as robots, vstig_hw.join(*robots.links, robot_id=50) as swarm:
        for name in ("live.log", "dangling.log"):
            with pytest.raises(ValueError, match=rf"{name} is a symbolic link"):
                swarm.record(tmp_path / name, overwrite=True)
    assert target.read_text() == "keep me" and not (tmp_path / "nowhere.log").exists()
