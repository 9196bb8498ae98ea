"""`vstig decode FILE...`: captures (ours, candump -l, python-can ASC/BLF/CSV) as text, JSON lines or CSV."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator

import click

from vstig_hw.capture.decodefile import FORMATS, decode_file, decode_to_mcap
from vstig_hw.capture.files import MCAP_EXTENSION
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.records import CaptureError
from vstig_hw.values import ValueType

from ._capture_inputs import input_format_option, input_name, readable_capture, renamed
from ._capture_options import echo_skipped, filter_options, parse_id_base, reading_options
from ._files import overwrite_option, refuse_to_replace
from .errors import reports_errors

_BAR_FROM = 1 << 20  # bytes: a smaller file decodes before a bar would be worth drawing


def _to_mcap(files: tuple[str, ...], output: str, skip_bad: bool, base: int | None, extended: bool,
             deployment: str | None, keep: Filter) -> None:
    count, drops, bad = decode_to_mcap(files, output, skip_bad=skip_bad, id_base=base, extended=extended, keep=keep,
                                       deployment=deployment)
    for error in bad[:5]:
        click.echo(f"skipped {error}", err=True)
    summary = f"{output}: {count} messages from {len(files)} files" + (f", {len(bad)} bad lines skipped" if bad else "")
    click.echo(summary + (f", dropped {drops.summary()}" if drops else ""), err=True)


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@input_format_option
@click.option("--format", "fmt", type=click.Choice([*FORMATS, "mcap"]), default="text", show_default=True,
              help="text: one readable line per message; jsonl: one JSON object per line; csv: a header, then rows; "
                   "mcap: a rosbag2 MCAP file (-o), one topic per link, for Foxglove and ros2 bag.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True), help="The file --format mcap writes.")
@overwrite_option("-o FILE")
@reading_options
@filter_options
@reports_errors
def command(files: tuple[str, ...], input_format: str | None, fmt: str, output: str | None, overwrite: bool,
            skip_bad: bool, value_type: ValueType, id_base: str | None, extended: bool, deployment: str | None,
            keep: Filter) -> None:
    """Print every message in FILES (or write them as rosbag2 MCAP); - reads stdin, pipes and <(...) work too.

    The filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    which messages are printed.

    Example: vstig decode swarm.log --format jsonl | jq 'select(.key == 3)'
    """
    base = parse_id_base(id_base)
    if (fmt == "mcap") != (output is not None):
        raise click.UsageError("--format mcap writes to -o FILE.mcap; the other formats print to stdout")
    if output is not None:
        _check_output(output, files, overwrite)
        with contextlib.ExitStack() as spooled:  # stdin and pipes too
            readable = tuple(spooled.enter_context(readable_capture(path, input_format))
                             for path in files)
            _to_mcap(readable, output, skip_bad, base, extended, deployment, keep)
        return
    for number, path in enumerate(files):
        name = input_name(path)
        with readable_capture(path, input_format) as readable, _progress_bar(readable) as progress:
            try:
                count, drops, bad = decode_file(readable, sys.stdout, fmt, value_type=value_type,
                                                skip_bad=skip_bad, id_base=base, extended=extended, keep=keep,
                                                deployment=deployment, progress=progress, csv_header=number == 0,
                                                file_column=len(files) > 1)
            except CaptureError as error:
                raise renamed(error, readable, name) from None
        sys.stdout.flush()
        echo_skipped(renamed(error, readable, name) for error in bad)
        summary = f"{name}: {count} messages" + (f", {len(bad)} bad lines skipped" if bad else "")
        if drops:
            summary += f", dropped {drops.summary()}"
        click.echo(summary, err=True)


def _check_output(output: str, files: tuple[str, ...], overwrite: bool) -> None:
    """Before any reading: -o names an .mcap file, an existing one needs --overwrite, and no input is the output
    (writing would empty it before it was read)."""
    if not output.lower().endswith(MCAP_EXTENSION):
        raise click.UsageError(f"an MCAP capture is named *{MCAP_EXTENSION} (got {output})")
    if os.path.exists(output) and any(path != "-" and os.path.samefile(path, output) for path in files):
        raise click.UsageError(f"{output} is also an input: decode into another file")
    refuse_to_replace(output, overwrite)


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
