"""`vstig`: the click group.

Each command lives in its own module of this package, named after the command,
and exposes it as `command`. The group finds them by module name and imports one
only when it runs, so `vstig put` does not pay for numpy or matplotlib.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import click

from vstig_hw import __version__

_NOT_COMMANDS = {"main", "errors"}


class CommandFolder(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        names = (m.name for m in pkgutil.iter_modules([str(Path(__file__).parent)]))
        return sorted(n.replace("_", "-") for n in names if not n.startswith("_") and n not in _NOT_COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.list_commands(ctx):
            return None
        module = importlib.import_module(f"{__package__}.{cmd_name.replace('-', '_')}")
        command: click.Command = module.command
        return command


@click.group(cls=CommandFolder, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vstig")
@click.option("--debug", is_flag=True, help="On failure, show the traceback too.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Put this PC into a robot swarm's virtual stigmergy through real radios."""
    ctx.obj = {"debug": debug}


def main() -> None:
    cli()


if __name__ == "__main__":
    main()
