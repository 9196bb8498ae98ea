"""One place for how every command fails: usage errors exit 2, runtime failures exit 1.

Each failure is one clear line naming the input; `vstig --debug ...` (or
VSTIG_DEBUG=1) shows the traceback too.
"""

from __future__ import annotations

import functools
import os
import traceback
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

from vstig_hw.capture.records import CaptureError

if TYPE_CHECKING:
    from vstig_hw.links import LinkSpec

F = TypeVar("F", bound=Callable[..., Any])


def runtime_errors() -> tuple[type[Exception], ...]:
    """The errors a user can cause; the transports' module is loaded only once something failed (decode never
    loads a transport)."""
    from vstig_hw.transports.base import TransportError

    return (TransportError, CaptureError, OSError, ValueError, RuntimeError)


def one_line(error: BaseException) -> str:
    """The transports' one-line form of an error, loaded (like `runtime_errors`) only once something failed."""
    from vstig_hw.transports.base import one_line

    return one_line(error)


def debugging() -> bool:
    ctx = click.get_current_context(silent=True)
    root = ctx.find_root() if ctx else None
    return bool(os.environ.get("VSTIG_DEBUG")) or bool(root and (root.obj or {}).get("debug"))


def describe(error: BaseException) -> str:
    """One line for the user: an OS error names its file first (`/proc/x: No such file or directory`)."""
    if isinstance(error, OSError) and error.strerror and error.filename is not None:
        return f"{error.filename}: {error.strerror}"
    return one_line(error)


def reports_errors(fn: F) -> F:
    """Turn the runtime errors a user can cause into one line and exit status 1.

    Ctrl-C passes through to `main`, which ends every command the same way (status 130, quietly).
    """

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort, KeyboardInterrupt):
            raise
        except Exception as error:
            if debugging():
                traceback.print_exc()
            if isinstance(error, runtime_errors()):
                raise click.ClickException(describe(error)) from None
            # a bug, not the user's fault: still one line unless debugging
            raise click.ClickException(f"unexpected {type(error).__name__}: {one_line(error)} "
                                       "(run `vstig --debug ...` for the traceback)") from None

    wrapper.reports_errors = True  # type: ignore[attr-defined]
    return wrapper  # type: ignore[return-value]


class LinkSpecType(click.ParamType):
    """A link spec on the command line; a bad one is a usage error (exit 2) naming the bad part."""

    name = "LINK"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> LinkSpec:
        from vstig_hw.links import LinkSpec, parse  # when a command takes links: decode never loads them

        if isinstance(value, LinkSpec):
            return value
        try:
            return parse(value)
        except ValueError as error:
            self.fail(str(error), param, ctx)


LINK = LinkSpecType()
