"""`--swarm-key FILE`: the swarm's master secret (SPEC.md 10.1), read and checked when the command line is parsed."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import click

from vstig_hw.auth import SwarmKeys, read_swarm_key
from vstig_hw.inputs import InputFileError

if TYPE_CHECKING:
    from vstig_hw.links import Link


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


def swarm_key_option(command: Callable[..., Any]) -> Callable[..., Any]:
    """`--swarm-key FILE` (as `swarm_key`, the 32 bytes or None) on a command that builds a Node."""
    return click.option("--swarm-key", "swarm_key", type=SWARM_KEY, metavar="FILE",
                        help="The swarm's master secret (`vstig keys --new FILE`, mode 600): check tags on the links "
                             "with auth=require or auth=prefer, and tag this command's writes (docs/how-to/auth.md)."
                        )(command)


def swarm_keys_for(links: Sequence[Link[Any]], master: bytes | None) -> SwarmKeys | None:
    """The keys a command's Node checks tags with; a usage error naming the link that asks for tags without them."""
    from vstig_hw.gateway.signing import unkeyed_policy

    complaint = unkeyed_policy(links) if master is None else None
    if complaint is not None:
        raise click.UsageError(complaint)
    return None if master is None else SwarmKeys(master)
