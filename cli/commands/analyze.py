"""`vstig analyze FILE...`: the paper's measure on a real swarm's capture (convergence per write, bandwidth)."""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import Any

import click

from vstig_hw.analysis import CONFLICT_RULES, DEFAULT_WINDOW, Analyzer, Conflict, Report, Traffic, WriteReport
from vstig_hw.capture.analyzefile import Fed, analyze_captures
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.records import CaptureError, Damage
from vstig_hw.counters import Counters
from vstig_hw.extras import require
from vstig_hw.roster_history import RosterAnalyzer, RosterHistory
from vstig_hw.values import ValueType, from_raw
from vstig_hw.wording import counted, shown_sender

from ..clock_merge import on_one_clock
from ..options import (
    Finite,
    echo_skipped,
    filter_options,
    input_format_option,
    input_name,
    overwrite_option,
    parse_id_base,
    readable_capture,
    reading_options,
    refuse_to_replace,
    renamed,
)
from ..robots import roster_thresholds, thresholds_error
from ..roster_text import print_roster, roster_json
from ..running import reports_errors

_PROGRESS_BYTES = 1 << 20  # captures larger than this get a progress bar (on a terminal)


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@input_format_option
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (writes, summary, bandwidth).")
@click.option("--plot", type=click.Path(dir_okay=False, writable=True, path_type=Path),
              help="Write a PNG: (a) a key's writes spreading through the senders, (b) convergence times, "
                   "(c) traffic per link (alone where no link names senders).")
@overwrite_option("the --plot FILE")
@click.option("--window", default=DEFAULT_WINDOW, show_default=True, type=Finite(0, min_open=True),
              help="Seconds either side of a write in which a sender must be heard to count as active.")
@click.option("--conflict", type=click.Choice(CONFLICT_RULES), default="robot", show_default=True,
              help="Which of two writes with one timestamp is newer: the higher robot id (Buzz's default) "
                   "or the larger value (the paper's Figure 1).")
@click.option("--trust-clock-notes", is_flag=True,
              help="Merge captures on one clock through every clock offset they noted, also those no certificate "
                   "proved (open links: any Zenoh peer can answer for any gateway's clock there).")
@click.option("--robots", is_flag=True,
              help="Add the roster over the capture's time: each robot, when it was heard, its silences longer than "
                   "--quiet-after and its state changes (docs/how-to/robots.md).")
@roster_thresholds
@reading_options
@filter_options
@reports_errors
def command(files: tuple[str, ...], input_format: str | None, as_json: bool, plot: Path | None, overwrite: bool,
            window: float, conflict: Conflict, trust_clock_notes: bool, robots: bool, quiet_after: float | None,
            gone_after: float | None, value_type: ValueType, damage: Damage, id_base: str | None, extended: bool,
            deployment: str | None, keep: Filter) -> None:
    """Measure convergence per write and bandwidth from captures.

    Convergence is how long each write took to reach every robot, the paper's measure.

    A write is a new (key, timestamp, robot) entry. Every PUT or GET a robot sends
    shows the entry it holds, and a CAN frame's ID names its sender, so a write
    has reached a sender when that sender first shows it or a newer entry. A write
    has converged when every sender heard within --window seconds of it has.
    Serial links name no sender: for them, the first and last time each write was
    heard per link is reported instead. Several FILES are merged by time, on
    the first one's clock where their clock notes join them (captures that
    zenoh links recorded on several PCs; the shift and its bound are said),
    through offsets a TLS certificate proved unless --trust-clock-notes. The
    filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    which messages count; --plot draws the first --key given. - reads stdin;
    pipes and <(...) work too, their type told by their first bytes.

    Example: vstig analyze swarm.log --key 3 --plot key3.png
    """
    base = parse_id_base(id_base)
    if plot is not None:
        refuse_to_replace(plot, overwrite)  # before reading: a capture typed as --plot is refused at once
        require("analyze", "vstig analyze --plot", ("matplotlib",))  # numpy alone was checked as the command loaded
    history = None
    if robots:
        try:
            history = RosterHistory(quiet_after=quiet_after, gone_after=gone_after)
        except ValueError as error:
            raise thresholds_error(error) from None
    elif quiet_after is not None or gone_after is not None:
        raise click.UsageError("--quiet-after and --gone-after are the roster's: give --robots too")
    analyzer = Analyzer(window, conflict) if history is None else RosterAnalyzer(history, window, conflict)
    # 11-bit unless told (--extended) or implied (--id-base names one width's base); else read from frames.
    width = True if extended else (False if base is not None else None)
    names = ", ".join(map(input_name, files))
    with contextlib.ExitStack() as spooled:  # stdin and pipes are copied to a file first
        readable = {spooled.enter_context(readable_capture(path, input_format)): input_name(path) for path in files}
        clocks = on_one_clock(readable, trust_clock_notes)
        try:
            drops, filtered_out = _read(readable, analyzer, damage, base, width, keep, deployment,
                                        [shift.seconds if shift else 0.0 for shift in clocks] if clocks else None)
        except CaptureError as error:
            raise renamed(error, error.path, readable.get(error.path, error.path)) from None
    echo_skipped(renamed(error, error.path, readable.get(error.path, error.path)) for error in damage.first)
    report = analyzer.report()
    if not report.messages:
        if filtered_out:
            raise click.ClickException(f"{names}: the filters ({_described(keep)}) left out all {filtered_out} "
                                       "stigmergy messages in the capture")
        reason = f" ({drops.summary()} dropped)" if drops else ""
        raise click.ClickException(f"{names}: no stigmergy messages in the capture{reason}")
    if plot is not None:
        from vstig_hw.analysis_plot import plot_report

        plot_report(report, plot, min(keep.keys) if keep.keys else None)
    roster = None if history is None else history.report()
    if as_json:
        result = _as_json(report, tuple(readable.values()), drops, damage.count, value_type)
        if clocks:
            result["capture"]["clocks"] = [None if shift is None else {"shift_s": shift.seconds, "error_s": shift.error}
                                           for shift in clocks]
        if roster is not None:
            result["robots"] = roster_json(roster)
        click.echo(json.dumps(result))
    else:
        _print_text(report, value_type)
        if roster is not None:
            print_roster(roster, report.start or 0.0)
    summary = counted(report.messages, "message") + (
        f", {counted(damage.count, 'bad line')} skipped" if damage.count else "")
    if drops:
        summary += f", dropped {drops.summary()}"
    click.echo(summary + (f"; wrote {plot}" if plot else ""), err=True)


