"""The paper's Figure 3 grid, its CSV files and the table that sets our numbers beside the paper's."""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from .experiment import Config, RunResult, Summary, Task, run_tasks, summarize

__all__ = ["PAPER_DROPS", "PAPER_ROBOTS", "PAPER_TOPOLOGIES", "STATIC_CONDITION", "Cell", "Claim", "claims_table",
           "conditions_table", "fmt_steps", "paper_claims", "run_grid", "write_csv"]

PAPER_TOPOLOGIES = ("cluster", "line", "scale-free")
PAPER_ROBOTS = (10, 100, 1000)
PAPER_DROPS = (0.0, 0.25, 0.5, 0.75, 0.95)


@dataclass(frozen=True)
class Cell:
    config: Config
    results: list[RunResult]

    @property
    def summary(self) -> Summary:
        return summarize(self.results)


def paper_configs(template: Config | None = None) -> list[Config]:
    base = template or Config("cluster", 10, 0.0)
    return [replace(base, topology=t, robots=n, drop=p)
            for t in PAPER_TOPOLOGIES for n in PAPER_ROBOTS for p in PAPER_DROPS]


def run_grid(
    configs: Sequence[Config], runs: int, seed: int = 1, workers: int | None = None,
    on_done: Callable[[Task, RunResult], None] | None = None,
) -> list[Cell]:
    tasks = [(config, seed, run) for config in configs for run in range(runs)]
    results = run_tasks(tasks, workers, on_done)
    return [Cell(config, [results[(config, seed, run)] for run in range(runs)]) for config in configs]


STATIC_CONDITION = ("topology", "robots", "drop")  # the Config fields that name a Figure 3 condition
_SUMMARY_FIELDS = ("runs", "converged", "median", "min", "max", "mean", "msgs_per_robot_step", "bytes_per_robot_step",
                   "deliveries_per_robot_step", "mean_degree", "split_runs", "largest_share")
_RUN_FIELDS = ("run", "steps", "steps_run", "messages", "deliveries", "mean_degree", "components", "layouts",
               "largest_share")


