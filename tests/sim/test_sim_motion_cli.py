"""`vstig sim --topology motion`, `--snapshot` and `vstig sim paper-motion` through click's CliRunner."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from click.testing import CliRunner

from vstig_cli.main import cli

_PNG = b"\x89PNG\r\n\x1a\n"


def test_motion_json_has_the_static_fields_and_the_motion_config() -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "motion", "--density", "5", "--speed", "0.2", "--robots",
                                      "30", "--drop", "0.25", "--runs", "2", "--workers", "1", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert {"median", "min", "max", "mean", "runs", "msgs_per_robot_step", "split_runs", "largest_share"} <= (
        summary.keys())
    assert summary["runs"] == summary["converged"] == 2 and summary["msgs_per_robot_step"] == 1.0
    config = summary["config"]
    assert (config["topology"], config["density"], config["speed"], config["control_step"]) == ("motion", 5, 0.2, 0.1)


def test_motion_text_names_density_and_speed() -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "motion", "--density", "1", "--speed", "0.2", "--robots",
                                      "20", "--runs", "1", "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert "motion D=1 S=0.2 N=20 P=0.0: 1 run, seed 1" in result.output
    assert "runs started split into components" in result.output and "which motion had to join" in result.output


def test_snapshot_draws_the_arena_at_a_chosen_step(tmp_path: Path) -> None:
    out = tmp_path / "d3.png"
    result = CliRunner().invoke(cli, ["sim", "--topology", "motion", "--density", "3", "--snapshot", str(out),
                                      "--snapshot-step", "20"])
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == _PNG
    assert f"wrote {out}: step 20," in result.output and "component(s)" in result.output


def test_snapshot_needs_the_motion_topology_and_a_writable_path(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "line", "--snapshot", str(tmp_path / "x.png")])
    assert result.exit_code == 2 and "--topology motion" in result.output
    result = CliRunner().invoke(cli, ["sim", "--topology", "motion", "--snapshot", str(tmp_path / "no" / "x.png")])
    assert result.exit_code == 1 and "cannot write" in result.output and "Traceback" not in result.output


def test_bad_motion_options_are_usage_errors_naming_them() -> None:
    for args, named in ((["--speed", "-1"], "--speed"), (["--control-step", "0"], "--control-step"),
                        (["--turn-noise", "nan"], "--turn-noise")):
        result = CliRunner().invoke(cli, ["sim", "--topology", "motion", "--runs", "1", *args])
        assert result.exit_code == 2, result.output
        assert named in result.output and "Traceback" not in result.output


def test_paper_motion_grid_writes_csv_png_and_every_statement(tmp_path: Path) -> None:
    out = tmp_path / "motion"
    args = ["sim", "paper-motion", "--runs", "2", "--robots", "20", "--densities", "3,5", "--speeds", "0.05,0.2",
            "--drops", "0,0.5", "--workers", "1", "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert len(rows) == 8  # 2 densities x 2 speeds x 2 drop probabilities
    assert {(r["density"], r["speed"], r["drop"]) for r in rows} >= {("3.0", "0.05", "0.0"), ("5.0", "0.2", "0.5")}
    assert all(r["topology"] == "motion" and r["robots"] == "20" and r["runs"] == "2" for r in rows)
    runs = list(csv.DictReader((out / "runs.csv").open()))
    assert len(runs) == 16 and all(r["steps"] for r in runs)
    assert (out / "figure5.png").read_bytes()[:8] == _PNG
    table = (out / "comparison.md").read_text()
    assert "Wall time for the grid" in table and "load average" in table
    for statement in ("most robots are connected, a few must move", "fully connected", "degrades gracefully",
                      "the faster the robots, the faster the spreading", "efficient even when a minority"):
        assert statement in table
    assert "| motion | 5.0 | 0.2 | 20 | 0.5 |" in table


def test_paper_motion_refuses_a_bad_list() -> None:
    result = CliRunner().invoke(cli, ["sim", "paper-motion", "--speeds", "fast"])
    assert result.exit_code == 2 and "--speeds" in result.output and "'fast'" in result.output
    result = CliRunner().invoke(cli, ["sim", "paper-motion", "--drops", "1.5"])
    assert result.exit_code == 2 and "drop probability" in result.output
