"""`vstig sniff LINK`: watch the swarm's traffic, decoded; never transmits."""

from __future__ import annotations

import sys
import time
from typing import Any

import click

from vstig_hw.engine import larger_value_wins
from vstig_hw.framing.can import CanFraming
from vstig_hw.gateway import Mode, Node
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard
from vstig_hw.links.spec import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw

from ._common import VALUE_TYPE_HELP, build_links, must_hear, print_counters, run_until_stopped
from .errors import LINK, reports_errors


def _table(view: SwarmView, value_type: ValueType) -> Any:
    from rich.table import Table

    table = Table(title=f"vstig sniff: {view.messages} messages")
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
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
              help=VALUE_TYPE_HELP)
@click.option("--larger-value-wins", "larger", is_flag=True,
              help="Settle conflicts as a swarm running the paper's Figure 1 rule does (larger value), "
                   "instead of the default higher robot id.")
@click.option("--for", "duration", type=click.FloatRange(0.0), help="Stop after this many seconds.")
@reports_errors
def command(link: LinkSpec, jsonl: bool, value_type: ValueType, larger: bool, duration: float | None) -> None:
    """Decode LINK's traffic live, per key; passive: never transmits.

    Example: vstig sniff can:socketcan:can0 --jsonl | jq .
    """
    must_hear(link, "sniff")
    node = Node(build_links([link], listen_only=True), mode=Mode.LISTEN)
    view = SwarmView(larger_value_wins) if larger else SwarmView()
    node.on_heard.append(view.add)
    if jsonl:
        import json

        out = sys.stdout

        # The same row as `decode --format jsonl`: can_id on CAN links only, sender where the medium names one.
        can_schemes = {link.name: link.framing.scheme for link in node.links if isinstance(link.framing, CanFraming)}

        def emit(heard: Heard) -> None:
            m = heard.message
            row: dict[str, Any] = {"t": round(heard.t, 6), "link": heard.link}
            scheme = can_schemes.get(heard.link)
            if scheme is not None and heard.sender is not None:
                row["can_id"] = scheme.can_id(m.op, heard.sender)
            row.update(op=m.op.name, key=m.key, value=from_raw(m.value, value_type), timestamp=m.timestamp,
                       robot=m.robot, sender=heard.sender)
            out.write(json.dumps(row) + "\n")
            out.flush()

        node.on_heard.append(emit)
        with node:
            run_until_stopped(node, duration=duration)
        print_counters(node)
        return
    from rich.live import Live

    if not sys.stdout.isatty():
        click.echo("stdout is not a terminal: the table is printed once, when sniff ends "
                   "(--jsonl streams every message instead)", err=True)

    with node, Live(_table(view, value_type), refresh_per_second=4, transient=False) as live:
        run_until_stopped(node, lambda: live.update(_table(view, value_type)), duration)
    print_counters(node)
