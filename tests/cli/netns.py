"""Network namespaces for the federation tests: each gateway on its own interface, cut and healed at will.

As root, `Lan` builds a hub namespace holding a Linux bridge and one namespace
per gateway, joined to the hub by a veth pair, with 10.77.0.<n>/24 addresses.
Every name starts with `zenoh` plus a per-run tag, so concurrent runs never
collide, and `close()` removes all of it (deleting a namespace deletes its
interfaces). `cut(n)` / `heal(n)` take gateway n's cable out and put it back.

Elsewhere `netns_unavailable()` says why, for a clear skip reason.
"""

from __future__ import annotations

import os
import shutil
import subprocess

SUBNET = "10.77.0"


def netns_unavailable() -> str | None:
    """Why namespaces cannot be used here, or None."""
    if os.geteuid() != 0:
        return "network namespaces need root (`ip netns add`); ran the zenoh gateways on loopback instead"
    if shutil.which("ip") is None:
        return "iproute2 (`ip`) is not installed (tests/sysdeps.sh installs it when run as root)"
    probe = f"zenoh-{os.getpid() % 100000:05d}-probe"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True, timeout=20, check=False)
    if made.returncode:
        return f"`ip netns add` failed here: {made.stderr.strip() or made.returncode}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=20, check=False)
    return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=20)


class Lan:
    def __init__(self, gateways: int) -> None:
        self.tag = f"{os.getpid() % 100000:05d}"
        self.hub = f"zenoh-{self.tag}-hub"
        self.names = [f"zenoh-{self.tag}-gw{n}" for n in range(gateways)]
        self._made: list[str] = []
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def _build(self) -> None:
        _ip("netns", "add", self.hub)
        self._made.append(self.hub)
        bridge = f"zenoh{self.tag}br"
        _ip("-n", self.hub, "link", "add", bridge, "type", "bridge")
        _ip("-n", self.hub, "link", "set", bridge, "up")
        for n, ns in enumerate(self.names):
            _ip("netns", "add", ns)
            self._made.append(ns)
            inside, outside = f"zenoh{self.tag}g{n}", self._port(n)
            _ip("link", "add", inside, "netns", ns, "type", "veth", "peer", "name", outside, "netns", self.hub)
            _ip("-n", self.hub, "link", "set", outside, "master", bridge)
            _ip("-n", self.hub, "link", "set", outside, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "addr", "add", f"{self.address(n)}/24", "dev", inside)
            _ip("-n", ns, "link", "set", inside, "up")

    def _port(self, n: int) -> str:
        return f"zenoh{self.tag}h{n}"

    def address(self, n: int) -> str:
        return f"{SUBNET}.{n + 1}"

    def command(self, n: int) -> list[str]:
        """The prefix that runs a command inside gateway n's namespace."""
        return ["ip", "netns", "exec", self.names[n]]

    def cut(self, n: int) -> None:
        _ip("-n", self.hub, "link", "set", self._port(n), "down")

    def heal(self, n: int) -> None:
        _ip("-n", self.hub, "link", "set", self._port(n), "up")

    def close(self) -> None:
        while self._made:
            subprocess.run(["ip", "netns", "del", self._made.pop()], capture_output=True, timeout=20, check=False)

