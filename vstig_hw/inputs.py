"""The rule every file vstig reads on a user's behalf at an edge follows (a deployment file, a config file):
a regular file, read whole up to a bound, opened so that a FIFO or a device cannot hold the command.

Errors name the file; `toml_line` finds the line a TOML key is set on (tomllib keeps no positions), so an
error about a value can name its line too. `parse_toml` is tomllib with both its failures named: bad TOML, and
arrays or tables nested deeper than Python's recursion limit (100,000 deep was "maximum recursion depth
exceeded", naming nothing).
"""

from __future__ import annotations

import os
import re
import stat
import tomllib
from typing import Any

__all__ = ["InputFileError", "parse_toml", "read_regular", "toml_line"]


class InputFileError(ValueError):
    """A named input that cannot be read as one: not a regular file, too large, unreadable. Names the file."""


def read_regular(path: str | os.PathLike[str], limit: int, what: str, *, private: bool = False) -> bytes:
    """The bytes of `path`, a regular file of at most `limit` bytes; anything else an InputFileError naming it.

    Opened without blocking (a FIFO would wait for a writer) and checked on the open descriptor, so a
    device (/dev/zero), a pipe or a folder is refused before a byte is read. `private`: a secret, refused
    while group or others may read or write it (checked on the descriptor, so a swap after the check fails).
    """
    name = os.fspath(path)
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except (OSError, ValueError) as error:  # ValueError: a NUL in the name
        reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
        raise InputFileError(f"{name}: cannot read {what}: {reason}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise InputFileError(f"{name}: {what} must be a regular file, not a device, pipe or folder")
    mode = stat.S_IMODE(mode)
    if private and mode & 0o077:
        os.close(fd)
        raise InputFileError(f"{name}: {what} is readable or writable by others (mode {mode:o}): chmod 600 {name}")
    with os.fdopen(fd, "rb") as file:
        data = file.read(limit + 1)  # not st_size alone: a file may grow while read
    if len(data) > limit:
        raise InputFileError(f"{name}: {what} is larger than the {limit >> 20} MiB read at most")
    return data


def toml_line(text: str, key: str) -> str:
    """`:N` for the first line of TOML `text` that sets `key` (bare or quoted) or opens a table of that name,
    or '' if none does."""
    name = rf"(?:{re.escape(key)}|\"{re.escape(key)}\"|'{re.escape(key)}')"
    match = re.search(rf"^[ \t]*(?:{name}[ \t]*=|\[\[?[ \t]*{name}[ \t]*\])", text, re.MULTILINE)
    return f":{text.count(chr(10), 0, match.start()) + 1}" if match else ""


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """tomllib.loads(text); InputFileError naming `source` if it is not TOML or nests too deeply to read."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputFileError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:  # tomllib recurses once per nested array or inline table
        raise InputFileError(f"{source}: arrays or tables nested too deeply to read") from None
