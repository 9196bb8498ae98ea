"""The paper's Figure 5 grid (section 4.2) and every statement the section makes, beside our numbers.

N = 100 robots diffuse through the 4-column arena at densities D in {1, 3, 5}
and forward speed caps S in {5, 10, 20} cm/s, for each drop probability P of
section 4.1. Figure 5 is a plot only: the text states no numbers for it, so each
statement is checked by a rule written in its `measure` column.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import replace

from .experiment import MOTION, Config, Summary
from .grid import PAPER_DROPS, Cell, Claim, claims_table, conditions_table, fmt_steps

__all__ = ["MOTION_CONDITION", "PAPER_DENSITIES", "PAPER_SPEEDS", "motion_claims", "motion_configs",
           "motion_markdown"]

PAPER_DENSITIES = (1.0, 3.0, 5.0)
PAPER_SPEEDS = (0.05, 0.1, 0.2)  # m/s
MOTION_ROBOTS = 100
MOTION_CONDITION = ("topology", "density", "speed", "robots", "drop")  # the Config fields naming a condition


def motion_configs(template: Config | None = None, densities: Sequence[float] = PAPER_DENSITIES,
                   speeds: Sequence[float] = PAPER_SPEEDS, drops: Sequence[float] = PAPER_DROPS) -> list[Config]:
    base = template or Config(MOTION, MOTION_ROBOTS, 0.0)
    return [replace(base, topology=MOTION, density=d, speed=s, drop=p)
            for d in densities for s in speeds for p in drops]


def _grid(cells: Sequence[Cell]) -> dict[tuple[float, float, float], Summary]:
    return {(c.config.density, c.config.speed, c.config.drop): c.summary for c in cells}


def _median(grid: dict[tuple[float, float, float], Summary], density: float, speed: float,
            drop: float) -> float | None:
    s = grid.get((density, speed, drop))
    return None if s is None or s.median is None else float(s.median)


def _ratios(pairs: Sequence[tuple[float | None, float | None]]) -> list[float] | None:
    """numerator/denominator for each pair; None if any is missing (a cell not run, or never converged)."""
    if not pairs or any(a is None or b is None for a, b in pairs):
        return None
    return [float(a) / float(b) for a, b in pairs if a is not None and b]


def _list(values: Sequence[float]) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def _connectivity(cells: Sequence[Cell], density: float) -> tuple[float, int, int] | None:
    """Over every run at `density`: mean share in the largest component at step 1, connected runs, runs."""
    runs = [r for c in cells if c.config.density == density for r in c.results]
    if not runs:
        return None
    return statistics.fmean(r.largest_share for r in runs), sum(r.components == 1 for r in runs), len(runs)


def _setup_holds(density: float, share: float, connected: int, runs: int) -> bool:
    if density == 1.0:
        return share < 0.5
    if density == 3.0:
        return share >= 0.5 and connected < runs
    return connected >= 0.9 * runs


_SETUP = {1.0: ("small islands of unconnected robots; motion is necessary", "under 50%"),
          3.0: ("most robots are connected, a few must move", "50% or more, not every run connected"),
          5.0: ("fully connected, as the cluster/scale-free case", "at least 90% of runs connected")}


def _setup_claims(cells: Sequence[Cell]) -> list[Claim]:
    """What section 4.2 says each density looks like at the start (its Figure 4)."""
    claims: list[Claim] = []
    for density, (paper, rule) in _SETUP.items():
        found = _connectivity(cells, density)
        if found is None:
            continue
        share, connected, runs = found
        claims.append(Claim(f"D={density:g}, at the start", f"robots in the largest component ({rule})", paper,
                            f"{share:.0%} of robots; {connected}/{runs} runs connected",
                            _setup_holds(density, share, connected, runs)))
    return claims


def motion_claims(cells: Sequence[Cell]) -> list[Claim]:
    """Every statement of section 4.2, beside ours. The rule for agreeing is in each row's `measure`."""
    grid = _grid(cells)
    densities = sorted({d for d, _, _ in grid})
    speeds = sorted({s for _, s, _ in grid})
    drops = sorted({p for _, _, p in grid})
    claims = _setup_claims(cells)
    slow, fast = (speeds[0], speeds[-1]) if len(speeds) > 1 else (None, None)
    for density in (5.0, 3.0):
        for speed in speeds:
            medians = [_median(grid, density, speed, p) for p in drops]
            if len(drops) < 2 or drops[0] != 0.0 or any(m is None for m in medians):
                continue
            # The line's loss (every drop costs a retry) is 1/(1-P); graceful is slower than that.
            worst = max((m or 0.0) / (medians[0] or 1.0) * (1 - p)
                        for m, p in zip(medians[1:], drops[1:], strict=True))
            claims.append(Claim(f"D={density:g} S={speed:g}", "median at P over median at P=0, as a fraction "
                                "of 1/(1-P) (graceful: at most 1 at every P)", "degrades gracefully",
                                f"medians {', '.join(fmt_steps(m) for m in medians)}; worst {worst:.2f}",
                                worst <= 1.0))
    if slow is not None and fast is not None:
        for density in densities:
            ratios = _ratios([(_median(grid, density, slow, p), _median(grid, density, fast, p)) for p in drops])
            if ratios is not None:
                claims.append(Claim(f"D={density:g}, P={_list(drops)}",
                                    f"median at S={slow:g} over median at S={fast:g} (faster: above 1 at every P)",
                                    "the faster the robots, the faster the spreading", _list(ratios),
                                    min(ratios) > 1.0))
    if 1.0 in densities and 5.0 in densities:
        ratios = _ratios([(_median(grid, 1.0, s, p), _median(grid, 5.0, s, p)) for s in speeds for p in drops])
        if ratios is not None:
            claims.append(Claim("D=1 against D=5, each S and P", "median ratio (slowly: at least 3 everywhere)",
                                "information spreads slowly", f"{min(ratios):.1f} to {max(ratios):.1f}",
                                min(ratios) >= 3.0))
    if 1.0 in densities and slow is not None and fast is not None:
        speed_effect = _ratios([(_median(grid, 1.0, slow, p), _median(grid, 1.0, fast, p)) for p in drops])
        if speed_effect is not None:
            expected = fast / slow
            claims.append(Claim(f"D=1, P={_list(drops)}", f"median at S={slow:g} over S={fast:g} (speed-limited: "
                                f"within 2x of the speed ratio {expected:g}, at every P)",
                                "forward speed is the limiting factor", _list(speed_effect),
                                all(expected / 2 <= r <= expected * 2 for r in speed_effect)))
            if len(drops) > 1:
                drop_effect = _ratios([(_median(grid, 1.0, s, drops[-1]), _median(grid, 1.0, s, drops[0]))
                                       for s in speeds])
                if drop_effect is not None:
                    claims.append(Claim(f"D=1, S={_list(speeds)}", f"median at P={drops[-1]:g} over P={drops[0]:g} "
                                        "(speed, not loss, limits: below the smallest speed ratio above)",
                                        "forward speed is the limiting factor", _list(drop_effect),
                                        max(drop_effect) < min(speed_effect)))
    if 3.0 in densities and 5.0 in densities:
        ratios = _ratios([(_median(grid, 3.0, s, p), _median(grid, 5.0, s, p)) for s in speeds for p in drops])
        found = _connectivity(cells, 3.0)
        if ratios is not None and found is not None:
            claims.append(Claim("D=3 against D=5, each S and P", "median ratio (efficient: at most 2 everywhere)",
                                "efficient even when a minority is disconnected",
                                f"{min(ratios):.2f} to {max(ratios):.2f}; {1 - found[0]:.0%} of robots outside the "
                                "largest component at the start", max(ratios) <= 2.0))
    return claims


