"""`vstig put KEY VALUE --on LINK`: write one value into the swarm, and exit 0 only once a neighbour took it."""

from __future__ import annotations

import time

import click

from vstig_hw.engine import Entry
from vstig_hw.gateway import Node
from vstig_hw.gateway.oneshot import HearsItself, not_taken, put_confirmed, unreached
from vstig_hw.links import LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw, to_raw

from ..options import KEY, Finite, NegativeNumbersAreArguments
from ..running import LINK, build_links, reports_errors
from ..swarm_key import swarm_key_option, swarm_keys_for


def shown(entry: Entry, value_type: ValueType) -> str:
    return f"value={from_raw(entry.value, value_type)} timestamp={entry.timestamp} robot={entry.robot}"


@click.command(cls=NegativeNumbersAreArguments)
@click.argument("key", type=KEY)
@click.argument("value")
@click.option("--on", "link", type=LINK, required=True, help="The link to put through.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=254, show_default=True)
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@click.option("--learn", type=Finite(0.0, 60.0), default=0.5, show_default=True,
              help="Seconds to ask the swarm for the key first (every control step), so the write is newer.")
@click.option("--wait", type=Finite(0.0, 3600.0), default=2.0, show_default=True,
              help="Seconds each write waits for a neighbour to show it took the write.")
@click.option("--tries", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Writes at most, when the swarm answers with a newer or conflicting entry.")
@click.option("--no-confirm", is_flag=True,
              help="Write and exit 0 without a neighbour's answer (radios that cannot answer, e.g. kilobot-ohc).")
@swarm_key_option
@reports_errors
def command(key: int, value: str, link: LinkSpec, robot_id: int, value_type: ValueType, learn: float,
            wait: float, tries: int, no_confirm: bool, swarm_key: bytes | None) -> None:
    """Put VALUE under KEY, as a robot would; exit 0 only when a neighbour shows it took the write.

    It asks the swarm for KEY every control step for --learn seconds and writes
    with a timestamp newer than anything heard. A neighbour shows the write was
    taken by re-broadcasting it, by an answer or a GET carrying it, or by writing
    the key on top of it (the next timestamp). If the swarm answers with a newer
    or conflicting entry first, it writes again (--tries in all); if no neighbour
    shows the write within --wait, it exits 1 saying what the swarm holds instead.
    A radio that echoes what we send cannot confirm anything: exit 1 saying so.
    KEY and VALUE take decimal or 0x hex; negative values need no --.

    Example: vstig put 3 1500 --on can:socketcan:can0 --robot-id 200
    """
    try:
        raw = to_raw(value, value_type)
    except ValueError as error:
        raise click.BadParameter(str(error), param_hint="VALUE") from None
    started = time.monotonic()  # --learn and --wait bound the whole command: opening the link is part of them
    built = build_links([link.lossless(opening=learn + wait)], robot_id)
    node = Node(built, robot_id, swarm_keys=swarm_keys_for(built, swarm_key))
    name = node.links[0].name
    transmit_only = node.links[0].transmit_only
    if transmit_only and not no_confirm:
        raise click.BadParameter(f"{name} only transmits: no neighbour can answer, so nothing can confirm "
                                 "the write (add --no-confirm to write anyway)", param_hint="'--on'")
    with node:
        try:
            result = put_confirmed(node, key, raw, learn=0.0 if transmit_only else learn, wait=wait, tries=tries,
                                   confirm=not no_confirm, spent=time.monotonic() - started)
        except HearsItself as error:
            raise click.ClickException(f"{error.reason} (--no-confirm writes anyway)") from None
        why = unreached(node.links)  # while the link is open: it names where it dials and found nobody
    problem = not_taken(result, key, name, wait, lambda entry: shown(entry, value_type), confirm=not no_confirm)
    if problem is not None:
        raise click.ClickException(problem + why)
    click.echo(f"put key={key} {shown(result.written, value_type)} on {name}"
               + (" (not confirmed: --no-confirm)" if no_confirm else ""))
    if result.shown is not None and result.shown != result.written:  # taken: a robot wrote on top of it
        click.echo(f"note: robot {result.shown.robot} wrote on top of it: {shown(result.shown, value_type)}",
                   err=True)
