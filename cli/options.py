"""The options and parameter types the commands share: finite numbers and keys, the files a user names
(none replaced unless --overwrite, never through a symbolic link), the capture files a command reads,
the options of commands that read captures, and the guard's options of bridge and sniff.

Light on purpose: decode imports it, and must load no gateway, link or transport; the guard's names are
loaded when its options are used."""

from __future__ import annotations

import contextlib
import functools
import itertools
import math
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar

import click

from vstig_hw.capture.records import READABLE_EXTENSIONS, CaptureError, Damage, line_capture_at, sniff_suffix
from vstig_hw.outputs import LinkedOutput, SpecialOutput, drop_setid, refuse_special, refuse_symlink
from vstig_hw.wire import KEY_MAX

if TYPE_CHECKING:
    from vstig_hw.gateway.guard import Guard, IdSet
    from vstig_hw.gateway.signing import Signing
    from vstig_hw.links import Link

__all__ = [
    "INPUT_FORMATS",
    "KEY",
    "LOOPBACK",
    "VALUE_TYPE_HELP",
    "ByteSize",
    "Finite",
    "GuardChoice",
    "NegativeNumbersAreArguments",
    "WireKey",
    "damage_option",
    "echo_skipped",
    "filter_options",
    "finite",
    "guard_options",
    "input_format_option",
    "input_name",
    "is_loopback",
    "listen_address",
    "overwrite_option",
    "parse_id_base",
    "readable_capture",
    "reading_options",
    "refuse_link",
    "refuse_links_in",
    "refuse_to_replace",
    "renamed",
    "take_warnings",
]


# -- Numbers: finite floats for every float option, a KEY in decimal or hex, negative VALUEs without `--`.

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


class ByteSize(click.ParamType):  # type: ignore[type-arg]  # generic only from click 8.3; we take 8.1 up
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


class WireKey(click.ParamType):  # type: ignore[type-arg]  # generic only from click 8.3; we take 8.1 up
    """A stigmergy key, 0..32767, written as VALUE may be: 23, 0x17, 0o27, 0b10111."""

    name = "KEY"
    high = KEY_MAX

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        if isinstance(value, int):
            number = value
        else:
            try:
                number = int(str(value), 0)
            except ValueError:
                self.fail(f"{value!r} is not an integer (e.g. 23 or 0x17)", param, ctx)
        if not 0 <= number <= self.high:
            self.fail(f"{value} is outside 0..{self.high} ({self.high:#x})", param, ctx)
        return number


class SenderId(WireKey):
    """The node that sent a unit: a CAN node id, a zenoh gateway id, or an XBee module's 64-bit address
    (0x0013A20040A1B2C3), so up to 2**64 - 1, in decimal or hex."""

    name = "ID"
    high = 0xFFFF_FFFF_FFFF_FFFF


KEY = WireKey()
SENDER = SenderId()


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


# -- Addresses a command serves on (--foxglove, --metrics): [HOST:]PORT, loopback unless a HOST is given.

LOOPBACK = "127.0.0.1"
Address: TypeAlias = "tuple[str, int]"


def listen_address(value: str, ctx: click.Context | None, param: click.Parameter | None) -> Address:
    """PORT or HOST:PORT ([::1]:PORT for IPv6) into (host, port), host LOOPBACK for PORT alone; bad ones are
    usage errors naming the option."""
    text = str(value)
    host, colon, port = text.rpartition(":")
    host = host.removeprefix("[").removesuffix("]") if colon else LOOPBACK
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise click.BadParameter(f"{text!r}: the port must be a number in 0..65535 (0: any free port)", ctx, param)
    if not host:
        raise click.BadParameter(f"{text!r}: an empty host (PORT alone binds {LOOPBACK})", ctx, param)
    return host, int(port)


def is_loopback(host: str) -> bool:
    """Whether `host` keeps a server to this PC; a name other than localhost may be the network."""
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


# -- The files a user names (-o FILE, --capture, --plot...): none replaced unless --overwrite says so.

def overwrite_option(target: str) -> Callable[..., Any]:
    """The --overwrite flag of a command that writes `target` (how its help names the file)."""
    return click.option("--overwrite", is_flag=True, help=f"Replace {target} if it exists (never done without this).")


def refuse_link(path: str | Path) -> None:
    """A usage error naming `path` if it is a symbolic link (dangling or not), or not a file to write into
    (a FIFO, a terminal, a socket: `vstig_hw.outputs`)."""
    try:
        refuse_symlink(path)
        refuse_special(path)
    except (LinkedOutput, SpecialOutput) as error:
        raise click.UsageError(str(error)) from None


