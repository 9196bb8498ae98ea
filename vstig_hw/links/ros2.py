"""ROS 2 links (`ros2:` specs): a ROS 2 system sees the swarm and writes to it (the `ros2` extra).

`ros2:<swarm>` gives the gateway an rclpy node under /vstig/<swarm> (stigmergy 0;
/vstig/<swarm>/stigmergy<N> for another): every message heard on every link, the
table's changes, the roster (`robots`), put/get/table services, the counters on /diagnostics, and a
`write` topic whose samples come in as this link's heard messages (the guard, the
engine and a per-source share see them as any link's). What the gateway
broadcasts goes out on `broadcast`; signed writes and entries with their writers' tags on
`write_tagged` and `broadcast_tagged` (SPEC.md 10.5). Topics, types and QoS: docs/how-to/ros2.md.

Closed by default, as the zenoh: links: Fast DDS listens on loopback and shared
memory only, so ROS 2 nodes on this PC find the gateway and nothing beyond it can;
`discovery=subnet` opens it to the LAN, with a warning (ROS 2 nodes authenticate
nobody unless SROS2 is set up). The node runs in a process of its own, started as the
link opens (transports/ros2.py); the gateway's process never imports rclpy.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from typing import Any

from ..tagged import AuthPolicy
from .grammar import bad, integer, safe_name, split_query
from .link import Link, LinkSpec

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "Ros2Spec", "parse_ros2", "ros2_link_from_spec"]

GRAMMAR = ("ros2:<swarm>[?namespace=/<ns>&domain=N&stigmergy=N&discovery=localhost|subnet&profile=<fastdds.xml>"
           "&qos=reliable|best_effort&depth=N&write_rate=N]",)
EXAMPLES = {
    "ros2": ("ros2:lab", "ros2:lab?domain=7", "ros2:lab?stigmergy=2&qos=best_effort",
             "ros2:lab?namespace=/arena1/swarm&discovery=subnet"),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "ros2": "ros2: a ROS 2 node of the gateway's (the ros2 extra) under /vstig/<swarm> (stigmergy N>0: "
            "/vstig/<swarm>/stigmergy<N>; namespace= overrides): heard/<link> and broadcast topics "
            "(vstig_msgs/Message), changes (vstig_msgs/Change, keyed, transient-local: a late subscriber gets the "
            "table), robots (vstig_msgs/Robots, transient-local: the roster, on change, at most once a second), "
            "put/get/table services, the counters on /diagnostics; what ROS 2 nodes publish on write comes "
            "in as this link's messages (a PUT with timestamp 0 is stamped after the gateway's entry), at most "
            "write_rate= a second (default 500); write_tagged and broadcast_tagged (vstig_msgs/TaggedMessage) carry "
            "writers' tags where auth= checks them (docs/how-to/auth.md). "
            "domain= is the ROS domain id (default $ROS_DOMAIN_ID, else 0). "
            "Closed by default: Fast DDS on this PC only (loopback and shared memory); discovery=subnet opens it "
            "to the LAN (a warning: nobody is authenticated), profile= passes a Fast DDS XML profile through. "
            "qos= and depth= (default reliable, 100) are the topics' reliability and history.",
}
_EXAMPLE = EXAMPLES["ros2"][0]
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_NAMESPACE = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+\Z")
MAX_DOMAIN = 232  # the ROS domain ids Fast DDS's port scheme allows
MAX_STIGMERGY = 0xFFFF
MAX_DEPTH = 10_000
MAX_WRITE_RATE = 1_000_000

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Ros2Spec(LinkSpec):
    swarm: str
    namespace: str | None = None  # None: /vstig/<swarm>[/stigmergy<N>]
    domain: int | None = None
    stigmergy: int = 0
    discovery: str = "localhost"
    profile: str | None = None
    reliable: bool = True
    depth: int = 100
    write_rate: int = 500
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)

    @property
    def kind(self) -> str:
        return "ros2"

    @property
    def name(self) -> str:
        return safe_name(f"ros2-{self.swarm}")

    @property
    def files_read(self) -> tuple[str, ...]:
        return (self.profile,) if self.profile else ()

    @property
    def full_namespace(self) -> str:
        if self.namespace is not None:
            return self.namespace
        return f"/vstig/{self.swarm}" + (f"/stigmergy{self.stigmergy}" if self.stigmergy else "")

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); the gateway's node is named vstig_<swarm>_<robot_id>."""
        from ..extras import require

        require("ros2", "a ros2: link")  # before any link of the command opens
        return ros2_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)


def parse_ros2(spec: str, body: str) -> Ros2Spec:
    """`body` is the spec after `ros2:`."""
    swarm, params = split_query(spec, body, _EXAMPLE, ("namespace", "domain", "stigmergy", "discovery", "profile",
                                                        "qos", "depth", "write_rate"))
    if not _TOKEN.match(swarm):
        raise bad(spec, f"swarm name {swarm!r} must be letters, digits and '_', not starting with a digit (it is "
                        "one token of a ROS 2 namespace)", _EXAMPLE)
    namespace = params.get("namespace")
    if namespace is not None and not _NAMESPACE.match(namespace):
        raise bad(spec, f"namespace={namespace!r} must be an absolute ROS 2 namespace (/a/b: letters, digits, '_', "
                        "no token starting with a digit)", _EXAMPLE)
    discovery = params.get("discovery", "localhost")
    if discovery not in ("localhost", "subnet"):
        raise bad(spec, f"discovery={discovery!r} must be localhost or subnet", _EXAMPLE)
    profile = params.get("profile")
    if profile is not None and any(ch in profile for ch in "\0\n\r"):
        raise bad(spec, "the profile path contains a control character", _EXAMPLE)
    qos = params.get("qos", "reliable")
    if qos not in ("reliable", "best_effort"):
        raise bad(spec, f"qos={qos!r} must be reliable or best_effort", _EXAMPLE)

    def number(key: str, low: int, high: int, default: int | None) -> int | None:
        return integer(spec, _EXAMPLE, key, params[key], low, high) if key in params else default

    return Ros2Spec(swarm=swarm, namespace=namespace, domain=number("domain", 0, MAX_DOMAIN, None),
                    stigmergy=number("stigmergy", 0, MAX_STIGMERGY, 0) or 0, discovery=discovery, profile=profile,
                    reliable=qos == "reliable", depth=number("depth", 1, MAX_DEPTH, 100) or 100,
                    write_rate=number("write_rate", 1, MAX_WRITE_RATE, 500) or 500)


def ros2_link_from_spec(spec: Ros2Spec, name: str, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
    """A ROS 2 link (not yet open) whose broadcasts name `robot_id` as their sender."""
    from ..framing.ros2 import Ros2Framing
    from ..transports.ros2 import Ros2Options, Ros2Transport

    if spec.profile is None and spec.discovery == "subnet":
        log.warning("%s: WARNING: discovery=subnet: any ROS 2 node on the network can read and write the swarm "
                    "(ROS 2 authenticates nobody unless SROS2 is set up; see docs/how-to/ros2.md)", name)
    options = Ros2Options(namespace=spec.full_namespace, domain=spec.domain, discovery=spec.discovery,
                          reliable=spec.reliable, depth=spec.depth, write_rate=spec.write_rate, profile=spec.profile)
    sender = 0 if listen_only else robot_id
    transport = Ros2Transport(options, name=name, node_name=f"vstig_{spec.swarm}_{robot_id}", robot_id=sender)
    # Every ROS 2 node subscribed to `write` hears every sample on it: a PUT heard there is not broadcast back.
    return Link(name, transport, Ros2Framing(sender), one_domain=True)
