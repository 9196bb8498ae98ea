"""The `vstig why --plot` figure: one key's timeline, in the style of analyze's (analysis_plot).

Each sender's shown timestamp over time as a step line, broken where the sender was not heard for longer
than `GAP` seconds (a gap in hearing); the gateway's sends as ticks on a strip below; the newest write's
first showing and the time asked about as vertical lines.
"""

from __future__ import annotations

from pathlib import Path

from .analysis_plot import _COLOURS, _DASHES, _STYLE
from .capture.trace import Trace
from .capture.why import Answer

__all__ = ["GAP", "MAX_SENDERS", "plot_key"]

GAP = 2.0  # seconds unheard that break a sender's line
MAX_SENDERS = 12  # lines drawn: the senders the answer names first, then the most talkative
SIZE_IN = (6.8, 3.6)  # two columns of a paper


def plot_key(trace: Trace, answer: Answer, path: Path) -> None:
    """Write the figure as a PNG (200 dpi)."""
    import matplotlib

    matplotlib.use("Agg")  # files only
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    shown = [s for s in trace.of(answer.key) if s.t <= answer.at]
    named = [v.sender for v in answer.verdicts]
    causes = {v.sender: v.cause or "no cause" for v in answer.verdicts}
    counts: dict[str, int] = {}
    for s in shown:
        if not s.sent:
            counts[s.sender] = counts.get(s.sender, 0) + 1
    senders = (named + sorted((c for c in counts if c not in named), key=lambda c: -counts[c]))[:MAX_SENDERS]
    with plt.rc_context(_STYLE):
        fig, (top, sends) = plt.subplots(2, 1, figsize=SIZE_IN, sharex=True, height_ratios=(4, 1),
                                         layout="constrained")
        for index, sender in enumerate(senders):
            xs: list[float] = []
            ys: list[float] = []
            for s in shown:
                if s.sender != sender or s.sent:
                    continue
                if xs and s.t - xs[-1] > GAP:  # a gap in hearing: the line breaks
                    xs.append(xs[-1])
                    ys.append(float("nan"))
                xs.append(s.t)
                ys.append(float(s.ts))
            if xs:
                top.step(xs, ys, where="post", color=_COLOURS[index % len(_COLOURS)],
                         linestyle=_DASHES[index // len(_COLOURS) % len(_DASHES)], marker=".", markersize=2,
                         label=f"{sender}: {causes[sender]}" if sender in causes else sender)
        if answer.newest is not None:
            top.axvline(answer.newest.t, color="grey", linewidth=0.8, linestyle=":")
            top.annotate(f"write ts {answer.newest.ts}", (answer.newest.t, answer.newest.ts), fontsize=6.5,
                         xytext=(3, 3), textcoords="offset points")
        top.axvline(answer.at, color="black", linewidth=0.8)
        top.annotate(f"T = {answer.at:.2f} s", (answer.at, 1), xycoords=("data", "axes fraction"), fontsize=6.5,
                     xytext=(-3, -8), textcoords="offset points", ha="right")
        top.yaxis.set_major_locator(MaxNLocator(integer=True))
        top.set_ylabel("timestamp shown")
        top.set_title(f"key {answer.key}: what each sender showed")
        top.legend(loc="upper left", bbox_to_anchor=(1.01, 1), title="sender: verdict")
        links = sorted({s.link for s in shown if s.sent})
        for row, link in enumerate(links):
            times = [s.t for s in shown if s.sent and s.link == link]
            sends.plot(times, [row] * len(times), "|", color="black", markersize=6)
        sends.set_yticks(range(len(links)), [f"sent on {link}" for link in links])
        sends.set_ylim(-0.7, max(len(links), 1) - 0.3)
        sends.set_xlabel("seconds since the capture's first record")
        fig.savefig(path, dpi=200)
        plt.close(fig)
