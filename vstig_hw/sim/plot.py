"""A PNG in the style of the paper's Figure 3: median with min-max bars, one panel per topology."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from .grid import PAPER_TOPOLOGIES, Cell

__all__ = ["plot_figure3"]

_OFFSET = 0.012  # the paper offsets markers slightly so the series stay visible


def plot_figure3(cells: Sequence[Cell], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")  # files only: no display on a lab server or in CI
    import matplotlib.pyplot as plt

    topologies = [t for t in PAPER_TOPOLOGIES if any(c.config.topology == t for c in cells)]
    fig, axes = plt.subplots(1, len(topologies), figsize=(5 * len(topologies), 4.2), squeeze=False)
    for ax, topology in zip(axes[0], topologies, strict=True):
        ours = [c for c in cells if c.config.topology == topology]
        sizes = sorted({c.config.robots for c in ours})
        for index, robots in enumerate(sizes):
            series = sorted((c for c in ours if c.config.robots == robots), key=lambda c: c.config.drop)
            points = [(c.config.drop, c.summary) for c in series if c.summary.median is not None]
            if not points:
                continue
            shift = (index - (len(sizes) - 1) / 2) * _OFFSET
            xs = [p + shift for p, _ in points]
            medians = [float(s.median or 0) for _, s in points]
            below = [m - float(s.min or 0) for m, (_, s) in zip(medians, points, strict=True)]
            above = [float(s.max or 0) - m for m, (_, s) in zip(medians, points, strict=True)]
            ax.errorbar(xs, medians, yerr=[below, above], fmt="o-", capsize=3, markersize=4, label=f"N = {robots}")
        ax.set_yscale("log")
        ax.set_title(f"Static {topology} topology")
        ax.set_xlabel("Packet drop probability P")
        ax.set_ylabel("Convergence time (control steps)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    runs = cells[0].summary.runs if cells else 0
    fig.suptitle(f"vstig-hw engine: median, min and max over {runs} runs per condition")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
