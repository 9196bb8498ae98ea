"""`vstig record LINK -o FILE`: capture a link's raw units; no frame lost on Ctrl-C."""

from __future__ import annotations

from typing import Any

import click

from vstig_hw.capture.files import CAN_EXTENSIONS, RotatingCapture
from vstig_hw.capture.records import CAN_FRAMING, Record
from vstig_hw.gateway import Mode, Node
from vstig_hw.links import Link
from vstig_hw.links.spec import CanSpec, LinkSpec

from ._common import build_links, print_counters, run_until_stopped
from .errors import LINK, reports_errors


def _size(text: str) -> int:
    units = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30}
    scale = units.get(text[-1:].lower(), 1)
    number = text[:-1] if scale > 1 else text
    if not number.isdigit() or int(number) <= 0:
        raise click.BadParameter(f"{text!r} is not a size like 500000, 64k or 10M")
    return int(number) * scale


@click.command()
@click.argument("link", type=LINK)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, writable=True),
              help="CAN: .log (candump) .asc .blf .csv; serial: any name (our line format).")
@click.option("--max-bytes", help="Rotate to FILE_001.ext, FILE_002.ext... past this size (e.g. 10M).")
@click.option("--for", "duration", type=click.FloatRange(0.0), help="Stop after this many seconds.")
@reports_errors
def command(link: LinkSpec, output: str, max_bytes: str | None, duration: float | None) -> None:
    """Record LINK's traffic to FILE until Ctrl-C (passive: never transmits).

    Example: vstig record can:socketcan:can0 -o swarm.log --max-bytes 50M
    """
    is_can = isinstance(link, CanSpec)
    if is_can and not output.lower().endswith(CAN_EXTENSIONS):
        raise click.UsageError(f"a CAN capture is chosen by extension: {', '.join(CAN_EXTENSIONS)} (got {output})")
    limit = _size(max_bytes) if max_bytes else None
    node = Node(build_links([link], listen_only=True), mode=Mode.LISTEN)
    capture = RotatingCapture(output, "can" if is_can else "serial", limit)

    def write(source: Link[Any], t: float, unit: Any) -> None:
        framing = CAN_FRAMING if is_can else source.framing.name
        capture.write(Record(t, source.name, framing, unit))

    node.on_unit.append(write)
    node.on_tick.append(lambda _: capture.flush())
    try:
        with node:
            click.echo(f"recording {node.links[0].name} to {output}; Ctrl-C stops", err=True)
            run_until_stopped(node, duration=duration)
    finally:
        capture.close()  # after the node: its close() handed over every unit already read
    print_counters(node)
    click.echo(f"{capture.records} units in {', '.join(capture.files)}", err=True)
