"""PNGs in the style of the paper's figures.

Figures 3 and 5: median with min-max bars against the drop probability, one
panel per topology (Figure 3) or per speed (Figure 5), one series per swarm size
or density. Figure 4: one moment of a motion run, the arena, its columns, the
robots and the links in range and sight.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .grid import PAPER_TOPOLOGIES, Cell
from .radio import Discs, Links
from .topology import Positions

__all__ = ["plot_figure3", "plot_figure5", "plot_snapshot"]

_OFFSET = 0.012  # the paper offsets markers slightly so the series stay visible


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only: no display on a lab server or in CI
    import matplotlib.pyplot as plt

    return plt


def _plot_panels(cells: Sequence[Cell], path: Path, panel_of: Callable[[Cell], Any], series_of: Callable[[Cell], Any],
                 panels: Sequence[Any], title: Callable[[Any], str], label: Callable[[Any], str],
                 sharey: bool = False) -> None:
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.2), squeeze=False, sharey=sharey)
    for ax, panel in zip(axes[0], panels, strict=True):
        ours = [c for c in cells if panel_of(c) == panel]
        keys = sorted({series_of(c) for c in ours})
        for index, key in enumerate(keys):
            series = sorted((c for c in ours if series_of(c) == key), key=lambda c: c.config.drop)
            points = [(c.config.drop, c.summary) for c in series if c.summary.median is not None]
            if not points:
                continue
            shift = (index - (len(keys) - 1) / 2) * _OFFSET
            xs = [p + shift for p, _ in points]
            medians = [float(s.median or 0) for _, s in points]
            below = [m - float(s.min or 0) for m, (_, s) in zip(medians, points, strict=True)]
            above = [float(s.max or 0) - m for m, (_, s) in zip(medians, points, strict=True)]
            ax.errorbar(xs, medians, yerr=[below, above], fmt="o-", capsize=3, markersize=4, label=label(key))
        ax.set_yscale("log")
        ax.set_title(title(panel))
        ax.set_xlabel("Packet drop probability P")
        ax.set_ylabel("Convergence time (control steps)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    runs = cells[0].summary.runs if cells else 0
    fig.suptitle(f"vstig-hw engine: median, min and max over {runs} runs per condition")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_figure3(cells: Sequence[Cell], path: Path) -> None:
    topologies = [t for t in PAPER_TOPOLOGIES if any(c.config.topology == t for c in cells)]
    _plot_panels(cells, path, lambda c: c.config.topology, lambda c: c.config.robots, topologies,
                 lambda topology: f"Static {topology} topology", lambda robots: f"N = {robots}")


def plot_figure5(cells: Sequence[Cell], path: Path) -> None:
    speeds = sorted({c.config.speed for c in cells})
    _plot_panels(cells, path, lambda c: c.config.speed, lambda c: c.config.density, speeds,
                 lambda speed: f"Max speed = {speed * 100:g} cm/s", lambda density: f"D = {density:g}",
                 sharey=True)  # one scale, so the panels show what speed buys


def plot_snapshot(positions: Positions, hearing: Links, side: float, columns: Discs, body_radius: float,
                  title: str, path: Path) -> None:
    """Figure 4's view: the walled arena, its columns, the robots and (cyan) who hears whom."""
    plt = _pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Rectangle

    fig, ax = plt.subplots(figsize=(6.4, 6.8))
    half = side / 2
    ax.add_patch(Rectangle((-half, -half), side, side, fill=False, linewidth=2, edgecolor="black"))
    for centre in columns.centres:
        ax.add_patch(Circle(tuple(centre), columns.radius, color="0.55"))
    pairs = hearing.src < hearing.dst
    segments = np.stack([positions[hearing.src[pairs]], positions[hearing.dst[pairs]]], axis=1)
    ax.add_collection(LineCollection(list(segments), colors="c", linewidths=1))
    for x, y in positions:
        ax.add_patch(Circle((x, y), max(body_radius, side / 300), color="0.1"))
    ax.set_xlim(-half * 1.02, half * 1.02)
    ax.set_ylim(-half * 1.02, half * 1.02)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
