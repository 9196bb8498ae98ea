"""stdout and stderr that fail the way a command-line tool should.

Python buffers the standard streams, so a failed write often surfaces far from
the code that wrote: in `print`, in click's help, or in the interpreter's last
flush, as a traceback or "Exception ignored". `guard()` rebuilds both streams
over a raw file that turns a failure into one of two click exceptions, which
every layer (commands, `reports_errors`, click) passes through unchanged:

- the reader went away (EPIPE, as in `vstig decode x.log | head -1`): `PipeClosed`,
  exit 0 quietly, as can-utils tools end in a pipeline;
- any other failure (`> /dev/full`, `>&-`): `OutputFailed`, one line naming the
  stream, exit 1.

After the first failure a stream swallows further writes, so the final flush
cannot report the same failure twice. stderr never stops a command: a closed
or full stderr swallows what it is given, as can-utils tools carry on.
"""

from __future__ import annotations

import io
import sys
from typing import Any, TextIO

import click

__all__ = ["OutputFailed", "PipeClosed", "flush", "guard"]


class PipeClosed(click.exceptions.Exit):
    """The reading end of our output pipe closed: stop quietly with status 0."""

    def __init__(self) -> None:
        super().__init__(0)


class OutputFailed(click.ClickException):
    """Writing to stdout failed (full disk, closed descriptor...): one line, status 1."""


class _GuardedFile(io.FileIO):
    """A standard stream's descriptor whose write errors become PipeClosed or OutputFailed."""

    def __init__(self, fd: int, label: str) -> None:
        super().__init__(fd, "wb", closefd=False)
        self.label = label
        self.failed = False

    def write(self, data: Any) -> int:
        if self.failed:
            return len(data)
        try:
            return super().write(data) or 0
        except OSError as error:
            self.failed = True
            if self.label == "stderr":
                return len(data)  # a status line nobody can see must not stop the work
            if isinstance(error, BrokenPipeError):
                raise PipeClosed() from None
            raise OutputFailed(f"cannot write to {self.label}: {error.strerror or error}") from None


class _ClosedStream(io.RawIOBase):
    """Stands in for a descriptor that was closed before we started (`>&-`)."""

    def __init__(self, label: str, complain: bool) -> None:
        super().__init__()
        self.label = label
        self.complain = complain

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        if self.complain:
            self.complain = False
            raise OutputFailed(f"cannot write to {self.label}: it is closed")
        return len(memoryview(data))


def _rebuild(stream: TextIO | None, fd: int, label: str) -> TextIO | None:
    if stream is None:  # Python found the descriptor closed at startup
        raw: io.RawIOBase = _ClosedStream(label, complain=(label == "stdout"))
        return io.TextIOWrapper(io.BufferedWriter(raw), encoding="utf-8", write_through=True)  # type: ignore[arg-type]
    try:
        if stream.fileno() != fd:
            return stream  # already redirected inside this process (a test harness): leave it be
    except (OSError, ValueError, io.UnsupportedOperation):
        return stream
    stream.flush()
    buffered = io.BufferedWriter(_GuardedFile(fd, label))
    return io.TextIOWrapper(buffered, encoding=stream.encoding, errors=stream.errors,  # type: ignore[arg-type]
                            line_buffering=stream.line_buffering, write_through=getattr(stream, "write_through", False))


def guard() -> None:
    """Replace sys.stdout and sys.stderr by guarded streams over the same descriptors."""
    sys.stdout = _rebuild(sys.stdout, 1, "stdout")  # type: ignore[assignment]
    sys.stderr = _rebuild(sys.stderr, 2, "stderr")  # type: ignore[assignment]


def flush() -> None:
    """Flush both streams now, so a failure is reported by us and not by the interpreter's exit."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
