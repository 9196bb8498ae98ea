"""The roster at the CLI's edge: its options, sniff's robots table, the per-second JSON rows, the view key.

docs/how-to/robots.md explains the states, the thresholds and each column.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import sys
import time
from collections.abc import Callable, Iterator
from typing import IO, Any, TypeVar

import click

from vstig_hw.gateway import Node
from vstig_hw.gateway.kept_roster import KeptRoster, keep_roster
from vstig_hw.gateway.roster import DEFAULT_MAX_ROBOTS, GONE_PERIODS, QUIET_PERIODS, RobotState, Roster
from vstig_hw.wording import counted, shown_sender

from .options import Finite

__all__ = ["ROBOTS_KEY", "RobotRows", "ViewKeys", "fit_few", "robots_table", "roster_options", "roster_thresholds",
           "start_roster", "thresholds_error"]

F = TypeVar("F", bound=Callable[..., Any])

ROBOTS_KEY = "r"  # pressed in sniff's live table: robots <-> keys
ROWS_EVERY = 1.0  # seconds between one robot's JSON rows
_TABLE_CHROME = 8  # lines a table needs besides its rows (as sniff's keys table)
_COLUMNS = ("robot", "by", "state", "links", "heard", "rate", "PUT", "GET", "behind", "refused")
_LINKS_WIDTH = 9  # with an XBee's 18-character id, the widest row still fits 80 columns
_BEHIND_WIDTH = 9
_STYLE = {RobotState.ALIVE: "green", RobotState.QUIET: "yellow", RobotState.GONE: "red"}


def roster_thresholds(fn: F) -> F:
    """--quiet-after, --gone-after: when a robot not heard is quiet, and gone (`vstig analyze --robots` too)."""
    for option in reversed([
        click.option("--quiet-after", type=Finite(0.0, min_open=True), metavar="SECONDS",
                     help=f"A robot not heard for this long (and for {QUIET_PERIODS} of its usual gaps) is quiet "
                          f"[default: {QUIET_PERIODS} control periods]."),
        click.option("--gone-after", type=Finite(0.0, min_open=True), metavar="SECONDS",
                     help=f"A robot not heard for this long is gone [default: {GONE_PERIODS} control periods]."),
    ]):
        fn = option(fn)
    return fn


def roster_options(fn: F) -> F:
    """--quiet-after, --gone-after, --max-robots: the roster's thresholds (every gateway keeps one); --no-roster."""
    for option in reversed([
        click.option("--no-roster", is_flag=True,
                     help="Keep no roster of robots (docs/how-to/robots.md): a little less CPU per message."),
        roster_thresholds,
        click.option("--max-robots", type=click.IntRange(1), default=DEFAULT_MAX_ROBOTS, show_default=True,
                     help="Robots the roster tracks; more are counted, never stored."),
    ]):
        fn = option(fn)
    return fn


def start_roster(node: Node, no_roster: bool, quiet_after: float | None, gone_after: float | None,
                 max_robots: int) -> KeptRoster | None:
    """The node's roster with the options' thresholds (None: --no-roster); a usage error (exit 2) names a bad
    pair."""
    if no_roster:
        return None
    try:
        roster = Roster(node.period, quiet_after=quiet_after, gone_after=gone_after, max_robots=max_robots)
    except ValueError as error:
        raise thresholds_error(error) from None
    return keep_roster(node, roster)


def thresholds_error(error: ValueError) -> click.UsageError:
    """The roster's refusal of its thresholds, in the options' words (their ranges leave only gone not after
    quiet)."""
    return click.UsageError(str(error).replace("_after", "-after").replace("gone-", "--gone-")
                            .replace("quiet-", "--quiet-"))


def fit_few(items: list[str], width: int) -> str:
    """The first items that fit `width` characters with how many more: `2 4 9 +10` (the first always)."""
    named = ""
    for count, item in enumerate(items):
        longer = f"{named} {item}".lstrip()
        rest = len(items) - count - 1
        if named and len(longer) + (len(f" +{rest}") if rest else 0) > width:
            return f"{named} +{len(items) - count}"
        named = longer
    return named