def _read(names: dict[str, str], analyzer: Analyzer, damage: Damage, base: int | None, width: bool | None,
          keep: Filter, deployment: str | None, shifts: list[float] | None = None) -> Fed:
    """`names`: the files to read, each with the name the user gave it; `shifts`: seconds off each one's times."""
    files = tuple(names)
    size = sum(os.path.getsize(path) for path in files)
    if not (sys.stderr.isatty() and size > _PROGRESS_BYTES):
        return analyze_captures(files, analyzer, damage=damage, id_base=base, extended=width, keep=keep,
                                deployment=deployment, shifts=shifts)
    from rich.console import Console
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(f"analyzing {os.path.basename(names[files[0]])}", total=size)
        result = analyze_captures(files, analyzer, damage=damage, id_base=base, extended=width, keep=keep,
                                  deployment=deployment, progress=lambda n: bar.advance(task, n), shifts=shifts)
    return result


def _described(keep: Filter) -> str:
    """The filter as the options that made it (--key 3 --op PUT)."""
    words = [f"--{name} {value}" for name, values in (("key", keep.keys), ("robot", keep.robots),
                                                      ("sender", keep.senders), ("link", keep.links))
             for value in sorted(values or ())]
    words += [f"--op {op.name}" for op in sorted(keep.ops or ())]
    words += [f"--{name} {value:g}" for name, value in (("since", keep.since), ("until", keep.until))
              if value is not None]
    return " ".join(words)


# -- JSON ---------------------------------------------------------------------------------------------------------
def _rounded(t: float | None) -> float | None:
    return None if t is None else round(t, 6)


def _write_json(w: WriteReport, value_type: ValueType) -> dict[str, Any]:
    return {"key": w.key, "value": from_raw(w.value, value_type), "timestamp": w.timestamp, "robot": w.robot,
            "t": _rounded(w.t), "link": w.link, "converged_after_s": _rounded(w.converged_after),
            "senders_total": w.senders_total, "senders_caught_up": w.senders_caught_up,
            "senders_behind": list(w.behind),
            "heard": {name: {"first": _rounded(h.first), "last": _rounded(h.last), "copies": h.copies}
                      for name, h in w.heard.items()}}


def _traffic_json(traffic: Traffic, seconds: float) -> dict[str, Any]:
    rate = (lambda n: round(n / seconds, 3)) if seconds > 0 else (lambda n: None)
    return {"messages": traffic.messages, "puts": traffic.puts, "gets": traffic.gets, "bytes": traffic.bytes,
            "messages_per_s": rate(traffic.messages), "bytes_per_s": rate(traffic.bytes)}