def motion_markdown(cells: Sequence[Cell], runs: int, wall_seconds: float | None = None,
                    circumstances: str = "") -> str:
    lines = ["# Figure 5 reproduced with vstig-hw's engine", ""]
    if cells:
        c = cells[0].config
        lines += [f"{runs} runs per condition, N={c.robots} robots; radio range {c.radio_range} m, budget {c.budget} "
                  f"message(s) per robot per step, occlusion by bodies and columns "
                  f"{'on' if c.occlusion else 'off'} (body radius {c.body_radius} m); dispersion: control step "
                  f"{c.control_step} s, repulsion gap {c.repulsion} m, turn noise {c.turn_noise} rad per step.", ""]
    if wall_seconds is not None:
        lines += [f"Wall time for the grid: {wall_seconds:.0f} s. {circumstances}".rstrip(), ""]
    lines += ["## Every statement section 4.2 makes, beside our numbers", "",
              "Figure 5 is a plot: the paper's text gives no numbers for it, so each statement is checked by the "
              "rule in its measure column. Connectivity is the hearing graph at step 1 (range and line of sight).",
              "", *claims_table(motion_claims(cells)),
              "", "## All conditions (convergence in control steps)", "", *conditions_table(cells, MOTION_CONDITION)]
    return "\n".join(lines) + "\n"
