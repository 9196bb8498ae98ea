"""Option values a user can mistype: every float option is finite, counts and sizes are bounded, and each
refusal is a usage error (exit 2) naming the option."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from vstig_cli.main import cli
from vstig_cli.options import Finite

CAPTURE = "(1.000000) can0 600#0001000200030004\n"


def _commands(group: click.Group, ctx: click.Context, path: str = "") -> Iterator[tuple[str, click.Command]]:
    for name in group.list_commands(ctx):
        command = group.get_command(ctx, name)
        assert command is not None, name
        yield f"{path}{name}", command
        if isinstance(command, click.Group):
            yield from _commands(command, click.Context(command, parent=ctx), f"{path}{name} ")


def test_no_float_option_takes_nan_or_inf() -> None:
    """Every float parameter of every command is Finite: a plain FLOAT or FloatRange lets NaN through."""
    ctx = click.Context(cli)
    floats = [(name, param.name) for name, command in _commands(cli, ctx) for param in command.params
              if isinstance(param.type, click.types.FloatParamType)]
    assert floats, "the walk found no float option at all"
    plain = [(name, option) for name, command in _commands(cli, ctx) for param in command.params
             if isinstance(param.type, click.types.FloatParamType) and not isinstance(param.type, Finite)
             for option in [param.name]]
    assert plain == []


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "NaN"])
@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["put", "3", "5", "--on", "can:virtual:x", "--wait", "{bad}"], "--wait"),
        (["get", "3", "--on", "can:virtual:x", "--wait", "{bad}"], "--wait"),
        (["put", "3", "5", "--on", "can:virtual:x", "--learn", "{bad}"], "--learn"),
        (["replay", "{capture}", "--table", "--speed", "{bad}"], "--speed"),
        (["replay", "{capture}", "--table", "--at", "{bad}"], "--at"),
        (["decode", "{capture}", "--since", "{bad}"], "--since"),
        (["decode", "{capture}", "--until", "{bad}"], "--until"),
        (["analyze", "{capture}", "--window", "{bad}"], "--window"),
        (["sniff", "can:virtual:x", "--for", "{bad}"], "--for"),
        (["record", "can:virtual:x", "-o", "{capture}.log", "--for", "{bad}"], "--for"),
        (["bridge", "can:virtual:x", "can:virtual:y", "--robot-id", "1", "--rate", "{bad}"], "--rate"),
        (["sim", "--drop", "{bad}"], "--drop"),
        (["sim", "--range", "{bad}"], "--range"),
        (["sim", "paper-motion", "--drops", "0,{bad}"], "--drops"),
        (["demo", "--step", "{bad}"], "--step"),
    ],
)
def test_a_float_option_refuses_nan_and_inf_naming_the_option(tmp_path: Path, args: list[str], option: str,
                                                             bad: str) -> None:
    capture = tmp_path / "c.log"
    capture.write_text(CAPTURE)
    line = [arg.format(bad=bad, capture=capture) for arg in args]
    result = CliRunner().invoke(cli, line)
    assert result.exit_code == 2, result.output
    assert option in result.output and "Traceback" not in result.output, result.output


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["sim", "--seed", "-5", "--runs", "1"], "--seed"),
        (["sim", "paper", "--seed", "-5", "--runs", "1"], "--seed"),
        (["record", "can:virtual:x", "-o", "{tmp}/r.log", "--max-bytes", "-5"], "--max-bytes"),
        (["record", "can:virtual:x", "-o", "{tmp}/r.log", "--max-bytes", "0"], "--max-bytes"),
    ],
)
def test_a_negative_count_or_size_is_a_usage_error_naming_the_option(tmp_path: Path, args: list[str],
                                                                      option: str) -> None:
    result = CliRunner().invoke(cli, [arg.format(tmp=tmp_path) for arg in args])
    assert result.exit_code == 2, result.output
    assert f"Invalid value for '{option}'" in result.output and "Traceback" not in result.output, result.output


def test_sniff_on_a_missing_port_says_only_the_error() -> None:
    result = CliRunner().invoke(cli, ["sniff", "serial:/dev/vstig-no-such-port"])  # stdout is no terminal here
    assert result.exit_code == 1
    assert result.output.splitlines() == [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert "vstig-no-such-port" in result.output
