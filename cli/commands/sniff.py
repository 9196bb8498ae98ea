"""`vstig sniff LINK...`: watch the swarm's traffic, decoded; never transmits."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import click

from vstig_hw.capture.filters import Filter
from vstig_hw.engine import larger_value_wins
from vstig_hw.gateway import Mode, Node, stop_on_signals
from vstig_hw.gateway.guard import Guard
from vstig_hw.gateway.ros2 import serve_ros2
from vstig_hw.gateway.signing import Signing
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard, LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw
from vstig_hw.wording import counted, shown_sender

from ..config import ConfiguredCommand, config_options
from ..live import foxglove_option, live_view
from ..ops.metrics import metrics_option, metrics_served
from ..options import VALUE_TYPE_HELP, Address, Finite, GuardChoice, filter_options, guard_options, take_warnings
from ..robots import ROBOTS_KEY, RobotRows, ViewKeys, fit_few, robots_table, roster_options, start_roster
from ..running import (
    LINK,
    LinkArguments,
    build_links,
    describe_links,
    must_hear,
    opened,
    print_counters,
    reports_errors,
    run_until_stopped,
)
from ..swarm_key import swarm_key_option, swarm_keys_for

_TABLE_CHROME = 8  # lines a table needs besides its rows: title, header and its rule, counters caption, a spare
# Short headers, so that the table fits 80 columns (docs/how-to/sniff.md explains each).
_COLUMNS = ("key", "value", "ts", "robot", "age", "PUT", "GET", "conflicts", "stale", "refused")
_STALE_WIDTH = 11  # characters of stale senders named in a row (at least one); "+N" counts the rest


def _table(view: SwarmView, value_type: ValueType, node: Node | None = None, height: int | None = None) -> Any:
    """The table, keys in order; on a terminal only the rows that fit, and the title says how many."""
    from rich import box
    from rich.table import Table

    keys = sorted(view.keys)
    shown = keys if height is None else keys[:max(1, height - _TABLE_CHROME)]
    title = f"vstig sniff: {counted(view.messages, 'message')}, {counted(len(keys), 'key')}"
    if len(shown) < len(keys):
        title += f" (keys {shown[0]}..{shown[-1]} shown; --key K for others)"
    # No side borders and one space between columns: ten columns fit 80 characters.
    table = Table(title=title, caption=node.summary() if node else None, box=box.SIMPLE_HEAD, padding=(0, 0),
                  show_edge=False)
    for column in _COLUMNS:
        table.add_column(column, justify="left" if column in ("stale", "refused") else "right")
    now = time.time()
    for key in shown:
        k = view.keys[key]
        # A key only ever asked for (empty GETs) holds no entry yet: "-", not a write of 0 by robot 0.
        entry = (str(from_raw(k.value, value_type)), str(k.timestamp), str(k.robot)) if k.has_entry else ("-",) * 3
        table.add_row(str(key), *entry, f"{now - k.last_seen:.1f}s", str(k.puts), str(k.gets), str(k.conflicts),
                      _few(k.stale_senders()), f"{k.refused} {k.refused_reason}" if k.refused else "")
    return table


def _few(senders: list[int]) -> str:
    """The first stale senders that fit the column and how many more: `2 4 9 +10`."""
    return fit_few([shown_sender(sender) for sender in senders], _STALE_WIDTH)


@click.command(cls=ConfiguredCommand)
@click.argument("links", nargs=-1, required=True, type=LINK, cls=LinkArguments)
@click.option("--jsonl", is_flag=True, help="Print one JSON object per message instead of the live table.")
@click.option("--robots", is_flag=True,
              help=f"One row per robot instead of per key (key {ROBOTS_KEY} switches the live table); with "
                   "--jsonl, one JSON object per robot every second.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
              help=VALUE_TYPE_HELP)
@click.option("--larger-value-wins", "larger", is_flag=True,
              help="Settle conflicts as a swarm running the paper's Figure 1 rule does (larger value), "
                   "instead of the default higher robot id.")
@click.option("--for", "duration", type=Finite(0.0), help="Stop after this many seconds.")
@click.option("--hide-refused", is_flag=True,
              help="Leave out what the guard options would refuse (it is still counted under the table).")
@roster_options
@foxglove_option
@metrics_option
@filter_options
@guard_options
@swarm_key_option
@config_options
@reports_errors
def command(links: tuple[LinkSpec, ...], jsonl: bool, robots: bool, value_type: ValueType, larger: bool,
            duration: float | None, hide_refused: bool, no_roster: bool, quiet_after: float | None,
            gone_after: float | None, max_robots: int, foxglove: Address | None, foxglove_viewers: int,
            metrics: Address | None, keep: Filter, guard: GuardChoice, swarm_key: bytes | None) -> None:
    """Decode what each LINK hears live, per key; passive: never transmits.

    The filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    what is shown; --since and --until count from the first message heard.

    The counters (live under the table, and on exit) include the receive outcomes
    an engine that heard every message would count: stored, answered, stale,
    same, conflict, unknown, invalid.

    Example: vstig sniff can:socketcan:can0 --jsonl | jq .

    The guard options are bridge's: what a bridge with them would refuse is shown too, marked
    with the reason (the "refused" column; "refused" in --jsonl, null for what passes), never
    changes a key's entry, and is counted under the table (drop_jump, drop_rate...).
    --hide-refused leaves it out. With --swarm-key FILE, the links with auth=require or auth=prefer
    check the writers' tags: what fails is refused as drop_untagged or drop_bad_tag.

    --foxglove 8765 serves the same live, to Foxglove (docs/how-to/live-view.md): every
    message, the table, each write's spread and the counters.

    --robots shows who is in the swarm (docs/how-to/robots.md): per robot its links, when
    it was last heard, its rate, writes and GETs, the keys it is behind on, and its state
    (alive, quiet after --quiet-after, gone after --gone-after).
    """
    for link in links:
        must_hear(link, "sniff")
    if robots and no_roster:
        raise click.UsageError("--robots shows the roster: give --robots or --no-roster, not both")
    rule = larger_value_wins if larger else None
    built = build_links(links, listen_only=True)
    firewall = guard.build(built)
    # The engine never transmits: it counts what each message would do to a robot that heard them all.
    node = Node(built, mode=Mode.LISTEN, count_outcomes=True, guard=firewall, onconflict=rule,
                swarm_keys=swarm_keys_for(built, swarm_key))
    serve_ros2(node)
    kept = start_roster(node, no_roster, quiet_after, gone_after, max_robots)
    view = SwarmView(rule) if rule else SwarmView()
    listeners: list[Callable[[Heard, str | None], None]] = [
        lambda message, reason: view.add(message) if reason is None else view.refuse(message, reason)]
    first: list[float] = []

    def heard(message: Heard, reason: str | None = None) -> None:
        first[:] = first or [message.t]
        if not keep or keep.accepts(message.t - first[0], message.link, message.sender, message.message):
            for listener in listeners:
                listener(message, reason)

    node.listen(heard=heard, refused=None if hide_refused else heard)
    if jsonl:
        import json

        out = sys.stdout
        rows = RobotRows(kept, out) if kept is not None and robots else None

        # The same row as `decode --format jsonl` (can_id on CAN links only, sender where the medium names one),
        # and `refused`: the drop counter a guarded bridge would count it under, or null.
        by_name = {link.name: link for link in node.links}

        def emit(heard: Heard, reason: str | None) -> None:
            m = heard.message
            row: dict[str, Any] = {"t": round(heard.t, 6), "link": heard.link}
            link = by_name.get(heard.link)
            can_id = None if link is None or heard.sender is None else link.can_id(m.op, heard.sender)
            if can_id is not None:
                row["can_id"] = can_id
            row.update(op=m.op.name, key=m.key, value=from_raw(m.value, value_type), timestamp=m.timestamp,
                       robot=m.robot, sender=heard.sender, refused=reason)
            out.write(json.dumps(row) + "\n")
            out.flush()

        if rows is None:
            listeners.append(emit)
        else:
            node.listen(tick=rows)
        node.listen(tick=lambda _node: _warn(firewall, node.signing))
        with (stop_on_signals() as stop,
              live_view(node, foxglove, value_type=value_type, larger_value_wins=larger, viewers=foxglove_viewers),
              metrics_served(node, metrics), opened(node, stop)):
            describe_links(node)
            run_until_stopped(node, stop, duration=duration)
        if rows is not None:
            rows.write()  # the roster as the sniff ends
        _warn(firewall, node.signing)
        print_counters(node)
        return
    from rich.live import Live

    # The live view first, then the node: a port that cannot be bound or opened is the one line said
    with (stop_on_signals() as stop,
          live_view(node, foxglove, value_type=value_type, larger_value_wins=larger, viewers=foxglove_viewers),
          metrics_served(node, metrics), opened(node, stop)):
        if not sys.stdout.isatty():
            click.echo("stdout is not a terminal: the table is printed once, when sniff ends "
                       "(--jsonl streams every message instead)", err=True)
        showing = [robots]  # the robots table (else the keys'); the key switches (unless --no-roster)

        def table(height: int | None = None) -> Any:
            if kept is not None and showing[0]:
                return robots_table(kept.roster, node, height)
            return _table(view, value_type, node, height)

        with ViewKeys().reading() as keys, Live(table(), refresh_per_second=4, transient=False) as live:
            def redraw() -> None:  # only what fits the terminal (a pipe gets every row, once, at the end)
                _warn(firewall, node.signing)  # on a terminal, Live prints stderr above the table
                showing[0] ^= keys.pressed().lower().count(ROBOTS_KEY) % 2 == 1
                height = live.console.size.height if live.console.is_terminal else None
                live.update(table(height))

            describe_links(node)
            run_until_stopped(node, stop, redraw, duration)
    _warn(firewall, node.signing)
    print_counters(node)


def _warn(firewall: Guard, signing: Signing | None) -> None:
    for warning in take_warnings(firewall) + take_warnings(signing):
        click.echo(warning, err=True)
