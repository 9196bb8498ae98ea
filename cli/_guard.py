"""The guard's options, shared by `bridge` and `sniff`: one decorator, one builder, one warning printer."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import click

from vstig_hw.gateway.guard import DEFAULT_MAX_JUMP, Guard, IdSet, LinkPolicy
from vstig_hw.links import Link
from vstig_hw.wire import KEY_MAX, U16_MAX

from ._numbers import Finite

Pairs = list[tuple[str, IdSet]]


def _pairs(limit: int, what: str) -> Callable[[click.Context, click.Parameter, tuple[str, ...]], Pairs]:
    """A click callback reading LINK=IDS values into (link name, IdSet) pairs; a bad one is a usage error."""

    def convert(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> Pairs:
        pairs = []
        for value in values:
            name, eq, ids = value.partition("=")
            if not eq or not name or not ids:
                raise click.BadParameter(f"{value!r} is not LINK={what.upper()} (e.g. can0=1-9,12)", ctx, param)
            try:
                pairs.append((name, IdSet.parse(ids, limit, what)))
            except ValueError as error:
                raise click.BadParameter(f"{value!r}: {error}", ctx, param) from None
        return pairs
    return convert


_OPTIONS = [
    click.option("--max-jump", type=click.IntRange(0, 0x7FFF), default=DEFAULT_MAX_JUMP, show_default=True,
                 help="Refuse a PUT/GET more than N timestamps newer than our entry (drop_jump); 0 turns it off. "
                      "A climb in steps skips at most N timestamps a second per key. "
                      "A key we do not hold passes at any timestamp (see --learn)."),
    click.option("--learn", type=Finite(0.0), metavar="S",
                 help="S seconds after the first message heard, a key we do not hold yet is new to the swarm: "
                      "it must start within --max-jump of timestamp 0 (drop_jump). Default: it passes at any "
                      "timestamp."),
    click.option("--rate", type=Finite(0.0, min_open=True), metavar="N",
                 help="At most N messages per second from each sender id the medium names (CAN node id, zenoh "
                      "gateway id; a serial link is one sender); excess counted drop_rate. Ids are claims: "
                      "see --source-rate."),
    click.option("--source-rate", type=Finite(0.0, min_open=True), metavar="N",
                 help="At most N messages per second from each real source, whatever ids it claims: a serial or "
                      "CAN link is one source, a zenoh peer's session (the id zenoh stamps on its samples) is one; "
                      "excess counted drop_source_rate."),
    click.option("--trust", multiple=True, metavar="LINK=IDS", callback=_pairs(U16_MAX, "ids"),
                 help="Accept on LINK only these sender ids, e.g. can0=1-20,33 (drop_untrusted). Repeatable."),
    click.option("--deny", multiple=True, metavar="LINK=IDS", callback=_pairs(U16_MAX, "ids"),
                 help="Refuse on LINK what these robots send or wrote (relayed by others too): "
                      "drop_untrusted. Repeatable."),
    click.option("--keys", multiple=True, metavar="LINK=RANGE", callback=_pairs(KEY_MAX, "keys"),
                 help="The keys LINK may write, e.g. radio=100-199 (drop_key); it may still read any. Repeatable."),
    click.option("--read-only", multiple=True, metavar="LINK",
                 help="What LINK says reaches our table but is never relayed to another link. Repeatable."),
    click.option("--flap", type=Finite(0.0, min_open=True), metavar="M",
                 help="Warn once about a key that changes hands by conflict more than M times a second "
                      "(two robots sharing an id)."),
]


@dataclass(frozen=True)
class GuardChoice:
    """The guard options as given; `build` checks them against the links."""

    max_jump: int
    learn: float | None
    rate: float | None
    source_rate: float | None
    trust: Sequence[tuple[str, IdSet]]
    deny: Sequence[tuple[str, IdSet]]
    keys: Sequence[tuple[str, IdSet]]
    read_only: Sequence[str]
    flap: float | None

    def build(self, links: Sequence[Link[Any]]) -> Guard:
        """The Guard; a link name that is not one of `links`, or a sender list for a medium that names nobody,
        is a usage error."""
        names = [link.name for link in links]
        anonymous = {link.name for link in links if not _names_senders(link)}
        policies: dict[str, dict[str, Any]] = {}
        for option, pairs in (("trust", self.trust), ("deny", self.deny), ("keys", self.keys),
                              ("read_only", [(name, True) for name in self.read_only])):
            for name, value in pairs:
                flag = f"--{option.replace('_', '-')}"
                if name not in names:
                    raise click.UsageError(f"{flag} {name}: no such link (links here: {', '.join(names)})")
                if option == "trust" and name in anonymous:
                    raise click.UsageError(f"{flag} {name}: this medium does not name its senders "
                                           "(only CAN does); use --deny, --keys or --read-only on it")
                fields = policies.setdefault(name, {})
                if option in fields:
                    raise click.UsageError(f"{flag} {name} given twice: join them with commas")
                fields[option] = value
        return Guard(max_jump=self.max_jump or None, learn=self.learn, rate=self.rate,
                     source_rate=self.source_rate, flap=self.flap,
                     links={name: LinkPolicy(**fields) for name, fields in policies.items()})


def _names_senders(link: Link[Any]) -> bool:
    """Whether the link can say who sent a unit: its framing reads it (CAN IDs), or the link class does."""
    return getattr(link.framing, "sender_of", None) is not None or type(link).sender_of is not Link.sender_of


def guard_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Add the guard's options to a command; it receives them as one `guard: GuardChoice` argument."""

    @functools.wraps(fn)
    def wrapper(*args: Any, max_jump: int, learn: float | None, rate: float | None, source_rate: float | None,
                trust: Sequence[tuple[str, IdSet]],
                deny: Sequence[tuple[str, IdSet]], keys: Sequence[tuple[str, IdSet]], read_only: Sequence[str],
                flap: float | None, **kwargs: Any) -> Any:
        return fn(*args, guard=GuardChoice(max_jump, learn, rate, source_rate, trust, deny, keys, read_only, flap),
                  **kwargs)

    for option in reversed(_OPTIONS):
        wrapper = option(wrapper)
    return wrapper


def take_warnings(guard: Guard) -> list[str]:
    """The guard's new warning lines, each handed out once."""
    lines = guard.warnings[:]
    guard.warnings.clear()
    return lines
