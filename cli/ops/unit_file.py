"""Writing a file another program trusts (a systemd unit) without a check-then-open race.

A new file is created with O_CREAT | O_EXCL | O_NOFOLLOW: the open itself is the check, so a symbolic
link planted at the path at any moment is never followed (O_EXCL fails on any existing name, a dangling
link included). Replacing (--overwrite) writes a new file beside it the same way, syncs it, and renames
it over the old name: rename replaces the name, never what a link there points to, and a reader sees the
old unit or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat

import click

__all__ = ["write_new_file"]

_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


def write_new_file(path: str, text: str, *, overwrite: bool, mode: int = 0o644) -> None:
    """Write `text` to `path`: created if absent; replaced atomically with `overwrite`; else a usage error.

    A usage error too for a path that is a symbolic link or not a regular file (a FIFO, a device, a folder).
    """
    if not overwrite:
        try:
            _write_fd(os.open(path, _CREATE, mode), text)
        except FileExistsError:
            raise click.UsageError(f"{path}{_kind(path) or ' exists: --overwrite replaces it'}") from None
        except OSError as error:
            raise click.UsageError(f"cannot write {path}: {error.strerror}") from None
        return
    kind = _kind(path)
    if kind:  # a check, not a guard: whatever is planted after it, rename below replaces the name only
        raise click.UsageError(f"{path}{kind}")
    folder = os.path.dirname(path) or "."
    temporary = os.path.join(folder, f".{os.path.basename(path)}.{secrets.token_hex(6)}.tmp")
    try:
        _write_fd(os.open(temporary, _CREATE, mode), text)
        os.rename(temporary, path)
    except OSError as error:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise click.UsageError(f"cannot write {path}: {error.strerror}") from None
    _sync_folder(folder)


def _write_fd(fd: int, text: str) -> None:
    with os.fdopen(fd, "w", encoding="utf-8") as file:
        file.write(text)
        file.flush()
        os.fsync(file.fileno())


def _kind(path: str) -> str:
    """Why `path` is not a file to replace ('' when it is one, or absent)."""
    try:
        info = os.lstat(path)
    except OSError:
        return ""
    if stat.S_ISLNK(info.st_mode):
        return " is a symbolic link: remove it, or write the unit elsewhere"
    if not stat.S_ISREG(info.st_mode):
        return " is not a regular file"
    return ""


def _sync_folder(folder: str) -> None:
    """The rename itself survives a power cut once the folder is synced."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
