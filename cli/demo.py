"""`vstig demo`: a virtual swarm converging on screen (in-process engines for now)."""

from __future__ import annotations

import random

import click

from vstig_hw import Stigmergy
from vstig_hw.engine import larger_value_wins


@click.command()
@click.option("--robots", default=10, show_default=True, type=click.IntRange(2, 1000))
@click.option("--drop", default=0.5, show_default=True, type=click.FloatRange(0, 0.99), help="drop probability")
@click.option("--seed", default=1, show_default=True, type=int)
def command(robots: int, drop: float, seed: int) -> None:
    """Fully connected robots agree on the highest id (the paper's task)."""
    rng = random.Random(seed)
    swarm = [Stigmergy(robot_id, onconflict=larger_value_wins) for robot_id in range(1, robots + 1)]
    for engine in swarm:
        engine.put(1, engine.robot_id)
    for step in range(1, 201):
        outgoing = [(sender, engine.drain(1)) for sender, engine in enumerate(swarm)]
        for sender, messages in outgoing:
            for receiver, engine in enumerate(swarm):
                if receiver != sender:
                    for msg in messages:
                        if rng.random() >= drop:
                            engine.receive(msg)
        values = [engine.get(1) for engine in swarm]
        agreed = sum(v == robots for v in values)
        click.echo(f"step {step:3d}: {agreed:3d}/{robots} robots hold {robots}")
        if agreed == robots:
            click.echo(f"converged in {step} steps")
            return
    raise click.ClickException("did not converge in 200 steps")
