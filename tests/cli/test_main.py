"""The `vstig` group itself: help and version, in-process and as the installed script."""

from __future__ import annotations

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


def test_cli_folder_is_not_installed_as_top_level_cli() -> None:
    import importlib.util

    spec = importlib.util.find_spec("vstig_cli")
    assert spec is not None and spec.origin is not None and spec.origin.endswith("cli/__init__.py")
