"""Khepera IV swarms running BuzzKH4: the gateway takes blabbermouth's place (`blabbermouth:` specs)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..tagged import AuthPolicy
from .grammar import bad, integer, split_query
from .link import Link, LinkSpec

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "BlabbermouthSpec", "blabbermouth_link_from_spec", "parse_blabbermouth"]

KH4_PORT = 24580  # the port bzzkh4 listens on (BuzzKH4 buzz_utility.c)

GRAMMAR = ("blabbermouth:<host>[:port],<host>[:port]...?size=N&deployment=<file.toml>",)
EXAMPLES = {
    "blabbermouth": ("blabbermouth:192.168.1.101,192.168.1.102,192.168.1.103?size=100&deployment=lab.toml",
                     "blabbermouth:k01.lab:24580,k02.lab:24580?size=64&deployment=kheperas.toml"),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "blabbermouth": "blabbermouth: replaces MISTLab's blabbermouth relay for Khepera IV robots running BuzzKH4 "
                    "(bzzkh4 tcp <size> ...): connects to each robot (port 24580 unless given), relays every "
                    "robot's frame to all the others, and sends our own under --robot-id. size= must be the "
                    "robots' msg_size; deployment= maps their Buzz keys and values to ours.",
}
_EXAMPLE = EXAMPLES["blabbermouth"][0]


@dataclass(frozen=True, slots=True)
class BlabbermouthSpec(LinkSpec):
    robots: tuple[tuple[str, int], ...]
    size: int
    deployment: str
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)

    @property
    def kind(self) -> str:
        return "blabbermouth"

    @property
    def name(self) -> str:
        return "blabbermouth"

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); our frames go out under `robot_id` (a sniffer sends none, but relays)."""
        return blabbermouth_link_from_spec(self, name or self.name, robot_id)


def parse_blabbermouth(spec: str, body: str) -> BlabbermouthSpec:
    """`body` is the spec after `blabbermouth:`."""
    addresses, params = split_query(spec, body, _EXAMPLE, ("size", "deployment"))
    robots = []
    for address in addresses.split(","):
        host, sep, port = address.strip().rpartition(":") if ":" in address else (address.strip(), "", "")
        if not host or any(ch in host for ch in "\0\n\r /?&"):
            raise bad(spec, f"robot address {address!r} is not host[:port]", _EXAMPLE)
        robots.append((host, integer(spec, _EXAMPLE, "port", port, 1, 65535) if sep else KH4_PORT))
    if "size" not in params or "deployment" not in params:
        raise bad(spec, "size=N (the robots' msg_size) and deployment=<file.toml> are both needed", _EXAMPLE)
    return BlabbermouthSpec(tuple(robots), integer(spec, _EXAMPLE, "size", params["size"], 5, 65535),
                            params["deployment"])


def blabbermouth_link_from_spec(spec: BlabbermouthSpec, name: str, robot_id: int) -> Link[bytes]:
    """Connects to every robot when opened; our own frames go out under `robot_id`."""
    from ..dialects.framing import BuzzKh4Framing
    from ..dialects.mapping import load_deployment
    from ..transports.blabbermouth import BlabbermouthTransport

    deployment = load_deployment(spec.deployment)
    transport = BlabbermouthTransport(list(spec.robots), spec.size, name=name)
    # the transport relays every robot's frame to every other robot: all of them heard what we heard
    return Link(name, transport, BuzzKh4Framing(deployment, robot_id, spec.size), one_domain=True)
