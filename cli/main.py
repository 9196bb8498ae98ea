"""`vstig`: the click group.

Each command lives in its own module of `commands/`, named after the command, and
exposes it as `command`; the shared options and the helpers for running and failing
live beside it (`options.py`, `running.py`), so no helper can become a command. The
group finds commands by module name and imports one only when it runs, so
`vstig put` does not pay for numpy or matplotlib. The command list in `vstig --help`
reads each command's docstring from its source for the same reason: importing them
all would load numpy and python-can.
A command beyond the core install (`_NEEDS_EXTRA`) whose extra is missing is refused
with one line naming the extra, before its module is imported.

Every command, loaded here, goes through `reports_errors`, and `main` is the
one place a run ends: usage errors exit 2, runtime failures 1 (one line each),
Ctrl-C 130 quietly (a shell's status for SIGINT), a closed output pipe 0 quietly (`| head`).

A stop (SIGINT, SIGTERM, SIGHUP) is taken over before anything heavy is imported: click,
the library and a command's python-can or zenoh take 0.2-0.5 s, and a SIGTERM then used to
kill vstig with no word. One that comes while vstig starts is kept and acted on once `run`
begins; from then until a command takes the signals over itself (`stop_on_signals`), a
stop ends the command as Ctrl-C does: status 0 for the commands that run until stopped
(they were asked to stop, and stopped), 130 for the others.
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType


class _EarlyStop:
    """Until `run` is under way a stop is only kept; from then on it interrupts (KeyboardInterrupt), as Ctrl-C."""

    def __init__(self) -> None:
        self.signum: int | None = None  # the first stop that came
        self.armed = False  # `run` is under way: a stop interrupts at once
        self.pid = os.getpid()  # a process forked from this one (sim's workers) keeps the signals' defaults

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        if os.getpid() != self.pid:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        if self.signum is None:
            self.signum = signum
        if self.armed:
            raise KeyboardInterrupt

    def install(self) -> None:
        for name in ("SIGINT", "SIGTERM", "SIGHUP"):  # SIGHUP: not on Windows; under nohup it stays ignored
            signum = getattr(signal, name, None)
            if signum is not None and signal.getsignal(signum) is not signal.SIG_IGN:
                signal.signal(signum, self)


_EARLY_STOP = _EarlyStop()
# Only when this process is the `vstig` program (its console script, or `python -m vstig_cli.main`): a program
# that imports the CLI (a test runner) keeps its own handlers.
if __name__ == "__main__" or os.path.basename(sys.argv[0]).removesuffix(".exe") == "vstig":
    _EARLY_STOP.install()

import ast  # noqa: E402  (the imports come after the handlers: that is the point)
import contextlib  # noqa: E402
import importlib  # noqa: E402
import pkgutil  # noqa: E402
from pathlib import Path  # noqa: E402

import click  # noqa: E402

from vstig_hw import __version__  # noqa: E402
from vstig_hw.extras import MissingExtra, require  # noqa: E402

from .running import flush_streams, guard_streams, reports_errors  # noqa: E402

INTERRUPTED = 128 + 2  # the shell's status for a command ended by SIGINT
# The commands whose normal end is a stop: they exit 0 on one, from the moment they start (docs/how-to/bridge.md).
RUN_UNTIL_STOPPED = frozenset({"bridge", "sniff", "record", "replay", "demo"})

# Commands beyond the core install: the extra each needs, and which of its modules the command loads
# as it starts (None: all of them). Checked before the command's module is imported.
_NEEDS_EXTRA: dict[str, tuple[str, tuple[str, ...] | None]] = {"sim": ("sim", None), "analyze": ("analyze", ("numpy",))}
_COMMANDS = Path(__file__).parent / "commands"


def _module(cmd_name: str) -> str:
    return cmd_name.replace("-", "_")


def _docstring(cmd_name: str) -> str:
    """The docstring of the module's `command` function, read without importing the module."""
    tree = ast.parse((_COMMANDS / f"{_module(cmd_name)}.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "command":
            return ast.get_docstring(node) or ""
    return ""


class CommandFolder(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        names = (m.name for m in pkgutil.iter_modules([str(_COMMANDS)]))
        return sorted(n.replace("_", "-") for n in names if not n.startswith("_"))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.list_commands(ctx):
            return None
        if cmd_name in _NEEDS_EXTRA:
            extra, modules = _NEEDS_EXTRA[cmd_name]
            try:
                require(extra, f"vstig {cmd_name}", modules)
            except MissingExtra as error:  # a runtime failure (exit 1), before any of the command runs
                raise click.ClickException(str(error)) from None
        module = importlib.import_module(f"{__package__}.commands.{_module(cmd_name)}")
        command: click.Command = module.command
        _report_errors(command)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        names = self.list_commands(ctx)
        if not names:
            return
        limit = formatter.width - 6 - max(map(len, names))
        with formatter.section("Commands"):
            # A bare Command with the same help shortens it exactly as the real one would.
            formatter.write_dl([(name, click.Command(name, help=_docstring(name)).get_short_help_str(limit))
                                for name in names])


def _version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    """--version: the version, and which data path this install runs (the compiled one, or pure Python and why)."""
    if not value or ctx.resilient_parsing:
        return
    from vstig_hw.native import why_pure

    click.echo(f"vstig {__version__} (data path: {f'pure Python: {why_pure}' if why_pure else 'compiled'})")
    ctx.exit()


@click.group(cls=CommandFolder, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--version", is_flag=True, expose_value=False, is_eager=True, callback=_version,
              help="Show the version and which data path runs (compiled, or pure Python and why), and exit.")
@click.option("--debug", is_flag=True, help="On failure, show the traceback too.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Put this PC into a robot swarm's virtual stigmergy through real radios."""
    ctx.obj = {"debug": debug}


def _report_errors(command: click.Command) -> None:
    """Put the command (and a group's subcommands) behind the one error wrapper, once."""
    if command.callback is not None and not getattr(command.callback, "reports_errors", False):
        command.callback = reports_errors(command.callback)
    for sub in getattr(command, "commands", {}).values():
        _report_errors(sub)


def _interrupted(args: list[str] | None) -> int:
    """The status of a command a stop interrupted before it took the signals over (see the module's docstring)."""
    words = sys.argv[1:] if args is None else args
    name = next((word for word in words if not word.startswith("-")), None)
    return 0 if name in RUN_UNTIL_STOPPED else INTERRUPTED


def run(args: list[str] | None = None) -> int:
    """Run the CLI and return its exit status; no exception escapes."""
    try:
        _EARLY_STOP.armed = True
        if _EARLY_STOP.signum is not None:  # asked while vstig was starting
            raise KeyboardInterrupt
        result = cli.main(args, standalone_mode=False)
        flush_streams()
    except click.ClickException as error:  # usage errors (2), runtime failures and failed output (1)
        error.show()
        return error.exit_code
    except click.exceptions.Exit as end:  # also a closed pipe: status 0, nothing said
        return end.exit_code
    except click.Abort as abort:  # click's form of Ctrl-C (or a declined prompt)
        if isinstance(abort.__context__, KeyboardInterrupt):
            return _interrupted(args)
        click.echo("Aborted!", err=True)
        return 1
    except KeyboardInterrupt:
        return _interrupted(args)
    finally:
        with contextlib.suppress(click.ClickException, click.exceptions.Exit):
            flush_streams()  # after a failure we already report: do not replace it
    return result if isinstance(result, int) else 0


def main() -> None:
    guard_streams()
    status = run()
    if "zenoh" in sys.modules:
        # Zenoh's own threads may still be inside a callback into Python (a sample or a transport event in flight)
        # while the interpreter finalizes: such a thread is then unwound through Rust and the process aborts
        # ("FATAL: exception not rethrown"). Every link is closed and every stream flushed by now: end here.
        import logging

        logging.shutdown()
        with contextlib.suppress(click.ClickException, click.exceptions.Exit, OSError, ValueError):
            flush_streams()  # run() reported any failure of theirs already
        os._exit(status)
    sys.exit(status)


if __name__ == "__main__":
    main()