def _as_json(report: Report, files: tuple[str, ...], drops: Counters, bad: int,
             value_type: ValueType) -> dict[str, Any]:
    seconds = report.duration
    return {
        "capture": {"files": list(files), "start": _rounded(report.start), "end": _rounded(report.end),
                    "duration_s": _rounded(seconds), "messages": report.messages,
                    "links": list(report.links), "links_without_sender": report.links_without_sender,
                    "dropped": dict(drops), "bad_lines_skipped": bad},
        "window_s": report.window, "conflict": report.conflict,
        "writes": [_write_json(w, value_type) for w in report.writes],
        "summary": {name: (_rounded(v) if isinstance(v, float) else v) for name, v in report.convergence().items()},
        "bandwidth": {"links": {name: _traffic_json(t, seconds) for name, t in report.links.items()},
                      "senders": {str(s): _traffic_json(t, seconds) for s, t in report.senders.items()},
                      "first_copies": report.first_copies, "rebroadcasts": report.rebroadcasts,
                      "conflicts": report.conflicts},
    }


# -- text ---------------------------------------------------------------------------------------------------------
def _seconds(t: float | None) -> str:
    return "-" if t is None else f"{t:.3f}"


def _print_text(report: Report, value_type: ValueType) -> None:
    start = report.start or 0.0
    click.echo(f"capture: {counted(report.messages, 'message')} over {report.duration:.3f} s "
               f"on {', '.join(report.links)}")
    if report.links_without_sender:
        click.echo(f"note: {', '.join(report.links_without_sender)} name no sender (serial): convergence cannot be "
                   "measured there; first and last time each write was heard per link shown")
    summary = report.convergence()
    if summary["measured"]:
        if summary["converged"]:
            click.echo(f"convergence: median {_seconds(summary['median'])} s  min {_seconds(summary['min'])} s  "
                       f"max {_seconds(summary['max'])} s  ({summary['converged']} of {summary['measured']} "
                       f"writes reached every active sender; window {report.window:g} s, "
                       f"conflicts by {report.conflict})")
        else:
            click.echo(f"convergence: none of {summary['measured']} writes reached every active sender")
    click.echo()
    heard_links = report.links_without_sender
    header = (f"{'converged_s':>11} {'key':>5} {'value':>8} {'ts':>5} {'robot':>5} {'t_s':>10} {'caught_up':>9}  "
              + "".join(f"{name + ' first..last':>24}" for name in heard_links) + "behind")
    click.echo(header.rstrip())
    by_convergence = sorted(report.writes, key=lambda w: (w.converged_after is None, w.converged_after or 0.0, w.t))
    for w in by_convergence:
        caught = f"{w.senders_caught_up}/{w.senders_total}" if w.senders_total else "-"
        heard = ""
        for name in heard_links:
            h = w.heard.get(name)
            heard += f"{'-':>24}" if h is None else f"{f'{h.first - start:.3f}..{h.last - start:.3f}':>24}"
        behind = " ".join(map(shown_sender, w.behind[:10])) + (" ..." if len(w.behind) > 10 else "")
        click.echo((f"{_seconds(w.converged_after):>11} {w.key:>5} {from_raw(w.value, value_type)!s:>8} "
                    f"{w.timestamp:>5} {w.robot:>5} {w.t - start:>10.3f} {caught:>9}  {heard}{behind}").rstrip())
    click.echo()
    _print_traffic(report)


def _print_traffic(report: Report) -> None:
    seconds = report.duration

    def row(name: str, traffic: Traffic) -> str:
        per_s = (f"{traffic.messages / seconds:>9.1f} {traffic.bytes / seconds:>9.1f}" if seconds > 0
                 else f"{'-':>9} {'-':>9}")
        return f"{name:<16} {traffic.messages:>9} {per_s} {traffic.puts:>9} {traffic.gets:>9}"

    click.echo(f"{'bandwidth':<16} {'messages':>9} {'msg/s':>9} {'B/s':>9} {'PUT':>9} {'GET':>9}")
    for name, traffic in report.links.items():
        click.echo(row(f"link {name}", traffic))
    for sender, traffic in report.senders.items():
        click.echo(row(f"sender {shown_sender(sender)}", traffic))
    click.echo(f"PUTs: {report.first_copies} first copies, {report.rebroadcasts} re-broadcasts; conflicts: "
               f"{counted(report.conflicts, 'write')} sharing a key and timestamp with another robot's write")
