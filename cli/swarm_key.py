"""`--swarm-key FILE`: the swarm's master secret (SPEC.md 10.1), read and checked when the command line is parsed."""

from __future__ import annotations

from typing import Any

import click

from vstig_hw.auth import read_swarm_key
from vstig_hw.inputs import InputFileError


class SwarmKeyFile(click.ParamType):  # type: ignore[type-arg]  # generic only from click 8.3; we take 8.1 up
    """A swarm key file on the command line, read to its 32 bytes; a bad one is a usage error naming the file."""

    name = "FILE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> bytes:
        if isinstance(value, bytes):
            return value
        try:
            return read_swarm_key(value)
        except InputFileError as error:
            self.fail(str(error), param, ctx)


SWARM_KEY = SwarmKeyFile()