def refuse_links_in(folder: Path, names: tuple[str, ...]) -> None:
    """refuse_link for each file a command names itself inside its output folder."""
    for name in names:
        refuse_link(folder / name)
        drop_setid(folder / name)


def refuse_to_replace(path: str | Path, overwrite: bool, otherwise: str = "") -> None:
    """A usage error naming `path` if it is a symbolic link or not a file to write into (a FIFO...), or if it
    holds something and --overwrite was not given.

    `otherwise` adds the command's other way out (record: ", --append adds to it"). An empty file holds
    nothing to lose, and the null device is not replaced by writing to it.
    """
    refuse_link(path)
    if not overwrite and os.path.isfile(path) and os.path.getsize(path) > 0:
        raise click.UsageError(f"{path} exists: --overwrite replaces it{otherwise}")
    drop_setid(path)  # what replaces it is not a program to run as its owner


# -- The capture files decode and analyze read: by extension, else (-, a pipe, <(...)) by first bytes.

INPUT_FORMATS = [*(suffix[1:] for suffix in READABLE_EXTENSIONS), "cap"]  # cap: our serial capture
_SNIFF_BYTES = 1 << 16


def input_format_option(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--input-format: the capture type, for a name that does not show it."""
    return click.option("--input-format", type=click.Choice(INPUT_FORMATS),
                        help="The capture type, for a name that does not show it (default: by extension, and for - "
                             "or a pipe by content).")(fn)


def input_name(path: str) -> str:
    """How messages name an input: stdin as <stdin>, anything else as typed."""
    return "<stdin>" if path == "-" else path


def renamed(error: CaptureError, read: str, name: str) -> CaptureError:
    """`error` about the file actually read (`read`, maybe a spooled copy) naming the input the user typed."""
    return error if read == name else CaptureError(name, error.line, error.problem)


@contextlib.contextmanager
def readable_capture(path: str, input_format: str | None) -> Iterator[str]:
    """A regular file to read `path` from whose name shows its type; a stream (-, a pipe) is copied first."""
    regular = path != "-" and os.path.isfile(path)
    if regular and input_format is None and (path.lower().endswith(READABLE_EXTENSIONS) or line_capture_at(path)):
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="vstig-capture-") as folder:
        spooled = os.path.join(folder, "input")
        if regular:  # a file whose name does not tell (/dev/stdin redirected from a file): look inside
            os.symlink(os.path.abspath(path), spooled)
            with open(path, "rb") as file:
                head = file.read(_SNIFF_BYTES)
        else:
            with contextlib.ExitStack() as stack:
                source = sys.stdin.buffer if path == "-" else stack.enter_context(open(path, "rb"))
                with open(spooled, "wb") as copy:
                    head = source.read(_SNIFF_BYTES)
                    copy.write(head)
                    shutil.copyfileobj(source, copy, 1 << 20)
        suffix = f".{input_format}" if input_format else sniff_suffix(head)
        if suffix is None:
            raise click.UsageError(f"{input_name(path)}: cannot tell the capture type from its first bytes: give "
                                   f"--input-format ({', '.join(INPUT_FORMATS)})")
        os.rename(spooled, spooled + suffix)
        yield spooled + suffix


# -- Options the commands that read captures share.

F = TypeVar("F", bound=Callable[..., Any])

SHOWN_SKIPPED = 5  # damage lines shown; the summary counts them all
VALUE_TYPE_HELP = "How to show the 16-bit value field: unsigned, signed (two's complement) or half-precision float."
damage_option = click.option(  # the command's `damage`: what reading does with damaged input
    "--skip-bad", "damage", is_flag=True, callback=lambda ctx, param, skip: Damage(skip),
    help="Count malformed lines, and a file cut short (a killed recorder's), and go on instead of stopping there.")


def echo_skipped(bad: Iterable[CaptureError]) -> None:
    """The damage a reader skipped, one line each (the first few), on stderr: every command says it alike."""
    for error in itertools.islice(bad, SHOWN_SKIPPED):
        click.echo(f"skipped {error}", err=True)


def parse_id_base(text: str | None) -> int | None:
    """`--id-base` as an integer (0x600 or 1536); a bad one is a usage error."""
    if text is None:
        return None
    try:
        return int(text, 0)
    except ValueError:
        raise click.BadParameter(f"{text!r} is not an integer (e.g. 0x600)", param_hint="--id-base") from None


def reading_options(fn: F) -> F:
    """Add how to read captures: --skip-bad, --value-type, --id-base, --extended, --deployment."""
    from vstig_hw.values import VALUE_TYPES

    options = [
        damage_option,
        click.option("--value-type", type=click.Choice(VALUE_TYPES), default="uint16", show_default=True,
                     help=VALUE_TYPE_HELP),
        click.option("--id-base", help="CAN ID base of the stigmergy (default 0x600, or 0x18000000 for 29-bit IDs)."),
        click.option("--extended", is_flag=True, help="The CAN capture uses 29-bit IDs."),
        click.option("--deployment", type=click.Path(exists=True, dir_okay=False),
                     help="For Buzz/BittyBuzz captures (blabbermouth, bittybuzz-kilobot): the TOML file mapping "
                          "their keys."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def filter_options(fn: F) -> F:
    """Add the capture filter options; the command receives them as one `keep: Filter` argument."""
    from vstig_hw.wire import KEY_MAX, U16_MAX

    options = [
        click.option("--key", "only_keys", multiple=True, type=click.IntRange(0, KEY_MAX),
                     help="Only this key (repeatable)."),
        click.option("--robot", "only_robots", multiple=True, type=click.IntRange(0, U16_MAX),
                     help="Only entries written by this robot (repeatable)."),
        click.option("--sender", "only_senders", multiple=True, type=SENDER,
                     help="Only messages sent by this node: a CAN frame's sender field, an XBee module's 64-bit "
                          "address (0x0013A200...) (repeatable)."),
        click.option("--op", "only_ops", multiple=True, type=click.Choice(["PUT", "GET"], case_sensitive=False),
                     help="Only PUTs or only GETs."),
        click.option("--link", "only_links", multiple=True, help="Only this link, by name (repeatable)."),
        click.option("--since", type=Finite(0), help="Only from this many seconds after the first record."),
        click.option("--until", type=Finite(0), help="Only before this many seconds after the first record."),
    ]

    @functools.wraps(fn)
    def with_filter(*args: Any, only_keys: tuple[int, ...], only_robots: tuple[int, ...],
                    only_senders: tuple[int, ...], only_ops: tuple[str, ...], only_links: tuple[str, ...],
                    since: float | None, until: float | None, **kwargs: Any) -> Any:
        from vstig_hw.capture.filters import Filter
        from vstig_hw.wire import Op

        if since is not None and until is not None and until <= since:
            raise click.BadParameter(f"{until:g} is not after --since {since:g}", param_hint="--until")
        keep = Filter(keys=frozenset(only_keys) or None, robots=frozenset(only_robots) or None,
                      senders=frozenset(only_senders) or None, ops=frozenset(Op[o.upper()] for o in only_ops) or None,
                      links=frozenset(only_links) or None, since=since, until=until)
        return fn(*args, keep=keep, **kwargs)

    for option in reversed(options):
        with_filter = option(with_filter)
    return with_filter  # type: ignore[return-value]


# -- The guard's options, shared by `bridge` and `sniff`: one decorator, one builder, one warning printer.

Pairs: TypeAlias = "list[tuple[str, IdSet]]"


def _pairs(limit: int, what: str) -> Callable[[click.Context, click.Parameter, tuple[str, ...]], Pairs]:
    """A click callback reading LINK=IDS values into (link name, IdSet) pairs; a bad one is a usage error."""

    def convert(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> Pairs:
        pairs = []
        for value in values:
            name, eq, ids = value.partition("=")
            if not eq or not name or not ids:
                raise click.BadParameter(f"{value!r} is not LINK={what.upper()} (e.g. can0=1-9,12)", ctx, param)
            try:
                from vstig_hw.gateway.guard import IdSet

                pairs.append((name, IdSet.parse(ids, limit, what)))
            except ValueError as error:
                raise click.BadParameter(f"{value!r}: {error}", ctx, param) from None
        return pairs
    return convert


def _guard_option_list() -> list[Callable[[Callable[..., Any]], Callable[..., Any]]]:
    """The guard's click options, built when a command that takes them is defined (not when decode imports us)."""
    from vstig_hw.gateway.guard import DEFAULT_MAX_JUMP

    return [
        click.option("--max-jump", type=click.IntRange(0, 0x7FFF), default=DEFAULT_MAX_JUMP, show_default=True,
                     help="Refuse a PUT/GET more than N timestamps newer than our entry (drop_jump); 0 turns it off. "
                          "A climb in steps skips at most N timestamps a second per key. "
                          "A key we do not hold passes at any timestamp (see --learn)."),
        click.option("--learn", type=Finite(0.0), metavar="S",
                     help="S seconds after the first message heard, a key we do not hold yet is new to the swarm: "
                          "it must start within --max-jump of timestamp 0 (drop_jump). Default: it passes at any "
                          "timestamp."),
        click.option("--rate", type=Finite(0.0, min_open=True), metavar="N",
                     help="At most N messages per second from each sender id the medium names (CAN node id, zenoh "
                          "gateway id; a serial link is one sender); excess counted drop_rate. Ids are claims: "
                          "see --source-rate."),
        click.option("--source-rate", type=Finite(0.0, min_open=True), metavar="N",
                     help="At most N messages per second from each real source, whatever ids it claims: a serial or "
                          "CAN link is one source; on zenoh, each session connected to ours (by the id stamped on its "
                          "samples); samples stamped with no connected session's id (unstamped, made up, relayed by a "
                          "router) share one more. On open loopback any local user can connect sessions: only "
                          "authenticated zenoh keeps them out; every source also gets only its fair share of each "
                          "link. Excess counted drop_source_rate."),
        click.option("--trust", multiple=True, metavar="LINK=IDS", callback=_pairs(SENDER.high, "ids"),
                     help="Accept on LINK only these sender ids, e.g. can0=1-20,33, or XBee modules' 64-bit "
                          "addresses, radio=0x0013A20040A1B2C3 (drop_untrusted). Repeatable."),
        click.option("--deny", multiple=True, metavar="LINK=IDS", callback=_pairs(SENDER.high, "ids"),
                     help="Refuse on LINK what these robots send or wrote (relayed by others too): "
                          "drop_untrusted. Repeatable."),
        click.option("--keys", multiple=True, metavar="LINK=RANGE", callback=_pairs(KEY_MAX, "keys"),
                     help="The keys LINK may write, e.g. radio=100-199 (drop_key); it may still read any. Repeatable."),
        click.option("--read-only", multiple=True, metavar="LINK",
                     help="What LINK says reaches our table but is never relayed to another link. Repeatable."),
        click.option("--flap", type=Finite(0.0, min_open=True), metavar="M",
                     help="Warn once about a key that changes hands by conflict more than M times a second "
                          "(two robots sharing an id)."),
    ]


@dataclass(frozen=True)
class GuardChoice:
    """The guard options as given; `build` checks them against the links."""

    max_jump: int
    learn: float | None
    rate: float | None
    source_rate: float | None
    trust: Sequence[tuple[str, IdSet]]
    deny: Sequence[tuple[str, IdSet]]
    keys: Sequence[tuple[str, IdSet]]
    read_only: Sequence[str]
    flap: float | None

    def build(self, links: Sequence[Link[Any]]) -> Guard:
        """The Guard; a link name that is not one of `links`, or a sender list for a medium that names nobody,
        is a usage error."""
        names = [link.name for link in links]
        anonymous = {link.name for link in links if not _names_senders(link)}
        policies: dict[str, dict[str, Any]] = {}
        for option, pairs in (("trust", self.trust), ("deny", self.deny), ("keys", self.keys),
                              ("read_only", [(name, True) for name in self.read_only])):
            for name, value in pairs:
                flag = f"--{option.replace('_', '-')}"
                if name not in names:
                    raise click.UsageError(f"{flag} {name}: no such link (links here: {', '.join(names)})")
                if option == "trust" and name in anonymous:
                    raise click.UsageError(f"{flag} {name}: this medium does not name its senders "
                                           "(CAN, zenoh and XBee do); use --deny, --keys or --read-only on it")
                fields = policies.setdefault(name, {})
                if option in fields:
                    raise click.UsageError(f"{flag} {name} given twice: join them with commas")
                fields[option] = value
        from vstig_hw.gateway.guard import Guard, LinkPolicy

        return Guard(max_jump=self.max_jump or None, learn=self.learn, rate=self.rate,
                     source_rate=self.source_rate, flap=self.flap,
                     links={name: LinkPolicy(**fields) for name, fields in policies.items()})


def _names_senders(link: Link[Any]) -> bool:
    """Whether the link can say who sent a unit: its framing reads it from the unit (CAN IDs)."""
    return link.names_senders


def guard_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Add the guard's options to a command; it receives them as one `guard: GuardChoice` argument."""

    @functools.wraps(fn)
    def wrapper(*args: Any, max_jump: int, learn: float | None, rate: float | None, source_rate: float | None,
                trust: Sequence[tuple[str, IdSet]],
                deny: Sequence[tuple[str, IdSet]], keys: Sequence[tuple[str, IdSet]], read_only: Sequence[str],
                flap: float | None, **kwargs: Any) -> Any:
        return fn(*args, guard=GuardChoice(max_jump, learn, rate, source_rate, trust, deny, keys, read_only, flap),
                  **kwargs)

    for option in reversed(_guard_option_list()):
        wrapper = option(wrapper)
    return wrapper


def take_warnings(source: Guard | Signing | None) -> list[str]:
    """The new warning lines of the guard or the swarm key's check (None: none), each handed out once."""
    if source is None:
        return []
    lines = source.warnings[:]
    source.warnings.clear()
    return lines
