"""`vstig demo`: about 30 robots on a virtual CAN bus and two pty radios, the gateway bridging them."""

from __future__ import annotations

import sys
from typing import Any

import click

from vstig_hw.demo.swarm import DemoConfig, DemoReport, Medium, run_demo
from vstig_hw.extras import require
from vstig_hw.gateway import stop_on_signals
from vstig_hw.wording import counted

from ..options import Finite
from ..running import reports_errors

# What the gateway's engine did with each message it heard, in plain words (docs/reference/counters.md).
_OUTCOMES = {
    "stored": ("newer entry stored", "newer entries stored"),
    "same": ("repeat of the entry held", "repeats of the entry held"),
    "conflict": ("conflict (same timestamp, another robot: the larger value kept)",
                 "conflicts (same timestamp, another robot: the larger value kept)"),
    "answered": ("GET answered with a newer entry", "GETs answered with a newer entry"),
    "stale": ("older PUT ignored", "older PUTs ignored"),
    "unknown": ("empty GET for a key not held", "empty GETs for a key not held"),
    "invalid": ("PUT with timestamp 0 refused", "PUTs with timestamp 0 refused"),
}
_LEGEND = """\
  messages: the PUTs and GETs its robots sent; frames: the CAN frames or radio
  packets carrying them. lost: each frame reaches every other robot (on a radio
  the gateway too) as one copy, and --drop {drop:g} loses each copy apart: lost is
  near {drop:.0%} of copies. framing drops: frames a robot's framing threw away, by
  reason. Every column and counter: docs/reference/counters.md."""


def _framing_drops(medium: Medium) -> str:
    """The robots' framing drops by reason, without their `drop_` prefix."""
    prefix = "drop_"
    return " ".join(f"{k[len(prefix):]}={v}" for k, v in sorted(medium.counters.items()) if k.startswith(prefix)) or "-"


def _lost(medium: Medium) -> str:
    """Copies the air lost, of those sent: `706 of 1000 (71%)`."""
    copies, lost = medium.counters["copies"], medium.counters["lost"]
    return f"{lost} of {copies}" + (f" ({lost / copies:.0%})" if copies else "")


def _live_table(step: int, media: list[Medium], agreed: int, total: int) -> Any:
    from rich import box
    from rich.table import Table

    table = Table(title=f"step {step}: {agreed}/{total} robots hold the highest id", box=box.SIMPLE_HEAD,
                  show_edge=False)
    # The summary's columns but the framing drops (the summary has them): a row never wraps at 80 columns.
    for column in ("medium", "robots", "agree", "messages", "frames", "bytes", "lost"):
        table.add_column(column, justify="left" if column == "medium" else "right")
    highest = total
    for medium in media:
        agree = sum(robot.entry(1) is not None and robot.entry(1).value == highest  # type: ignore[union-attr]
                    for robot in medium.robots)
        c = medium.counters
        table.add_row(medium.name, str(len(medium.robots)), str(agree), str(c["messages"]), str(c["frames"]),
                      str(c["bytes"]), _lost(medium))
    return table


def _engine(outcomes: dict[str, int]) -> list[str]:
    """`1 newer entry stored`, `94 repeats of the entry held`...: zeros left out."""
    return [counted(outcomes[name], one, many) for name, (one, many) in _OUTCOMES.items() if outcomes.get(name)]


def _report(report: DemoReport, drop: float) -> None:
    robots = sum(len(m.robots) for m in report.media)
    took = f"{counted(report.converged_at or report.steps, 'step')} ({report.seconds:.1f} s)"
    if report.converged_at is not None:
        click.echo(f"converged: all {robots} robots hold {report.highest} after {took}")
    else:
        click.echo(f"not converged after {took}")
    click.echo(f"{'medium':<7} {'robots':>6} {'messages':>8} {'frames':>6} {'bytes':>6}  lost")
    for medium in report.media:
        c = medium.counters
        click.echo(f"{medium.name:<7} {len(medium.robots):>6} {c['messages']:>8} {c['frames']:>6} {c['bytes']:>6}  "
                   f"{_lost(medium)}")
    dropped = [f"{medium.name} {_framing_drops(medium)}" for medium in report.media if _framing_drops(medium) != "-"]
    click.echo(f"framing drops: {'; '.join(dropped) or 'none'}")
    click.echo(_LEGEND.format(drop=drop))
    several = any("/" in name for name in report.gateway)  # names are "<gateway id>/<link>" then
    click.echo(f"{'each gateway' if several else 'the gateway'}'s links (counters: docs/reference/counters.md):")
    engines = {}
    for name, counters in report.gateway.items():
        if name == "engine" or name.endswith("/engine"):
            engines[name] = counters
        else:
            click.echo(f"  {name}: {counters.summary()}")
    for name, counters in engines.items():
        owner = f"gateway {name.split('/')[0]}" if several else "the gateway"
        click.echo(f"{owner}'s engine, for each message it heard:")
        for outcome in _engine(dict(counters)) or ["nothing heard"]:
            click.echo(f"  {outcome}")


@click.command()
@click.option("--robots", default=30, show_default=True, type=click.IntRange(6, 240),
              help="Swarm size, split over the three media.")
@click.option("--drop", default=0.75, show_default=True, type=Finite(0, 0.95),
              help="Probability that a robot (or the gateway, on a radio) misses a frame: each copy is lost apart.")
@click.option("--seed", default=1, show_default=True, type=int, help="Random seed: the same seed, the same run.")
@click.option("--step", default=0.1, show_default=True, type=Finite(0.01, 1.0),
              help="Seconds per control step.")
@click.option("--max-steps", default=300, show_default=True, type=click.IntRange(1, 10_000),
              help="Give up (exit 1) if the swarm has not agreed after this many control steps.")
@click.option("--gateways", default=1, show_default=True, type=click.IntRange(1, 2),
              help="2: the e-puck arena gets a gateway of its own, joined to the first by a zenoh link (loopback).")
@reports_errors
def command(robots: int, drop: float, seed: int, step: float, max_steps: int, gateways: int) -> None:
    """Robots split over a virtual CAN bus, a cobs8 radio and an epuck4 radio agree on the highest id.

    Everything below the robots is real: python-can's virtual bus, two ptys opened through pyserial,
    the real framings, and the gateway bridging them. With --gateways 2, two gateways (two arenas)
    join over a real Zenoh session on loopback, and the summary shows each gateway's traffic.
    """
    if gateways == 2:
        require("zenoh", "vstig demo --gateways 2")  # the gateways meet over a zenoh link
    config = DemoConfig(robots=robots, drop=drop, seed=seed, step=step, max_steps=max_steps, gateways=gateways)
    with stop_on_signals() as stop:
        if sys.stdout.isatty():
            from rich.live import Live

            with Live(refresh_per_second=8, transient=False) as live:
                report = run_demo(config, lambda s, media, agreed: live.update(
                    _live_table(s, media, agreed, robots)), stop)
        else:
            def line(s: int, media: list[Medium], agreed: int) -> None:
                if s % 5 == 0 or agreed == robots:
                    click.echo(f"step {s:3d}: {agreed:3d}/{robots} robots hold {robots}")

            report = run_demo(config, line, stop)
    if report.interrupted:  # run_demo sets `stop` itself to end its gateways: that is no interruption
        click.echo("interrupted", err=True)
    _report(report, drop)
    if report.converged_at is None and not report.interrupted:
        raise click.ClickException(f"the swarm did not converge in {counted(max_steps, 'step')}")
