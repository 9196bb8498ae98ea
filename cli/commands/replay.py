"""`vstig replay FILE --onto LINK` (faithful timing) or `--table [--at T]` (an offline engine)."""

from __future__ import annotations

import itertools
import time
from collections import Counter
from collections.abc import Iterator
from typing import Any

import click

from vstig_hw.capture.decoded import Decoder, default_framings, filter_records
from vstig_hw.capture.filters import Filter
from vstig_hw.capture.records import Damage, Record, read_capture
from vstig_hw.capture.replay import replay
from vstig_hw.engine import Stigmergy
from vstig_hw.gateway import stop_on_signals
from vstig_hw.links import Link, LinkSpec
from vstig_hw.values import VALUE_TYPES, ValueType, from_raw
from vstig_hw.wording import counted

from ..options import VALUE_TYPE_HELP, Finite, damage_option, echo_skipped, filter_options
from ..running import LINK, StatusLine, build_links, open_unless_stopped, reports_errors

_OBSERVER_ID = 0xFFFF  # the offline engine's id: it never writes, so it never wins a conflict it causes


def _sender(link: Link[Any], deployment: str | None) -> Any:
    """Write a record as is when the link's framing takes it so (`Framing.replay_unit`: the same framing, for XBee
    frames we sent, for CAN the default ID scheme a CAN capture is read with); otherwise re-encode its messages.
    """
    decoder = Decoder(default_framings(deployment=deployment))

    def send(record: Record) -> None:
        unit = link.replay_unit(record.unit, record.framing, record.direction)
        if unit is not None:
            link.write(unit)
            link.counters["out_units"] += 1
            return
        for decoded in decoder.decode(record):
            link.send(decoded.message)

    return send


class _CountingSender:
    """`send`, with a live counter line on stderr when it is a terminal (at most twice a second)."""

    def __init__(self, send: Any, links: list[Link[Any]]) -> None:
        self.send, self.links = send, links
        self.line = StatusLine()
        self.sent = 0
        self.next_draw = 0.0

    def __call__(self, record: Record) -> None:
        self.send(record)
        self.sent += 1
        if self.line.live and time.monotonic() >= self.next_draw:
            self.next_draw = time.monotonic() + 0.5
            self.line.show(f"sent {counted(self.sent, 'unit')}  " + "  ".join(f"{link.name}: {link.stats().summary()}"
                                                                     for link in self.links))


class OntoType(click.ParamType):  # type: ignore[type-arg]  # generic only from click 8.3; we take 8.1 up
    """`--onto SPEC` (every link of the capture) or `--onto NAME=SPEC` (the capture's link NAME)."""

    name = "[NAME=]LINK"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[str | None, Any]:
        if isinstance(value, tuple):
            return value
        name, sep, spec = value.partition("=")
        # A spec starts with its kind and a colon; link names never hold "=", so NAME=SPEC is unambiguous.
        if not sep or ":" in name:
            return None, LINK.convert(value, param, ctx)
        if not name:
            self.fail(f"{value!r}: the link name before '=' is empty", param, ctx)
        return name, LINK.convert(spec, param, ctx)


ONTO = OntoType()


def _targets(onto: tuple[tuple[str | None, LinkSpec], ...], robot_id: int) -> dict[str | None, Link[Any]]:
    """Link name (None: every link) -> the target link, built but not open."""
    names = [name for name, _ in onto]
    if None in names and len(onto) > 1:
        raise click.UsageError("give one --onto LINK for every link, or --onto NAME=LINK per link, not both")
    if len(set(names)) < len(names):
        raise click.UsageError("each capture link goes onto one target: a NAME appears in two --onto")
    links = build_links([spec.lossless() for _, spec in onto], robot_id)
    return dict(zip(names, links, strict=True))


def _table(path: str, at: float | None, value_type: ValueType, keep: Filter, deployment: str | None,
           damage: Damage) -> None:
    engine = Stigmergy(_OBSERVER_ID)
    decoder, reader = (Decoder(default_framings(deployment=deployment)) for _ in range(2))  # framings keep state
    t0 = None
    for decoded in decoder.decode_all(filter_records(read_capture(path, damage), keep, reader)):
        t0 = decoded.t if t0 is None else t0
        if at is not None and decoded.t - t0 > at:
            break
        engine.receive(decoded.message)
    when = "the end" if at is None else f"t={at:g} s"
    click.echo(f"what the swarm believed at {when} of {path}:")
    click.echo(f"{'key':>6} {'value':>8} {'ts':>6} {'robot':>6}")
    for key, entry in sorted(engine.entries()):
        click.echo(f"{key:>6} {from_raw(entry.value, value_type)!s:>8} {entry.timestamp:>6} {entry.robot:>6}")
    echo_skipped(damage.first)


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--onto", type=ONTO, multiple=True,
              help="Send the capture onto this link with its original timing; NAME=LINK sends only the capture's "
                   "link NAME there (repeat for each link; links not named are skipped).")
@click.option("--speed", type=Finite(0.001, 1000), default=1.0, show_default=True,
              help="Play this many times faster than recorded (0.5: half speed).")
