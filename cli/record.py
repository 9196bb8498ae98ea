"""`vstig record LINK [-o FILE|FOLDER]`: capture a link's raw units; no frame lost on Ctrl-C, no file lost ever."""

from __future__ import annotations

import os
import time
from typing import Any

import click

from vstig_hw.capture.files import APPENDABLE, CAN_EXTENSIONS, RotatingCapture
from vstig_hw.capture.records import CAN_FRAMING, Record
from vstig_hw.gateway import Mode, Node
from vstig_hw.links import Link
from vstig_hw.links.spec import CanSpec, LinkSpec

from ._common import StatusLine, build_links, must_hear, print_counters, run_until_stopped
from .errors import LINK, reports_errors


def _size(text: str) -> int:
    units = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30}
    scale = units.get(text[-1:].lower(), 1)
    number = text[:-1] if scale > 1 else text
    if not number.isdigit() or int(number) <= 0:
        raise click.BadParameter(f"{text!r} is not a size like 500000, 64k or 10M")
    return int(number) * scale


def _target(output: str | None, link: LinkSpec, is_can: bool) -> str:
    """The file to write: OUTPUT itself, or a new timestamped name in OUTPUT (a folder) or here."""
    if output is not None and not os.path.isdir(output):
        if is_can and not output.lower().endswith(CAN_EXTENSIONS):
            raise click.UsageError(f"a CAN capture is chosen by extension: {', '.join(CAN_EXTENSIONS)} "
                                   f"(got {output})")
        return output
    folder = output or ""
    stem = os.path.join(folder, f"vstig-{link.name}-{time.strftime('%Y-%m-%d_%H%M%S')}")
    extension = ".log" if is_can else ".cap"
    path, n = stem + extension, 1
    while os.path.lexists(path):  # two recorders started in the same second
        n += 1
        path = f"{stem}-{n}{extension}"
    return path


def _refuse_to_destroy(path: str, overwrite: bool, append: bool) -> None:
    if overwrite and append:
        raise click.UsageError("give --overwrite or --append, not both")
    if os.path.isfile(path) and os.path.getsize(path) > 0 and not (overwrite or append):
        raise click.UsageError(f"{path} exists: --overwrite replaces it, --append adds to it")


@click.command()
@click.argument("link", type=LINK)
@click.option("-o", "--output", type=click.Path(path_type=str),
              help="FILE, or a folder for a timestamped name (the default: one here, as candump -l). "
                   f"CAN by extension: {' '.join(CAN_EXTENSIONS)} (.log is candump's); serial: any name "
                   "(our line format).")
@click.option("--overwrite", is_flag=True, help="Replace FILE if it exists (never done without this).")
@click.option("--append", is_flag=True, help=f"Add to FILE if it exists (CAN: {' '.join(APPENDABLE)}; serial).")
@click.option("--max-bytes", help="Rotate to FILE_001.ext, FILE_002.ext... past this size (e.g. 10M); "
                                  "an existing numbered file is skipped, never replaced.")
@click.option("--for", "duration", type=click.FloatRange(0.0), help="Stop after this many seconds.")
@reports_errors
def command(link: LinkSpec, output: str | None, overwrite: bool, append: bool, max_bytes: str | None,
            duration: float | None) -> None:
    """Record LINK's traffic to a file until Ctrl-C (passive: never transmits).

    The link is opened before the file, and an existing capture is never replaced
    unless you say so (--overwrite, --append).

    Example: vstig record can:socketcan:can0 -o swarm.log --max-bytes 50M
    """
    must_hear(link, "record")
    is_can = isinstance(link, CanSpec)
    limit = _size(max_bytes) if max_bytes else None
    path = _target(output, link, is_can)
    _refuse_to_destroy(path, overwrite, append)
    node = Node(build_links([link], listen_only=True), mode=Mode.LISTEN)
    captures: list[RotatingCapture] = []  # opened once the link is: a dead link leaves the file alone

    def write(source: Link[Any], t: float, unit: Any) -> None:
        if captures:  # units handed over while a failed file open closes the node have nowhere to go
            framing = CAN_FRAMING if is_can else source.framing.name
            captures[0].write(Record(t, source.name, framing, unit))

    node.on_unit.append(write)
    node.on_tick.append(lambda _: captures and captures[0].flush())
    try:
        with node:
            captures.append(RotatingCapture(path, "can" if is_can else "serial", limit, append=append))
            click.echo(f"recording {node.links[0].name} to {path}; Ctrl-C stops", err=True)
            line = StatusLine()
            status = (lambda: line.show(f"{captures[0].records} units  {node.summary()}")) if line.live else None
            try:
                run_until_stopped(node, status, duration)
            finally:
                line.end()
    finally:
        if captures:
            captures[0].close()  # after the node: its close() handed over every unit already read
    print_counters(node)
    click.echo(f"{captures[0].records} units in {', '.join(captures[0].files)}", err=True)
