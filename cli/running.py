"""How a command runs and ends: every failure as one line and its exit status (usage 2, runtime 1),
stdout and stderr that fail the way a command-line tool should, and running a node over links until
stopped. The gateway and the links load only when a command uses them: decode imports this module too."""

from __future__ import annotations

import contextlib
import functools
import io
import os
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, TextIO, TypeVar

import click

from vstig_hw.capture.records import CaptureError

if TYPE_CHECKING:
    from vstig_hw.gateway import Node
    from vstig_hw.links import Link, LinkSpec


# -- How every command fails: usage errors exit 2, runtime failures exit 1.

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


class LinkSpecType(click.ParamType):  # type: ignore[type-arg]  # generic only from click 8.3; we take 8.1 up
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


class LinkArguments(click.Argument):
    """The LINKs of bridge, sniff and record (`type=LINK`, `nargs=-1`): more than one gateway takes
    (vstig_hw.links.assemble.MAX_LINKS) are a usage error before a single one is parsed, from a config file too."""

    def type_cast_value(self, ctx: click.Context, value: Any) -> Any:
        from vstig_hw.links.assemble import LinkBuildError, check_link_count

        if isinstance(value, list | tuple):
            try:
                check_link_count(len(value))
            except LinkBuildError as error:
                raise click.BadParameter(str(error), ctx, self) from None
        return super().type_cast_value(ctx, value)


# -- stdout and stderr that fail the way a command-line tool should.

class PipeClosed(click.exceptions.Exit):
    """The reading end of our output pipe closed: stop quietly with status 0."""

    def __init__(self) -> None:
        super().__init__(0)


class OutputFailed(click.ClickException):
    """Writing to stdout failed (full disk, closed descriptor...): one line, status 1."""


class _GuardedFile(io.FileIO):
    """A standard stream's descriptor whose write errors become PipeClosed or OutputFailed."""

    def __init__(self, fd: int, label: str) -> None:
        super().__init__(fd, "wb", closefd=False)
        self.label = label
        self.failed = False

    def write(self, data: Any) -> int:
        if self.failed:
            return len(data)
        try:
            return super().write(data) or 0
        except OSError as error:
            self.failed = True
            if self.label == "stderr":
                return len(data)  # a status line nobody can see must not stop the work
            if isinstance(error, BrokenPipeError):
                raise PipeClosed() from None
            raise OutputFailed(f"cannot write to {self.label}: {error.strerror or error}") from None


class _ClosedStream(io.RawIOBase):
    """Stands in for a descriptor that was closed before we started (`>&-`)."""

    def __init__(self, label: str, complain: bool) -> None:
        super().__init__()
        self.label = label
        self.complain = complain

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        if self.complain:
            self.complain = False
            raise OutputFailed(f"cannot write to {self.label}: it is closed")
        return len(memoryview(data))


def _rebuild(stream: TextIO | None, fd: int, label: str) -> TextIO | None:
    if stream is None:  # Python found the descriptor closed at startup
        raw: io.RawIOBase = _ClosedStream(label, complain=(label == "stdout"))
        return io.TextIOWrapper(io.BufferedWriter(raw), encoding="utf-8", write_through=True)
    try:
        if stream.fileno() != fd:
            return stream  # already redirected inside this process (a test harness): leave it be
    except (OSError, ValueError, io.UnsupportedOperation):
        return stream
    stream.flush()
    buffered = io.BufferedWriter(_GuardedFile(fd, label))
    return io.TextIOWrapper(buffered, encoding=stream.encoding, errors=stream.errors,
                            line_buffering=bool(stream.line_buffering),
                            write_through=getattr(stream, "write_through", False))


def guard_streams() -> None:
    """Replace sys.stdout and sys.stderr by guarded streams over the same descriptors."""
    sys.stdout = _rebuild(sys.stdout, 1, "stdout")
    sys.stderr = _rebuild(sys.stderr, 2, "stderr")


