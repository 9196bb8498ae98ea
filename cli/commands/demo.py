"""`vstig demo`: about 30 robots on a virtual CAN bus and two pty radios, the gateway bridging them."""

from __future__ import annotations

import sys
from typing import Any

import click

from vstig_hw.demo.swarm import DemoConfig, DemoReport, Medium, run_demo
from vstig_hw.extras import require
from vstig_hw.gateway import stop_on_signals

from ..options import Finite
from ..running import reports_errors


def _drops(medium: Medium) -> str:
    """The medium's drops by reason, without their `drop_` prefix."""
    prefix = "drop_"
    return " ".join(f"{k[len(prefix):]}={v}" for k, v in sorted(medium.counters.items()) if k.startswith(prefix)) or "-"


def _live_table(step: int, media: list[Medium], agreed: int, total: int) -> Any:
    from rich.table import Table

    table = Table(title=f"step {step}: {agreed}/{total} robots hold the highest id")
    for column in ("medium", "robots", "agree", "messages", "bytes", "drops"):
        table.add_column(column, justify="left" if column in ("medium", "drops") else "right")
    highest = total
    for medium in media:
        agree = sum(robot.entry(1) is not None and robot.entry(1).value == highest  # type: ignore[union-attr]
                    for robot in medium.robots)
        table.add_row(medium.name, str(len(medium.robots)), str(agree), str(medium.counters["messages"]),
                      str(medium.counters["bytes"]), _drops(medium))
    return table


def _report(report: DemoReport) -> None:
    if report.converged_at is not None:
        click.echo(f"converged: all {sum(len(m.robots) for m in report.media)} robots hold {report.highest} "
                   f"after {report.converged_at} steps ({report.seconds:.1f} s)")
    else:
        click.echo(f"not converged after {report.steps} steps ({report.seconds:.1f} s)")
    click.echo(f"{'medium':<8} {'robots':>6} {'messages':>9} {'bytes':>8}  drops by reason")
    for medium in report.media:
        click.echo(f"{medium.name:<8} {len(medium.robots):>6} {medium.counters['messages']:>9} "
                   f"{medium.counters['bytes']:>8}  {_drops(medium)}")
    for name, counters in report.gateway.items():
        click.echo(f"gateway {name}: {counters.summary()}")


@click.command()
@click.option("--robots", default=30, show_default=True, type=click.IntRange(6, 240),
              help="Swarm size, split over the three media.")
@click.option("--drop", default=0.75, show_default=True, type=Finite(0, 0.95),
              help="Probability that a robot (or the gateway, on a radio) misses a message.")
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
    _report(report)
    if report.converged_at is None and not report.interrupted:
        raise click.ClickException(f"the swarm did not converge in {max_steps} steps")
