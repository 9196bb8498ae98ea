"""`vstig service --config FILE`: a systemd unit that runs a gateway (bridge, sniff or record) from its config
file, with readiness, a watchdog and restarts; printed, or written to -o FILE."""

from __future__ import annotations

import importlib
import os
import re
import sys
from pathlib import Path

import click

from ..options import overwrite_option, refuse_to_replace
from ..running import reports_errors

COMMANDS = ("bridge", "sniff", "record")
_USER = re.compile(r"[a-z_][a-z0-9_-]{0,31}\Z")
_PLAIN = re.compile(r"[A-Za-z0-9_./:=@+,-]+\Z")  # words ExecStart= takes as they are


def _exec_word(word: str) -> str:
    """One word of ExecStart= (systemd.service(5), "Command lines"): quoted where needed, % and $ doubled."""
    word = word.replace("%", "%%").replace("$", "$$")
    if _PLAIN.match(word):
        return word
    return '"' + word.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _vstig() -> list[str]:
    """How the unit starts this same vstig: the script beside this interpreter, else `python -m`."""
    script = Path(sys.executable).with_name("vstig")
    if os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, "-m", "vstig_cli.main"]


def _check(command: str, config: str, ctx: click.Context) -> None:
    """Parse `vstig COMMAND --config FILE` as the service will (links, values, keys), without running it."""
    module = importlib.import_module(f"{__package__}.{command}")
    try:
        module.command.make_context(command, ["--config", config], parent=ctx.find_root())
    except click.MissingParameter as error:
        missing = error.param.name if error.param else "more"
        raise click.UsageError(f"{config}: vstig {command} needs {missing}: set it in the file", ctx) from None


def unit_text(command: str, config: str, *, watchdog: int, user: str | None, description: str) -> str:
    exec_start = " ".join(_exec_word(word) for word in [*_vstig(), command, "--config", config])
    lines = [
        "# Written by `vstig service`: a gateway for days (docs/how-to/service.md).",
        "[Unit]",
        f"Description={description}",
        "After=network-online.target",
        "Wants=network-online.target",
        "",
        "[Service]",
        "Type=notify",  # READY=1 once every link is open
        "NotifyAccess=main",
        f"ExecStart={exec_start}",
        *([f"WatchdogSec={watchdog}"] if watchdog else []),
        "TimeoutStartSec=60",  # opening may wait for devices and Zenoh peers
        "TimeoutStopSec=15",  # a stop closes links and prints the counters in a few seconds
        "Restart=on-failure",
        "RestartSec=5",
        *([f"User={user}", "SupplementaryGroups=dialout"] if user else []),  # dialout: serial radios on Debian
        "",
        "[Install]",
        "WantedBy=multi-user.target",
    ]
    return "\n".join(lines) + "\n"


@click.command()
@click.option("--config", required=True, type=click.Path(dir_okay=False), metavar="FILE",
              help="The gateway's config file (see --config of bridge, sniff and record); checked now.")
@click.option("--command", "gateway", type=click.Choice(COMMANDS), default="bridge", show_default=True,
              help="What the service runs.")
@click.option("--watchdog", type=click.IntRange(0, 3600), default=30, show_default=True,
              help="WatchdogSec: seconds without a ping from the gateway's loop before systemd restarts it "
                   "(0: no watchdog).")
@click.option("--user", help="Run as this user (with the dialout group, for serial radios); default root.")
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
    if user is not None and not _USER.match(user):
        raise click.BadParameter(f"{user!r} is not a user name", param_hint="--user")
    if output is not None:
        refuse_to_replace(output, overwrite)
    absolute = os.path.abspath(config)
    _check(gateway, absolute, ctx)
    text = unit_text(gateway, absolute, watchdog=watchdog, user=user,
                     description=f"vstig {gateway} ({os.path.basename(absolute)})")
    if output is None:
        click.echo(text, nl=False)
        return
    with open(output, "w", encoding="utf-8") as file:
        file.write(text)
    click.echo(f"wrote {output}: systemctl daemon-reload, then systemctl enable --now {Path(output).stem}",
               err=True)
