"""The capture files a command reads: a named file by its extension, anything else (-, a pipe, <(...), a
name that does not tell) by its first bytes. decode and analyze open their inputs this one way."""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from typing import Any

import click

from vstig_hw.capture.records import READABLE_EXTENSIONS, CaptureError, line_capture_at, sniff_suffix

__all__ = ["INPUT_FORMATS", "input_format_option", "input_name", "readable_capture", "renamed"]

INPUT_FORMATS = [*(suffix[1:] for suffix in READABLE_EXTENSIONS), "cap"]  # cap: our serial capture
_SNIFF_BYTES = 1 << 16


def input_format_option(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--input-format: the capture type, for a name that does not show it."""
    return click.option("--input-format", type=click.Choice(INPUT_FORMATS),
                        help="The capture type, for a name that does not show it (default: by extension, and for - "
                             "or a pipe by content).")(fn)


def input_name(path: str) -> str:
    """How messages name an input: stdin as <stdin>, anything else as typed."""
    return "<stdin>" if path == "-" else path


def renamed(error: CaptureError, read: str, name: str) -> CaptureError:
    """`error` about the file actually read (`read`, maybe a spooled copy) naming the input the user typed."""
    return error if read == name else CaptureError(name, error.line, error.problem)


@contextlib.contextmanager
def readable_capture(path: str, input_format: str | None) -> Iterator[str]:
    """A regular file to read `path` from whose name shows its type; a stream (-, a pipe) is copied first."""
    regular = path != "-" and os.path.isfile(path)
    if regular and input_format is None and (path.lower().endswith(READABLE_EXTENSIONS) or line_capture_at(path)):
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="vstig-capture-") as folder:
        spooled = os.path.join(folder, "input")
        if regular:  # a file whose name does not tell (/dev/stdin redirected from a file): look inside
            os.symlink(os.path.abspath(path), spooled)
            with open(path, "rb") as file:
                head = file.read(_SNIFF_BYTES)
        else:
            with contextlib.ExitStack() as stack:
                source = sys.stdin.buffer if path == "-" else stack.enter_context(open(path, "rb"))
                with open(spooled, "wb") as copy:
                    head = source.read(_SNIFF_BYTES)
                    copy.write(head)
                    shutil.copyfileobj(source, copy, 1 << 20)
        suffix = f".{input_format}" if input_format else sniff_suffix(head)
        if suffix is None:
            raise click.UsageError(f"{input_name(path)}: cannot tell the capture type from its first bytes: give "
                                   f"--input-format ({', '.join(INPUT_FORMATS)})")
        os.rename(spooled, spooled + suffix)
        yield spooled + suffix
