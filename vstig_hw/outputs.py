"""The rules every file vstig writes on a user's behalf follows, from the CLI and from a program alike.

No output is written through a symbolic link, with or without permission to replace: a dangling link would
create its target wherever it points, and a live one replace a file the user never named (a capture tool is
often run as root). A link to a folder is fine: the file made inside it is a new name.

A file that is replaced or added to loses its setuid and setgid bits first: it will hold bytes robots sent,
and the bits would let anyone run them as its owner. Linux clears them itself when a process without
CAP_FSETID writes, so this is for root, whom the kernel lets keep them.

No output is written into something that may hold its writer or is no place for a capture: a named pipe
(FIFO) holds its writer in `open()` until some program reads it, and then in every write it is slow to take,
a terminal in every write its flow control holds back, so a command writing there could not be stopped; a
socket or a block device (a disk) is no place for a capture either. Other devices are sinks that answer at
once (`/dev/null`, `/dev/full`). Checked before any work, so nothing runs for an output that cannot be written.
"""

from __future__ import annotations

import os
import stat

__all__ = ["LinkedOutput", "SpecialOutput", "drop_setid", "refuse_special", "refuse_symlink"]

_PTY_SLAVES = range(136, 144)  # the kernel's major numbers of /dev/pts/N (UNIX98_PTY_SLAVE_MAJOR and on)


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
    """SpecialOutput if `path` is a named pipe, a terminal, a socket or a block device."""
    try:
        info = os.stat(path)
    except OSError:  # not there (yet): a file will be made
        return
    kind = _special_kind(info)
    if kind is not None:
        raise SpecialOutput(f"{os.fspath(path)} is {kind}: vstig writes its outputs into regular files only (a "
                            "writer into a pipe or a terminal waits for its reader, and could not be stopped)")


def _special_kind(info: os.stat_result) -> str | None:
    mode = info.st_mode
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISCHR(mode):
        major, minor = os.major(info.st_rdev), os.minor(info.st_rdev)
        subsystem = os.path.realpath(f"/sys/dev/char/{major}:{minor}/subsystem")  # Linux; elsewhere not there
        if major in _PTY_SLAVES or os.path.basename(subsystem) == "tty":
            return "a terminal"
    return None
