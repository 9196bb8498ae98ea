"""Simulated control steps per second at N=1000, beside what the Figure 3 grid needs (issue 7).

The anchor is the rate at which one core must simulate 1000-robot control steps
for the whole grid (3 topologies x 3 sizes x 5 drop rates x 50 runs) to finish
in 30 minutes on 2 cores. The grid's work, in robot-steps, is read from the last
`vstig sim paper` output committed under benchmarks/results/paper/ (scaled to 50
runs); ratio >= 1 means we make it, if the cores are ours alone.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Iterator
from pathlib import Path

from vstig_hw.sim import Config, run_once, seed_for

from .registry import Result, benchmark

_RUNS = 50
_BUDGET_SECONDS = 30 * 60
_CORES = 2
_RESULTS = Path(__file__).parent / "results" / "paper" / "runs.csv"


def grid_robot_steps(path: Path = _RESULTS, runs: int = _RUNS) -> float:
    """Robot-steps the whole grid simulates at `runs` runs per condition, from a recorded grid."""
    with path.open(newline="") as rows:
        records = list(csv.DictReader(rows))
    conditions = {(r["topology"], r["robots"], r["drop"]) for r in records}
    recorded_runs = len(records) / len(conditions)
    work = sum(int(r["steps_run"]) * int(r["robots"]) for r in records)
    return work * runs / recorded_runs


def _steps_per_second(config: Config) -> float:
    start = time.perf_counter()
    result = run_once(config, seed_for(config, 1, 0))
    return result.steps_run / (time.perf_counter() - start)


@benchmark("sim")
def steps_at_n1000() -> Iterator[Result]:
    if not _RESULTS.exists():
        raise SystemExit(f"{_RESULTS} is missing: run `vstig sim paper -o {_RESULTS.parent}` first")
    needed = grid_robot_steps() / 1000 / (_BUDGET_SECONDS * _CORES)
    anchor = f"needed: {_RUNS}-run grid in 30 min on {_CORES} cores"
    cluster = Config("cluster", 1000, 0.75)
    yield Result("sim.cluster_n1000_p0.75", _steps_per_second(cluster), "steps/s", anchor, needed)
    # Two thirds of the grid's work is this one condition: 1000 robots in a line at P=0.95.
    line = Config("line", 1000, 0.95, max_steps=2_000)
    yield Result("sim.line_n1000_p0.95", _steps_per_second(line), "steps/s", anchor, needed)
