"""The rule every file vstig writes on a user's behalf follows, from the CLI and from a program alike.

No output is written through a symbolic link, with or without permission to replace: a dangling link would
create its target wherever it points, and a live one replace a file the user never named (a capture tool is
often run as root). A link to a folder is fine: the file made inside it is a new name.
"""

from __future__ import annotations

import os

__all__ = ["LinkedOutput", "refuse_symlink"]


class LinkedOutput(ValueError):
    """An output path that is a symbolic link; the message names it."""


def refuse_symlink(path: str | os.PathLike[str]) -> None:
    """LinkedOutput if `path` is a symbolic link (dangling or not)."""
    if os.path.islink(path):
        raise LinkedOutput(f"{os.fspath(path)} is a symbolic link: name the file itself (no output is written "
                           "through a link, even one allowed to replace a file)")
