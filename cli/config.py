"""`--config FILE` and `--print-config`: the options and links of a command that runs unattended (bridge, sniff,
record) from a TOML file, the command line overriding it.

A file's top-level keys are the command's long option names without their dashes (`robot-id`, `max-jump`,
`for`, `refresh = false` for `--no-refresh`) and `links`, a list of link specs:

    links = ["can:socketcan:can0", "serial:/dev/ttyUSB0?framing=epuck4"]
    robot-id = 200
    trust = ["can0=1-20"]

Each value goes through the option's own type and checks, so a file is refused exactly where the command
line would be (`tick = nan`, `budget = 0`), and every error names the file, the line and the option (exit 2).
An option given on the command line replaces the file's (a repeatable one's whole list; LINKs replace
`links`). The file follows the deployment-file rules (vstig_hw.inputs: a regular file of at most 1 MiB).
`--print-config` writes the effective configuration as such a file and runs nothing.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Callable, Iterable
from typing import Any

import click
from click.core import ParameterSource

from vstig_hw.inputs import InputFileError, parse_toml, read_regular, toml_line

__all__ = ["CONFIG_MAX_BYTES", "ConfiguredCommand", "config_options", "shown"]

CONFIG_MAX_BYTES = 1 << 20  # a gateway's options and links fit in a few kilobytes
_ARGV = "vstig.config.argv"  # ctx.meta: the command line as given, read again by --print-config
_FILE = "vstig.config.file"  # ctx.meta: the file's values as text, by parameter name
_PRINT = "vstig.config.print"
_ECHO = 80  # characters of a value an error shows
_MESSAGE = 1000  # characters of an error line

Scalar = str | int | float | bool


class ConfiguredCommand(click.Command):
    """A command whose options may come from `--config FILE`; with `--print-config` it prints them instead of
    running."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        ctx.meta[_ARGV] = list(args)
        return super().parse_args(ctx, args)

    def invoke(self, ctx: click.Context) -> Any:
        if ctx.meta.get(_PRINT):
            click.echo(effective_config(ctx), nl=False)
            return None
        return super().invoke(ctx)


def config_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Add --config and --print-config to a ConfiguredCommand (neither reaches its function)."""
    fn = click.option("--print-config", is_flag=True, expose_value=False,
                      callback=lambda ctx, _param, value: ctx.meta.__setitem__(_PRINT, value),
                      help="Print the effective configuration (the --config file's values, then the command "
                           "line's) as a TOML file --config reads, and exit.")(fn)
    return click.option("--config", metavar="FILE", expose_value=False, is_eager=True, callback=_load,
                        help="Take options and links from this TOML file (keys: the long option names, and "
                             "links = [...]); the command line overrides it.")(fn)


def config_keys(command: click.Command, ctx: click.Context) -> dict[str, click.Parameter]:
    """The command's parameters a config file may set, by key: `links`, `robot-id`, `for`..."""
    keys: dict[str, click.Parameter] = {}
    for param in command.get_params(ctx):
        if not param.expose_value or param.name is None:
            continue
        if isinstance(param, click.Option):
            long = [opt for opt in param.opts if opt.startswith("--")]
            keys[long[0][2:] if long else param.name] = param
        else:
            keys[param.name] = param
    return keys


def _load(ctx: click.Context, _param: click.Parameter, path: str | None) -> None:
    """Read FILE, check every value as its option would, and make them the command's defaults."""
    if path is None:
        return
    try:
        data = read_regular(path, CONFIG_MAX_BYTES, "the config file")
    except InputFileError as error:
        raise click.UsageError(str(error)) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise click.UsageError(f"{path}:{line}: not UTF-8 text") from None
    try:
        doc = parse_toml(text, path)
    except InputFileError as error:
        raise click.UsageError(str(error)) from None
    keys = config_keys(ctx.command, ctx)
    values: dict[str, Any] = {}
    for key, value in doc.items():
        where = f"{path}{toml_line(text, key)}"
        param = keys.get(key)
        if param is None:
            raise click.UsageError(f"{where}: {shown(key)} is not an option of vstig {ctx.info_name}"
                                   f"{_did_you_mean(key, keys)} (the keys: {', '.join(keys)})")
        raw = _as_text(value, param, f"{where}: {key}")
        try:
            param.process_value(ctx, raw)  # its type and callback: refused as on the command line
        except click.BadParameter as error:
            raise click.UsageError(f"{where}: {key}: {_capped(error.message, raw)}") from None
        values[param.name or key] = raw
    ctx.meta[_FILE] = values
    ctx.default_map = {**(ctx.default_map or {}), **values}


