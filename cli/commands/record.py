"""`vstig record LINK... [-o FILE|FOLDER]`: capture links' raw units into one file; no frame lost on Ctrl-C,
and no capture lost ever: an existing file is replaced only when asked."""

from __future__ import annotations

import os
import time
from typing import Any

import click

from vstig_hw.capture.clock_notes import clock_note, offset_note
from vstig_hw.capture.decoded import Decoder, RecordFilter, default_framings
from vstig_hw.capture.files import RotatingCapture
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.plan import capture_medium
from vstig_hw.capture.records import (
    APPENDABLE,
    CAN_EXTENSIONS,
    MCAP_EXTENSION,
    Record,
    link_names_lost,
)
from vstig_hw.extras import require
from vstig_hw.gateway import Mode, Node, stop_on_signals
from vstig_hw.links import Link, LinkSpec
from vstig_hw.wording import counted

from ..config import ConfiguredCommand, config_options
from ..ops.metrics import metrics_option, metrics_served
from ..options import Address, ByteSize, Finite, filter_options, overwrite_option, refuse_to_replace
from ..robots import roster_options, start_roster
from ..running import (
    LINK,
    LinkArguments,
    StatusLine,
    build_links,
    describe_links,
    must_hear,
    opened,
    print_counters,
    reports_errors,
    run_until_stopped,
)
from ..swarm_key import swarm_key_option, swarm_keys_for

EARLY_UNITS = 1 << 16  # units heard before the file opened (a file opens in milliseconds: ~7 s of a full CAN bus)

def _target(output: str | None, link: LinkSpec, extension: str) -> str:
    """The file to write: OUTPUT itself, or a new timestamped name (named after the first link) in OUTPUT
    (a folder) or here."""
    if output is not None and not os.path.isdir(output):
        return output
    folder = output or ""
    stem = os.path.join(folder, f"vstig-{link.name}-{time.strftime('%Y-%m-%d_%H%M%S')}")
    path, n = stem + extension, 1
    while os.path.lexists(path):  # two recorders started in the same second
        n += 1
        path = f"{stem}-{n}{extension}"
    return path


def _refuse_to_destroy(path: str, overwrite: bool, append: bool) -> None:
    if overwrite and append:
        raise click.UsageError("give --overwrite or --append, not both")
    refuse_to_replace(path, overwrite or append, ", --append adds to it")  # appending replaces nothing


@click.command(cls=ConfiguredCommand)
@click.argument("links", nargs=-1, required=True, type=LINK, cls=LinkArguments)
@click.option("-o", "--output", type=click.Path(path_type=str),
              help="FILE, or a folder for a timestamped name (the default: one here, as candump -l). "
                   f"CAN by extension: {' '.join(CAN_EXTENSIONS)} (.log is candump's); serial and zenoh: any name "
                   f"(our line formats); any links: {MCAP_EXTENSION} (rosbag2, decoded messages, one topic per link).")
@overwrite_option("FILE")
@click.option("--append", is_flag=True, help=f"Add to FILE if it exists (CAN: {' '.join(APPENDABLE)}; serial).")
@click.option("--max-bytes", type=ByteSize(), help="Rotate to FILE_001.ext, FILE_002.ext... past this size (e.g. 10M); "
                                  "an existing numbered file is skipped, never replaced.")
