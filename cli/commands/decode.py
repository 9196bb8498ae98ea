"""`vstig decode FILE...`: captures (ours, candump -l, python-can ASC/BLF/CSV) as text, JSON lines or CSV, or
converted (-o FILE) into any format `record` writes."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator

import click

from vstig_hw.capture.decoded import FORMATS, decode_file
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.records import CAN_EXTENSIONS, MCAP_EXTENSION, CaptureError, Damage, link_names_lost
from vstig_hw.capture.time_columns import TIME_STYLES, TimeColumn
from vstig_hw.extras import require
from vstig_hw.values import ValueType
from vstig_hw.wording import counted

from ..options import (
    echo_skipped,
    filter_options,
    input_format_option,
    input_name,
    overwrite_option,
    parse_id_base,
    readable_capture,
    reading_options,
    refuse_link,
    refuse_to_replace,
    renamed,
)
from ..running import reports_errors

_BAR_FROM = 1 << 20  # bytes: a smaller file decodes before a bar would be worth drawing


def _convert(files: dict[str, str], output: str, damage: Damage, base: int | None, extended: bool,
             deployment: str | None, keep: Filter) -> None:
    """Convert `files` (the file read -> the name the user gave) into `output`; errors name the user's files."""

    from vstig_hw.capture.convert import convert  # only -o converts: decode's printing path never loads it

    def named(error: CaptureError) -> CaptureError:
        return renamed(error, error.path, files.get(error.path, error.path))

    try:
        count, drops = convert(tuple(files), output, damage=damage, id_base=base, extended=extended, keep=keep,
                               deployment=deployment)
    except CaptureError as error:
        raise named(error) from None
    echo_skipped(map(named, damage.first))
    summary = (f"{output}: {counted(count, 'record')} from {counted(len(files), 'file')}"
               + (f", {counted(damage.count, 'bad line')} skipped" if damage.count else ""))
    click.echo(summary + (f", dropped {drops.summary()}" if drops else ""), err=True)
    if link_names_lost(output):
        click.echo(f"{output} names no link: decode reads its frames back as one unnamed link", err=True)


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@input_format_option
@click.option("--format", "fmt", type=click.Choice([*FORMATS, "mcap"]), default="text", show_default=True,
              help="text: one readable line per message; jsonl: one JSON object per line; csv: a header, then rows; "
                   "mcap: a rosbag2 MCAP file (-o), one topic per link, for Foxglove and ros2 bag.")
@click.option("-t", "--time", "time_style", type=click.Choice(TIME_STYLES),
              help="The text lines' time, as candump -t: a absolute (the default), A local date and time, "
                   "d since the line before, z since the first line.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True),
              help="Convert into this file instead, in the format its extension names, as record writes it: "
                   f"CAN {' '.join(CAN_EXTENSIONS)}; {MCAP_EXTENSION} (decoded messages of any links); "
                   "any other name: our serial or zenoh capture.")
@overwrite_option("-o FILE")
@reading_options
@filter_options
@reports_errors
def command(files: tuple[str, ...], input_format: str | None, fmt: str, time_style: str | None, output: str | None,
            overwrite: bool, damage: Damage, value_type: ValueType, id_base: str | None, extended: bool,
            deployment: str | None, keep: Filter) -> None:
    """Print every message in FILES, or convert them (-o FILE) into any format record
    writes; - reads stdin, pipes and <(...) work too.

    The filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    which messages are printed or converted. A conversion merges FILES by time and
    keeps each record's time and link name.

    \b
    Examples:
      vstig decode swarm.log --format jsonl | jq 'select(.key == 3)'
      vstig decode swarm.log -o swarm.blf
    """
    base = parse_id_base(id_base)
    _check_choices(fmt, time_style, output)
    if output is not None:
        _check_output(output, files, fmt, overwrite)
        with contextlib.ExitStack() as spooled:  # stdin and pipes too
            inputs = {spooled.enter_context(readable_capture(path, input_format)): input_name(path)
                      for path in files}
            _convert(inputs, output, damage, base, extended, deployment, keep)
        return
    clock = TimeColumn(time_style) if time_style else None
    for number, path in enumerate(files):
        name = input_name(path)
        skipped = damage.fresh()  # each file's summary counts its own
        with readable_capture(path, input_format) as readable, _progress_bar(readable) as progress:
            try:
                count, drops = decode_file(readable, sys.stdout, fmt, value_type=value_type, damage=skipped,
                                           id_base=base, extended=extended, keep=keep, deployment=deployment,
                                           progress=progress, csv_header=number == 0, file_column=len(files) > 1,
                                           clock=clock)
            except CaptureError as error:
                raise renamed(error, readable, name) from None
        sys.stdout.flush()
        echo_skipped(renamed(error, readable, name) for error in skipped.first)
        summary = f"{name}: {counted(count, 'message')}" + (
            f", {counted(skipped.count, 'bad line')} skipped" if skipped.count else "")
        if drops:
            summary += f", dropped {drops.summary()}"
        click.echo(summary, err=True)


def _check_choices(fmt: str, time_style: str | None, output: str | None) -> None:
    """--format and --time print; -o writes a capture in its own format, times as they were."""
    if fmt == "mcap" and output is None:
        raise click.UsageError("--format mcap writes to -o FILE.mcap; the other formats print to stdout")
    if output is not None and fmt in ("jsonl", "csv"):
        raise click.UsageError(f"-o writes the format its extension names; --format {fmt} prints to stdout")
    if time_style is not None and (output is not None or fmt != "text"):
        raise click.UsageError("--time styles the text lines' time column; -o, jsonl and csv keep absolute times")


def _check_output(output: str, files: tuple[str, ...], fmt: str, overwrite: bool) -> None:
    """Before any reading: -o has a name we can write (--format mcap: an .mcap one), an existing one needs
    --overwrite, and no input is the output (writing would empty it before it was read)."""
    refuse_link(output)  # first: a link to an input is refused as a link
    if fmt == "mcap" and not output.lower().endswith(MCAP_EXTENSION):
        raise click.UsageError(f"an MCAP capture is named *{MCAP_EXTENSION} (got {output})")
    if os.path.exists(output) and any(path != "-" and os.path.samefile(path, output) for path in files):
        raise click.UsageError(f"{output} is also an input: decode into another file")
    refuse_to_replace(output, overwrite)
    if output.lower().endswith(MCAP_EXTENSION):
        require("mcap", f"vstig decode -o {output}")


@contextlib.contextmanager
def _progress_bar(path: str) -> Iterator[Callable[[int], None] | None]:
    """A bar on stderr for a big file, only when stderr is a terminal and stdout is not the same screen."""
    size = os.path.getsize(path)
    if size < _BAR_FROM or not _isatty(sys.stderr) or _isatty(sys.stdout):
        yield None
        return
    from rich.console import Console
    from rich.progress import Progress

    # Never let rich take over sys.stdout: the decoded lines must reach it untouched.
    with Progress(console=Console(stderr=True), transient=True, redirect_stdout=False,
                  redirect_stderr=False) as bar:
        task = bar.add_task(f"decoding {os.path.basename(path)}", total=size)
        yield lambda done: bar.update(task, completed=done)


def _isatty(stream: object) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except (OSError, ValueError):
        return False
