"""`vstig decode FILE...`: captures (ours, candump -l, python-can ASC/BLF/CSV) as text, JSON lines or CSV."""

from __future__ import annotations

import os
import sys

import click

from vstig_hw.capture.decodefile import FORMATS, decode_file, decode_to_mcap
from vstig_hw.capture.files import MCAP_EXTENSION
from vstig_hw.capture.filters import Filter
from vstig_hw.values import VALUE_TYPES, ValueType

from ._capture_options import filter_options, parse_id_base
from .errors import reports_errors


def _to_mcap(files: tuple[str, ...], output: str, skip_bad: bool, base: int | None, extended: bool,
             deployment: str | None, keep: Filter) -> None:
    if not output.lower().endswith(MCAP_EXTENSION):
        raise click.UsageError(f"an MCAP capture is named *{MCAP_EXTENSION} (got {output})")
    count, drops, bad = decode_to_mcap(files, output, skip_bad=skip_bad, id_base=base, extended=extended, keep=keep,
                                       deployment=deployment)
    for error in bad[:5]:
        click.echo(f"skipped {error}", err=True)
    summary = f"{output}: {count} messages from {len(files)} files" + (f", {len(bad)} bad lines skipped" if bad else "")
    click.echo(summary + (f", dropped {drops.summary()}" if drops else ""), err=True)


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--format", "fmt", type=click.Choice([*FORMATS, "mcap"]), default="text", show_default=True,
              help="mcap: a rosbag2 MCAP file (-o), one topic per link, for Foxglove and ros2 bag.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True), help="The file --format mcap writes.")
@click.option("--skip-bad", is_flag=True, help="Count malformed lines and go on instead of stopping at the first.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@click.option("--id-base", help="CAN ID base of the stigmergy (default 0x600, or 0x18000000 with --extended).")
@click.option("--extended", is_flag=True, help="The CAN capture uses 29-bit IDs.")
@click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
              help="For Buzz/BittyBuzz captures (blabbermouth, bittybuzz-kilobot): the TOML file mapping their keys.")
@filter_options
@reports_errors
def command(files: tuple[str, ...], fmt: str, output: str | None, skip_bad: bool, value_type: ValueType,
            id_base: str | None, extended: bool, deployment: str | None, keep: Filter) -> None:
    """Print every message in FILES (or write them as rosbag2 MCAP).

    The filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    which messages are printed.

    Example: vstig decode swarm.log --format jsonl | jq 'select(.key == 3)'
    """
    base = parse_id_base(id_base)
    if (fmt == "mcap") != (output is not None):
        raise click.UsageError("--format mcap writes to -o FILE.mcap; the other formats print to stdout")
    if output is not None:
        _to_mcap(files, output, skip_bad, base, extended, deployment, keep)
        return
    total_bad = 0
    for path in files:
        size = os.path.getsize(path)
        if sys.stderr.isatty() and size > 1 << 20:
            from rich.progress import Progress

            with Progress(transient=True) as bar:
                task = bar.add_task(f"decoding {os.path.basename(path)}", total=size)
                count, drops, bad = decode_file(path, sys.stdout, fmt, value_type=value_type, skip_bad=skip_bad,
                                                id_base=base, extended=extended, keep=keep,
                                                deployment=deployment,
                                                progress=lambda n, t=task: bar.advance(t, n))  # type: ignore[misc]
        else:
            count, drops, bad = decode_file(path, sys.stdout, fmt, value_type=value_type, skip_bad=skip_bad,
                                            id_base=base, extended=extended, keep=keep,
                                            deployment=deployment)
        sys.stdout.flush()
        total_bad += len(bad)
        for error in bad[:5]:
            click.echo(f"skipped {error}", err=True)
        summary = f"{path}: {count} messages" + (f", {len(bad)} bad lines skipped" if bad else "")
        if drops:
            summary += f", dropped {drops.summary()}"
        click.echo(summary, err=True)
