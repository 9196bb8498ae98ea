"""The analyze figure: how a key's writes spread through the senders, and how long writes took to converge.

Sized for one column of a two-column paper (3.4 in wide), 8 pt text, 300 dpi.
"""

from __future__ import annotations

import statistics
from pathlib import Path

from .analysis import Report, WriteReport

__all__ = ["MAX_LINES", "plot_report", "plotted_key"]

MAX_LINES = 12  # writes drawn in panel (a): the key's newest ones; more would be a blur at column width
_WIDTH_IN, _HEIGHT_IN = 3.4, 4.6


def plotted_key(report: Report) -> int | None:
    """The key with the most writes (lowest key on a tie): what panel (a) shows unless the user picks one."""
    counts: dict[int, int] = {}
    for write in report.writes:
        counts[write.key] = counts.get(write.key, 0) + 1
    return min(counts, key=lambda k: (-counts[k], k)) if counts else None


def plot_report(report: Report, path: Path, key: int | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")  # files only: no display on a lab server or in CI
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    key = plotted_key(report) if key is None else key
    with plt.rc_context({"font.size": 8, "axes.titlesize": 8, "legend.fontsize": 6}):
        fig, (spread, histogram) = plt.subplots(2, 1, figsize=(_WIDTH_IN, _HEIGHT_IN))
        writes = [w for w in report.writes if w.key == key and w.senders_total]
        shown = sorted(writes, key=lambda w: w.rank)[-MAX_LINES:]
        for write in shown:
            xs, ys = _spread(write)
            spread.step(xs, ys, where="post", linewidth=1,
                        label=f"ts {write.timestamp} robot {write.robot}")
        if shown:
            spread.set_ylim(0, 1.05)
            if len(shown) <= 6:
                spread.legend(loc="lower right")
        else:
            spread.text(0.5, 0.5, "no sender named on these links" if report.writes else "no writes",
                        ha="center", va="center", transform=spread.transAxes)
        more = f", newest {len(shown)} of {len(writes)}" if len(writes) > len(shown) else ""
        spread.set_title(f"(a) key {key}: spread of each write{more}")
        spread.set_xlabel("time since the write first appeared (s)")
        spread.set_ylabel("senders holding it or newer")
        spread.grid(True, alpha=0.3)

        times = [t for w in report.writes if (t := w.converged_after) is not None]
        if times:
            histogram.hist(times, bins=min(30, max(5, len(set(times)))), color="tab:blue", alpha=0.8)
            median = statistics.median(times)
            histogram.set_ylim(top=histogram.get_ylim()[1] * 1.15)  # headroom for the median's label
            histogram.axvline(median, color="black", linestyle="--", linewidth=1)
            histogram.annotate(f" median {median:.3g} s", xy=(median, 0.98), xycoords=("data", "axes fraction"),
                               va="top", ha="left", fontsize=6)
        else:
            histogram.text(0.5, 0.5, "no write reached every active sender", ha="center", va="center",
                             transform=histogram.transAxes)
        histogram.set_title(f"(b) convergence time, {len(times)} of {len(report.writes)} writes")
        histogram.set_xlabel("time to reach every active sender (s)")
        histogram.set_ylabel("writes")
        histogram.yaxis.set_major_locator(MaxNLocator(integer=True))
        histogram.grid(True, alpha=0.3)
        fig.tight_layout()
        fig.savefig(path, dpi=300)
        plt.close(fig)


def _spread(write: WriteReport) -> tuple[list[float], list[float]]:
    """Step points: the fraction of the write's active senders that had caught up, over time since the write."""
    xs, ys = [0.0], [0.0]
    for done, after in enumerate(write.caught_up_after, 1):
        xs.append(after)
        ys.append(done / write.senders_total)
    return xs, ys
