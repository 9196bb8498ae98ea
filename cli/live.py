"""`--foxglove [HOST:]PORT`, shared by `sniff` and `bridge`: read it, check the extra, serve the live view."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, TypeVar

import click

from vstig_hw.extras import MissingExtra, require
from vstig_hw.gateway import Node
from vstig_hw.values import ValueType

from .options import LOOPBACK, Address, is_loopback, listen_address

if TYPE_CHECKING:
    from vstig_hw.live.view import LiveView

DOCS = "docs/how-to/live-view.md"
F = TypeVar("F", bound=Callable[..., Any])


def _address(ctx: click.Context, param: click.Parameter, value: str | None) -> Address | None:
    """--foxglove's [HOST:]PORT; the live extra is checked here, before any link opens (one line, exit 1)."""
    if value is None:
        return None
    address = listen_address(value, ctx, param)
    try:
        require("live", "--foxglove")
    except MissingExtra as error:
        raise click.ClickException(str(error)) from None
    return address


VIEWERS = 16  # vstig_hw.live.server.VIEWERS, not imported: the live extra may be missing
MAX_VIEWERS = 1000  # each viewer the server holds may cost it ~0.4 MB (its queue of BACKLOG messages)


def foxglove_option(fn: F) -> F:
    """--foxglove [HOST:]PORT and --foxglove-viewers N, for `live_view`."""
    fn = click.option(
        "--foxglove-viewers", "foxglove_viewers", type=click.IntRange(1, MAX_VIEWERS), default=VIEWERS,
        show_default=True, metavar="N",
        help="With --foxglove: at most N viewers at once; one more is closed with the reason (WebSocket close "
             "1013, try again later) and counted as viewers_refused.")(fn)
    return click.option(
        "--foxglove", "foxglove", metavar="[HOST:]PORT", callback=_address,
        help=f"Serve the live view to Foxglove on PORT (8765 is Foxglove's default), on {LOOPBACK} unless HOST "
             f"is given. Needs the live extra. Channels and layout: {DOCS}.")(fn)


@contextlib.contextmanager
def live_view(node: Node, address: Address | None, *, value_type: ValueType = "uint16",
              larger_value_wins: bool = False, viewers: int = VIEWERS) -> Iterator[LiveView | None]:
    """Serve `node`'s traffic at `address` for the duration (nothing when None); its counters on exit.

    Enter it before the node opens: a port in use or a bad host fails before any link opens.
    """
    if address is None:
        yield None
        return
    from vstig_hw.live.view import LIVE_STATS, LiveView

    host, port = address
    view = LiveView(node, host, port, value_type=value_type, larger_value_wins=larger_value_wins, viewers=viewers)
    try:
        view.open()
    except RuntimeError as error:  # the SDK's FoxgloveError: cannot bind, cannot resolve the host
        reason = str(error).removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
        raise click.ClickException(f"--foxglove {host}:{port}: cannot listen: {reason}") from None
    if not is_loopback(host):
        click.echo(f"--foxglove: WARNING: the live view listens on {view.url} with no authentication: anyone "
                   f"on the network can watch the swarm's traffic (the default, {LOOPBACK}, with an SSH tunnel "
                   f"keeps it to you; see {DOCS})", err=True)
    click.echo(f"live view: {view.url} (in Foxglove: Open connection, Foxglove WebSocket; layout "
               "docs/foxglove/vstig-layout.json)", err=True)
    try:
        yield view
    finally:
        view.close()
        click.echo(f"{LIVE_STATS}: {view.counters.summary()}", err=True)
