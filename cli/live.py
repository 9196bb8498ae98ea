"""`--foxglove [HOST:]PORT`, shared by `sniff` and `bridge`: read it, check the extra, serve the live view."""

from __future__ import annotations

import contextlib
import ipaddress
from collections.abc import Iterator
from typing import TYPE_CHECKING

import click

from vstig_hw.extras import MissingExtra, require
from vstig_hw.gateway import Node
from vstig_hw.values import ValueType

if TYPE_CHECKING:
    from vstig_hw.live.view import LiveView

Address = tuple[str, int]
LOOPBACK = "127.0.0.1"
DOCS = "docs/how-to/live-view.md"


def _address(ctx: click.Context, param: click.Parameter, value: str | None) -> Address | None:
    """PORT or HOST:PORT ([::1]:PORT for IPv6) into (host, port); bad ones are usage errors."""
    if value is None:
        return None
    host, colon, port = value.rpartition(":")
    host = host.removeprefix("[").removesuffix("]") if colon else LOOPBACK
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise click.BadParameter(f"{value!r}: the port must be a number in 0..65535 (0: any free port)", ctx, param)
    if not host:
        raise click.BadParameter(f"{value!r}: an empty host (PORT alone binds {LOOPBACK})", ctx, param)
    try:
        require("live", "--foxglove")  # here, before any link opens: one line, exit 1
    except MissingExtra as error:
        raise click.ClickException(str(error)) from None
    return host, int(port)


foxglove_option = click.option(
    "--foxglove", "foxglove", metavar="[HOST:]PORT", callback=_address,
    help=f"Serve the live view to Foxglove on PORT (8765 is Foxglove's default), on {LOOPBACK} unless HOST "
         f"is given. Needs the live extra. Channels and layout: {DOCS}.")


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a name: wherever it resolves, it may be the network
        return False


@contextlib.contextmanager
def live_view(node: Node, address: Address | None, *, value_type: ValueType = "uint16",
              larger_value_wins: bool = False) -> Iterator[LiveView | None]:
    """Serve `node`'s traffic at `address` for the duration (nothing when None); its counters on exit.

    Enter it before the node opens: a port in use or a bad host fails before any link opens.
    """
    if address is None:
        yield None
        return
    from vstig_hw.live.view import LIVE_STATS, LiveView

    host, port = address
    view = LiveView(node, host, port, value_type=value_type, larger_value_wins=larger_value_wins)
    try:
        view.open()
    except RuntimeError as error:  # the SDK's FoxgloveError: cannot bind, cannot resolve the host
        reason = str(error).removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
        raise click.ClickException(f"--foxglove {host}:{port}: cannot listen: {reason}") from None
    if not _loopback(host):
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
