"""Helpers the commands share: building links from specs, running a node until stopped."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import click

from vstig_hw.gateway import Node, stop_on_signals
from vstig_hw.links import Link, LinkSpec
from vstig_hw.links.assemble import LinkBuildError, assemble_links
from vstig_hw.links.can import CanSpec
from vstig_hw.links.zenoh import ZenohSpec


def build_links(specs: Sequence[LinkSpec], robot_id: int = 0, listen_only: bool = False) -> list[Link[Any]]:
    """One Link per spec, named after its device (made unique: radio, radio-2...).

    A robot id that a CAN link's ID scheme has no room for is a usage error naming --robot-id.
    """
    try:
        links = assemble_links(specs, robot_id, listen_only)
    except LinkBuildError as error:
        if error.argument == "robot_id":
            raise click.BadParameter(str(error), param_hint="'--robot-id'") from None
        raise click.UsageError(str(error)) from None
    for spec in specs:  # once every link could be built: a link that cannot (a missing extra) is the one line said
        if isinstance(spec, CanSpec) and spec.interface == "virtual":
            click.echo(f"note: can:virtual:{spec.channel} is a bus inside this process only: no other program "
                       "hears it (vcan or can:udp_multicast: reach other processes)", err=True)
    return links


def describe_links(node: Node) -> None:
    """One line per link whose transport says where it is reachable (a Zenoh link's endpoints)."""
    for link in node.links:
        about = getattr(link.transport, "about", "")
        if about:
            click.echo(f"{link.name}: {about}", err=True)


def lossless(spec: LinkSpec, opening: float | None = None) -> LinkSpec:
    """The spec for a command that must not lose what it sends (put, get, replay): Zenoh BLOCKs, not DROPs.

    `opening`: the seconds a one-shot command (get, put) lets the link take to open, so its --wait bounds the
    whole command (a Zenoh link otherwise waits 3 s for a peer it was told to connect to).
    """
    if not isinstance(spec, ZenohSpec):
        return spec
    return replace(spec, block=True, **({} if opening is None else {"peer_wait": opening}))


def run_until_stopped(node: Node, status: Any = None, duration: float | None = None) -> None:
    """Run the node until Ctrl-C/SIGTERM (or `duration`), refreshing `status()` every half second."""
    with stop_on_signals() as stop:
        if status is None:
            node.run(stop=stop, duration=duration)
            return
        import time

        end = None if duration is None else time.monotonic() + duration
        while not stop.is_set() and (end is None or time.monotonic() < end):
            node.run(stop=stop, duration=0.5 if end is None else max(0.0, min(0.5, end - time.monotonic())))
            status()


def print_counters(node: Node) -> None:
    for name, counters in node.stats().items():
        click.echo(f"{name}: {counters.summary()}", err=True)


class StatusLine:
    """One line on stderr, redrawn in place, only when stderr is a terminal (a log file gets none)."""

    def __init__(self) -> None:
        self.live = sys.stderr.isatty()
        self.drawn = False

    def show(self, text: str) -> None:
        if self.live:
            click.echo(f"\r\x1b[K{text}", nl=False, err=True)
            self.drawn = True

    def end(self) -> None:
        if self.drawn:
            click.echo(err=True)
            self.drawn = False


def must_hear(spec: LinkSpec, command: str) -> None:
    """Refuse a listening command on a transmit-only link, instead of listening to nothing."""
    if spec.kind == "kilobot-ohc":
        raise click.UsageError(f"{command} needs a link that receives; kilobot-ohc:{spec.name} is transmit-only "
                               "(the overhead controller never hears the robots)")
