"""`vstig get KEY --on LINK [--wait S]`: ask the swarm for a key's value."""

from __future__ import annotations

import time

import click

from vstig_hw.gateway import Node
from vstig_hw.gateway.oneshot import get_newest, unreached
from vstig_hw.links import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType

from ..options import KEY, Finite
from ..running import LINK, build_links, reports_errors
from ..swarm_key import swarm_key_option, swarm_keys_for
from .put import shown


@click.command()
@click.argument("key", type=KEY)
@click.option("--on", "link", type=LINK, required=True, help="The link to ask through.")
@click.option("--wait", type=Finite(0.0, 3600.0), default=2.0, show_default=True,
              help="Seconds to ask and listen; the newest entry heard in that time is printed.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=254, show_default=True)
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@swarm_key_option
@reports_errors
def command(key: int, link: LinkSpec, wait: float, robot_id: int, value_type: ValueType,
            swarm_key: bytes | None) -> None:
    """Print the newest value neighbours hold for KEY, heard within --wait (exit 1 if none answers).

    It asks every control step for the whole --wait, so a newer entry that
    arrives after the first answer is the one printed. KEY takes decimal or 0x hex.

    Example: vstig get 3 --on serial:/dev/ttyUSB0?framing=epuck4 --wait 5
    """
    started = time.monotonic()  # --wait bounds the whole command: opening the link is part of it
    built = build_links([link.lossless(opening=wait)], robot_id)
    node = Node(built, robot_id, swarm_keys=swarm_keys_for(built, swarm_key))
    name = node.links[0].name
    if node.links[0].transmit_only:
        raise click.BadParameter(f"{name} only transmits: no neighbour can answer", param_hint="'--on'")
    with node:
        entry = get_newest(node, key, max(0.0, wait - (time.monotonic() - started)))
        why = unreached(node.links)  # while the link is open: it names where it dials and found nobody
    if entry is None:
        raise click.ClickException(f"no neighbour on {name} answered for key {key} within {wait:g} s{why}")
    click.echo(f"key={key} {shown(entry, value_type)}")
