"""The `vstig` group itself: help and version, in-process and as the installed script."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from vstig_cli.main import cli
from vstig_hw import __version__


def test_version_and_help() -> None:
    runner = CliRunner()
    result = runner.invoke(cli, ["--version"])
    assert result.exit_code == 0 and __version__ in result.output
    result = runner.invoke(cli, ["--help"])
    assert result.exit_code == 0 and "swarm" in result.output


def test_installed_console_script_runs() -> None:
    vstig = Path(sys.executable).with_name("vstig")
    assert vstig.exists(), f"the vstig console script is not installed beside {sys.executable}"
    done = subprocess.run([vstig, "--version"], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0 and __version__ in done.stdout


def test_version_says_which_data_path_runs_and_vstig_pure_turns_the_compiled_one_off() -> None:
    from vstig_hw.native import why_pure

    vstig = Path(sys.executable).with_name("vstig")
    done = subprocess.run([vstig, "--version"], capture_output=True, text=True, timeout=60, check=False)
    said = "compiled" if not why_pure else f"pure Python: {why_pure}"
    assert done.stdout == f"vstig {__version__} (data path: {said})\n"
    pure = subprocess.run([vstig, "--version"], capture_output=True, text=True, timeout=60, check=False,
                          env={**os.environ, "VSTIG_PURE": "1"})
    assert pure.stdout == f"vstig {__version__} (data path: pure Python: VSTIG_PURE=1)\n"


def test_cli_folder_is_not_installed_as_top_level_cli() -> None:
    import importlib.util

    spec = importlib.util.find_spec("vstig_cli")
    assert spec is not None and spec.origin is not None and spec.origin.endswith("cli/__init__.py")


def test_command_list_in_help_matches_what_each_command_says() -> None:
    import click

    ctx = click.Context(cli)
    for width in (80, 200):
        ours, clicks = click.HelpFormatter(width=width), click.HelpFormatter(width=width)
        cli.format_commands(ctx, ours)
        click.Group.format_commands(cli, ctx, clicks)  # imports every command to ask it
        assert ours.getvalue() == clicks.getvalue() and "sniff" in ours.getvalue()


def test_the_commands_are_the_modules_of_the_commands_folder_and_nothing_else() -> None:
    import click

    folder = Path(__file__).parents[2] / "cli" / "commands"
    modules = sorted(p.stem.replace("_", "-") for p in folder.glob("*.py") if not p.stem.startswith("_"))
    assert cli.list_commands(click.Context(cli)) == modules
    assert {"analyze", "bridge", "decode", "demo", "get", "links", "put", "record", "replay", "sim", "sniff"} <= set(
        modules)
    assert not {"main", "options", "running"} & set(modules)  # the shared helpers live outside the folder


def test_help_does_not_import_the_heavy_libraries() -> None:
    probe = ("import sys\nfrom vstig_cli.main import cli\n"
             "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
             "print(sorted({'numpy', 'can', 'matplotlib', 'rich'} & {m.split('.')[0] for m in sys.modules}))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout
