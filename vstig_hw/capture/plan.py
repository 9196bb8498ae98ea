"""Which writer a capture of some links takes, and why a path cannot hold them (`vstig record`, `Swarm.record`)."""

from __future__ import annotations

from collections.abc import Sequence

from .records import CAN_EXTENSIONS, MCAP_EXTENSION, capture_suffix, link_names_lost

__all__ = ["capture_medium"]


def capture_medium(path: str, media: Sequence[str]) -> str:
    """The capture medium (can, serial, zenoh or mcap) for links of `media` (one per link, in order) at `path`.

    ValueError with one line when the path's format cannot hold them.
    """
    medium = "mcap" if path.lower().endswith(MCAP_EXTENSION) else media[0]
    if medium != "mcap" and len(set(media)) > 1:
        raise ValueError(f"links of different media (CAN, serial, zenoh) go into a {MCAP_EXTENSION} capture "
                         "together (a CAN log holds CAN frames, a serial capture UART bytes, a zenoh capture "
                         "samples)")
    if medium == "can" and not path.lower().endswith(CAN_EXTENSIONS):
        raise ValueError(f"a CAN capture is chosen by extension: {', '.join(CAN_EXTENSIONS)} or "
                         f"{MCAP_EXTENSION} (got {path})")
    if medium == "can" and link_names_lost(path) and len(media) > 1:
        raise ValueError(f"a {capture_suffix(path)} capture names no link, so {len(media)} links would become "
                         "one: record them as .log, .asc, .blf or .mcap")
    return medium
