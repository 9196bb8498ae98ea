"""The generated reference covers what exists: every `vstig` command has its block on the CLI page."""

from __future__ import annotations

import importlib.util
import re

import click
import pytest
from docs_blocks import ROOT

from vstig_cli.main import cli


def test_every_command_is_on_the_cli_reference() -> None:
    page = (ROOT / "docs" / "reference" / "cli.md").read_text(encoding="utf-8")
    documented = re.findall(r"^\s+:module: vstig_cli\.commands\.(\w+)\n\s+:command: command\n"
                            r"\s+:prog_name: vstig ([\w-]+)$", page, flags=re.M)
    commands = cli.list_commands(click.Context(cli))
    assert len(commands) >= 10
    assert sorted(name for _, name in documented) == sorted(commands), "a command is missing from cli.md"
    assert all(module == name.replace("-", "_") for module, name in documented)


def test_pages_include_sections_of_files_kept_elsewhere() -> None:
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs_hooks.py")  # mkdocs loads it so
    assert spec is not None and spec.loader is not None
    docs_hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(docs_hooks)
    page = docs_hooks.include("{{ include firmware_spec/DECISIONS.md#differences-from-buzz }}")
    assert "| timestamp order |" in page and "serial-number arithmetic" in page
    assert "](#" not in page, "links into the included file must become text"
    with pytest.raises(ValueError, match="no section 'no-such-section'"):
        docs_hooks.include("{{ include firmware_spec/DECISIONS.md#no-such-section }}")
