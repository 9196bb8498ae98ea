"""`vstig sniff LINK`: watch the swarm's traffic, decoded; never transmits."""

from __future__ import annotations

import sys
import time
from typing import Any

import click

from vstig_hw.gateway import Mode, Node
from vstig_hw.gateway.guard import Guard
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard
from vstig_hw.links.spec import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw

from ._common import build_links, describe_links, print_counters, run_until_stopped
from ._guard import GuardChoice, guard_options, take_warnings
from .errors import LINK, reports_errors


def _table(view: SwarmView, value_type: ValueType, node: Node) -> Any:
    from rich.table import Table

    table = Table(title=f"vstig sniff: {view.messages} messages", caption=node.summary())
    for column in ("key", "value", "ts", "robot", "last seen", "PUT", "GET", "conflicts", "stale senders"):
        table.add_column(column, justify="left" if column == "stale senders" else "right")
    now = time.time()
    for key in sorted(view.keys):
        k = view.keys[key]
        stale = k.stale_senders()
        table.add_row(str(key), str(from_raw(k.value, value_type)), str(k.timestamp), str(k.robot),
                      f"{now - k.last_seen:.1f}s ago", str(k.puts), str(k.gets), str(k.conflicts),
                      ", ".join(map(str, stale[:12])) + (" ..." if len(stale) > 12 else ""))
    return table


@click.command()
@click.argument("link", type=LINK)
@click.option("--jsonl", is_flag=True, help="Print one JSON object per message instead of the live table.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@click.option("--for", "duration", type=click.FloatRange(0.0), help="Stop after this many seconds.")
@guard_options
@reports_errors
def command(link: LinkSpec, jsonl: bool, value_type: ValueType, duration: float | None, guard: GuardChoice) -> None:
    """Decode LINK's traffic live, per key; passive: never transmits.

    The counters (live under the table, and on exit) include the receive outcomes
    an engine that heard every message would count: stored, answered, stale,
    same, conflict, unknown, invalid.

    Example: vstig sniff can:socketcan:can0 --jsonl | jq .

    The guard options are bridge's: what a bridge with them would refuse is left out of the
    table and counted under the table (drop_jump, drop_rate...); --max-jump 0 shows everything.
    """
    built = build_links([link], listen_only=True)
    firewall = guard.build(built)
    # The engine never transmits: it counts what each message would do to a robot that heard them all.
    node = Node(built, mode=Mode.LISTEN, count_outcomes=True, guard=firewall)
    view = SwarmView()
    node.on_heard.append(view.add)
    if jsonl:
        import json

        out = sys.stdout

        def emit(heard: Heard) -> None:
            m = heard.message
            row = {"t": round(heard.t, 6), "link": heard.link, "op": m.op.name, "key": m.key,
                   "value": from_raw(m.value, value_type), "timestamp": m.timestamp, "robot": m.robot,
                   "sender": heard.sender}
            out.write(json.dumps(row) + "\n")
            out.flush()

        node.on_heard.append(emit)
        node.on_tick.append(lambda _node: _warn(firewall))
        with node:
            describe_links(node)
            run_until_stopped(node, duration=duration)
        _warn(firewall)
        print_counters(node)
        return
    from rich.live import Live

    with node, Live(_table(view, value_type, node), refresh_per_second=4, transient=False) as live:
        def refresh() -> None:
            _warn(firewall)  # on a terminal, Live prints stderr above the table
            live.update(_table(view, value_type, node))

        describe_links(node)
        run_until_stopped(node, refresh, duration)
    _warn(firewall)
    print_counters(node)


def _warn(firewall: Guard) -> None:
    for warning in take_warnings(firewall):
        click.echo(warning, err=True)
