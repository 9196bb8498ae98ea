"""`vstig service --config FILE`: a systemd unit that runs a gateway (bridge, sniff or record) from its config
file, with readiness, a watchdog and restarts; printed, or written to -o FILE."""

from __future__ import annotations

import contextlib
import grp
import importlib
import os
import pwd
import re
import sys
from pathlib import Path

import click

from ..config import shown
from ..ops.unit import HOMES, TEMPORARY, Needs, checked, home_bind, needs_of, under, unit_text
from ..ops.unit_file import write_new_file
from ..options import overwrite_option
from ..running import reports_errors

COMMANDS = ("bridge", "sniff", "record")
DYNAMIC_USER = "vstig"  # the user systemd makes for the unit (DynamicUser=), or a static one of that name
_USER = re.compile(r"[a-z_][a-z0-9_-]{0,31}\Z")


def _vstig() -> list[str]:
    """How the unit starts this same vstig: the script beside this interpreter, else `python -m`."""
    script = Path(sys.executable).with_name("vstig")
    if os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, "-m", "vstig_cli.main"]


def _check(command: str, config: str, ctx: click.Context) -> dict[str, object]:
    """Parse `vstig COMMAND --config FILE` as the service will (links, values, keys), without running it:
    the parameters it would run with."""
    module = importlib.import_module(f"{__package__}.{command}")
    try:
        checked = module.command.make_context(command, ["--config", config], parent=ctx.find_root())
    except click.MissingParameter as error:
        missing = error.param.name if error.param else "more"
        raise click.UsageError(f"{config}: vstig {command} needs {missing}: set it in the file", ctx) from None
    except click.UsageError as error:  # named as what was typed: vstig service, not the command it checks
        raise click.UsageError(f"{error.format_message()} (checked as vstig {command} will read it)",
                               ctx) from None
    if command == "record" and not checked.params.get("output"):
        raise click.UsageError(f"{config}: a record service needs output = \"/a/folder\" in the file "
                               "(a service runs from /, which it cannot write)", ctx)
    return dict(checked.params)


def _user(name: str | None, needs: Needs) -> tuple[str | None, bool]:
    """(User=, DynamicUser=) for --user NAME: an existing user, or by default one systemd makes; root warned."""
    if name is None:
        if any(under(path, TEMPORARY) for path in needs.reads + needs.writes):
            raise click.UsageError("a service with its own user sees a /tmp of its own (PrivateTmp=): move "
                                   f"{_in_tmp(needs)} out of /tmp, or give --user NAME")
        _warn_unreadable(DYNAMIC_USER, needs)
        return DYNAMIC_USER, True
    if not _USER.match(name):
        raise click.BadParameter(f"{shown(name)} is not a user name", param_hint="--user")
    try:
        account = pwd.getpwnam(name)
    except KeyError:
        raise click.BadParameter(
            f"no user {name!r} on this machine: create it (useradd --system --no-create-home --shell "
            f"/usr/sbin/nologin {name}), or leave --user out for a user systemd makes for the unit",
            param_hint="--user") from None
    if account.pw_uid == 0:
        click.echo(f"warning: the unit runs the gateway as {name} (uid 0): a flaw in it, or in a library it loads, "
                   "could change anything the sandbox leaves writable; leave --user out for a user of its own",
                   err=True)
        return None, False
    _warn_unreadable(name, needs)
    return name, False


def _in_tmp(needs: Needs) -> str:
    return next(path for path in needs.reads + needs.writes if under(path, TEMPORARY))


def _warn_unreadable(name: str, needs: Needs) -> None:
    """Warn for each file the service's user cannot reach: the service would fail at its start. A user
    systemd makes has no files and no groups but dialout (for serial devices)."""
    try:
        account = pwd.getpwnam(name)
        uid, groups = account.pw_uid, set(os.getgrouplist(name, account.pw_gid))
    except KeyError:
        uid, groups = -1, set()
    if needs.serial:
        with contextlib.suppress(KeyError):
            groups.add(grp.getgrnam("dialout").gr_gid)
    for path in needs.reads:
        if not _reachable(path, uid, groups):
            click.echo(f"warning: user {name} cannot read {path}: the service would fail to start", err=True)


def _reachable(path: str, uid: int, groups: set[int]) -> bool:
    """Whether uid (in groups) may search every folder up to `path` and read it, by the mode bits."""
    shown_from = Path(home_bind(path)) if under(path, HOMES) else Path("/")  # ProtectHome=tmpfs: homes are 0755
    folders = [folder for folder in reversed(Path(path).parents) if shown_from in (folder, *folder.parents)]
    for item, bit in [*((folder, 1) for folder in folders), (Path(path), 4)]:
        try:
            info = item.stat()
        except OSError:
            return False
        shift = 6 if info.st_uid == uid else 3 if info.st_gid in groups else 0
        if not (info.st_mode >> shift) & bit:
            return False
    return True


def _program_files() -> list[str]:
    """What the unit runs: vstig's script and the interpreter it names (a venv in a home folder needs
    ProtectHome=read-only)."""
    return list(dict.fromkeys([_vstig()[0], os.path.realpath(sys.executable)]))


@click.command()
@click.option("--config", required=True, type=click.Path(dir_okay=False), metavar="FILE",
              help="The gateway's config file (see --config of bridge, sniff and record); checked now.")
@click.option("--command", "gateway", type=click.Choice(COMMANDS), default="bridge", show_default=True,
              help="What the service runs.")
@click.option("--watchdog", type=click.IntRange(0, 3600), default=30, show_default=True,
              help="WatchdogSec: seconds without a ping from the gateway's loop before systemd restarts it "
                   "(0: no watchdog).")
@click.option("--user", help="Run as this existing user (with the dialout group, for serial radios); default: "
                             f"a user systemd makes for the unit (User={DYNAMIC_USER}, DynamicUser=yes).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="FILE",
              help="Write the unit to FILE (e.g. /etc/systemd/system/vstig-lab.service) instead of stdout.")
@overwrite_option("FILE")
@click.pass_context
@reports_errors
def command(ctx: click.Context, config: str, gateway: str, watchdog: int, user: str | None, output: str | None,
            overwrite: bool) -> None:
    """Write a systemd unit that runs `vstig COMMAND --config FILE` for days.

    The unit is Type=notify: the gateway says READY=1 once every link is open,
    pings the watchdog from its loop (a loop that stalls is restarted), and stops
    cleanly on SIGTERM. The config file is checked first, as the service will read
    it, and named by its absolute path.

    \b
    Example:
      vstig service --config /etc/vstig/lab.toml -o /etc/systemd/system/vstig-lab.service
      systemctl daemon-reload && systemctl enable --now vstig-lab
    """
    absolute = checked("--config", os.path.abspath(config))
    params = _check(gateway, absolute, ctx)
    needs = needs_of(params, [absolute, *_program_files()])
    name, dynamic = _user(user, needs)
    for link in needs.unknown_devices:
        click.echo(f"warning: {link}: vstig service does not know its devices, so the unit leaves DevicePolicy= "
                   "out (add DeviceAllow= for them to close it)", err=True)
    text = unit_text([*_vstig(), gateway, "--config", absolute],
                     f"vstig {gateway} ({os.path.basename(absolute)})", needs,
                     watchdog=watchdog, user=name, dynamic=dynamic)
    if output is None:
        click.echo(text, nl=False)
        return
    write_new_file(output, text, overwrite=overwrite)
    click.echo(f"wrote {output}: systemctl daemon-reload, then systemctl enable --now {Path(output).stem}",
               err=True)
