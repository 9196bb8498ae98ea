"""`vstig links`: the link-spec grammar, with examples."""

from __future__ import annotations

import click

from vstig_hw.links import examples, grammar, notes


@click.command()
def command() -> None:
    """List the link-spec grammar every command accepts, with examples."""
    click.echo("A LINK names a transport, a device and a framing in one string:\n")
    for rule in grammar():
        click.echo(f"  {rule}")
    click.echo("  Every kind also takes auth=require|prefer|off (default off): what a gateway with --swarm-key does "
               "with untagged messages and bad tags on it (docs/how-to/auth.md).")
    click.echo("\nExamples:")
    for specs in examples().values():
        for example in specs:
            click.echo(f"  {example}")
    click.echo("\nNotes:")
    for note in notes().values():
        click.echo(f"  {note}")
