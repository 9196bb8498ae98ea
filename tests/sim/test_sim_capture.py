"""`vstig analyze` against the truth: the simulator knows when every robot learned the highest id."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from vstig_cli.main import cli
from vstig_hw.capture.records import read_capture
from vstig_hw.sim import Config

STEP_SECONDS = Config.control_step  # the paper's 0.1 s, which --control-step changes


@pytest.mark.parametrize(("topology", "robots", "drop"), [
    ("cluster", 20, 0.0), ("cluster", 20, 0.5), ("line", 12, 0.0), ("line", 12, 0.5),
    ("scale-free", 40, 0.75), ("scale-free", 300, 0.5),  # 300 robots: 29-bit IDs, read from the frames
])
def test_analyze_reports_the_simulators_convergence_time(tmp_path: Path, topology: str, robots: int,
                                                         drop: float) -> None:
    capture = tmp_path / "sim.log"
    sim = CliRunner().invoke(cli, ["sim", "--topology", topology, "--robots", str(robots), "--drop", str(drop),
                                   "--runs", "1", "--workers", "1", "--redraw-disconnected", "--json",
                                   "--capture", str(capture)])
    assert sim.exit_code == 0, sim.output
    (steps,) = json.loads(sim.stdout)["steps"]
    assert f"captured run 0 (converged at step {steps}" in sim.stderr

    analyzed = CliRunner().invoke(cli, ["analyze", str(capture), "--json", "--conflict", "value"])
    assert analyzed.exit_code == 0, analyzed.output
    report = json.loads(analyzed.stdout)
    writes = {w["robot"]: w for w in report["writes"]}
    assert len(writes) == robots and report["capture"]["messages"] == robots * steps
    highest = writes[robots - 1]  # the write every robot must end up holding
    # The simulator counts steps from init, whose PUT leaves at the end of step 1 (t = 0.1 s):
    # the last robot shows the highest id in what it sends at the end of step `steps`.
    assert highest["t"] == pytest.approx(STEP_SECONDS)
    assert highest["converged_after_s"] == pytest.approx((steps - 1) * STEP_SECONDS, abs=1e-6)
    assert highest["senders_total"] == highest["senders_caught_up"] == robots
    assert report["summary"]["converged"] == robots
    assert report["summary"]["max"] == pytest.approx((steps - 1) * STEP_SECONDS, abs=1e-6)


def test_capture_names_each_robot_as_a_can_node(tmp_path: Path) -> None:
    capture = tmp_path / "sim.log"
    result = CliRunner().invoke(cli, ["sim", "--topology", "line", "--robots", "5", "--runs", "1", "--workers", "1",
                                      "--capture", str(capture)])
    assert result.exit_code == 0, result.output
    records = list(read_capture(str(capture)))
    first_step = [r for r in records if r.t == pytest.approx(STEP_SECONDS)]
    assert sorted(r.unit.arbitration_id & 0xFF for r in first_step) == [0, 1, 2, 3, 4]
    assert all(r.link == "sim" and not r.unit.is_extended_id for r in records)
    assert {round(r.t / STEP_SECONDS, 6) for r in records} == {1, 2, 3, 4, 5}  # t = step x 0.1 s, steps 1..5


def test_capture_to_an_unknown_format_is_a_usage_error(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["sim", "--robots", "5", "--runs", "1", "--workers", "1",
                                      "--capture", str(tmp_path / "sim.txt")])
    assert result.exit_code == 2 and "chosen by extension" in result.output


def test_a_capture_is_stamped_at_the_runs_control_step(tmp_path: Path) -> None:
    capture = tmp_path / "slow.log"
    sim = CliRunner().invoke(cli, ["sim", "--topology", "line", "--robots", "5", "--runs", "1", "--workers", "1",
                                   "--control-step", "0.25", "--json", "--capture", str(capture)])
    assert sim.exit_code == 0, sim.output
    (steps,) = json.loads(sim.stdout)["steps"]
    assert steps == 5  # a lossless line of 5 robots: one hop per step
    records = list(read_capture(str(capture)))
    assert sorted({r.t for r in records}) == pytest.approx([0.25, 0.5, 0.75, 1.0, 1.25])  # t = step x 0.25 s
    analyzed = CliRunner().invoke(cli, ["analyze", str(capture), "--json", "--conflict", "value"])
    assert analyzed.exit_code == 0, analyzed.output
    report = json.loads(analyzed.stdout)
    highest = next(w for w in report["writes"] if w["robot"] == 4)
    assert highest["t"] == pytest.approx(0.25)
    assert highest["converged_after_s"] == pytest.approx((steps - 1) * 0.25, abs=1e-6)
    assert report["capture"]["duration_s"] == pytest.approx((steps - 1) * 0.25, abs=1e-6)


def test_bandwidth_per_second_follows_the_control_step() -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "line", "--robots", "5", "--runs", "1", "--workers", "1",
                                      "--control-step", "0.25"])
    assert result.exit_code == 0, result.output
    # A lossless line sends one 8-byte message per robot per step: 8 B / 0.25 s.
    assert "8.0 B per robot per step (32 B/s at 0.25 s steps)" in result.stdout
