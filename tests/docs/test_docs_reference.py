"""The generated reference covers what exists: every `vstig` command has its block on the CLI page."""

from __future__ import annotations

import re

import click
from docs_blocks import ROOT

from vstig_cli.main import cli


def test_every_command_is_on_the_cli_reference() -> None:
    page = (ROOT / "docs" / "reference" / "cli.md").read_text(encoding="utf-8")
    documented = re.findall(r"^\s+:module: vstig_cli\.(\w+)\n\s+:command: command\n\s+:prog_name: vstig ([\w-]+)$",
                            page, flags=re.M)
    commands = cli.list_commands(click.Context(cli))
    assert len(commands) >= 10
    assert sorted(name for _, name in documented) == sorted(commands), "a command is missing from cli.md"
    assert all(module == name.replace("-", "_") for module, name in documented)
