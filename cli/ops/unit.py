"""The systemd unit `vstig service` writes: every value checked and quoted, and a sandbox cut to what the
gateway's config needs (its devices, address families and the folder it records into).

Each sandbox setting is one the gateway runs under (tests/cli/test_service.py runs it under each one this
machine can apply; docs/how-to/service.md lists what the gateway needs of each).
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import click

from ..config import shown

__all__ = ["HOMES", "TEMPORARY", "Needs", "checked", "exec_word", "home_bind", "needs_of", "under", "unit_text"]

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")  # C0, DEL and C1: a newline would start a directive of its own
_PLAIN = re.compile(r"[A-Za-z0-9_./:=@+,-]+\Z")  # words systemd takes as they are
_TTY = re.compile(r"/dev/(ttyUSB|ttyACM|ttyS|ttyAMA|ttyTHS|rfcomm)\d+\Z")  # device classes known without the device
_NETWORK = ("AF_INET", "AF_INET6")
_CAN_KNOWN = {"socketcan": ("AF_CAN", "AF_NETLINK"), "virtual": (), "socketcand": _NETWORK,
              "udp_multicast": _NETWORK, "slcan": ()}
HOMES = ("/home", "/root", "/run/user")  # what ProtectHome= hides
TEMPORARY = ("/tmp", "/var/tmp")  # what PrivateTmp= replaces


@dataclass
class Needs:
    """What the gateway a config describes touches, beyond AF_UNIX (its notify socket) and its own files."""

    families: set[str] = field(default_factory=set)  # RestrictAddressFamilies= beyond AF_UNIX
    devices: list[str] = field(default_factory=list)  # DeviceAllow= entries: char-ttyUSB, or a path
    serial: bool = False  # a serial device: SupplementaryGroups=dialout
    unknown_devices: list[str] = field(default_factory=list)  # links whose devices we cannot name
    reads: list[str] = field(default_factory=list)  # files the gateway reads (config, deployments...)
    writes: list[str] = field(default_factory=list)  # folders it writes into (ReadWritePaths=)


def needs_of(params: dict[str, Any], reads: Iterable[str]) -> Needs:
    """The needs of a gateway run with these parsed parameters (links, metrics, foxglove, output)."""
    needs = Needs(reads=list(reads))
    for spec in params.get("links") or ():
        _add_link(needs, spec)
    if params.get("metrics") is not None or params.get("foxglove") is not None:
        needs.families.update(_NETWORK)
    output = params.get("output")
    if output:
        absolute = os.path.abspath(output)
        needs.writes.append(absolute if os.path.isdir(absolute) else os.path.dirname(absolute))
    return needs


def _add_link(needs: Needs, spec: Any) -> None:
    kind = spec.kind
    needs.reads.extend(os.path.abspath(path) for path in spec.files_read)
    if kind in ("zenoh", "ros2"):
        needs.families.update((*_NETWORK, "AF_NETLINK"))  # NETLINK: their interface lists
    elif kind == "blabbermouth":
        needs.families.update(_NETWORK)
    elif kind == "can":
        families = _CAN_KNOWN.get(spec.interface)
        if families is None:
            needs.unknown_devices.append(f"can:{spec.interface}")
            needs.families.update((*_NETWORK, "AF_NETLINK", "AF_CAN"))
        needs.families.update(families or ())
        if spec.interface == "slcan":
            _add_port(needs, spec.channel)
    else:  # serial, kilobot-ohc
        _add_port(needs, spec.port)


def _add_port(needs: Needs, port: str) -> None:
    """A device path, or a pyserial URL (spy:// wraps another port; socket:// and rfc2217:// are TCP)."""
    scheme, sep, rest = port.partition("://")
    if not sep:
        needs.devices.append(_device_rule(port))
        needs.serial = True
    elif scheme == "spy":
        _add_port(needs, rest.split("?", 1)[0])
    elif scheme != "loop":
        needs.families.update(_NETWORK)


def _device_rule(path: str) -> str:
    """DeviceAllow='s name for a serial device: its class (char-ttyUSB: the same radio replugged as ttyUSB1 is
    still allowed), else the path itself."""
    try:
        info = os.stat(path)
    except OSError:
        info = None
    if info is not None and stat.S_ISCHR(info.st_mode) and os.major(info.st_rdev) in _char_majors():
        return f"char-{_char_majors()[os.major(info.st_rdev)]}"
    named = _TTY.match(path)
    return f"char-{named[1]}" if named else path


@cache
def _char_majors() -> dict[int, str]:
    """/proc/devices' character devices by major number: the names DeviceAllow=char-NAME takes."""
    majors: dict[int, str] = {}
    try:
        with open("/proc/devices", encoding="ascii") as file:
            lines = file.read().split("\n\n")[0].splitlines()[1:]
    except OSError:
        return majors
    for line in lines:
        number, _, name = line.strip().partition(" ")
        if number.isdigit() and _PLAIN.match(name):
            majors[int(number)] = name
    return majors


def checked(what: str, value: str) -> str:
    """`value` for a line of the unit; a usage error naming it if it holds a control character."""
    if _CONTROL.search(value):
        raise click.UsageError(f"{what} {shown(value)} holds a control character, which a unit file cannot "
                               f"carry: rename it")
    return value


def exec_word(word: str, what: str = "the command line") -> str:
    """One word of ExecStart= (systemd.service(5), "Command lines"): quoted where needed, % and $ doubled."""
    word = checked(what, word).replace("%", "%%").replace("$", "$$")
    if _PLAIN.match(word):
        return word
    return '"' + word.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _path_word(path: str, what: str) -> str:
    """A path in ReadWritePaths= or DeviceAllow=: quoted where needed, % doubled (no $ expansion there)."""
    path = checked(what, path).replace("%", "%%")
    if _PLAIN.match(path):
        return path
    if '"' in path or "\\" in path:
        raise click.UsageError(f"{what} {shown(path)} holds a quote or a backslash, which a unit's path "
                               f"settings cannot carry: rename it")
    return f'"{path}"'


def under(path: str, roots: Iterable[str]) -> bool:
    return any(path == root or path.startswith(root + "/") for root in roots)


def home_bind(path: str) -> str:
    """What of a home folder a unit shows for `path`: its first part below the home (/root/.pyenv for
    /root/.pyenv/versions/3.11/bin/python), so a user other than the home's owner may still reach it."""
    depth = next(len(Path(root).parts) + (root != "/root") for root in HOMES if under(path, (root,)))
    return str(Path(*Path(path).parts[:depth + 1]))


def _homes(needs: Needs) -> list[str]:
    """ProtectHome=: every home hidden (tmpfs), but what the gateway reads or writes there bound back."""
    reads = [home_bind(path) for path in needs.reads if under(path, HOMES)]
    writes = [path for path in needs.writes if under(path, HOMES)]
    if not reads and not writes:
        return ["ProtectHome=yes"]
    return ["ProtectHome=tmpfs",
            *(f"BindReadOnlyPaths={_path_word(path, 'the file')}" for path in dict.fromkeys(reads)),
            *(f"BindPaths={_path_word(path, 'the folder recorded into')}" for path in writes)]


def _sandbox(needs: Needs) -> list[str]:
    """The [Service] lines that confine the gateway to what `needs` names."""
    paths = [*needs.reads, *needs.writes]
    lines = [
        "NoNewPrivileges=yes",
        "ProtectSystem=strict",  # everything read-only but ReadWritePaths=
        "PrivateMounts=yes",
        *([] if needs.families else ["PrivateNetwork=yes"]),  # serial only: no network (a CAN bus is one)
        *_homes(needs),
        *([] if any(under(p, TEMPORARY) for p in paths) else ["PrivateTmp=yes"]),
        *(f"ReadWritePaths={_path_word(folder, 'the folder recorded into')}" for folder in needs.writes
          if not under(folder, HOMES)),
        "ProtectKernelTunables=yes", "ProtectKernelModules=yes", "ProtectKernelLogs=yes",
        "ProtectControlGroups=yes", "ProtectClock=yes", "ProtectHostname=yes", "ProtectProc=invisible",
        "ProcSubset=pid", "RestrictNamespaces=yes", "RestrictRealtime=yes", "RestrictSUIDSGID=yes",
        "LockPersonality=yes", "MemoryDenyWriteExecute=yes", "RemoveIPC=yes", "PrivateIPC=yes",
        "CapabilityBoundingSet=", "AmbientCapabilities=",
        "SystemCallArchitectures=native", "SystemCallFilter=@system-service",
        "SystemCallFilter=~@privileged @resources",
        "RestrictAddressFamilies=" + " ".join(["AF_UNIX", *sorted(needs.families)]),
        "UMask=0077",
    ]
    if needs.unknown_devices:
        return lines  # DevicePolicy= left out: those devices are not ours to name
    if not needs.devices:
        return [*lines, "PrivateDevices=yes", "DevicePolicy=closed"]
    return [*lines, "DevicePolicy=closed",
            *(f"DeviceAllow={_path_word(rule, 'the device')} rw" for rule in dict.fromkeys(needs.devices))]


def unit_text(exec_start: list[str], description: str, needs: Needs, *, watchdog: int, user: str | None,
              dynamic: bool) -> str:
    """The unit: `exec_start` run as `user` (None: root; `dynamic`: a user systemd makes), confined."""
    start = " ".join(exec_word(word) for word in exec_start)
    groups = ["SupplementaryGroups=dialout"] if needs.serial and user is not None else []  # dialout: serial, Debian
    lines = [
        "# Written by `vstig service`: a gateway for days (docs/how-to/service.md).",
        "[Unit]",
        f"Description={checked('the description', description).replace('%', '%%')}",
        "After=network-online.target",
        "Wants=network-online.target",
        "",
        "[Service]",
        "Type=notify",  # READY=1 once every link is open
        "NotifyAccess=main",
        f"ExecStart={start}",
        *([f"WatchdogSec={watchdog}"] if watchdog else []),
        "TimeoutStartSec=60",  # opening may wait for devices and Zenoh peers
        "TimeoutStopSec=15",  # a stop closes links and prints the counters in a few seconds
        "Restart=on-failure",
        "RestartSec=5",
        *([f"User={checked('the user', user)}"] if user else []),
        *(["DynamicUser=yes"] if dynamic else []),
        *groups,
        *_sandbox(needs),
        "",
        "[Install]",
        "WantedBy=multi-user.target",
    ]
    return "\n".join(lines) + "\n"
