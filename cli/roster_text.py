"""`vstig analyze --robots`: the roster over a capture's time, as text (80 columns) and as JSON.

docs/how-to/robots.md explains the states, the thresholds and the gaps.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import click

from vstig_hw.gateway.roster import RobotState
from vstig_hw.roster_history import RosterReport
from vstig_hw.wording import counted, shown_sender

from .robots import fit_few

__all__ = ["print_roster", "roster_json"]

_LINKS_WIDTH = 12
_BEHIND_WIDTH = 10
GAP_ROWS = 50  # silences listed in the text; --json has them all


def _r(t: float | None) -> float | None:
    return None if t is None else round(t, 6)


def roster_json(report: RosterReport) -> dict[str, Any]:
    return {"quiet_after_s": report.quiet_after, "gone_after_s": report.gone_after, "untracked": report.untracked,
            "robots": [{**{k: v for k, v in view.as_json().items() if k not in ("last_heard_s", "rate")},
                        "state_at_end": view.state.value, "first_heard": _r(view.first_heard),
                        "last_heard": _r(view.last_heard),
                        "gaps": [{"start": _r(gap.start), "end": _r(gap.end), "seconds": _r(gap.seconds)}
                                 for gap in report.gaps if gap.robot == view.robot]}
                       for view in report.robots],
            "changes": [{"t": _r(change.t), "robot": change.robot, "from": change.old.value, "to": change.new.value}
                        for change in report.changes],
            "gaps_untold": report.gaps_untold, "changes_untold": report.changes_untold}


def print_roster(report: RosterReport, start: float) -> None:
    """The roster at the capture's end, its silences (times from the capture's start) and its state changes."""
    views = report.robots
    states = Counter(view.state for view in views)
    click.echo()
    click.echo(f"robots: {counted(len(views), 'robot')} at the end ("
               + ", ".join(f"{states[state]} {state.value}" for state in RobotState)
               + (f"; {report.untracked} more untracked" if report.untracked else "") + ")")
    click.echo(f"  quiet after {report.quiet_after:g} s without a message, gone after {report.gone_after:g} s")
    click.echo(f"{'robot':>7} {'by':<2} {'state':<5} {'links':<{_LINKS_WIDTH}} {'first_s':>9} {'last_s':>9} "
               f"{'PUT':>6} {'GET':>6} behind")
    for view in views:
        click.echo((f"{shown_sender(view.robot):>7} {view.named_by[0]:<2} {view.state.value:<5} "
                    f"{fit_few(list(view.links), _LINKS_WIDTH):<{_LINKS_WIDTH}} {view.first_heard - start:>9.3f} "
                    f"{view.last_heard - start:>9.3f} {view.writes:>6} {view.gets:>6} "
                    f"{fit_few([str(key) for key in view.behind], _BEHIND_WIDTH)}").rstrip())
    gaps = report.gaps
    click.echo()
    if not gaps:
        click.echo(f"silences: none longer than {report.quiet_after:g} s")
    else:
        click.echo(f"silences that made a robot quiet: {len(gaps) + report.gaps_untold} (from when last heard)")
        click.echo(f"{'robot':>7} {'from_s':>9} {'to_s':>9} {'seconds':>9}")
        for gap in gaps[:GAP_ROWS]:
            end = "-" if gap.end is None else f"{gap.end - start:.3f}"
            click.echo(f"{shown_sender(gap.robot):>7} {gap.start - start:>9.3f} {end:>9} {gap.seconds:>9.3f}"
                       + ("  (until the end)" if gap.end is None else ""))
        if len(gaps) > GAP_ROWS:
            click.echo(f"... {len(gaps) - GAP_ROWS} more (--json lists them all)")
    kinds = Counter(f"{change.old.value}->{change.new.value}" for change in report.changes)
    total = len(report.changes) + report.changes_untold
    click.echo(f"state changes: {total}" + (f" ({', '.join(f'{k} {n}' for k, n in sorted(kinds.items()))})"
                                            if kinds else ""))
