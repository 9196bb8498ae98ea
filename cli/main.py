"""`vstig`: the click group. Each command lives in its own module and registers here."""

from __future__ import annotations

import click

from vstig_hw import __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vstig")
def cli() -> None:
    """Put this PC into a robot swarm's virtual stigmergy through real radios."""


from .demo import demo  # noqa: E402

cli.add_command(demo)


def main() -> None:
    cli()


if __name__ == "__main__":
    main()
