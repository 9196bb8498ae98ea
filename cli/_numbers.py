"""Command-line numbers: finite floats for every float option, a KEY in decimal or hex, and negative VALUEs
without `--` (put, get)."""

from __future__ import annotations

import math
import re
from typing import Any

import click

from vstig_hw.wire import KEY_MAX

# What a negative VALUE looks like (int16 -5, float16 -1.5e3, -inf, -0x10): an argument, not an option.
_NEGATIVE_NUMBER = re.compile(r"-(\d|\.\d|inf\b|nan\b)", re.IGNORECASE)


class Finite(click.FloatRange):
    """A float option's type: a finite number, within the bounds given (as click.FloatRange).

    Click's FloatRange lets NaN through every bound (no comparison with NaN is true) and `inf` through an open
    one: `--wait nan` would wait for ever, `--speed nan` send everything at once. Every float option uses this
    type (tests/cli/test_option_values.py walks them all).
    """

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return super().convert(number, param, ctx)


def finite(text: str) -> float:
    """A finite float from text a command splits itself (`--drops 0,0.5`); ValueError otherwise."""
    number = float(text)
    if not math.isfinite(number):
        raise ValueError(f"{text!r} is not a finite number")
    return number


_SIZE_UNITS = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30}


class ByteSize(click.ParamType):
    """A positive size in bytes: 500000, 64k, 10M, 1G."""

    name = "SIZE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        if isinstance(value, int):
            return value
        text = str(value)
        scale = _SIZE_UNITS.get(text[-1:].lower(), 1)
        number = text[:-1] if scale > 1 else text
        if not number.isdigit() or int(number) <= 0:
            self.fail(f"{text!r} is not a size like 500000, 64k or 10M", param, ctx)
        return int(number) * scale


class WireKey(click.ParamType):
    """A stigmergy key, 0..32767, written as VALUE may be: 23, 0x17, 0o27, 0b10111."""

    name = "KEY"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        if isinstance(value, int):
            number = value
        else:
            try:
                number = int(str(value), 0)
            except ValueError:
                self.fail(f"{value!r} is not an integer (e.g. 23 or 0x17)", param, ctx)
        if not 0 <= number <= KEY_MAX:
            self.fail(f"{value} is outside 0..{KEY_MAX} ({KEY_MAX:#x})", param, ctx)
        return number


KEY = WireKey()


class NegativeNumbersAreArguments(click.Command):
    """A command whose arguments may be negative numbers: `vstig put 3 -5`, no `--` needed.

    Click reads every token that starts with '-' as an option. Here a token that
    reads as a number and is not an option's value is an argument; any other
    unknown option is still the usual usage error.
    """

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        options = [p for p in self.get_params(ctx) if isinstance(p, click.Option)]
        known = {name for p in options for name in (*p.opts, *p.secondary_opts)}
        takes_value = {name for p in options if not p.is_flag and not p.count for name in p.opts}
        value_next = False
        for arg in args:
            if arg == "--":
                break
            name = arg.split("=", 1)[0]
            if arg.startswith("-") and not value_next and name not in known and not _NEGATIVE_NUMBER.match(arg):
                raise click.NoSuchOption(name, possibilities=sorted(known), ctx=ctx)
            value_next = not value_next and name in takes_value and "=" not in arg
        ctx.ignore_unknown_options = True  # what is left unknown is a negative number
        return super().parse_args(ctx, args)
