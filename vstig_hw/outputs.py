"""The rules every file vstig writes on a user's behalf follows, from the CLI and from a program alike.

No output is written through a symbolic link, with or without permission to replace: a dangling link would
create its target wherever it points, and a live one replace a file the user never named (a capture tool is
often run as root). A link to a folder is fine: the file made inside it is a new name.

A file that is replaced or added to loses its setuid and setgid bits first: it will hold bytes robots sent,
and the bits would let anyone run them as its owner. Linux clears them itself when a process without
CAP_FSETID writes, so this is for root, whom the kernel lets keep them.
"""

from __future__ import annotations

import os
import stat

__all__ = ["LinkedOutput", "drop_setid", "refuse_symlink"]


class LinkedOutput(ValueError):
    """An output path that is a symbolic link; the message names it."""


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
