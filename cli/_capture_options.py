"""Options the commands that read captures share."""

from __future__ import annotations

import click


def parse_id_base(text: str | None) -> int | None:
    """`--id-base` as an integer (0x600 or 1536); a bad one is a usage error."""
    if text is None:
        return None
    try:
        return int(text, 0)
    except ValueError:
        raise click.BadParameter(f"{text!r} is not an integer (e.g. 0x600)", param_hint="--id-base") from None
