"""The analyze figure: how a key's writes spread, how long writes took to converge, and the traffic per link.

Sized for one column of a two-column paper (3.4 in wide), 8 pt text, 300 dpi.
Where no link names its senders (serial links only), convergence cannot be
measured and the figure is the traffic panel alone.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .analysis import TIMELINE_STEP, Report, Timeline, WriteReport
from .wire import MESSAGE_SIZE

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["FULL_SIZE_IN", "MAX_LINES", "TRAFFIC_SIZE_IN", "draw", "plot_report", "plotted_key"]

FULL_SIZE_IN = (3.4, 6.2)  # panels (a), (b), (c)
TRAFFIC_SIZE_IN = (3.4, 2.2)  # the traffic panel alone
MAX_LINES = 200  # writes drawn one by one in panel (a), the key's newest; the median and quartiles use them all
_FEW = 5  # up to this many writes are told apart by colour and legend; more are drawn grey around their median
_TRAFFIC_BINS = 60  # at most this many bars in panel (c): whole control steps each, so periodic traffic stays flat
_GRID_POINTS = 400  # time points at which panel (a)'s median and quartiles are evaluated
_DASHES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1)))  # writes that overlap stay apart, in grey print too
_COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")  # Okabe-Ito: colour-blind safe
_STYLE: dict[Any, Any] = {
    "font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "legend.fontsize": 6.5, "xtick.labelsize": 7,
    "ytick.labelsize": 7, "axes.spines.top": False, "axes.spines.right": False, "legend.frameon": True,
    "legend.framealpha": 0.85, "legend.edgecolor": "none", "legend.borderaxespad": 0.3,
    "axes.titlelocation": "left", "lines.linewidth": 1.0}


def plotted_key(report: Report) -> int | None:
    """The key with the most writes (lowest key on a tie): what panel (a) shows unless the user picks one."""
    counts: dict[int, int] = {}
    for write in report.writes:
        counts[write.key] = counts.get(write.key, 0) + 1
    return min(counts, key=lambda k: (-counts[k], k)) if counts else None


def plot_report(report: Report, path: Path, key: int | None = None) -> None:
    """Write the figure as a PNG (300 dpi); `key` for panel (a), else `plotted_key`."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display on a lab server or in CI
    import matplotlib.pyplot as plt

    fig = draw(report, key)
    fig.savefig(path, dpi=300)
    plt.close(fig)


def draw(report: Report, key: int | None = None) -> Figure:
    """The figure: panels (a) to (c), or the traffic panel alone where no write can be measured."""
    import matplotlib.pyplot as plt

    measurable = any(w.senders_total for w in report.writes)
    with plt.rc_context(_STYLE):
        if measurable:
            fig, (spread, convergence, traffic) = plt.subplots(3, 1, figsize=FULL_SIZE_IN,
                                                               gridspec_kw={"height_ratios": [1.15, 1, 0.9]})
            _spread_panel(spread, report, plotted_key(report) if key is None else key)
            _convergence_panel(convergence, report)
            right = max(spread.get_xlim()[1], convergence.get_xlim()[1])  # one time scale: (a) and (b) compare
            spread.set_xlim(0, right)
            convergence.set_xlim(0, right)
            _traffic_panel(traffic, report, "(c) ")
        else:
            fig, traffic = plt.subplots(figsize=TRAFFIC_SIZE_IN)
            _traffic_panel(traffic, report, "")
        fig.tight_layout(h_pad=1.2)
        fig.align_ylabels()
    return fig


def _share_axes(ax: Any, title: str, xlabel: str, ylabel: str) -> None:
    """A panel whose y axis is a share (0-100%) of senders or writes."""
    from matplotlib.ticker import PercentFormatter

    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.yaxis.set_major_formatter(PercentFormatter(1.0))
    ax.set_ylim(0, 1.04)


def _say(ax: Any, text: str) -> None:
    """A panel with nothing to draw says why, in its middle."""
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)


