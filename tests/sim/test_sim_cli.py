"""`vstig sim` through click's CliRunner: the JSON summary, the notes, and a small paper grid."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from vstig_cli.main import cli


def test_json_summary_of_a_lossless_line() -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "line", "--robots", "12", "--drop", "0", "--runs", "3",
                                      "--workers", "1", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert {"median", "min", "max", "mean", "runs", "msgs_per_robot_step"} <= summary.keys()
    assert (summary["median"], summary["min"], summary["max"], summary["mean"]) == (12, 12, 12, 12.0)
    assert summary["runs"] == 3 and summary["msgs_per_robot_step"] == 1.0
    assert summary["config"]["topology"] == "line"


def test_text_summary_and_a_clear_note_when_the_step_cap_is_hit() -> None:
    result = CliRunner().invoke(cli, ["sim", "--topology", "line", "--robots", "40", "--drop", "0.5", "--runs", "2",
                                      "--workers", "1", "--max-steps", "20"])
    assert result.exit_code == 0, result.output
    assert "no run converged" in result.output
    assert "2 of 2 runs did not converge within 20 steps" in result.output


def test_bad_drop_is_named() -> None:
    result = CliRunner().invoke(cli, ["sim", "--drop", "1"])
    assert result.exit_code == 2 and "--drop" in result.output


def test_an_arena_too_dense_for_the_bodies_is_a_clear_error() -> None:
    result = CliRunner().invoke(cli, ["sim", "--robots", "10", "--density", "1000", "--runs", "1", "--workers", "1"])
    assert result.exit_code == 1 and "Error: cannot place robot" in result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(("option", "value", "named"), [
    ("--range", "nan", "'--range'"), ("--range", "1e300", "radio_range"), ("--range", "inf", "'--range'"),
    ("--density", "nan", "'--density'"), ("--body-radius", "nan", "'--body-radius'"),
])
def test_silly_geometry_is_a_usage_error_not_a_traceback(option: str, value: str, named: str) -> None:
    result = CliRunner().invoke(cli, ["sim", "--robots", "5", "--runs", "1", "--workers", "1", option, value])
    assert result.exit_code == 2, result.output
    assert named in result.output and "Traceback" not in result.output


def test_paper_grid_for_ten_robots_writes_csv_png_and_comparison(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    args = ["sim", "paper", "--runs", "3", "--robots", "10", "--workers", "1", "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert len(rows) == 15  # 3 topologies x 5 drop probabilities
    assert {(r["topology"], r["drop"]) for r in rows} >= {("cluster", "0.75"), ("line", "0.95"), ("scale-free", "0.0")}
    line_lossless = next(r for r in rows if (r["topology"], r["drop"]) == ("line", "0.0"))
    assert (line_lossless["median"], line_lossless["runs"]) == ("10", "3")
    assert len(list(csv.DictReader((out / "runs.csv").open()))) == 45
    assert (out / "figure3.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = (out / "comparison.md").read_text()
    assert "| cluster N=10 P=0.75 | mean" in table and "| 6 |" in table


@pytest.mark.parametrize(("args", "says"), [
    (["sim", "--runs", "99999999999999999999"], "'--runs': 99999999999999999999 is not in the range 1<=x<=100000"),
    (["sim", "--runs", "100001"], "'--runs': 100001 is not in the range 1<=x<=100000"),
    (["sim", "paper", "--runs", "10000", "-o", "{tmp}/paper"], "at most 2,222 per condition"),
    (["sim", "paper-motion", "--runs", "10000", "-o", "{tmp}/paper"], "at most 2,222 per condition"),
    (["sim", "--workers", "100000"], "'--workers': 100000 is not in the range"),
])
def test_runs_are_bounded_before_anything_is_allocated(tmp_path: Path, args: list[str], says: str) -> None:
    result = CliRunner().invoke(cli, [arg.format(tmp=tmp_path) for arg in args])
    assert result.exit_code == 2 and says in result.output, result.output
    assert not (tmp_path / "paper").exists()  # refused before its folder is made


def test_long_runs_show_a_bar_on_a_terminal(tmp_path: Path) -> None:
    """stderr on a pty: the bar counts runs done (a log file gets none: see the JSON test)."""
    import os
    import subprocess
    import sys

    master, slave = os.openpty()
    try:
        done = subprocess.run([sys.executable, "-m", "vstig_cli.main", "sim", "--robots", "10", "--runs", "40",
                               "--workers", "1", "--json"], stdout=subprocess.PIPE, stderr=slave, timeout=120)
        os.close(slave)
        screen = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the pty is closed and drained
                break
            if not chunk:
                break
            screen += chunk
    finally:
        os.close(master)
    assert done.returncode == 0 and json.loads(done.stdout)["runs"] == 40
    assert b"/40" in screen and b"cluster N=10" in screen, screen[-400:]
