"""Options the commands that read captures share."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

import click

from vstig_hw.capture.records import CaptureError

from ._numbers import Finite

F = TypeVar("F", bound=Callable[..., Any])

SHOWN_SKIPPED = 5  # damage lines shown; the summary counts them all
VALUE_TYPE_HELP = "How to show the 16-bit value field: unsigned, signed (two's complement) or half-precision float."
skip_bad_option = click.option(
    "--skip-bad", is_flag=True,
    help="Count malformed lines, and a file cut short (a killed recorder's), and go on instead of stopping there.")


def echo_skipped(bad: Iterable[CaptureError]) -> None:
    """The damage a reader skipped, one line each (the first few), on stderr: every command says it alike."""
    for error in itertools.islice(bad, SHOWN_SKIPPED):
        click.echo(f"skipped {error}", err=True)


def parse_id_base(text: str | None) -> int | None:
    """`--id-base` as an integer (0x600 or 1536); a bad one is a usage error."""
    if text is None:
        return None
    try:
        return int(text, 0)
    except ValueError:
        raise click.BadParameter(f"{text!r} is not an integer (e.g. 0x600)", param_hint="--id-base") from None


def reading_options(fn: F) -> F:
    """Add how to read captures: --skip-bad, --value-type, --id-base, --extended, --deployment."""
    from vstig_hw.values import VALUE_TYPES

    options = [
        skip_bad_option,
        click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
                     help=VALUE_TYPE_HELP),
        click.option("--id-base", help="CAN ID base of the stigmergy (default 0x600, or 0x18000000 for 29-bit IDs)."),
        click.option("--extended", is_flag=True, help="The CAN capture uses 29-bit IDs."),
        click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
                     help="For Buzz/BittyBuzz captures (blabbermouth, bittybuzz-kilobot): the TOML file mapping "
                          "their keys."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def filter_options(fn: F) -> F:
    """Add the capture filter options; the command receives them as one `keep: Filter` argument."""
    from vstig_hw.wire import KEY_MAX, U16_MAX

    options = [
        click.option("--key", "only_keys", multiple=True, type=click.IntRange(0, KEY_MAX),
                     help="Only this key (repeatable)."),
        click.option("--robot", "only_robots", multiple=True, type=click.IntRange(0, U16_MAX),
                     help="Only entries written by this robot (repeatable)."),
        click.option("--sender", "only_senders", multiple=True, type=click.IntRange(0, U16_MAX),
                     help="Only messages sent by this node: a CAN frame's sender field (repeatable)."),
        click.option("--op", "only_ops", multiple=True, type=click.Choice(["PUT", "GET"], case_sensitive=False),
                     help="Only PUTs or only GETs."),
        click.option("--link", "only_links", multiple=True, help="Only this link, by name (repeatable)."),
        click.option("--since", type=Finite(0), help="Only from this many seconds after the first record."),
        click.option("--until", type=Finite(0), help="Only before this many seconds after the first record."),
    ]

    @functools.wraps(fn)
    def with_filter(*args: Any, only_keys: tuple[int, ...], only_robots: tuple[int, ...],
                    only_senders: tuple[int, ...], only_ops: tuple[str, ...], only_links: tuple[str, ...],
                    since: float | None, until: float | None, **kwargs: Any) -> Any:
        from vstig_hw.capture.filters import Filter
        from vstig_hw.wire import Op

        if since is not None and until is not None and until <= since:
            raise click.BadParameter(f"{until:g} is not after --since {since:g}", param_hint="--until")
        keep = Filter(keys=frozenset(only_keys) or None, robots=frozenset(only_robots) or None,
                      senders=frozenset(only_senders) or None, ops=frozenset(Op[o.upper()] for o in only_ops) or None,
                      links=frozenset(only_links) or None, since=since, until=until)
        return fn(*args, keep=keep, **kwargs)

    for option in reversed(options):
        with_filter = option(with_filter)
    return with_filter  # type: ignore[return-value]
