"""`vstig get KEY --on LINK [--wait S]`: ask the swarm for a key's value."""

from __future__ import annotations

import click

from vstig_hw.gateway import Node
from vstig_hw.links.spec import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw
from vstig_hw.wire import KEY_MAX

from ._common import build_links
from .errors import LINK, reports_errors


@click.command()
@click.argument("key", type=click.IntRange(0, KEY_MAX))
@click.option("--on", "link", type=LINK, required=True, help="The link to ask through.")
@click.option("--wait", type=click.FloatRange(0.0, 3600.0), default=2.0, show_default=True,
              help="Seconds to wait for a neighbour's answer.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=254, show_default=True)
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@reports_errors
def command(key: int, link: LinkSpec, wait: float, robot_id: int, value_type: ValueType) -> None:
    """Print the value the swarm holds for KEY once a neighbour answers (exit 1 if none does).

    Example: vstig get 3 --on serial:/dev/ttyUSB0?framing=epuck4 --wait 5
    """
    node = Node(build_links([link], robot_id), robot_id)
    engine = node.engine
    assert engine is not None

    def ask_again(_: Node) -> None:  # one GET per control step, as a robot's program would
        if not engine.has(key):
            node.get(key)

    node.on_tick.append(ask_again)
    with node:
        node.get(key)
        node.run(until=lambda: engine.has(key), duration=wait)
    entry = engine.entry(key)
    if entry is None:
        raise click.ClickException(f"no neighbour on {node.links[0].name} answered for key {key} within {wait:g} s")
    click.echo(f"key={key} value={from_raw(entry.value, value_type)} timestamp={entry.timestamp} robot={entry.robot}")