@click.option("--loop", is_flag=True, help="Start again at the end, until Ctrl-C.")
@click.option("--skip-gaps", type=Finite(0.0), metavar="SECONDS",
              help="Wait at most SECONDS between two units, however long the capture's gap.")
@click.option("--ignore-timestamps", is_flag=True, help="Send every unit at once, one after the other.")
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), default=0, show_default=True,
              help="Sender id for messages re-encoded onto another medium.")
@click.option("--table", is_flag=True, help="Feed an offline engine instead and print its table.")
@click.option("--at", type=Finite(0.0), help="With --table: stop at T seconds after the first record.")
@click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
              help=VALUE_TYPE_HELP)
@click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
              help="For Buzz/BittyBuzz captures replayed onto another medium or shown with --table: their TOML map.")
@click.option("--verbose", "-v", is_flag=True,
              help="Say how the replay ran: under SCHED_FIFO (where permitted) or normal scheduling, and why.")
@damage_option
@filter_options
@reports_errors
def command(file: str, onto: tuple[tuple[str | None, LinkSpec], ...], speed: float, loop: bool,
            skip_gaps: float | None, ignore_timestamps: bool, robot_id: int, table: bool, at: float | None,
            value_type: ValueType, deployment: str | None, verbose: bool, damage: Damage, keep: Filter) -> None:
    """Replay FILE onto live links, or show what the swarm believed (--table).

    Ctrl-C, SIGTERM or SIGHUP stops at once, even in a long gap: nothing is sent after it.
    Where permitted (root or CAP_SYS_NICE) the replay runs under SCHED_FIFO; --verbose says which.
    A file cut short (its recorder was killed) is sent up to the cut, which is then
    reported: as an error, or with --skip-bad as a skipped line.

    The filters (--key, --robot, --sender, --op, --link, --since, --until) choose
    what is replayed; a serial chunk they cut is re-encoded in its framing.

    Examples: vstig replay swarm.log --onto can:socketcan:vcan0 --speed 2;
    vstig replay bridged.log --onto can0=can:socketcan:vcan0 --onto radio0=serial:/dev/ttyUSB1;
    vstig replay radio.cap --table --at 30
    """
    if table == bool(onto):
        raise click.UsageError("give exactly one of --onto LINK or --table")
    if table:
        ignored = [name for name, given in (("--loop", loop), ("--skip-gaps", skip_gaps is not None),
                                            ("--ignore-timestamps", ignore_timestamps)) if given]
        if ignored:
            raise click.UsageError(f"{', '.join(ignored)} go with --onto, not --table")
        _table(file, at, value_type, keep, deployment, damage)
        return
    if at is not None:
        raise click.UsageError("--at goes with --table")
    targets = _targets(onto, robot_id)
    senders = {name: _sender(link, deployment) for name, link in targets.items()}
    every_link = senders.get(None)
    reader = Decoder(default_framings(deployment=deployment))  # for filters that look into the messages
    unmapped: Counter[str] = Counter()

    def dispatch(record: Record) -> None:
        target = every_link or senders.get(record.link)
        if target is None:
            unmapped[record.link] += 1
        else:
            target(record)

    send = _CountingSender(dispatch, list(targets.values()))
    opened: list[Link[Any]] = []
    passes_done = 0
    try:
        with stop_on_signals() as stop:  # before the links open: a signal while they do is a clean stop too
            def open_links() -> None:
                for link in targets.values():
                    link.open()
                    opened.append(link)

            open_unless_stopped(open_links, stop)  # a stop while they open: nothing is sent, none waited for
            passes: Iterator[int] = itertools.count() if loop else iter([0])
            for _ in passes:
                damage = damage.fresh()  # what the last pass skipped
                done = replay(filter_records(read_capture(file, damage), keep, reader), send, speed=speed,
                              stop=stop, skip_gaps=skip_gaps, ignore_timestamps=ignore_timestamps)
                passes_done += 1
                if stop.is_set() or done.frames == 0:
                    break
    finally:
        send.line.end()
        for link in opened:
            link.close()
    stats = [link.stats() for link in targets.values()]
    sent = sum(s["tx"] for s in stats)
    lost = sum(s["tx_dropped"] + s["tx_timeout"] for s in stats)
    over = (f" over {counted(passes_done, 'pass', 'passes')}" if loop
            else f" in {done.took:.3f} s (logged {done.logged:.3f} s)")
    click.echo(f"sent {counted(sent, 'unit')}{over}" + (f"; {lost} the links could not send" if lost else "")
               + ("; stopped by a signal" if done.stopped else ""), err=True)
    for link in targets.values():
        click.echo(f"{link.name}: {link.stats().summary()}", err=True)
    if verbose:
        click.echo(f"replay thread: {done.scheduling}", err=True)
    if unmapped:
        skipped = ", ".join(f"{name} ({counted(count, 'unit')})" for name, count in sorted(unmapped.items()))
        click.echo(f"skipped links with no --onto: {skipped}", err=True)
    echo_skipped(damage.first)