def write_csv(cells: Sequence[Cell], summary_path: Path, runs_path: Path,
              condition: Sequence[str] = STATIC_CONDITION) -> None:
    """One row per condition (summary) and one per run (for your own statistics).

    `condition` names the Config fields that tell the conditions apart; they lead each row.
    """
    with summary_path.open("w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow([*condition, *_SUMMARY_FIELDS])
        for cell in cells:
            s = cell.summary
            writer.writerow([*_condition_values(cell.config, condition), s.runs, s.converged, s.median, s.min, s.max,
                             _fmt(s.mean), _fmt(s.msgs_per_robot_step), _fmt(s.bytes_per_robot_step),
                             _fmt(s.deliveries_per_robot_step), _fmt(s.mean_degree), s.split_runs,
                             _fmt(s.largest_share)])
    with runs_path.open("w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow([*condition, *_RUN_FIELDS])
        for cell in cells:
            leading = _condition_values(cell.config, condition)
            for r in cell.results:
                writer.writerow([*leading, r.run, r.steps, r.steps_run, r.messages, r.deliveries,
                                 _fmt(r.mean_degree), r.components, r.layouts, _fmt(r.largest_share)])


def _condition_values(config: Config, condition: Sequence[str]) -> list[object]:
    return [getattr(config, name) for name in condition]


def _fmt(value: float | None) -> str:
    return "" if value is None else f"{value:.4g}"


@dataclass(frozen=True)
class Claim:
    """One number the paper states, and ours for the same condition."""

    condition: str
    measure: str
    paper: str
    ours: str
    agrees: bool | None  # None when we have no converged run to compare


def _find(cells: Sequence[Cell], topology: str, robots: int, drop: float) -> Summary | None:
    for cell in cells:
        c = cell.config
        if (c.topology, c.robots, c.drop) == (topology, robots, drop):
            return cell.summary
    return None


def _within(value: float | None, low: float, high: float) -> bool | None:
    return None if value is None else low <= value <= high


def paper_claims(cells: Sequence[Cell]) -> list[Claim]:
    """Every number section 4.1 states, beside ours. Agreement rules are in each row's `measure`."""
    claims: list[Claim] = []
    s = _find(cells, "cluster", 10, 0.75)
    if s:
        claims.append(Claim("cluster N=10 P=0.75", "mean (agrees within ±25%)", "6", fmt_steps(s.mean),
                            _within(s.mean, 4.5, 7.5)))
    s = _find(cells, "cluster", 1000, 0.75)
    if s:
        claims.append(Claim("cluster N=1000 P=0.75", "mean (agrees within ±25%)", "13", fmt_steps(s.mean),
                            _within(s.mean, 9.75, 16.25)))
        claims.append(Claim("cluster N=1000 P=0.75", "[min, max] (agrees if it overlaps)", "[10, 15]",
                            _range(s), _overlaps(s, 10, 15)))
    s = _find(cells, "scale-free", 1000, 0.75)
    if s:
        claims.append(Claim("scale-free N=1000 P=0.75", "[min, max] (agrees if it overlaps)", "[11, 26]",
                            _range(s), _overlaps(s, 11, 26)))
    for robots in PAPER_ROBOTS:
        flat = [_find(cells, "cluster", robots, p) for p in PAPER_DROPS[:4]]
        steep = _find(cells, "cluster", robots, 0.95)
        if all(f and f.median for f in flat) and steep and steep.median:
            medians = [f.median for f in flat if f and f.median]
            ratio = max(medians) / min(medians)
            claims.append(Claim(f"cluster N={robots}, P=0..0.75", "max/min of medians (flat: at most 1.5)",
                                "flat (no increase)", f"{ratio:.2f} ({', '.join(fmt_steps(m) for m in medians)})",
                                ratio <= 1.5))
            jump = steep.median / medians[-1]
            claims.append(Claim(f"cluster N={robots}, P=0.95", "median / median at P=0.75 (drops: at least 1.5)",
                                "drops significantly", f"{jump:.2f}", jump >= 1.5))
    return claims


def fmt_steps(value: float | None) -> str:
    if value is None:
        return "-"
    return f"{value:.0f}" if abs(value) >= 100 or value == int(value) else f"{value:.1f}"


def _range(s: Summary) -> str:
    return "-" if s.min is None else f"[{s.min}, {s.max}]"


def _overlaps(s: Summary, low: int, high: int) -> bool | None:
    return None if s.min is None or s.max is None else s.min <= high and s.max >= low


def markdown_table(cells: Sequence[Cell], runs: int, wall_seconds: float | None = None) -> str:
    lines = ["# Figure 3 reproduced with vstig-hw's engine", ""]
    first = cells[0].config if cells else None
    if first:
        lines += [f"{runs} runs per condition; radio range {first.radio_range} m, cluster density D={first.density}, "
                  f"budget {first.budget} message(s) per robot per step, occlusion by bodies "
                  f"{'on' if first.occlusion else 'off'} (body radius {first.body_radius} m).", ""]
    if wall_seconds is not None:
        lines += [f"Wall time for the grid: {wall_seconds:.0f} s.", ""]
    lines += ["## Every number the paper states, beside ours", "", *claims_table(paper_claims(cells))]
    lines += ["", "## All conditions (convergence in control steps)", "", *conditions_table(cells, STATIC_CONDITION)]
    return "\n".join(lines) + "\n"


def claims_table(claims: Sequence[Claim]) -> list[str]:
    lines = ["| condition | measure | paper | ours | agrees |", "|---|---|---|---|---|"]
    for claim in claims:
        verdict = "-" if claim.agrees is None else ("yes" if claim.agrees else "**no**")
        lines.append(f"| {claim.condition} | {claim.measure} | {claim.paper} | {claim.ours} | {verdict} |")
    return lines


_HEADINGS = {"topology": "topology", "robots": "N", "drop": "P", "density": "D", "speed": "S (m/s)"}


def conditions_table(cells: Sequence[Cell], condition: Sequence[str]) -> list[str]:
    """Markdown rows: each condition's convergence statistics, bandwidth and connectivity."""
    head = [_HEADINGS.get(name, name) for name in condition]
    lines = ["| " + " | ".join(head) + " | median | min | max | mean | converged | msg/robot/step | "
             "receptions/robot/step | mean degree | split layouts |",
             "|" + "---|" * (len(head) + 9)]
    for cell in cells:
        s = cell.summary
        leading = " | ".join(str(value) for value in _condition_values(cell.config, condition))
        lines.append(f"| {leading} | {fmt_steps(s.median)} | {fmt_steps(s.min)} | {fmt_steps(s.max)} | "
                     f"{fmt_steps(s.mean)} | {s.converged}/{s.runs} | {s.msgs_per_robot_step:.3f} | "
                     f"{s.deliveries_per_robot_step:.3f} | {s.mean_degree:.2f} | {s.split_runs} |")
    return lines
