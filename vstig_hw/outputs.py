"""The rules every file vstig writes on a user's behalf follows, from the CLI and from a program alike.

No output is written through a symbolic link, with or without permission to replace: a dangling link would
create its target wherever it points, and a live one replace a file the user never named (a capture tool is
often run as root). A link to a folder is fine: the file made inside it is a new name.

A file that is replaced or added to loses its setuid and setgid bits first: it will hold bytes robots sent,
and the bits would let anyone run them as its owner. Linux clears them itself when a process without
CAP_FSETID writes, so this is for root, whom the kernel lets keep them.

No output is written into something that is not a file: a named pipe (FIFO) holds its writer in `open()`
until some program reads it, and then in every write it is slow to take, so a command writing there could
not be stopped; a socket or a device is no place for a capture either. Only the null device is taken, as the
sink it is. Checked before any work, so nothing runs for an output that cannot be written.
"""

from __future__ import annotations

import os
import stat

__all__ = ["LinkedOutput", "SpecialOutput", "drop_setid", "refuse_special", "refuse_symlink"]

_KINDS = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"))


class LinkedOutput(ValueError):
    """An output path that is a symbolic link; the message names it."""


class SpecialOutput(ValueError):
    """An output path that exists and is not a regular file or a folder (a FIFO, a socket, a device)."""


def refuse_symlink(path: str | os.PathLike[str]) -> None:
    """LinkedOutput if `path` is a symbolic link (dangling or not)."""
    if os.path.islink(path):
        raise LinkedOutput(f"{os.fspath(path)} is a symbolic link: name the file itself (no output is written "
                           "through a link, even one allowed to replace a file)")


def drop_setid(path: str | os.PathLike[str]) -> None:
    """Clear the setuid and setgid bits of `path` if it is a regular file about to be written (nothing if it is
    not there or cannot be reached: writing it fails as it would have; nothing if it is not ours to change: then
    the kernel clears them as we write)."""
    try:
        mode = os.lstat(path).st_mode
        if stat.S_ISREG(mode) and mode & (stat.S_ISUID | stat.S_ISGID):
            os.chmod(path, stat.S_IMODE(mode) & ~(stat.S_ISUID | stat.S_ISGID))
    except OSError:
        pass

def refuse_special(path: str | os.PathLike[str]) -> None:
    """SpecialOutput if `path` is a named pipe, a socket or a device (the null device excepted)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:  # not there (yet): a file will be made
        return
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode) or os.path.realpath(path) == os.devnull:
        return
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    raise SpecialOutput(f"{os.fspath(path)} is {kind}: vstig writes its outputs into regular files only (a "
                        "writer into a pipe waits for its reader, and could not be stopped)")