def flush_streams() -> None:
    """Flush both streams now, so a failure is reported by us and not by the interpreter's exit."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()


# -- Running a node over links: building them from specs, running until stopped, its counters.

def build_links(specs: Sequence[LinkSpec], robot_id: int = 0, listen_only: bool = False) -> list[Link[Any]]:
    """One Link per spec, named after its device (made unique: radio, radio-2...).

    A robot id that a CAN link's ID scheme has no room for is a usage error naming --robot-id.
    """
    from vstig_hw.links.assemble import LinkBuildError, assemble_links

    try:
        links = assemble_links(specs, robot_id, listen_only)
    except LinkBuildError as error:
        if error.argument == "robot_id":
            raise click.BadParameter(str(error), param_hint="'--robot-id'") from None
        raise click.UsageError(str(error)) from None
    for spec in specs:  # once every link could be built: a link that cannot (a missing extra) is the one line said
        if spec.reach_note:
            click.echo(f"note: {spec.reach_note}", err=True)
    return links


def describe_links(node: Node) -> None:
    """One line per link whose transport says where it is reachable (a Zenoh link's endpoints)."""
    for link in node.links:
        about = link.about
        if about:
            click.echo(f"{link.name}: {about}", err=True)


OPEN_POLL = 0.05  # seconds between two looks at the stop while links open
STATUS_PERIOD = 0.5  # seconds between two redraws of a command's status line
SIGNAL_NAP = 0.05  # seconds a command sleeps between two looks at its stop (see _nap_until)


def open_unless_stopped(open_links: Callable[[], None], stop: threading.Event) -> bool:
    """Run `open_links` in a thread of its own and wait for it, or for `stop`: True once it is done (its failure
    raised here), False when a stop came first.

    A device may take long to open (a Zenoh peer that does not answer, a robot's TCP port, an adapter that hangs in
    its driver) and no bound on one call holds for every driver; so a stop does not wait for the open. What the
    thread opens after that is left to the process's end: the command stops at once, with its counters.
    """
    done = threading.Event()
    failure: list[BaseException] = []

    def opening() -> None:
        try:
            open_links()
        except BaseException as error:  # raised on the command's thread, unless a stop came first
            failure.append(error)
        finally:
            done.set()

    threading.Thread(target=opening, name="open-links", daemon=True).start()
    while not done.wait(OPEN_POLL):
        if stop.is_set():
            return False
    if failure:
        raise failure[0]
    return True


@contextlib.contextmanager
def opened(node: Node, stop: threading.Event) -> Iterator[Node]:
    """`with node:` for a command under `stop_on_signals`: a stop while the links open does not wait for them
    (`open_unless_stopped`): the block then runs with `stop` set, and the node is not closed (the process is about
    to end, and the opening thread may still hold it)."""
    if not open_unless_stopped(node.open, stop):
        yield node
        return
    try:
        yield node
    finally:
        node.close()


def run_until_stopped(node: Node, stop: threading.Event, status: Any = None, duration: float | None = None) -> None:
    """Wait while the open node runs (on its own thread) until `stop` (the command's `stop_on_signals()`, entered
    before its links opened: a signal any time after "Ctrl-C stops" is said ends it cleanly), `duration`, or the
    node closing by itself (what broke it is raised here), refreshing `status()` every half second.

    Under a service manager (systemd's $NOTIFY_SOCKET, `Type=notify`) it says READY=1 as it starts (every link
    is open by then), pings the watchdog from the loop's tick, and says STOPPING=1 as the stop begins.
    """
    from .ops.notify import ServiceNotifier

    service = ServiceNotifier.from_environment()
    ended = node.listen(closed=stop.set)  # a Node whose loop failed closed itself: the command ends, saying why
    if service is not None:
        node.listen(tick=service.tick)
        service.ready(_readiness(node))
    try:
        end = None if duration is None else time.monotonic() + duration
        while not stop.is_set() and (end is None or time.monotonic() < end):
            left = STATUS_PERIOD if end is None else max(0.0, end - time.monotonic())
            if _nap_until(stop, left if status is None else min(left, STATUS_PERIOD)):
                break
            if status is not None:
                status()
        if node.failure is not None:
            raise node.failure
    finally:
        ended.cancel()
        if service is not None:
            service.stopping()
            service.close()


def _nap_until(stop: threading.Event, seconds: float) -> bool:
    """Wait `seconds` or until `stop` is set; True if it was. Short sleeps, not `stop.wait`: the signal handler's
    `stop.set()` runs on this thread, and `Event.wait` holds the lock `set` takes at its edges, so a signal landing
    there would wait on itself forever (a bridge that ignored SIGTERM)."""
    end = time.monotonic() + seconds
    while not stop.is_set() and (left := end - time.monotonic()) > 0:
        time.sleep(min(left, SIGNAL_NAP))
    return stop.is_set()


def _readiness(node: Node) -> str:
    """The STATUS= of READY=1: the links, and those still waiting for their device (a router not up yet)."""
    waiting = [link.name for link in node.links if not link.connected]
    line = f"running on {', '.join(link.name for link in node.links)}"
    return f"{line}; waiting for {', '.join(waiting)}" if waiting else line


def print_counters(node: Node) -> None:
    for name, counters in node.stats().items():
        click.echo(f"{name}: {counters.summary()}", err=True)


class StatusLine:
    """One line on stderr, redrawn in place, only when stderr is a terminal (a log file gets none)."""

    def __init__(self) -> None:
        self.live = sys.stderr.isatty()
        self.drawn = False

    def show(self, text: str) -> None:
        if self.live:
            click.echo(f"\r\x1b[K{text}", nl=False, err=True)
            self.drawn = True

    def end(self) -> None:
        if self.drawn:
            click.echo(err=True)
            self.drawn = False


def must_hear(spec: LinkSpec, command: str) -> None:
    """Refuse a listening command on a transmit-only link, instead of listening to nothing."""
    if spec.kind == "kilobot-ohc":
        raise click.UsageError(f"{command} needs a link that receives; kilobot-ohc:{spec.name} is transmit-only "
                               "(the overhead controller never hears the robots)")
