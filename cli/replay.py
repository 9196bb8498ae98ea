"""`vstig replay FILE --onto LINK` (faithful timing) or `--table [--at T]` (an offline engine)."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator
from typing import Any

import click

from vstig_hw.capture.decoded import Decoder, default_framings
from vstig_hw.capture.files import read_capture
from vstig_hw.capture.records import CAN_FRAMING, Record
from vstig_hw.capture.replay import replay
from vstig_hw.engine import Stigmergy
from vstig_hw.gateway import stop_on_signals
from vstig_hw.links import Link
from vstig_hw.links.spec import CanSpec, LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw

from ._common import VALUE_TYPE_HELP, StatusLine, build_links
from .errors import LINK, reports_errors

_OBSERVER_ID = 0xFFFF  # the offline engine's id: it never writes, so it never wins a conflict it causes


def _sender(link: Link[Any], onto: LinkSpec, deployment: str | None) -> Any:
    """Write a record as is when the medium and framing match; otherwise re-encode its messages.

    A CAN capture is read with the default ID scheme (11-bit, base 0x600); a target that asks for
    another (id_base, extended, stigmergy) gets the messages re-encoded in its own IDs.
    """
    decoder = Decoder(default_framings(deployment=deployment))
    is_can = isinstance(onto, CanSpec)
    default_ids = is_can and onto.id_base in (None, 0x600) and not onto.extended and onto.stigmergy == 0

    def send(record: Record) -> None:
        same = (record.framing == CAN_FRAMING and default_ids) if is_can else (record.framing == link.framing.name)
        if same:
            link.transport.write(_fresh(record.unit) if is_can else record.unit)
            link.counters["out_units"] += 1
            return
        for decoded in decoder.decode(record):
            link.send(decoded.message)

    return send


class _CountingSender:
    """`send`, with a live counter line on stderr when it is a terminal (at most twice a second)."""

    def __init__(self, send: Any, link: Link[Any]) -> None:
        self.send, self.link = send, link
        self.line = StatusLine()
        self.sent = 0
        self.next_draw = 0.0

    def __call__(self, record: Record) -> None:
        self.send(record)
        self.sent += 1
        if self.line.live and time.monotonic() >= self.next_draw:
            self.next_draw = time.monotonic() + 0.5
            self.line.show(f"sent {self.sent} units  {self.link.name}: {self.link.stats().summary()}")


def _fresh(frame: Any) -> Any:
    import can

    return can.Message(arbitration_id=frame.arbitration_id, is_extended_id=frame.is_extended_id, data=frame.data,
                       is_fd=frame.is_fd, bitrate_switch=frame.bitrate_switch, is_remote_frame=frame.is_remote_frame,
                       dlc=frame.dlc, check=False)


def _table(path: str, at: float | None, value_type: ValueType, deployment: str | None) -> None:
    engine = Stigmergy(_OBSERVER_ID)
    decoder = Decoder(default_framings(deployment=deployment))
    t0 = None
    for decoded in decoder.decode_all(read_capture(path)):
        t0 = decoded.t if t0 is None else t0
        if at is not None and decoded.t - t0 > at:
            break
        engine.receive(decoded.message)
    when = "the end" if at is None else f"t={at:g} s"
    click.echo(f"what the swarm believed at {when} of {path}:")
    click.echo(f"{'key':>6} {'value':>8} {'ts':>6} {'robot':>6}")
    for key, entry in sorted(engine.entries()):
        click.echo(f"{key:>6} {from_raw(entry.value, value_type)!s:>8} {entry.timestamp:>6} {entry.robot:>6}")


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--onto", type=LINK, help="Send the capture onto this link with its original timing.")
@click.option("--speed", type=click.FloatRange(0.001, 1000), default=1.0, show_default=True,
              help="Play this many times faster than recorded (0.5: half speed).")
@click.option("--loop", is_flag=True, help="Start again at the end, until Ctrl-C.")
@click.option("--skip-gaps", type=click.FloatRange(0.0), metavar="SECONDS",
              help="Wait at most SECONDS between two units, however long the capture's gap.")
@click.option("--ignore-timestamps", is_flag=True, help="Send every unit at once, one after the other.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=0, show_default=True,
              help="Sender id for messages re-encoded onto another medium.")
@click.option("--table", is_flag=True, help="Feed an offline engine instead and print its table.")
@click.option("--at", type=click.FloatRange(0.0), help="With --table: stop at T seconds after the first record.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
              help=VALUE_TYPE_HELP)
@click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
              help="For Buzz/BittyBuzz captures replayed onto another medium or shown with --table: their TOML map.")
@reports_errors
def command(file: str, onto: LinkSpec | None, speed: float, loop: bool, skip_gaps: float | None,
            ignore_timestamps: bool, robot_id: int, table: bool, at: float | None, value_type: ValueType,
            deployment: str | None) -> None:
    """Replay FILE onto a live link, or show what the swarm believed (--table).

    Ctrl-C or SIGTERM stops at once, even in a long gap: nothing is sent after it.

    Examples: vstig replay swarm.log --onto can:socketcan:vcan0 --speed 2;  vstig replay radio.cap --table --at 30
    """
    if table == (onto is not None):
        raise click.UsageError("give exactly one of --onto LINK or --table")
    if table:
        ignored = [name for name, given in (("--loop", loop), ("--skip-gaps", skip_gaps is not None),
                                            ("--ignore-timestamps", ignore_timestamps)) if given]
        if ignored:
            raise click.UsageError(f"{', '.join(ignored)} go with --onto, not --table")
        _table(file, at, value_type, deployment)
        return
    if at is not None:
        raise click.UsageError("--at goes with --table")
    assert onto is not None
    link = build_links([onto], robot_id)[0]
    send = _CountingSender(_sender(link, onto, deployment), link)
    link.open()
    passes_done = 0
    try:
        with stop_on_signals() as stop:
            passes: Iterator[int] = itertools.count() if loop else iter([0])
            for _ in passes:
                done = replay(read_capture(file), send, speed=speed, stop=stop, skip_gaps=skip_gaps,
                              ignore_timestamps=ignore_timestamps)
                passes_done += 1
                if stop.is_set() or done.frames == 0:
                    break
    finally:
        send.line.end()
        link.close()
    stats = link.stats()
    lost = stats["tx_dropped"] + stats["tx_timeout"]
    over = f" over {passes_done} passes" if loop else f" in {done.took:.3f} s (logged {done.logged:.3f} s)"
    click.echo(f"sent {stats['tx']} units{over}" + (f"; {lost} the link could not send" if lost else "")
               + ("; stopped by a signal" if done.stopped else ""), err=True)
    click.echo(f"{link.name}: {stats.summary()}", err=True)
