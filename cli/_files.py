"""The files a user names (-o FILE, --capture, --plot, --snapshot): none is replaced unless --overwrite says so.

A file the user names may be the wrong one (a capture typed where a picture was meant), so every command
refuses it the same way, before doing any work. Reports a command names itself inside an output folder
(`sim paper -o DIR`) are its own and are regenerated in place. No output is written through a symbolic
link, even with --overwrite (vstig_hw.outputs, the rule a program's recordings follow too).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from vstig_hw.outputs import LinkedOutput, refuse_symlink


def overwrite_option(target: str) -> Callable[..., Any]:
    """The --overwrite flag of a command that writes `target` (how its help names the file)."""
    return click.option("--overwrite", is_flag=True, help=f"Replace {target} if it exists (never done without this).")


def refuse_link(path: str | Path) -> None:
    """A usage error naming `path` if it is a symbolic link (dangling or not)."""
    try:
        refuse_symlink(path)
    except LinkedOutput as error:
        raise click.UsageError(str(error)) from None


def refuse_links_in(folder: Path, names: tuple[str, ...]) -> None:
    """refuse_link for each file a command names itself inside its output folder."""
    for name in names:
        refuse_link(folder / name)


def refuse_to_replace(path: str | Path, overwrite: bool, otherwise: str = "") -> None:
    """A usage error naming `path` if it is a symbolic link, or if it holds something and --overwrite was
    not given.

    `otherwise` adds the command's other way out (record: ", --append adds to it"). An empty file holds
    nothing to lose, and a device (/dev/null) is not replaced by writing to it.
    """
    refuse_link(path)
    if not overwrite and os.path.isfile(path) and os.path.getsize(path) > 0:
        raise click.UsageError(f"{path} exists: --overwrite replaces it{otherwise}")
