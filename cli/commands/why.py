"""`vstig why FILES... --key K [--robot R] [--at T]`: why a robot holds the entry it holds (docs/how-to/why.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from vstig_hw.capture.records import Damage
from vstig_hw.capture.trace import Shown, Trace, read_trace
from vstig_hw.capture.why import Answer, explain
from vstig_hw.extras import require
from vstig_hw.wire import KEY_MAX

from ..clock_merge import on_one_clock
from ..options import Finite, damage_option, echo_skipped, overwrite_option, refuse_to_replace
from ..running import reports_errors


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--key", required=True, type=click.IntRange(0, KEY_MAX), help="The key to explain.")
@click.option("--robot", help="The sender to explain: its id where the medium names senders (CAN, zenoh), else "
                              "the serial link it is heard on (ttyUSB1); default: every sender that showed the key.")
@click.option("--at", type=Finite(0.0), help="Seconds after the first record (as replay --table --at); default: "
                                             "the end of the capture.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (for programs).")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path),
              help="Write a PNG: each sender's shown timestamp for the key over time, the writes, the sends, the gaps.")
@overwrite_option("the --plot FILE")
@click.option("--trust-clock-notes", is_flag=True, help="Merge several captures on one clock through every clock "
                                                        "offset they noted, also unproved ones (as analyze).")
@damage_option
@click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
              help="For Buzz/BittyBuzz captures: the TOML file mapping their keys.")
@reports_errors
def command(files: tuple[str, ...], key: int, robot: str | None, at: float | None, as_json: bool,
            plot: Path | None, overwrite: bool, trust_clock_notes: bool, damage: Damage,
            deployment: str | None) -> None:
    """Explain why a robot holds the value it holds for a key: trace every write through captures.

    Every PUT or GET a robot sends shows the entry it holds, so captures (several are merged on one
    clock, as analyze merges them) say what each sender showed when. For the newest write at T:
    where it was first heard, each link and sender that showed it next (with each hop's delay), and
    what the gateway did with it (a `vstig bridge --record` capture holds its sends and its
    decisions: guard refusals, fair-share drops, full queues, conflicts). For each sender (or
    --robot R): when it was last heard, the last entry it showed, and a one-line verdict: holds the
    newest, never asked, refused by the guard, lost a conflict, never sent (and why), deaf, behind.

    Example: vstig why swarm.cap --key 3 --robot ttyUSB1 --at 40
    """
    if plot is not None:
        refuse_to_replace(plot, overwrite)
        require("analyze", "vstig why --plot", ("matplotlib",))
    names = {path: path for path in files}
    clocks = on_one_clock(names, trust_clock_notes)
    trace = read_trace(files, shifts=[s.seconds if s else 0.0 for s in clocks] if clocks else None,
                       damage=damage, deployment=deployment)
    echo_skipped(damage.first)
    if not trace.messages:
        raise click.ClickException(f"{', '.join(files)}: no stigmergy messages in the capture")
    if at is not None and at > trace.end:
        click.echo(f"--at {at:g} is past the capture's end ({trace.end:.2f} s): answering for its end", err=True)
    answer = explain(trace, key, robot, at)
    if robot is not None and robot not in trace.senders:
        click.echo(f"--robot {robot}: no such sender in the capture (senders: "
                   f"{', '.join(sorted(trace.senders)) or 'none'})", err=True)
    if plot is not None:
        from vstig_hw.why_plot import plot_key

        plot_key(trace, answer, plot)
    click.echo(json.dumps(_as_json(answer)) if as_json else _as_text(answer, trace))
    if plot is not None:
        click.echo(f"wrote {plot}", err=True)


def _entry(shown: Shown | None) -> dict[str, Any] | None:
    if shown is None:
        return None
    return {"t": round(shown.t, 6), "link": shown.link, "sender": shown.sender, "ts": shown.ts,
            "robot": shown.robot, "value": shown.value, "op": "PUT" if shown.put else "GET"}


def _as_json(answer: Answer) -> dict[str, Any]:
    return {
        "key": answer.key, "at": round(answer.at, 6), "newest": _entry(answer.newest),
        "path": [{"t": round(h.t, 6), "link": h.link, "sender": h.sender, "sent": h.sent,
                  "delay": round(h.delay, 6)} for h in answer.path],
        "gateway": answer.did,
        "senders": [{"sender": v.sender, "cause": v.cause, "verdict": v.line,
                     "last_heard": None if v.last_heard is None else round(v.last_heard, 6),
                     "shown": _entry(v.shown)} for v in answer.verdicts],
    }


def _as_text(answer: Answer, trace: Trace) -> str:
    lines = [f"key {answer.key} at {answer.at:.2f} s (the capture: {trace.end:.2f} s, {trace.messages} messages)"]
    newest = answer.newest
    if newest is None:
        lines.append("  no write of this key by then")
    else:
        lines.append(f"  newest write: ts {newest.ts} by robot {newest.robot} (value {newest.value}), first heard "
                     f"at {newest.t:.2f} s on {newest.link} from {newest.sender}")
        for hop in answer.path[1:]:
            who = f"sent on {hop.link}" if hop.sent else f"shown by {hop.sender} on {hop.link}"
            lines.append(f"    {hop.t:8.2f} s  +{hop.delay:.3f} s  {who}")
        lines.extend(f"  {did}" for did in answer.did)
    for verdict in answer.verdicts:
        shown = verdict.shown
        heard = "never heard" if verdict.last_heard is None else f"last heard at {verdict.last_heard:.2f} s"
        showed = "" if shown is None else f"; last showed ts {shown.ts} (robot {shown.robot}) at {shown.t:.2f} s"
        lines.append(f"{verdict.sender}: {heard}{showed}")
        lines.append(f"  {verdict.line}")
    return "\n".join(lines)