def robots_table(roster: Roster, node: Node | None = None, height: int | None = None) -> Any:
    """One row per robot, sorted by state then id, state coloured; on a terminal only the rows that fit."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    views = roster.snapshot(time.time())
    shown = views if height is None else views[:max(1, height - _TABLE_CHROME)]
    states = {state: sum(v.state is state for v in views) for state in RobotState}
    title = f"vstig sniff: {counted(len(views), 'robot')} ({', '.join(f'{n} {s.value}' for s, n in states.items())})"
    if roster.untracked:
        title += f", {roster.untracked} untracked"
    if len(shown) < len(views):
        title += f" ({len(shown)} shown)"
    table = Table(title=title, caption=node.summary() if node else f"press {ROBOTS_KEY}: keys",
                  box=box.SIMPLE_HEAD, padding=(0, 0), show_edge=False)
    widths = {"links": _LINKS_WIDTH, "behind": _BEHIND_WIDTH}
    for column in _COLUMNS:
        table.add_column(column, justify="left" if column in ("by", "state", "links", "behind") else "right",
                         no_wrap=True, max_width=widths.get(column), overflow="ellipsis")
    for view in shown:
        table.add_row(shown_sender(view.robot), view.named_by[0], Text(view.state.value, style=_STYLE[view.state]),
                      fit_few(list(view.links), _LINKS_WIDTH), _ago(view.last_heard_s), _short(view.rate),
                      _short(view.writes), _short(view.gets), fit_few([str(key) for key in view.behind], _BEHIND_WIDTH),
                      _short(view.refused) if view.refused else "")
    return table


def _ago(seconds: float) -> str:
    """At most five characters: 0.3s, 59.9s, 12m, 5h, 3d."""
    if seconds < 60:
        return f"{seconds:.1f}s"
    for unit, size in (("m", 60), ("h", 3600), ("d", 86400)):
        if seconds < 100 * size:
            return f"{seconds // size:.0f}{unit}"
    return f"{seconds // 86400:.0f}d"


def _short(number: float) -> str:
    """At most five characters: 7, 12.5, 9999, 12k, 1.2M."""
    if isinstance(number, float) and number < 100:
        return f"{number:.1f}"
    if number < 10_000:
        return f"{number:.0f}"
    if number < 1_000_000:
        return f"{number / 1000:.0f}k"
    return f"{number / 1e6:.1f}M"


class RobotRows:
    """`sniff --robots --jsonl`: every ROWS_EVERY seconds, one JSON object per robot (a tick listener)."""

    def __init__(self, kept: KeptRoster, out: IO[str]) -> None:
        self.kept, self.out = kept, out
        self._next = 0.0

    def __call__(self, _node: Node) -> None:
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + ROWS_EVERY
        self.write()

    def write(self) -> None:
        t = round(time.time(), 3)
        for view in self.kept.snapshot():
            self.out.write(json.dumps({"t": t, **view.as_json()}) + "\n")
        self.out.flush()


class ViewKeys:
    """Keys pressed in the live table, read without waiting: stdin in cbreak mode while it is a terminal (restored
    on exit); elsewhere nothing is ever pressed."""

    def __init__(self) -> None:
        self._fd = -1
        self._saved: list[Any] | None = None

    @contextlib.contextmanager
    def reading(self) -> Iterator[ViewKeys]:
        stdin = sys.stdin
        if stdin is None or not stdin.isatty():
            yield self
            return
        import termios
        import tty

        self._fd = stdin.fileno()
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)  # one key at a time, no echo; Ctrl-C still signals
        try:
            yield self
        finally:
            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._fd = -1

    def pressed(self) -> str:
        """What was typed since the last look ("" if nothing, or not a terminal)."""
        if self._fd < 0:
            return ""
        typed = b""
        while select.select([self._fd], [], [], 0)[0]:
            chunk = os.read(self._fd, 64)
            if not chunk:
                break
            typed += chunk
        return typed.decode("utf-8", "replace")
