"""Links from what a user names them by: spec strings, parsed specs or ready Link objects, with unique names.

Shared by the CLI (`bridge`, `put`, `get`...) and the Python API (`vstig_hw.join`), so a spec means the
same thing in both and the same bad spec gets the same one line.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..counters import ENGINE_STATS
from ..tagged import AuthPolicy
from .link import Link, LinkSpec, NamesSenders
from .registry import parse

__all__ = ["MAX_LINKS", "MAX_LINKS_OF_KIND", "LinkBuildError", "assemble_links", "check_link_count", "check_robot_id"]

# How many links one gateway (a command, a join) takes (docs/reference/link-specs.md, "How many links"; DECISIONS.md):
# a lab's radios, buses and PCs fit, and each costs a thread or two, so a stop stays well within its 2 s.
MAX_LINKS = 64
MAX_LINKS_OF_KIND = {"ros2": 2}  # each a ROS 2 process of its own (~80 MB, ~25 threads, up to 0.5 s to stop)
LIMITS_DOCS = "docs/reference/link-specs.md"


class LinkBuildError(ValueError):
    """A link that cannot be built as asked; `argument` names what is wrong: "robot_id" or "links"."""

    def __init__(self, message: str, argument: str) -> None:
        super().__init__(message)
        self.argument = argument


def check_link_count(count: int) -> None:
    """LinkBuildError("links") when `count` links are more than one gateway takes: checked before any is parsed."""
    if count > MAX_LINKS:
        raise LinkBuildError(f"{count} links: one gateway takes at most {MAX_LINKS} (run several, each with its "
                             f"own links; see {LIMITS_DOCS})", "links")


def _check_kinds(specs: Sequence[LinkSpec | Link[Any]]) -> None:
    kinds = [spec.kind for spec in specs if isinstance(spec, LinkSpec)]
    for kind, most in MAX_LINKS_OF_KIND.items():
        if kinds.count(kind) > most:
            raise LinkBuildError(f"{kinds.count(kind)} {kind} links: one gateway takes at most {most} (see "
                                 f"{LIMITS_DOCS})", "links")


def check_robot_id(specs: Sequence[LinkSpec], robot_id: int) -> None:
    """LinkBuildError("robot_id") when a spec's sender field (a CAN ID scheme) has no room for `robot_id`."""
    for spec in specs:
        if isinstance(spec, NamesSenders):
            try:
                spec.check_sender(robot_id)
            except ValueError as error:
                raise LinkBuildError(str(error), "robot_id") from None


def assemble_links(items: Sequence[str | LinkSpec | Link[Any]], robot_id: int = 0,
                   listen_only: bool = False) -> list[Link[Any]]:
    """One Link per item, a spec named after its device (made unique: radio, radio-2...); Links pass as they are.

    A bad spec or item, or more links than MAX_LINKS (MAX_LINKS_OF_KIND), raises LinkBuildError("links") with
    one line naming it.
    """
    check_link_count(len(items))
    specs: list[LinkSpec | Link[Any]] = []
    for number, item in enumerate(items):
        if isinstance(item, str):
            try:
                specs.append(parse(item))
            except ValueError as error:
                raise LinkBuildError(str(error), "links") from None
        elif isinstance(item, Link | LinkSpec):
            specs.append(item)
        else:
            raise LinkBuildError(f"link {number + 1} is a {type(item).__name__}: give a spec string "
                                 "(e.g. 'can:socketcan:can0') or a Link", "links")
    _check_kinds(specs)
    if not listen_only:
        check_robot_id([spec for spec in specs if not isinstance(spec, Link)], robot_id)
    links: list[Link[Any]] = []
    seen: dict[str, int] = {ENGINE_STATS: 1}  # that name is taken by the engine's counters
    for spec in specs:
        if isinstance(spec, Link):
            seen[spec.name] = seen.get(spec.name, 0) + 1
            links.append(spec)
            continue
        name = spec.name
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}-{seen[name]}"
        try:
            link = spec.build(name, robot_id=robot_id, listen_only=listen_only)
        except ValueError as error:  # building opens nothing: what fails here is how the link was asked for
            raise LinkBuildError(f"{spec.kind}:{spec.name}: {error}", "links") from None
        if spec.auth is AuthPolicy.REQUIRE and not link.framing.carries_tags:
            raise LinkBuildError(f"{spec.kind}:{spec.name}: auth=require, but {link.framing.name} frames have no room "
                                 "for tags (SPEC.md 10.5): give its robots a link of their own with auth=off", "links")
        link.auth = spec.auth
        links.append(link)
    return links
