"""Simulated control steps per second, beside what the Figure 3 and Figure 5 grids need.

The anchor is the rate at which one core must simulate control steps for the
whole grid to finish in 30 minutes on 2 cores: Figure 3 (3 topologies x 3 sizes
x 5 drop rates x 50 runs) in 1000-robot steps, Figure 5 (3 densities x 3 speeds
x 5 drop rates x 50 runs of 100 moving robots) in 100-robot steps. The grid's
work is read from the last `vstig sim paper` / `paper-motion` output committed
under benchmarks/results/ (scaled to 50 runs); ratio >= 1 means we make it, if
the cores are ours alone. For Figure 5, `sim.motion_grid_estimate` adds up each
density's work at its own measured rate: the grid's minutes on 2 cores.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Iterator
from dataclasses import replace
from itertools import count
from pathlib import Path

from vstig_hw.sim import Config, run_once, seed_for

from .registry import Result, benchmark

_RUNS = 50
_BUDGET_SECONDS = 30 * 60
_CORES = 2
_RESULTS = Path(__file__).parent / "results" / "paper" / "runs.csv"
_MOTION_RESULTS = Path(__file__).parent / "results" / "paper-motion" / "runs.csv"


def grid_robot_steps(path: Path = _RESULTS, runs: int = _RUNS) -> float:
    """Robot-steps the whole grid simulates at `runs` runs per condition, from a recorded grid."""
    with path.open(newline="") as rows:
        records = list(csv.DictReader(rows))
    recorded_runs = len({r["run"] for r in records})
    work = sum(int(r["steps_run"]) * int(r["robots"]) for r in records)
    return work * runs / recorded_runs


def _steps_per_second(config: Config, min_steps: int = 1) -> float:
    """Control steps per second over runs 0, 1, ... until `min_steps` were simulated (runs that converge early)."""
    run_once(replace(config, max_steps=2), seed_for(config, 2, 0))  # loads the compiled loops: once per process
    steps, start = 0, time.perf_counter()
    for run in count():
        steps += run_once(config, seed_for(config, 1, run), run).steps_run
        if steps >= min_steps:
            return steps / (time.perf_counter() - start)
    raise AssertionError("unreachable")


def _steps_by_density(path: Path, runs: int = _RUNS) -> dict[float, float]:
    """Control steps the recorded motion grid simulates at each density, scaled to `runs` runs per condition."""
    with path.open(newline="") as rows:
        records = list(csv.DictReader(rows))
    recorded_runs = len({r["run"] for r in records})
    steps: dict[float, float] = {}
    for r in records:
        steps[float(r["density"])] = steps.get(float(r["density"]), 0.0) + int(r["steps_run"]) * runs / recorded_runs
    return steps


def _needed(path: Path, robots: int, command: str) -> tuple[str, float]:
    """The anchor: `robots`-robot steps per second per core that the recorded grid needs."""
    if not path.exists():
        raise SystemExit(f"{path} is missing: run `vstig sim {command} -o {path.parent}` first")
    return (f"needed: {_RUNS}-run grid in 30 min on {_CORES} cores",
            grid_robot_steps(path) / robots / (_BUDGET_SECONDS * _CORES))


@benchmark("sim")
def steps_at_n1000() -> Iterator[Result]:
    anchor, needed = _needed(_RESULTS, 1000, "paper")
    cluster = Config("cluster", 1000, 0.75)
    yield Result("sim.cluster_n1000_p0.75", _steps_per_second(cluster), "steps/s", anchor, needed)
    # Two thirds of the grid's work is this one condition: 1000 robots in a line at P=0.95.
    line = Config("line", 1000, 0.95, max_steps=2_000)
    yield Result("sim.line_n1000_p0.95", _steps_per_second(line), "steps/s", anchor, needed)


@benchmark("sim")
def motion_steps_at_n100() -> Iterator[Result]:
    anchor, needed = _needed(_MOTION_RESULTS, 100, "paper-motion")
    # D = 1 is most of the Figure 5 grid's work (islands wait thousands of steps for motion), but a
    # step at D = 5 costs more (more neighbours, more receptions): the estimate weighs each density's rate.
    seconds = 0.0
    for density, steps in sorted(_steps_by_density(_MOTION_RESULTS).items()):
        config = Config("motion", 100, 0.5, density=density, speed=0.1, max_steps=2_000)
        rate = _steps_per_second(config, min_steps=2_000)
        yield Result(f"sim.motion_d{density:g}_n100_p0.5", rate, "steps/s", anchor, needed)
        seconds += steps / rate
    yield Result("sim.motion_grid_estimate", seconds / _CORES / 60, "min", "the 30 min budget (<= 1 makes it)",
                 _BUDGET_SECONDS / 60)
