"""Khepera IV swarms running BuzzKH4: the gateway takes blabbermouth's place (`blabbermouth:` specs)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..dialects.framing import BuzzKh4Framing
from ..dialects.mapping import load_deployment
from ..transports.blabbermouth import BlabbermouthTransport
from .link import Link

if TYPE_CHECKING:
    from .spec import BlabbermouthSpec

__all__ = ["blabbermouth_link_from_spec"]


def blabbermouth_link_from_spec(spec: BlabbermouthSpec, name: str, robot_id: int) -> Link[bytes]:
    """Connects to every robot when opened; our own frames go out under `robot_id`."""
    deployment = load_deployment(spec.deployment)
    transport = BlabbermouthTransport(list(spec.robots), spec.size, name=name)
    # the transport relays every robot's frame to every other robot: all of them heard what we heard
    return Link(name, transport, BuzzKh4Framing(deployment, robot_id, spec.size), one_domain=True)
