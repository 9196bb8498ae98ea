"""`vstig links`: the link-spec grammar, with examples."""

from __future__ import annotations

import click

from vstig_hw.links.spec import EXAMPLES, GRAMMAR, NOTES


@click.command()
def command() -> None:
    """List the link-spec grammar every command accepts, with examples."""
    click.echo("A LINK names a transport, a device and a framing in one string:\n")
    for rule in GRAMMAR:
        click.echo(f"  {rule}")
    click.echo("\nExamples:")
    for examples in EXAMPLES.values():
        for example in examples:
            click.echo(f"  {example}")
    click.echo("\nNotes:")
    for note in NOTES.values():
        click.echo(f"  {note}")
