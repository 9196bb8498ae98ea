"""Several stigmergies (Buzz's `stigmergy.create(id)`): the link specs that carry table N on the same media.

A table is carried apart from the others where the medium has room for it:
29-bit CAN IDs have an 8-bit stigmergy field (`can:...?extended=1&stigmergy=N`),
a zenoh link a key space per stigmergy (`vstig/<swarm>/<N>/...`). A table's
zenoh session cannot bind the first one's endpoints again: it listens on none and
connects where the first connects and to the first's own endpoints, so it meets
every session the first one meets (checked on loopback with two programs). Everything
else is refused in one line naming the link: 11-bit CAN tells tables apart only
by `id_base`, which a lab assigns, and a serial radio or a Buzz dialect link
carries one table. Each medium's spec says which (`LinkSpec.for_table`).
"""

from __future__ import annotations

from collections.abc import Sequence

from ..links.link import LinkSpec

__all__ = ["MAX_TABLE", "specs_for_table", "table_of"]

MAX_TABLE = 255  # the CAN stigmergy field is 8 bits; zenoh allows as many


def table_of(specs: Sequence[LinkSpec]) -> int | None:
    """The table these specs carry, when they all name one (a spec with no stigmergy field carries table 0)."""
    tables = {spec.stigmergy for spec in specs}
    return tables.pop() if len(tables) == 1 else None


def specs_for_table(specs: Sequence[LinkSpec], table: int,
                    listening: Sequence[tuple[str, ...]] = ()) -> list[LinkSpec]:
    """The specs that carry `table` where `specs` carry theirs; ValueError naming a link that cannot.

    `listening` has, per spec, the endpoints its open link listens on (zenoh).
    """
    return [spec.for_table(table, listening[number] if number < len(listening) else ())
            for number, spec in enumerate(specs)]
