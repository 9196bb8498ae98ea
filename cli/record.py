"""`vstig record LINK... -o FILE`: capture links' raw units into one file; no frame lost on Ctrl-C."""

from __future__ import annotations

from typing import Any

import click

from vstig_hw.capture.decoded import Decoder, default_framings
from vstig_hw.capture.files import CAN_EXTENSIONS, MCAP_EXTENSION, RotatingCapture
from vstig_hw.capture.filters import Filter, RecordFilter
from vstig_hw.capture.records import CAN_FRAMING, Record
from vstig_hw.framing.can import CanFraming
from vstig_hw.gateway import Mode, Node
from vstig_hw.links import Link
from vstig_hw.links.spec import CanSpec, LinkSpec, ZenohSpec

from ._capture_options import filter_options
from ._common import build_links, describe_links, print_counters, run_until_stopped
from .errors import LINK, reports_errors


def _size(text: str) -> int:
    units = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30}
    scale = units.get(text[-1:].lower(), 1)
    number = text[:-1] if scale > 1 else text
    if not number.isdigit() or int(number) <= 0:
        raise click.BadParameter(f"{text!r} is not a size like 500000, 64k or 10M")
    return int(number) * scale


def _medium(spec: LinkSpec) -> str:
    """The capture format a link's units go into without .mcap."""
    return "can" if isinstance(spec, CanSpec) else "zenoh" if isinstance(spec, ZenohSpec) else "serial"


@click.command()
@click.argument("links", nargs=-1, required=True, type=LINK)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, writable=True),
              help="CAN: .log (candump) .asc .blf .csv; serial and zenoh: any name (our line formats); any links: "
                   ".mcap (rosbag2, decoded messages, one topic per link).")
@click.option("--max-bytes", help="Rotate to FILE_001.ext, FILE_002.ext... past this size (e.g. 10M).")
@click.option("--for", "duration", type=click.FloatRange(0.0), help="Stop after this many seconds.")
@filter_options
@reports_errors
def command(links: tuple[LinkSpec, ...], output: str, max_bytes: str | None, duration: float | None,
            keep: Filter) -> None:
    """Record the LINKS' traffic into FILE until Ctrl-C (passive: never transmits).

    Each record keeps its link's name, so several links make one capture in time
    order. The filters (--key, --robot, --sender, --op, --link, --since, --until)
    choose what is kept; a serial chunk they cut is re-encoded in its framing.

    Example: vstig record can:socketcan:can0 can:socketcan:can1 -o swarm.log --max-bytes 50M
    """
    media = {_medium(link) for link in links}
    medium = "mcap" if output.lower().endswith(MCAP_EXTENSION) else media.pop()
    if medium != "mcap" and media:
        raise click.UsageError(f"links of different media (CAN, serial, zenoh) go into a {MCAP_EXTENSION} capture "
                               "together (a CAN log holds CAN frames, a serial capture UART bytes, a zenoh capture "
                               "samples)")
    if medium == "can" and not output.lower().endswith(CAN_EXTENSIONS):
        raise click.UsageError(f"a CAN capture is chosen by extension: {', '.join(CAN_EXTENSIONS)} or "
                               f"{MCAP_EXTENSION} (got {output})")
    limit = _size(max_bytes) if max_bytes else None
    node = Node(build_links(links, listen_only=True), mode=Mode.LISTEN)
    # Units become messages again for an .mcap file and for filters that look into messages: robot dialects'
    # links name the deployment file that maps their keys.
    deployment = next((d for spec in links if (d := getattr(spec, "deployment", None))), None)
    capture = RotatingCapture(output, medium, limit, Decoder(default_framings(deployment=deployment)))
    passing = RecordFilter(keep, Decoder(default_framings(deployment=deployment)))

    def write(source: Link[Any], t: float, unit: Any) -> None:
        framing = CAN_FRAMING if isinstance(source.framing, CanFraming) else source.framing.name
        record = Record(t, source.name, framing, unit)
        for kept in passing.units(record) if keep else (record,):
            capture.write(kept)

    node.on_unit.append(write)
    node.on_tick.append(lambda _: capture.flush())
    try:
        with node:
            click.echo(f"recording {', '.join(link.name for link in node.links)} to {output}; Ctrl-C stops",
                       err=True)
            describe_links(node)
            run_until_stopped(node, duration=duration)
    finally:
        capture.close()  # after the node: its close() handed over every unit already read
    print_counters(node)
    click.echo(f"{capture.records} units in {', '.join(capture.files)}", err=True)
