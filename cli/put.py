"""`vstig put KEY VALUE --on LINK`: write one value into the swarm and leave."""

from __future__ import annotations

import time

import click

from vstig_hw.gateway import Node
from vstig_hw.links.spec import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, to_raw
from vstig_hw.wire import KEY_MAX

from ._common import build_links
from .errors import LINK, reports_errors


@click.command()
@click.argument("key", type=click.IntRange(0, KEY_MAX))
@click.argument("value")
@click.option("--on", "link", type=LINK, required=True, help="The link to put through.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=254, show_default=True)
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@click.option("--learn", type=click.FloatRange(0.0, 60.0), default=0.5, show_default=True,
              help="Seconds to ask the swarm for the key's current timestamp first, so the write is newer.")
@reports_errors
def command(key: int, value: str, link: LinkSpec, robot_id: int, value_type: ValueType, learn: float) -> None:
    """Put VALUE under KEY, as a robot would.

    Example: vstig put 3 1500 --on can:socketcan:can0 --robot-id 200
    """
    try:
        raw = to_raw(value, value_type)
    except ValueError as error:
        raise click.BadParameter(str(error), param_hint="VALUE") from None
    node = Node(build_links([link], robot_id), robot_id)
    engine = node.engine
    assert engine is not None
    with node:
        if learn:
            node.get(key)
            node.run(until=lambda: engine.has(key), duration=learn)
        node.put(key, raw)
        node.run(until=lambda: all(not len(o) for o in node.outlets), duration=5.0)
        time.sleep(0.05)  # let the device's own buffer drain before the port closes
    entry = engine.entry(key)
    assert entry is not None
    click.echo(f"put key={key} value={value} timestamp={entry.timestamp} robot={robot_id} on {node.links[0].name}")
