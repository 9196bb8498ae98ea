"""What a Node is made of, chosen once when it is built: the compiled path or the Python one, the outlets, the
engine and the part that handles what the links heard (see `node` for the modes)."""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from ..auth import SwarmKeys
from ..engine import ConflictResolver, Stigmergy
from ..links.link import Link
from .compiled import Compiled, checks_tags_for, compiled_for, jump_guard
from .guard import Guard
from .outlet import Outlet
from .parts import INTAKE_TICKS, ChangeListener, RawRelay, Seat
from .signing import Signing, unkeyed_policy

__all__ = ["Mode", "NodeParts", "build_parts"]


class Mode(enum.Enum):
    """What a Node is; each picks the part that handles what links heard (see `parts`).

    * ENGINE: the Node is a robot (a `Seat`). What any link hears goes into its
      engine; what the engine queues goes out on every link (its own queue per link,
      see `outlet`). Data crosses media because the protocol re-broadcasts what is new
      and answers stale GETs, not because the gateway relays.
    * RAW: a transparent bridge (a `RawRelay`). Every message heard on one link is
      re-encoded in each other link's framing and sent as is: no engine, no merging.
    * LISTEN: a sniffer or recorder. Nothing is ever written to any link. With
      `count_outcomes` a `Seat` with no outlets still judges everything, so `stats()`
      tells what the traffic would do to a robot (sniff shows it).
    """

    ENGINE = "engine"
    RAW = "raw"
    LISTEN = "listen"


@dataclass(frozen=True)
class NodeParts:
    compiled: Compiled | None  # the builder of the compiled parts (None: every part is Python)
    signing: Signing | None  # the swarm key's part (None: no tags checked)
    guard: Guard | None  # sees what links heard before the part does
    outlets: list[Outlet]  # outlets[i] is links[i]'s (none in LISTEN)
    engine: Stigmergy | None
    seat: Seat | None  # the engine's part: ENGINE, or LISTEN with count_outcomes
    part: Seat | RawRelay | None  # what handles the messages links heard (None: nothing)


def build_parts(links: list[Link[Any]], robot_id: int, mode: Mode, period: float, budget: int | None,
                onconflict: ConflictResolver | None, count_outcomes: bool, guard: Guard | None, pure: bool,
                swarm_keys: SwarmKeys | None, on_room: Callable[[], None],
                on_change: Sequence[ChangeListener]) -> NodeParts:
    """A Node's parts; ValueError naming what cannot work (a raw bridge of one link, a key it cannot use...)."""
    signing = _signing(links, mode, swarm_keys)
    names = [link.name for link in links]
    if len(set(names)) != len(names):
        raise ValueError(f"link names must differ, got {', '.join(names)}")
    if mode is Mode.RAW and len(links) < 2:
        raise ValueError("a raw bridge needs at least two links")
    # A relaying Node's parts are compiled where this install has the compiled path: the same interfaces, so the
    # Node works on either; VSTIG_PURE=1 keeps them Python, and so does `pure` (a recording bridge: the compiled
    # outlets write to the device where no recorder sees what they send), and so does the swarm key where a link
    # checks tags the compiled path does not (`compiled.checks_tags_for`: XBee's and MAVLink's tagged units).
    tags_in_c = signing is None or all(checks_tags_for(link) for link in links)
    compiled = None if pure or not tags_in_c else compiled_for(mode is not Mode.LISTEN, links)
    if compiled is not None:
        guard = jump_guard(guard)
    make_outlet = Outlet if compiled is None else compiled.outlet
    outlets = [] if mode is Mode.LISTEN else [
        make_outlet(link, budget, period, keep_all=mode is Mode.RAW, on_room=on_room) for link in links]
    engine: Stigmergy | None = None
    seat: Seat | None = None
    part: Seat | RawRelay | None = None
    if mode is Mode.RAW:
        part = (RawRelay if compiled is None else compiled.relay)(outlets, guard)
    elif mode is Mode.ENGINE or count_outcomes:
        if signing is not None:
            engine = signing.engine_for(robot_id, onconflict, compiled)
        else:
            engine = Stigmergy(robot_id, onconflict=onconflict) if compiled is None else \
                compiled.engine(robot_id, onconflict)
        intake = INTAKE_TICKS * budget if mode is Mode.ENGINE and budget is not None else None
        part = seat = (Seat if compiled is None else compiled.seat)(engine, links, outlets, guard, on_change, intake,
                                                                    period)
    return NodeParts(compiled, signing, guard, outlets, engine, seat, part)


def _signing(links: list[Link[Any]], mode: Mode, keys: SwarmKeys | None) -> Signing | None:
    """The swarm key's part of a Node (None: without the key, or no link with auth=require or prefer: every tag
    would be ignored, and the compiled path serves); ValueError naming what cannot work."""
    complaint = unkeyed_policy(links)
    if keys is None or complaint is None:
        if keys is None and complaint is not None:
            raise ValueError(complaint)
        return None
    if mode is Mode.RAW:
        raise ValueError("a raw bridge keeps no entries, so it cannot keep their proofs: run it with an engine "
                         "(without --raw) to check tags")
    return Signing(keys, links)