@click.option("--for", "duration", type=Finite(0.0), help="Stop after this many seconds.")
@roster_options
@metrics_option
@filter_options
@swarm_key_option
@config_options
@reports_errors
def command(links: tuple[LinkSpec, ...], output: str | None, overwrite: bool, append: bool, max_bytes: int | None,
            duration: float | None, no_roster: bool, quiet_after: float | None, gone_after: float | None,
            max_robots: int, metrics: Address | None, keep: Filter, swarm_key: bytes | None) -> None:
    """Record the LINKS' traffic into a file until Ctrl-C (passive: never transmits).

    The links are opened before the file, and an existing capture is never replaced
    unless you say so (--overwrite, --append).

    Each record keeps its link's name, so several links make one capture in time
    order. The filters (--key, --robot, --sender, --op, --link, --since, --until)
    choose what is kept; a serial chunk they cut is re-encoded in its framing.

    Example: vstig record can:socketcan:can0 can:socketcan:can1 -o swarm.log --max-bytes 50M
    """
    for link in links:
        must_hear(link, "record")
    media = {link.capture_medium for link in links}
    first = links[0].capture_medium
    path = _target(output, links[0], MCAP_EXTENSION if len(media) > 1 else ".log" if first == "can" else ".cap")
    try:
        medium = capture_medium(path, [link.capture_medium for link in links])
    except ValueError as error:
        raise click.UsageError(str(error)) from None
    _refuse_to_destroy(path, overwrite, append)
    if medium == "mcap":
        require("mcap", f"vstig record -o {path}")  # before the links open
    built = build_links(links, listen_only=True)
    node = Node(built, mode=Mode.LISTEN, swarm_keys=swarm_keys_for(built, swarm_key))
    start_roster(node, no_roster, quiet_after, gone_after, max_robots)  # who is heard: --metrics
    # Units become messages again for an .mcap file and for filters that look into messages: robot dialects'
    # links name the deployment file that maps their keys.
    deployment = next((spec.deployment for spec in links if spec.deployment), None)
    passing = RecordFilter(keep, Decoder(default_framings(deployment=deployment)))
    captures: list[RotatingCapture] = []  # opened once the links are: a dead link leaves the file alone
    # What the links hear between opening and the file opening (their readers deliver at once) waits here.
    early: list[tuple[Link[Any], float, Any]] = []

    def write(source: Link[Any], t: float, unit: Any) -> None:
        if not captures:
            if len(early) < EARLY_UNITS:
                early.append((source, t, unit))
            else:
                source.counters["drop_before_file"] += 1
            return
        record = Record(t, source.name, source.capture_name, unit)
        for kept in passing.units(record) if keep else (record,):
            captures[0].write(kept)

    # Zenoh links measure their peers' clocks: the capture keeps whose clock it is and the offsets (clock_notes).
    clocks = [clock for link in node.links if (clock := link.clock) is not None]

    def flush(_: Node) -> None:  # every tick: what a kill leaves behind is at most one tick's frames
        if captures:
            for clock in clocks:
                for trip in clock.take():
                    captures[0].note(offset_note(trip))
            captures[0].flush()

    node.listen(unit=write, tick=flush)
    try:
        with stop_on_signals() as stop, metrics_served(node, metrics), opened(node, stop):
            capture = RotatingCapture(path, medium, max_bytes, Decoder(default_framings(deployment=deployment)),
                                      append=append)

            def start_writing() -> None:  # with the Node to itself, no reader writes: the early units go first
                if clocks:
                    capture.note(clock_note(), every_file=True)
                captures.append(capture)
                for unit in early:
                    write(*unit)
                early.clear()

            node.submit(start_writing).result()  # the Node's loop runs it; a Node that closes first raises
            click.echo(f"recording {', '.join(link.name for link in node.links)} to {path}; Ctrl-C stops",
                       err=True)
            if clocks and not capture.takes_notes:
                click.echo(f"{path} keeps no clock notes: to merge captures from several PCs on one clock, record "
                           "the zenoh link into a line capture (.cap) of its own too", err=True)
            if medium == "can" and link_names_lost(path):
                click.echo(f"{path} names no link: decode reads its frames back as one unnamed link", err=True)
            describe_links(node)
            line = StatusLine()
            status = ((lambda: line.show(f"{counted(captures[0].records, 'unit')}  {node.summary()}")) if line.live
                      else None)
            try:
                run_until_stopped(node, stop, status, duration)
            finally:
                line.end()
    finally:
        if captures:
            captures[0].close()  # after the node: its close() handed over every unit already read
    print_counters(node)
    click.echo(f"{counted(captures[0].records, 'unit')} in {', '.join(captures[0].files)}", err=True)