# -- (a) -------------------------------------------------------------------------------------------------------------
def _spread_panel(ax: Any, report: Report, key: int | None) -> None:
    writes = sorted((w for w in report.writes if w.key == key and w.senders_total), key=lambda w: w.rank)
    _share_axes(ax, f"(a) key {key}: {len(writes)} write{'s' * (len(writes) != 1)} spreading",
                "time since the write first appeared (s)", "active senders\nholding it or newer")
    if not writes:
        _say(ax, f"no write of key {key} with a named sender")
        return
    end = max((w.caught_up_after[-1] for w in writes if w.caught_up_after), default=0.0) or TIMELINE_STEP
    ax.set_xlim(0, end * 1.03)
    if len(writes) <= _FEW:
        for colour, dashes, write in zip(_COLOURS, _DASHES, writes, strict=False):
            xs, ys = _steps(write, end)
            behind = "" if write.converged_after is not None else f" ({len(write.behind)} behind)"
            ax.step(xs, ys, where="post", color=colour, linestyle=dashes,
                    label=f"ts {write.timestamp}, robot {write.robot}{behind}")
        ax.legend(loc="best")
        return
    drawn = writes[-MAX_LINES:]
    for number, write in enumerate(drawn):
        xs, ys = _steps(write, end)
        ax.step(xs, ys, where="post", color="0.65", linewidth=0.4, alpha=0.6,
                label=(f"one write (newest {len(drawn)} of {len(writes)})" if len(drawn) < len(writes)
                       else "one write") if number == 0 else None)
    grid = np.linspace(0.0, end, _GRID_POINTS)
    held = np.array([np.searchsorted(w.caught_up_after, grid, side="right") / w.senders_total for w in writes])
    low, median, high = np.percentile(held, [25, 50, 75], axis=0)
    ax.fill_between(grid, low, high, step="post", color=_COLOURS[0], alpha=0.25, linewidth=0,
                    label="interquartile range")
    ax.step(grid, median, where="post", color=_COLOURS[0], linewidth=1.4, label="median")
    ax.legend(loc="best")


def _steps(write: WriteReport, end: float) -> tuple[list[float], list[float]]:
    """The fraction of the write's active senders that had caught up, over time since the write, held to `end`."""
    xs, ys = [0.0], [0.0]
    for done, after in enumerate(write.caught_up_after, 1):
        xs.append(after)
        ys.append(done / write.senders_total)
    return [*xs, end], [*ys, ys[-1]]


# -- (b) -------------------------------------------------------------------------------------------------------------
def _convergence_panel(ax: Any, report: Report) -> None:
    measured = [w for w in report.writes if w.senders_total]
    times = sorted(t for w in measured if (t := w.converged_after) is not None)
    _share_axes(ax, f"(b) convergence: {len(times)} of {len(measured)} writes",
                "time to reach every active sender (s)", "writes that reached\nevery active sender")
    if not times:
        _say(ax, "no write reached every active sender")
        return
    # As far as any write took to reach a sender, so the writes that never converge show as the gap below 100%.
    end = max((w.caught_up_after[-1] for w in measured if w.caught_up_after), default=0.0) or TIMELINE_STEP
    xs = [0.0, *times, end * 1.03]
    ys = [0.0, *(np.arange(1, len(times) + 1) / len(measured)).tolist(), len(times) / len(measured)]
    ax.step(xs, ys, where="post", color=_COLOURS[0], label="converged by then")
    median = statistics.median(times)
    ax.axvline(median, color="black", linestyle="--", linewidth=0.8, label=f"median of those: {median:.3g} s")
    ax.set_xlim(0, end * 1.03)
    ax.legend(loc="best")


# -- (c) -------------------------------------------------------------------------------------------------------------
def _traffic_panel(ax: Any, report: Report, letter: str) -> None:
    names = list(report.timelines)
    ax.set_title(f"{letter}traffic " + (f"on {names[0]}" if len(names) == 1 else "per link"))
    ax.set_xlabel("time since the first message (s)")
    ax.set_ylabel("messages/s")
    start = report.start or 0.0
    slots = math.floor(report.duration / TIMELINE_STEP + 1e-3) + 1
    for colour, (name, timeline) in zip(_COLOURS * 8, report.timelines.items(), strict=False):
        edges, rate = _rebinned(timeline, start, slots)
        ax.stairs(rate, edges, baseline=None, color=colour, label=name)
    ax.set_ylim(bottom=0, top=ax.get_ylim()[1] * (1.3 if len(names) > 1 else 1.1))  # room for the legend
    ax.set_xlim(0, report.duration or TIMELINE_STEP)
    ax.secondary_yaxis("right", functions=(lambda m: m * MESSAGE_SIZE, lambda b: b / MESSAGE_SIZE)).set_ylabel(
        "bytes/s")
    if len(names) > 1:
        ax.legend(loc="upper center", ncol=min(4, len(names)))


def _rebinned(timeline: Timeline, start: float, slots: int) -> tuple[Any, Any]:
    """Bin edges (s since `start`) and messages/s over `slots` TIMELINE_STEP slots, in bins of whole slots."""
    per_bin = max(1, math.ceil(slots / _TRAFFIC_BINS))
    bins = math.ceil(slots / per_bin)
    offset = round((timeline.start - start) / TIMELINE_STEP)  # whole slots: every link's timeline starts on one
    messages = np.bincount((timeline.slots + offset) // per_bin, weights=timeline.counts, minlength=bins)[:bins]
    widths = np.minimum(per_bin, slots - per_bin * np.arange(bins)) * TIMELINE_STEP  # the last bin may be short
    return np.r_[0.0, np.cumsum(widths)], messages / widths