def _did_you_mean(key: str, keys: Iterable[str]) -> str:
    """`robot_id`: did you mean robot-id? (the closest key, by difflib, if one is close)"""
    close = difflib.get_close_matches(key.replace("_", "-").lower(), list(keys), n=1, cutoff=0.6)
    return f"; did you mean {close[0]}?" if close else ""


def shown(value: str) -> str:
    """A value as an error echoes it: quoted, and cut after _ECHO characters (a 1 MB string is not a line)."""
    return repr(value) if len(value) <= _ECHO else f"{value[:_ECHO]!r}… ({len(value.encode())} bytes)"


def _capped(message: str, raw: str | tuple[str, ...]) -> str:
    """An option's error with each long value it echoes cut (click's own messages quote them whole)."""
    for value in (raw,) if isinstance(raw, str) else raw:
        if len(value) > _ECHO:
            message = message.replace(repr(value), shown(value)).replace(value, shown(value))
    if len(message) <= _MESSAGE:  # escaped forms the replace missed: cut the line itself
        return message
    return f"{message[:_MESSAGE]}… ({len(message.encode())} bytes)"


def _many(param: click.Parameter) -> bool:
    return param.multiple or param.nargs == -1


def _as_text(value: Any, param: click.Parameter, where: str) -> str | tuple[str, ...]:
    """A TOML value as the text the command line would have given (a list for a repeatable option)."""
    if _many(param):
        if not isinstance(value, list):
            raise click.UsageError(f"{where}: a list, e.g. [\"...\", \"...\"]")
        return tuple(_scalar_text(item, where) for item in value)
    return _scalar_text(value, where)


def _scalar_text(value: Any, where: str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)  # nan and inf stay words the option's type refuses by name
    if isinstance(value, str):
        return value
    kind = "a table" if isinstance(value, dict) else "a list" if isinstance(value, list) else type(value).__name__
    raise click.UsageError(f"{where}: {kind} is not a value this option takes")


# -- --print-config: the effective configuration, as a file --config reads back.

def effective_config(ctx: click.Context) -> str:
    """Every option of the command with the value it runs with (unset ones as comments), as TOML."""
    command = ctx.command
    parser = command.make_parser(ctx)
    given, _, _ = parser.parse_args(args=list(ctx.meta.get(_ARGV, [])))
    from_file: dict[str, Any] = ctx.meta.get(_FILE, {})
    lines = [f"# vstig {ctx.info_name}: the effective configuration (--config FILE reads it back)"]
    for key, param in config_keys(command, ctx).items():
        name = param.name or key
        source = ctx.get_parameter_source(name)
        value = ctx.params.get(name)
        if not _plain(value, param):  # a link spec, an address, an id list: the text it was given as
            value = given.get(name) if source == ParameterSource.COMMANDLINE else from_file.get(name, value)
        if value is None or (_many(param) and not value) or not _plain(value, param):
            lines.append(f"# {key}: not set")
        else:
            lines.append(f"{key} = {_toml(value)}")
    return "\n".join(lines) + "\n"


def _plain(value: Any, param: click.Parameter) -> bool:
    scalar = (str, int, float, bool)
    if _many(param):
        return isinstance(value, tuple | list) and all(isinstance(item, scalar) for item in value)
    return isinstance(value, scalar)


def _toml(value: Scalar | Iterable[Scalar]) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value).replace("\x7f", "\\u007f")  # JSON's escapes are TOML's; DEL must be escaped too
    return "[" + ", ".join(_toml(item) for item in value) + "]"
