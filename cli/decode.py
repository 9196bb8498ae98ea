"""`vstig decode FILE...`: captures (ours, candump -l, python-can ASC/BLF/CSV) as text, JSON lines or CSV."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator

import click

from vstig_hw.capture.decodefile import FORMATS, decode_file
from vstig_hw.values import VALUE_TYPES, ValueType

from .errors import reports_errors

_BAR_FROM = 1 << 20  # bytes: a smaller file decodes before a bar would be worth drawing


def _base(text: str | None) -> int | None:
    if text is None:
        return None
    try:
        return int(text, 0)
    except ValueError:
        raise click.BadParameter(f"{text!r} is not an integer (e.g. 0x600)", param_hint="--id-base") from None


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(list(FORMATS)), default="text", show_default=True)
@click.option("--skip-bad", is_flag=True, help="Count malformed lines and go on instead of stopping at the first.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True)
@click.option("--id-base", help="CAN ID base of the stigmergy (default 0x600, or 0x18000000 with --extended).")
@click.option("--extended", is_flag=True, help="The CAN capture uses 29-bit IDs.")
@reports_errors
def command(files: tuple[str, ...], fmt: str, skip_bad: bool, value_type: ValueType, id_base: str | None,
            extended: bool) -> None:
    """Print every message in FILES.

    Example: vstig decode swarm.log --format jsonl | jq 'select(.key == 3)'
    """
    base = _base(id_base)
    total_bad = 0
    for number, path in enumerate(files):
        with _progress_bar(path) as progress:
            count, drops, bad = decode_file(path, sys.stdout, fmt, value_type=value_type, skip_bad=skip_bad,
                                            id_base=base, extended=extended, progress=progress,
                                            csv_header=number == 0, file_column=len(files) > 1)
        sys.stdout.flush()
        total_bad += len(bad)
        for error in bad[:5]:
            click.echo(f"skipped {error}", err=True)
        summary = f"{path}: {count} messages" + (f", {len(bad)} bad lines skipped" if bad else "")
        if drops:
            summary += f", dropped {drops.summary()}"
        click.echo(summary, err=True)


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
